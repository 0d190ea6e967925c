// The child-process guard around HDF5 (netcdf4_probe.h): a crash or an endless loop in the child
// becomes a clear error naming the file, the parent lives on; valid netCDF-4 files pass.
#include <gtest/gtest.h>
#include <netcdf.h>
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include "netcdf4_probe.h"
#include "volume_io.h"

namespace tfm {
namespace {

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

TEST(Netcdf4Probe, ACrashInTheChildIsAnErrorNamingTheFile) {
  const std::string e = error_of([] { run_isolated("bad.nc", [] { raise(SIGSEGV); }, std::chrono::seconds(10)); });
  EXPECT_NE(e.find("bad.nc: malformed netCDF-4/HDF5 file: the HDF5 library crashed"), std::string::npos) << e;
  EXPECT_NE(e.find("Segmentation fault"), std::string::npos) << e;
}

TEST(Netcdf4Probe, AChildThatExitsWithAnErrorStatusIsAnError) {
  const std::string e = error_of([] { run_isolated("abort.nc", [] { _exit(1); }, std::chrono::seconds(10)); });
  EXPECT_NE(e.find("abort.nc: malformed netCDF-4/HDF5 file: the HDF5 library failed"), std::string::npos) << e;
  EXPECT_NE(e.find("status 1"), std::string::npos) << e;
}

TEST(Netcdf4Probe, AChildThatNeverEndsIsKilledAfterTheTimeout) {
  // The probe's own grace is the timeout it is given; past it, it looks every 2 ms, kills and
  // reaps: the fork, the kill and the reaping take milliseconds, kSlack allows for a loaded
  // two-core machine scheduling them late.
  constexpr std::chrono::milliseconds kTimeout{300};
  constexpr std::chrono::duration<double> kSlack{1.0};
  const auto t0 = std::chrono::steady_clock::now();
  const std::string e = error_of([&] {
    run_isolated("loop.nc", [] { for (;;) std::this_thread::sleep_for(std::chrono::seconds(1)); }, kTimeout);
  });
  const std::chrono::duration<double> s = std::chrono::steady_clock::now() - t0;
  EXPECT_NE(e.find("loop.nc: malformed netCDF-4/HDF5 file: the HDF5 library did not finish reading its metadata "
                   "within 0.30 s"),
            std::string::npos)
      << e;
  EXPECT_GE(s.count(), std::chrono::duration<double>(kTimeout).count()) << "killed before its timeout";
  EXPECT_LT(s.count(), std::chrono::duration<double>(kTimeout + kSlack).count());
}

TEST(Netcdf4Probe, ANormalChildPassesQuietly) {
  EXPECT_EQ(error_of([] { run_isolated("fine.nc", [] {}, std::chrono::seconds(10)); }), "");
}

TEST(Netcdf4Probe, RecognizesTheHdf5SignatureWhereHdf5LooksForIt) {
  const std::string sig("\x89HDF\r\n\x1a\n", 8);
  EXPECT_TRUE(has_hdf5_signature(sig + "rest"));
  EXPECT_TRUE(has_hdf5_signature(std::string(512, 'u') + sig));   // after a user block
  EXPECT_TRUE(has_hdf5_signature(std::string(1024, 'u') + sig));
  EXPECT_FALSE(has_hdf5_signature(std::string(100, 'u') + sig));  // not an allowed offset
  EXPECT_FALSE(has_hdf5_signature("CDF\x01rest"));
  EXPECT_FALSE(has_hdf5_signature(""));
}

// A real netCDF-4 file goes through the probe and loads; a truncated one is refused with a
// message naming it (netCDF-C's, or the probe's), never a crash of the test process.
TEST(Netcdf4Probe, ValidNetcdf4FilesLoadAndTruncatedOnesFailCleanly) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "tfmatch_probe_test";
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "v.nc").string();
  int nc = 0, dims[3], var = 0;
  ASSERT_EQ(nc_create(path.c_str(), NC_CLOBBER | NC_NETCDF4, &nc), NC_NOERR);
  nc_def_dim(nc, "z", 3, &dims[0]);
  nc_def_dim(nc, "y", 4, &dims[1]);
  nc_def_dim(nc, "x", 5, &dims[2]);
  nc_def_var(nc, "t", NC_FLOAT, 3, dims, &var);
  nc_enddef(nc);
  std::vector<float> values(60);
  for (size_t i = 0; i < values.size(); ++i) values[i] = float(i);
  nc_put_var_float(nc, var, values.data());
  ASSERT_EQ(nc_close(nc), NC_NOERR);
  probe_netcdf4_metadata(path);
  const Volume v = load_volume(path + ":t");
  EXPECT_EQ(v.values.size(), 60u);

  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string cut = (dir / "cut.nc").string();
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  const std::string e = error_of([&] { load_volume(cut + ":t"); });
  EXPECT_NE(e.find(cut), std::string::npos) << e;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tfm
