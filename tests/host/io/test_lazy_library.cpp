// LazyLibrary (host/io/lazy_library.h), the opening of netCDF-C and ecCodes on first use: a
// library that cannot be opened or lacks a function is a clear error, every time; the folder the
// build found a library in is the fallback.
#include <gtest/gtest.h>

#include <dlfcn.h>

#include <filesystem>

#include "cli_runner.h"
#include "tfmatch/io/lazy_library.h"

namespace tfm {
namespace {

TEST(LazyLibraries, MissingLibrariesAndFunctionsAreClearErrors) {
  LazyLibrary missing("libtfmatch-no-such-library.so.7", "", "Nothing (Debian: nothing)");
  for (int attempt = 0; attempt < 2; ++attempt) {  // the same error again, not a crash or a retry
    try {
      missing.symbol("f");
      ADD_FAILURE() << "a missing library gave a function";
    } catch (const std::runtime_error& e) {
      EXPECT_EQ(std::string(e.what()).rfind("Nothing (Debian: nothing): cannot load libtfmatch-no-such-library.so.7: ", 0),
                0u)
          << e.what();
    }
  }
  // libz, which this program links: the function is the one the loader gives everyone.
  LazyLibrary zlib("libz.so.1", "", "zlib");
  EXPECT_EQ(zlib.symbol("zlibVersion"), dlsym(RTLD_DEFAULT, "zlibVersion"));
  EXPECT_THROW(zlib.symbol("tfmatch_no_such_function"), std::runtime_error);
  try {
    zlib.symbol("tfmatch_no_such_function");
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "zlib: libz.so.1 has no function tfmatch_no_such_function");
  }
}

// A name the loader's search does not find is opened from the folder the build found it in.
TEST(LazyLibraries, TheBuildsFolderIsTheFallback) {
  Dl_info zlib{};
  ASSERT_NE(dladdr(dlsym(RTLD_DEFAULT, "zlibVersion"), &zlib), 0);
  test::TempDir dir;
  std::filesystem::copy_file(zlib.dli_fname, dir / "libtfmatch-fallback-test.so");
  LazyLibrary fallback("libtfmatch-fallback-test.so", dir.path.c_str(), "test");
  EXPECT_NE(fallback.symbol("zlibVersion"), nullptr);
}

}  // namespace
}  // namespace tfm
