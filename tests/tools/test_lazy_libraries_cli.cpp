// netCDF-C and ecCodes as a user meets them: opened when a file needs them, never at start-up
// (host/io/lazy_library.h), so commands that read no such file do not load their ~40 libraries.
#include <gtest/gtest.h>

#include "cli_runner.h"
#include "slab_test_files.h"

namespace tfm {
namespace {

using test::loader_log_shows;

TEST(LazyLibraries, OpenedOnlyByTheFilesThatNeedThem) {
  test::TempDir dir;
  const std::string raw = slab_test::write_raw(dir.path, "a", slab_test::test_field({5, 4, 3}, 1)).string();
  const std::string nc = slab_test::write_netcdf(dir.path, "b", slab_test::test_field({5, 4, 3}, 2)).string();
  const test::CliEnvironment env{{"LD_DEBUG", "libs"}};
  for (const std::string args : {std::string("--version"), "info " + raw}) {
    const test::CliResult r = test::run_cli(args, test::kCliTimeout, env);
    ASSERT_EQ(r.exit_code, 0) << args << "\n" << r.output;
    ASSERT_TRUE(loader_log_shows(r.output, "libc.so.6")) << "no loader log: " << r.output.substr(0, 2000);
    for (const std::string library : {"libnetcdf.so", "libeccodes.so", "libhdf5_serial.so", "libcurl-gnutls.so"})
      EXPECT_FALSE(loader_log_shows(r.output, library)) << args << " loaded " << library;
  }
  const test::CliResult r = test::run_cli("info " + nc, test::kCliTimeout, env);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(loader_log_shows(r.output, "libnetcdf.so")) << r.output.substr(0, 4000);
  EXPECT_FALSE(loader_log_shows(r.output, "libeccodes.so")) << "a netCDF file loaded ecCodes";
}

}  // namespace
}  // namespace tfm
