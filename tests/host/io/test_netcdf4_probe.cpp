// The child-process guard around HDF5 (netcdf4_probe.h): a crash or an endless loop in the child
// becomes a clear error naming the file, the parent lives on; valid netCDF-4 files pass.
#include <gtest/gtest.h>
#include <netcdf.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <thread>

#include "formats_test_util.h"
#include "scoped_env.h"
#include "tfmatch/io/netcdf4_probe.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/cancellation.h"

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

// A temporary folder for shell scripts standing in for the probe program: what their child
// does is up to the test.
class ScriptDir {
 public:
  std::string script(const std::string& name, const std::string& body) const {
    const std::string file = path(name).string();
    std::ofstream(file) << "#!/bin/sh\n" << body << "\n";
    chmod(file.c_str(), 0755);
    return file;
  }
  std::filesystem::path path(const std::string& name) const { return dir_ / name; }

 private:
  formats_test::TempDir dir_;
};

using test::ScopedEnv;

TEST(Netcdf4Probe, AProgramThatCrashesExitsOrHangsIsAnErrorNamingTheFile) {
  const ScriptDir dir;
  const auto run = [&](const std::string& body, std::chrono::milliseconds timeout = std::chrono::seconds(10)) {
    return error_of([&] { EXPECT_TRUE(run_program_isolated("bad.nc", dir.script("p", body), {}, {}, timeout)); });
  };
  std::string e = run("kill -SEGV $$");
  EXPECT_NE(e.find("bad.nc: malformed netCDF-4/HDF5 file: the HDF5 library crashed"), std::string::npos) << e;
  EXPECT_NE(e.find("Segmentation fault"), std::string::npos) << e;
  e = run("exit 1");
  EXPECT_NE(e.find("bad.nc: malformed netCDF-4/HDF5 file: the HDF5 library failed"), std::string::npos) << e;
  EXPECT_NE(e.find("status 1"), std::string::npos) << e;
  const auto t0 = std::chrono::steady_clock::now();
  e = run("exec sleep 100", std::chrono::milliseconds(300));
  EXPECT_NE(e.find("bad.nc: malformed netCDF-4/HDF5 file: the HDF5 library did not finish"), std::string::npos) << e;
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0);
  EXPECT_EQ(run("exit 0"), "");
}

// Arguments reach the program as given, the input as its standard input (the whole of it), and
// its standard output goes nowhere (the caller's is not its to write on).
TEST(Netcdf4Probe, TheProgramGetsItsArgumentsAndInput) {
  const ScriptDir dir;
  const std::string seen = dir.path("seen").string();
  const std::string program = dir.script("p", "printf '%s|' \"$@\" > " + seen + "; cat >> " + seen + "; echo to-stdout");
  std::string input(300000, 'x');
  input.back() = 'y';
  testing::internal::CaptureStdout();
  EXPECT_TRUE(run_program_isolated("f.nc", program, {"--a", "b c", "-- d"}, input, std::chrono::seconds(10)));
  EXPECT_EQ(testing::internal::GetCapturedStdout(), "");
  std::ifstream in(seen, std::ios::binary);
  const std::string got((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(got, "--a|b c|-- d|" + input);
}

// A program that is not there, or cannot run (status 127: what a shell or the dynamic loader
// gives), runs nothing and says so: the probe then forks instead.
TEST(Netcdf4Probe, AProgramThatCannotStartIsReportedNotBlamedOnTheFile) {
  const ScriptDir dir;
  EXPECT_FALSE(run_program_isolated("f.nc", dir.path("missing").string(), {}, {}, std::chrono::seconds(10)));
  EXPECT_FALSE(run_program_isolated("f.nc", dir.script("p", "exit 127"), {}, {}, std::chrono::seconds(10)));
  const ScopedEnv missing("TFMATCH_NETCDF4_PROBE", dir.path("missing").string());
  EXPECT_EQ(error_of([] { probe_netcdf4_metadata("f.nc", {}, std::chrono::seconds(10)); }), "");
}

// The probe runs the program TFMATCH_NETCDF4_PROBE names (ctest names the build's), in its own
// process: a crash there is the file's error.
TEST(Netcdf4Probe, TheProbeRunsItsProgram) {
  const ScriptDir dir;
  const ScopedEnv crashing("TFMATCH_NETCDF4_PROBE", dir.script("p", "kill -SEGV $$"));
  EXPECT_EQ(netcdf4_probe_program(), dir.path("p").string());
  const std::string e = error_of([] { probe_netcdf4_metadata("x.nc", "bytes", std::chrono::seconds(10)); });
  EXPECT_NE(e.find("x.nc: malformed netCDF-4/HDF5 file: the HDF5 library crashed"), std::string::npos) << e;
}

// A cancellation (Ctrl-C, SIGTERM, or a host's request) stops the wait: the child is killed and
// the caller gets Cancelled, not an error about the file.
TEST(Netcdf4Probe, ACancellationStopsTheWaitAndKillsTheChild) {
  const ScriptDir dir;
  const std::string program = dir.script("p", "exec sleep 100");
  std::thread canceller([] {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    request_cancel(SIGINT);
  });
  const auto t0 = std::chrono::steady_clock::now();
  int signal = -1;
  try {
    run_program_isolated("slow.nc", program, {}, {}, std::chrono::seconds(60));
  } catch (const Cancelled& c) {
    signal = c.signal();
  }
  canceller.join();
  reset_cancel();
  EXPECT_EQ(signal, SIGINT);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0);
}

// A file is probed once while it stays as it was (its verdict, pass or error, is remembered); a
// changed one is probed again; bytes in memory always are.
TEST(Netcdf4Probe, AFileIsProbedOncePerProcessWhileItStaysTheSame) {
  const ScriptDir dir;
  const std::string count = dir.path("count").string();
  const ScopedEnv counting("TFMATCH_NETCDF4_PROBE", dir.script("p", "echo run >> " + count));
  const std::string file = dir.path("f.nc").string();
  std::ofstream(file) << "first";
  const auto runs = [&] {
    std::ifstream in(count);
    return std::count(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>(), '\n');
  };
  probe_netcdf4_metadata(file);
  probe_netcdf4_metadata(file);
  EXPECT_EQ(runs(), 1);
  std::ofstream(file, std::ios::app) << " and more";
  probe_netcdf4_metadata(file);
  EXPECT_EQ(runs(), 2);
  probe_netcdf4_metadata(file, "bytes");
  probe_netcdf4_metadata(file, "bytes");
  EXPECT_EQ(runs(), 4);
  // One that failed fails again with the same message, at once (the slab reader, then the whole
  // load, of a file on which HDF5 loops wait for one timeout, not two); changed, it is probed anew.
  const std::string bad = dir.path("bad.nc").string();
  std::ofstream(bad) << "bad";
  {
    const ScopedEnv looping("TFMATCH_NETCDF4_PROBE", dir.script("c", "echo run >> " + count + "; exec sleep 100"));
    const std::string first = error_of([&] { probe_netcdf4_metadata(bad, {}, std::chrono::milliseconds(300)); });
    EXPECT_NE(first.find(bad + ": malformed netCDF-4/HDF5 file: the HDF5 library did not finish"), std::string::npos)
        << first;
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_EQ(error_of([&] { probe_netcdf4_metadata(bad, {}, std::chrono::milliseconds(300)); }), first);
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 0.2);
    EXPECT_EQ(runs(), 5);
  }
  std::ofstream(bad, std::ios::app) << ", repaired";
  probe_netcdf4_metadata(bad);
  EXPECT_EQ(runs(), 6);
}

// The build's program (the test program names it in TFMATCH_NETCDF4_PROBE; a test build carried
// to another machine without it skips). On its own: wrong arguments are status 2 (never 127); a
// file it cannot finish reading (a FIFO nobody writes: netCDF-C's open waits on it forever) ends
// it after the seconds it was given, even when no caller is left to kill it.
TEST(Netcdf4Probe, TheProgramRefusesWrongArgumentsAndGivesUpByItself) {
  const char* built = std::getenv("TFMATCH_NETCDF4_PROBE");
  if (!built || access(built, X_OK) != 0)
    GTEST_SKIP() << "the build's tfmatch-netcdf4-probe is not here: " << (built ? built : "TFMATCH_NETCDF4_PROBE unset");
  std::string e = error_of([&] { run_program_isolated("a.nc", built, {"a.nc"}, {}, std::chrono::seconds(10)); });
  EXPECT_NE(e.find("status 2"), std::string::npos) << e;
  e = error_of([&] { run_program_isolated("a.nc", built, {"--give-up-after", "0", "--", "a.nc"}, {}, std::chrono::seconds(10)); });
  EXPECT_NE(e.find("status 2"), std::string::npos) << e;
  const ScriptDir dir;
  const std::string fifo = dir.path("fifo.nc").string();
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  const auto t0 = std::chrono::steady_clock::now();
  e = error_of([&] { run_program_isolated(fifo, built, {"--give-up-after", "1", "--", fifo}, {}, std::chrono::seconds(20)); });
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_NE(e.find("the HDF5 library crashed reading its metadata (Alarm clock)"), std::string::npos) << e;
  EXPECT_GE(s, 0.9);
  EXPECT_LT(s, 10.0);
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
  // The bytes in memory go through the program too; so do half of them (netCDF-C's own error
  // is the caller's to report).
  probe_netcdf4_metadata(path, bytes);
  probe_netcdf4_metadata(path, std::string_view(bytes).substr(0, bytes.size() / 2));
  const std::string cut = (dir / "cut.nc").string();
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  const std::string e = error_of([&] { load_volume(cut + ":t"); });
  EXPECT_NE(e.find(cut), std::string::npos) << e;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tfm
