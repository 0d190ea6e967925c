// A shared library opened on first use: the file-format libraries that only some commands need
// (netCDF-C with HDF5, curl, GnuTLS, Kerberos and LDAP behind it; ecCodes), so that the others do
// not pay for loading them at every start (netCDF-C's 40 libraries: ~19 ms of a 37 ms
// `tfmatch --version` on the 2-core development machine). netcdf_library.cpp and
// eccodes_library.cpp define the library functions tfmatch calls, each forwarding to the real one
// resolved here, so the code calling them is unchanged.
#pragma once

#include <string>

namespace tfm {

class LazyLibrary {
 public:
  // `soname`: what a program linked to the library would load (libnetcdf.so.19); `fallback_dir`:
  // the folder the build found it in, tried when the loader's search does not find it; `what`:
  // the library's name in messages, with the package that provides it.
  LazyLibrary(const char* soname, const char* fallback_dir, const char* what);
  LazyLibrary(const LazyLibrary&) = delete;
  LazyLibrary& operator=(const LazyLibrary&) = delete;

  // The function `name` of the library, opened on the first call (once, thread-safe). Throws
  // std::runtime_error "<what>: cannot load <soname>: <loader's reason>" when the library cannot
  // be opened (the same error on every later call) or lacks the function.
  void* symbol(const char* name);

 private:
  std::string soname_, fallback_dir_, what_;
  void* handle_ = nullptr;
  std::string error_;
};

}  // namespace tfm

// The body of a forwarding definition of the library function `name` (tfmatch's own definition,
// whose type is the declared one): the real function resolved once, then called.
#define TFM_LAZY_FORWARD(library, name, ...)                                                   \
  static const auto real = reinterpret_cast<decltype(&::name)>((library).symbol(#name));    \
  return real(__VA_ARGS__);
