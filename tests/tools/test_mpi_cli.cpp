// `mpirun -n R tfmatch optimize --stream on` and `correlate` as a user runs them (docs/mpi.md): the
// TF file and the correlation field are byte-identical for R = 1, 2, 3, 4 and to a run without a
// launcher; a rank that fails (rank 1
// given a device that does not exist) stops every rank with its message, a non-zero exit and no
// output; commands that do not split over ranks say so. Skipped, saying why, where tfmatch was
// built without MPI.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <vector>

#include "cli_runner.h"
#include "slab_test_files.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;

using test::read_text;

#ifdef TFMATCH_MPIEXEC
// What OpenMPI needs on test machines: CI runs tests as root, which it refuses unless told; and in
// containers that forbid reading another process's memory (process_vm_readv) its shared-memory
// transport's single-copy path fails, so it copies through the shared segment instead.
void mpi_environment() {
  setenv("OMPI_ALLOW_RUN_AS_ROOT", "1", 1);
  setenv("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1", 1);
  setenv("OMPI_MCA_btl_vader_single_copy_mechanism", "none", 0);
}

// `COMMAND` through the shell, stdout and stderr together, within 5 minutes.
test::CliResult run_shell(const std::string& command) {
  mpi_environment();
  return test::run_shell("timeout 300 " + command);
}

// `mpirun --oversubscribe -n R tfmatch ARGS` (OpenMPI's launcher; ranks may outnumber the cores).
test::CliResult run_mpi(int ranks, const std::string& args) {
  return run_shell(std::string(TFMATCH_MPIEXEC) + " --oversubscribe -n " + std::to_string(ranks) + " " +
                   TFMATCH_CLI_PATH + " " + args);
}

// Whether the launcher starts two processes here at all (a machine without a usable network or
// shared memory cannot run any MPI job): the launcher's own output when it cannot, else empty.
std::string launcher_problem() {
  static const std::string problem = [] {
    const test::CliResult r = run_shell(std::string(TFMATCH_MPIEXEC) + " --oversubscribe -n 2 /bin/true");
    return r.exit_code == 0 ? std::string() : "exit " + std::to_string(r.exit_code) + ": " + r.output;
  }();
  return problem;
}
#endif

#ifdef TFMATCH_MPIEXEC
// Runs the launcher command `cmd` with its output in `log`, sends SIGINT to the launcher (Ctrl-C)
// 1.5 s after `started` appears in the log (at once when empty: after 1.5 s), and returns its
// wait status; fails the test when the job has not stopped within 20 s.
int interrupt_job(const std::string& cmd, const fs::path& log, const std::string& started) {
  mpi_environment();
  const pid_t pid = fork();
  if (pid < 0) {
    ADD_FAILURE() << "fork failed";
    return -1;
  }
  if (pid == 0) {
    const std::string shell = "exec " + cmd + " > " + log.string() + " 2>&1";
    execl("/bin/sh", "sh", "-c", shell.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  const auto begun = std::chrono::steady_clock::now();
  while (!started.empty() && read_text(log).find(started) == std::string::npos &&
         std::chrono::steady_clock::now() - begun < std::chrono::seconds(60))
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  kill(pid, SIGINT);
  int status = 0;
  const auto t0 = std::chrono::steady_clock::now();
  while (waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() - t0 > std::chrono::seconds(60)) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      ADD_FAILURE() << "the job did not stop within 60 s of SIGINT:\n" << read_text(log);
      return status;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(20));
  return status;
}
#endif

class MpiCli : public ::testing::Test {
 protected:
  void SetUp() override {
#ifndef TFMATCH_MPIEXEC
    GTEST_SKIP() << "tfmatch was built without MPI (TFMATCH_MPI off: no MPI implementation was found; "
                    "Debian: libopenmpi-dev openmpi-bin)";
#else
    if (const std::string problem = launcher_problem(); !problem.empty())
      GTEST_SKIP() << "the MPI launcher cannot start two processes of /bin/true on this machine (" << problem
                   << "): not tfmatch's doing";
#endif
    const Volume ref = slab_test::test_field({37, 29, 23}, 0), field = slab_test::test_field({37, 29, 23}, 6);
    ref_file = slab_test::write_raw(dir.path(), "ref", ref).string();
    field_file = slab_test::write_raw(dir.path(), "field", field).string();
  }
  std::string args(const std::string& out, const std::string& stream = "on") const {
    return "optimize --ref " + ref_file + " --field " + field_file + " --ref-tf viridis --tf-size 24 --stream " + stream +
           " --out " + (dir / out).string();
  }
  formats_test::TempDir dir;
  std::string ref_file, field_file;
};

TEST_F(MpiCli, TfBytesAreTheSameForEveryRankCount) {
#ifdef TFMATCH_MPIEXEC
  const auto plain = test::run_cli(args("plain.json"));
  ASSERT_EQ(plain.exit_code, 0) << plain.output;
  const std::string expected = read_text(dir / "plain.json");
  ASSERT_FALSE(expected.empty());
  for (int ranks : {1, 2, 3, 4}) {
    SCOPED_TRACE(std::to_string(ranks) + " ranks");
    const std::string out = "ranks" + std::to_string(ranks) + ".json";
    const auto r = run_mpi(ranks, args(out) + " --json " + (dir / ("summary" + std::to_string(ranks) + ".json")).string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_EQ(read_text(dir / out), expected);
    // Rank 0 alone reports: one summary, naming the ranks when there are several.
    size_t wrote = 0;
    for (size_t at = r.output.find("wrote "); at != std::string::npos; at = r.output.find("wrote ", at + 1)) ++wrote;
    EXPECT_EQ(wrote, 1u) << r.output;
    if (ranks > 1) {
      // Rank 0's share of the 23 slices as it reads them: 12 of 2 ranks, 8 of 3, 6 of 4.
      const std::string n = std::to_string(ranks == 2 ? 12 : ranks == 3 ? 8 : 6);
      EXPECT_NE(r.output.find("1 slab of " + n + " z-slices, 2 passes over the files (rank 0's share: z-slices 0–" +
                              std::to_string(std::stoi(n) - 1) + " of 23, " + std::to_string(ranks) + " MPI ranks)"),
                std::string::npos)
          << r.output;
      EXPECT_NE(read_text(dir / ("summary" + std::to_string(ranks) + ".json")).find("\"mpi_ranks\": " + std::to_string(ranks)),
                std::string::npos);
    }
  }
#endif
}

// correlate: each rank its z-slices of every member, gathered on rank 0: the same field bytes as
// one process loading the members whole, for 1 to 4 ranks.
TEST_F(MpiCli, CorrelationFieldBytesAreTheSameForEveryRankCount) {
#ifdef TFMATCH_MPIEXEC
  std::string members;
  for (int m = 0; m < 7; ++m)
    members += " " + slab_test::write_raw(dir.path(), "member" + std::to_string(m), slab_test::test_field({37, 29, 23}, m))
                         .string();
  const std::string args = "correlate --members" + members + " --point 4,5,6 --measure spearman --out ";
  const auto plain = test::run_cli(args + (dir / "plain.raw").string() + " --stream off");
  ASSERT_EQ(plain.exit_code, 0) << plain.output;
  const std::string expected = read_text(dir / "plain.raw");
  ASSERT_EQ(expected.size(), 37u * 29 * 23 * 4);
  for (int ranks : {1, 2, 3, 4}) {
    SCOPED_TRACE(std::to_string(ranks) + " ranks");
    const std::string out = "ranks" + std::to_string(ranks) + ".raw";
    const auto r = run_mpi(ranks, args + (dir / out).string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_EQ(read_text(dir / out), expected);
  }
  // Slabs of 2 slices: ranks with 8, 8 and 7 slices (.pvti: 9, 9, 7) meet after each slab to add up
  // their progress, the ones with fewer slabs as often as the others.
  for (const char* ext : {".raw", ".pvti"}) {
    SCOPED_TRACE(ext);
    const std::string out = std::string("slabs") + ext;
    const auto r = run_mpi(3, args + (dir / out).string() + " --slab-slices 2 --json " + (dir / "slabs.json").string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(read_text(dir / "slabs.json").find("\"slab_slices\": 2"), std::string::npos) << read_text(dir / "slabs.json");
    if (std::string(ext) == ".raw") EXPECT_EQ(read_text(dir / out), expected);
  }
#endif
}

// correlate --out x.pvti: ParaView's parallel image data, one .vti piece per rank (neighbouring
// pieces share a slice), as VTK's own reader loads it: the one-process field, bit for bit.
TEST_F(MpiCli, ParallelImageDataOpensInVtksReader) {
#ifdef TFMATCH_MPIEXEC
  const std::string python = fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
  if (std::system((python + " -c 'import vtk' >/dev/null 2>&1").c_str()) != 0)
    GTEST_SKIP() << "VTK's Python package is not installed (Debian python3-vtk9): no independent read-back";
  std::string members;
  for (int m = 0; m < 5; ++m)
    members += " " + slab_test::write_raw(dir.path(), "m" + std::to_string(m), slab_test::test_field({37, 29, 23}, m)).string();
  const std::string args = "correlate --members" + members + " --point 30,20,10 --out ";
  const auto plain = test::run_cli(args + (dir / "plain.raw").string());
  ASSERT_EQ(plain.exit_code, 0) << plain.output;
  const std::string expected = read_text(dir / "plain.raw");
  const std::string script = std::string(TFMATCH_SOURCE_DIR) + "/tests/tools/pvti_with_vtk.py";
  for (int ranks : {1, 3, 4}) {
    SCOPED_TRACE(std::to_string(ranks) + " ranks");
    const std::string name = "field" + std::to_string(ranks);
    const auto r = run_mpi(ranks, args + (dir / (name + ".pvti")).string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_EQ(test::files_under(dir / name).size(), size_t(ranks)) << "one piece per rank";
    const std::string back = (dir / (name + "_vtk.raw")).string();
    ASSERT_EQ(std::system((python + " " + script + " " + (dir / (name + ".pvti")).string() + " " + back).c_str()), 0);
    EXPECT_EQ(read_text(back), expected);
  }
  // A failing rank: no .pvti, no pieces, no directory.
  const auto failed = run_mpi(2, "--device 0,9 " + args + (dir / "failed.pvti").string());
  EXPECT_NE(failed.exit_code, 0) << failed.output;
  EXPECT_FALSE(fs::exists(dir / "failed.pvti"));
  EXPECT_FALSE(fs::exists(dir / "failed"));
#endif
}

TEST_F(MpiCli, AFailingRankStopsEveryRankAndNothingIsWritten) {
#ifdef TFMATCH_MPIEXEC
  // Rank 1 takes the second device of the list, which does not exist.
  const auto r = run_mpi(2, "--device 0,9 " + args("failed.json") + " --report " + (dir / "report").string());
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("tfmatch: rank 1: error: device index 9 out of range"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "failed.json"));
  EXPECT_FALSE(fs::exists(dir / "report"));
  // A bad file fails on every rank: reported once, by rank 0.
  const auto missing = run_mpi(3, "optimize --ref " + (dir / "none_4x4x4_float32.raw").string() + " --field " + field_file +
                                      " --ref-tf viridis --stream on --out " + (dir / "x.json").string());
  EXPECT_EQ(missing.exit_code, 1) << missing.output;
  size_t reports = 0;
  for (size_t at = missing.output.find("tfmatch: "); at != std::string::npos; at = missing.output.find("tfmatch: ", at + 1))
    ++reports;
  EXPECT_EQ(reports, 1u) << missing.output;
  EXPECT_NE(missing.output.find("none_4x4x4_float32.raw"), std::string::npos) << missing.output;
#endif
}

// SIGINT to mpirun (Ctrl-C): OpenMPI passes a SIGTERM on to every rank, which stop as one process
// does: a non-zero exit within seconds and no output (a mi-kraskov field of 64 members of
// 64x64x40 in slabs of one slice takes about 5 s on two lavapipe ranks; the signal comes at 1.5 s).
TEST_F(MpiCli, AnInterruptStopsEveryRankAndWritesNothing) {
#ifdef TFMATCH_MPIEXEC
  std::vector<float> values(64 * 64 * 40);
  std::string members;
  for (int m = 0; m < 64; ++m) {
    for (size_t i = 0; i < values.size(); ++i) values[i] = float(std::sin(0.0137 * double(i) * (m + 1)) + 0.001 * double(i % 97));
    const fs::path path = dir.path() / ("s" + std::to_string(100 + m) + "_64x64x40_float32.raw");
    std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(values.data()),
                                                std::streamsize(values.size() * sizeof(float)));
    members += " " + path.string();
  }
  const fs::path out = dir.path() / "interrupted.pvti", log = dir.path() / "log.txt";
  const std::string cmd = std::string(TFMATCH_MPIEXEC) + " --oversubscribe -n 2 " + TFMATCH_CLI_PATH +
                          " correlate --members" + members + " --point 5,6,7 --measure mi-kraskov --slab-slices 1 --out " +
                          out.string();
  const int status = interrupt_job(cmd, log, "");
  EXPECT_FALSE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << read_text(log);
  EXPECT_FALSE(fs::exists(out)) << read_text(log);
  EXPECT_FALSE(fs::exists(dir.path() / "interrupted")) << "the pieces' directory";
#endif
}

// Ctrl-C while rank 1 is held in a step (TFMATCH_PAUSE_AT, set for it alone by a wrapper) and
// rank 0 waits for it where the ranks meet: one message, rank 1's, and not also rank 0's watchdog
// line while the job's teardown waits for rank 1.
TEST_F(MpiCli, AnInterruptIsReportedOnce) {
#ifdef TFMATCH_MPIEXEC
  const fs::path wrapper = dir / "hold_rank_1.sh", log = dir / "log.txt";
  std::ofstream(wrapper) << "#!/bin/sh\n[ \"$OMPI_COMM_WORLD_RANK\" = 1 ] && export TFMATCH_PAUSE_AT='stream#2'\n"
                         << "exec " << TFMATCH_CLI_PATH << " \"$@\"\n";
  fs::permissions(wrapper, fs::perms::owner_all);
  setenv("TFMATCH_TRACE_PHASES", "1", 1);
  const int status = interrupt_job(std::string(TFMATCH_MPIEXEC) + " --oversubscribe -x TFMATCH_TRACE_PHASES -n 2 " +
                                       wrapper.string() + " " + args("held.json"),
                                   log, "tfmatch: phase stream");
  unsetenv("TFMATCH_TRACE_PHASES");
  const std::string output = read_text(log);
  EXPECT_FALSE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << output;
  EXPECT_NE(output.find("tfmatch: rank 1: interrupted (SIGTERM)"), std::string::npos) << output;
  EXPECT_EQ(output.find("stopped without waiting"), std::string::npos) << output;
  EXPECT_FALSE(fs::exists(dir / "held.json"));
#endif
}

TEST_F(MpiCli, CommandsThatDoNotSplitSaySo) {
#ifdef TFMATCH_MPIEXEC
  const auto r = run_mpi(2, "render --ref " + ref_file + " --out " + (dir / "r.png").string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("only `optimize --stream on` and `correlate` are split over ranks"), std::string::npos)
      << r.output;
  const auto off = run_mpi(2, args("off.json", "off"));
  EXPECT_EQ(off.exit_code, 2) << off.output;
  EXPECT_NE(off.output.find("--stream on or auto"), std::string::npos) << off.output;
  EXPECT_FALSE(fs::exists(dir / "off.json"));
#endif
}

// Ranks that read other files under the same names (a node with a stale copy): every rank stops
// before any work, naming the rank and both grids, and nothing is written. Each rank runs in a
// folder of its own (OpenMPI names the rank in OMPI_COMM_WORLD_RANK); rank 1's grid is a slice
// shorter.
TEST_F(MpiCli, RanksThatReadDifferentGridsStopBeforeAnyWork) {
#ifdef TFMATCH_MPIEXEC
  for (int rank : {0, 1}) {
    const fs::path folder = dir / ("rank" + std::to_string(rank));
    fs::create_directories(folder);
    const std::array<uint64_t, 3> dims{37, 29, uint64_t(rank == 0 ? 23 : 22)};
    for (int m = 0; m < 3; ++m)
      fs::rename(slab_test::write_vti_file(folder, "m", slab_test::test_field(dims, m), false),
                 folder / ("m" + std::to_string(m) + ".vti"));
  }
  const fs::path wrapper = dir / "in_rank_folder.sh";
  std::ofstream(wrapper) << "#!/bin/sh\ncd '" << dir.path().string() << "/rank'\"$OMPI_COMM_WORLD_RANK\" && exec "
                         << TFMATCH_CLI_PATH << " \"$@\"\n";
  fs::permissions(wrapper, fs::perms::owner_all);
  const std::string launch = std::string(TFMATCH_MPIEXEC) + " --oversubscribe -n 2 " + wrapper.string() + " ";
  const auto opt = run_shell(launch + "optimize --ref m0.vti --field m1.vti --ref-tf viridis --stream on --out " +
                             (dir / "tf.json").string());
  const auto cor = run_shell(launch + "correlate --members m0.vti m1.vti m2.vti --point 1,1,1 --out " +
                             (dir / "c.raw").string());
  for (const auto* r : {&opt, &cor}) {
    EXPECT_EQ(r->exit_code, 1) << r->output;
    EXPECT_NE(r->output.find("tfmatch: rank 1: "), std::string::npos) << r->output;
    EXPECT_NE(r->output.find("reads a grid 37x29x22 (spacing 0.5, 2, 1.5; origin -1, 3, 7)"), std::string::npos)
        << r->output;
    EXPECT_NE(r->output.find("where rank 0 reads 37x29x23"), std::string::npos) << r->output;
  }
  EXPECT_NE(cor.output.find("of 3 members"), std::string::npos) << cor.output;
  EXPECT_FALSE(fs::exists(dir / "tf.json"));
  EXPECT_FALSE(fs::exists(dir / "c.raw"));
#endif
}

// A usage error on one rank alone (here its environment's TFMATCH_MAX_MEMORY, as a node's profile
// may set it) stops every rank with that rank's message, as any failure does; the failing rank
// used to return alone and leave the others waiting in their first collective until the job's
// wall time (and print nothing).
TEST_F(MpiCli, AUsageErrorOnOneRankStopsEveryRank) {
#ifdef TFMATCH_MPIEXEC
  const fs::path wrapper = dir / "rank_1_budget.sh";
  std::ofstream(wrapper) << "#!/bin/sh\n[ \"$OMPI_COMM_WORLD_RANK\" = 1 ] && export TFMATCH_MAX_MEMORY=1M\n"
                         << "exec " << TFMATCH_CLI_PATH << " \"$@\"\n";
  fs::permissions(wrapper, fs::perms::owner_all);
  const auto t0 = std::chrono::steady_clock::now();
  const auto r = run_shell("timeout 60 " + std::string(TFMATCH_MPIEXEC) + " --oversubscribe -n 2 " + wrapper.string() +
                           " " + args("usage.json"));
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_LT(seconds, 50.0) << "the job waited for the failed rank";
  EXPECT_NE(r.output.find("tfmatch: rank 1: error: TFMATCH_MAX_MEMORY: TFMATCH_MAX_MEMORY=1M is below"), std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(dir / "usage.json"));
#endif
}

// correlate to a .raw or .vti under MPI gathers the whole field on rank 0: checked against rank
// 0's budget before any work (it was checked per rank only, and a 150 MiB field went to 303 MiB
// under a 200 MiB budget, or failed at the write after the whole computation). The refusal
// suggests .pvti; a .pvti run of the same job succeeds and counts its pieces.
TEST_F(MpiCli, WhatWritingTheFieldTakesIsCheckedBeforeTheWork) {
#ifdef TFMATCH_MPIEXEC
  std::string members;
  for (int m = 0; m < 3; ++m) {
    std::vector<uint8_t> bytes(size_t(256) * 256 * 512);
    for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = uint8_t((i * (m + 3) + i / 4093) % 251);
    const fs::path path = dir.path() / ("g" + std::to_string(m) + "_256x256x512_uint8.raw");
    std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    members += " " + path.string();
  }
  // Rank 0: ~110 MiB in use (lavapipe, validation layer on), its part 64 MiB; the whole field
  // 128 MiB beside it needs ~300 MiB.
  const std::string job = "--max-memory 270M correlate --members" + members + " --point 3,4,5 --out ";
  const auto t0 = std::chrono::steady_clock::now();
  const auto raw = run_mpi(2, job + (dir / "whole.raw").string());
  EXPECT_EQ(raw.exit_code, 1) << raw.output;
  EXPECT_NE(raw.output.find("rank 0 gathers the whole 256x256x512 field to write it (a .pvti output keeps each rank's "
                            "piece on its rank)"),
            std::string::npos)
      << raw.output;
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 30.0) << "refused first";
  EXPECT_FALSE(fs::exists(dir / "whole.raw"));
  // A piece's write (its compressed copy, twice the piece) is checked before the work too: it
  // failed at the write, after the whole computation.
  const auto t1 = std::chrono::steady_clock::now();
  const auto tight = run_mpi(2, job + (dir / "tight.pvti").string());
  EXPECT_EQ(tight.exit_code, 1) << tight.output;
  EXPECT_NE(tight.output.find("this rank's piece of 256 z-slices and its compressed copy as it is written"),
            std::string::npos)
      << tight.output;
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count(), 30.0) << "refused first";
  EXPECT_FALSE(fs::exists(dir / "tight.pvti"));
  EXPECT_FALSE(fs::exists(dir / "tight"));
  // With room for a piece's compressed copy as it is written, the job runs.
  std::string pvti_job = job;
  pvti_job.replace(pvti_job.find("270M"), 4, "600M");
  const auto pieces = run_mpi(2, pvti_job + (dir / "pieces.pvti").string() + " --json " + (dir / "pieces.json").string());
  EXPECT_EQ(pieces.exit_code, 0) << pieces.output;
  EXPECT_NE(read_text(dir / "pieces.json").find("\"pieces\": 2"), std::string::npos);
#endif
}

// optimize's outputs are rank 0's alone: a rank where the output folder does not exist (another
// node's file system) reads its share and the job succeeds; it used to stop every rank.
TEST_F(MpiCli, OnlyRankZeroChecksWhereOptimizeWrites) {
#ifdef TFMATCH_MPIEXEC
  fs::create_directories(dir / "rank0" / "out");
  fs::create_directories(dir / "rank1");
  const fs::path wrapper = dir / "in_rank_folder.sh";
  std::ofstream(wrapper) << "#!/bin/sh\ncd '" << dir.path().string() << "/rank'\"$OMPI_COMM_WORLD_RANK\" && exec "
                         << TFMATCH_CLI_PATH << " \"$@\"\n";
  fs::permissions(wrapper, fs::perms::owner_all);
  const auto r = run_shell(std::string(TFMATCH_MPIEXEC) + " --oversubscribe -n 2 " + wrapper.string() + " optimize --ref " +
                           ref_file + " --field " + field_file + " --ref-tf viridis --stream on --out out/t.json");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::exists(dir / "rank0" / "out" / "t.json"));
#endif
}

// NetCDF-4 input where the probe program is not found (a binary copied alone to a cluster's
// scratch): the probe forks this threaded process, and the child loaded netCDF-C itself, which
// failed in about one run of four under mpirun, blaming the file ("malformed ... exited with
// status 127"). Four runs: each must read the file.
TEST_F(MpiCli, NetCdf4InputsReadWithoutTheProbeProgram) {
#ifdef TFMATCH_MPIEXEC
  const std::string data = test::shared_data_dir();
  if (data.empty()) GTEST_SKIP() << "no ../shared/data: the WRF NetCDF-4 file is not here";
  const std::string wrf = data + "/wrf_katrina/ci_test_file.nc";
  setenv("TFMATCH_NETCDF4_PROBE", "/nonexistent/tfmatch-netcdf4-probe", 1);
  for (int run = 0; run < 4; ++run) {
    const std::string out = (dir / ("wrf" + std::to_string(run) + ".json")).string();
    const auto r = run_shell(std::string(TFMATCH_MPIEXEC) + " -x TFMATCH_NETCDF4_PROBE --oversubscribe -n 2 " +
                             TFMATCH_CLI_PATH + " -q optimize --ref " + wrf + ":T --field " + wrf +
                             ":QVAPOR --ref-tf viridis --stream on --out " + out);
    EXPECT_EQ(r.exit_code, 0) << "run " << run << ":\n" << r.output;
  }
  unsetenv("TFMATCH_NETCDF4_PROBE");
#endif
}

}  // namespace
}  // namespace tfm
