// A shared library opened on first use (lazy_library.h). By hand: glibc has no lazy loading of a
// program's dependencies, and Debian packages no stub generator for it.
#include "tfmatch/io/lazy_library.h"

#include <dlfcn.h>

#include <mutex>
#include <stdexcept>

namespace tfm {

LazyLibrary::LazyLibrary(const char* soname, const char* fallback_dir, const char* what)
    : soname_(soname), fallback_dir_(fallback_dir), what_(what) {}

void* LazyLibrary::symbol(const char* name) {
  // A function-local flag per object would do; one lock for all is simpler and opens are rare.
  static std::mutex lock;
  std::lock_guard guard(lock);
  if (!handle_ && error_.empty()) {
    // RTLD_GLOBAL: as if linked (the library's own plugins, HDF5's filters, may look up its symbols).
    handle_ = dlopen(soname_.c_str(), RTLD_NOW | RTLD_GLOBAL);
    if (!handle_) {
      const char* why = dlerror();
      error_ = why ? why : "unknown reason";
      if (!fallback_dir_.empty()) {
        handle_ = dlopen((fallback_dir_ + "/" + soname_).c_str(), RTLD_NOW | RTLD_GLOBAL);
        if (handle_) error_.clear();
      }
    }
  }
  if (!handle_) throw std::runtime_error(what_ + ": cannot load " + soname_ + ": " + error_);
  dlerror();
  void* found = dlsym(handle_, name);
  if (!found) throw std::runtime_error(what_ + ": " + soname_ + " has no function " + name);
  return found;
}

}  // namespace tfm
