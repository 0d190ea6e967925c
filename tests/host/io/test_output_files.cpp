// Outputs (host/io/output_check.h, host/io/atomic_file.h): the up-front check of a command's
// files (same file by path, symbolic link and hard link; read-only targets; missing, unwritable or
// file-shaped directories; report directories), atomic writes, output batches that commit
// together or leave nothing, staged directories, and cancellation in the middle of a write.
#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <fstream>
#include <chrono>
#include <string>
#include <thread>

#include "cli_runner.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/model/cancellation.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;
using test::files_under;
using test::TempDir;

void write_text(const fs::path& path, const std::string& text) { std::ofstream(path) << text; }
using test::read_text;

// Runs plan.check() and expects a std::runtime_error whose message holds every needle.
void expect_refused(const FilePlan& plan, std::initializer_list<std::string> needles) {
  try {
    plan.check();
    ADD_FAILURE() << "check() accepted the plan";
  } catch (const std::runtime_error& e) {
    for (const std::string& n : needles) EXPECT_NE(std::string(e.what()).find(n), std::string::npos) << e.what();
  }
}

TEST(FilePlan, AcceptsDistinctWritableOutputs) {
  TempDir dir;
  write_text(dir / "in.raw", "x");
  write_text(dir / "old.json", "{}");  // an existing, writable output is replaced: fine
  EXPECT_NO_THROW(FilePlan()
                      .input(dir / "in.raw", "--ref")
                      .input_spec(dir / "in.raw:VAR", "--field")
                      .output(dir / "old.json", "--out")
                      .output(dir / "new.json", "--json")
                      .output("", "--unused")
                      .output_directory(dir / "report/deep", "--report", {"index.html"})
                      .check());
}

TEST(FilePlan, RefusesOneFileForTwoOutputs) {
  TempDir dir;
  expect_refused(FilePlan().output(dir / "x.json", "--out").output(dir / "x.json", "--json"),
                 {"--json", "x.json", "same file as --out"});
  // Spelled differently: "./" and "..".
  expect_refused(FilePlan().output(dir / "x.json", "--out").output(dir / "sub/../x.json", "--json"), {"same file"});
  // Inside a report directory, under a name the report writes.
  expect_refused(FilePlan().output(dir / "r/metrics.json", "--json").output_directory(dir / "r", "--report", {"metrics.json"}),
                 {"--json", "same file as --report", "metrics.json"});
}

TEST(FilePlan, RefusesAnOutputThatIsAnInput) {
  TempDir dir;
  write_text(dir / "ref.raw", "data");
  expect_refused(FilePlan().input(dir / "ref.raw", "--ref").output(dir / "ref.raw", "--out"),
                 {"--out", "same file as --ref", "destroy"});
  // FILE:VAR names FILE.
  expect_refused(FilePlan().input_spec(dir / "ref.raw" + ":U", "--ref").output(dir / "ref.raw", "--out"),
                 {"same file as --ref"});
  // A symbolic link to the input, and a hard link to it.
  fs::create_symlink(dir / "ref.raw", dir / "link.raw");
  expect_refused(FilePlan().input(dir / "ref.raw", "--ref").output(dir / "link.raw", "--out"), {"an input"});
  fs::create_hard_link(dir / "ref.raw", dir / "hard.raw");
  expect_refused(FilePlan().input(dir / "ref.raw", "--ref").output(dir / "hard.raw", "--out"), {"an input"});
}

// An output that is a symbolic link is written through, as other tools do: the link stays and the
// file it names gets the bytes (the link was replaced by a file of its own, and a link to
// /dev/full "succeeded"). A device, pipe or socket is no output file.
TEST(AtomicFile, WritesThroughSymbolicLinksAndRefusesDevices) {
  TempDir dir;
  fs::create_directory(dir / "real");
  fs::create_symlink("real/target.json", dir / "link.json");  // dangling until written
  fs::create_symlink("link.json", dir / "chain.json");
  write_file_atomically(dir / "chain.json", "first");
  EXPECT_TRUE(fs::is_symlink(dir / "chain.json"));
  EXPECT_TRUE(fs::is_symlink(dir / "link.json"));
  EXPECT_EQ(read_text(dir / "real/target.json"), "first");
  {
    OutputBatch batch;
    write_file_atomically(dir / "link.json", "second");
    batch.commit();
  }
  EXPECT_TRUE(fs::is_symlink(dir / "link.json"));
  EXPECT_EQ(read_text(dir / "real/target.json"), "second");
  EXPECT_EQ(output_target(dir / "chain.json"), fs::weakly_canonical(dir / "real/target.json"));
  EXPECT_EQ(output_target(dir / "plain.json"), dir / "plain.json");
  // A link into a missing directory fails as a path into it would, naming the link.
  fs::create_symlink("nowhere/x.json", dir / "dangling.json");
  expect_refused(FilePlan().output(dir / "dangling.json", "--out"), {"--out", "dangling.json", "nowhere", "does not exist"});
  // Devices, directly or through a link: refused up front and when written.
  fs::create_symlink("/dev/null", dir / "null.json");
  expect_refused(FilePlan().output(dir / "null.json", "--out"),
                 {"--out", "null.json (a link to /dev/null)", "is a device, pipe or socket, not a file"});
  expect_refused(FilePlan().output("/dev/null", "--json"), {"--json /dev/null: is a device, pipe or socket"});
  EXPECT_THROW(write_file_atomically(dir / "null.json", "x"), std::runtime_error);
  EXPECT_TRUE(fs::is_symlink(dir / "null.json"));
  EXPECT_TRUE(pending_temporary_paths().empty());
}

TEST(FilePlan, RefusesUnwritableTargets) {
  TempDir dir;
  write_text(dir / "ro.json", "keep");
  fs::permissions(dir / "ro.json", fs::perms::owner_read | fs::perms::group_read);
  expect_refused(FilePlan().output(dir / "ro.json", "--out"), {"--out", "ro.json", "read-only"});
  expect_refused(FilePlan().output(dir / "missing/x.json", "--out"), {"missing", "does not exist"});
  fs::create_directory(dir / "adir");
  expect_refused(FilePlan().output(dir / "adir", "--out"), {"is a directory"});
  write_text(dir / "afile", "");
  expect_refused(FilePlan().output(dir / "afile/x.json", "--out"), {"not a directory"});
  // A report directory that is a file, or below one.
  expect_refused(FilePlan().output_directory(dir / "afile", "--report", {}), {"--report", "not a directory"});
  expect_refused(FilePlan().output_directory(dir / "afile/sub", "--report", {}), {"cannot be created", "is a file"});
  EXPECT_EQ(read_text(dir / "ro.json"), "keep");
}

TEST(AtomicFile, WritesWholeAndRefusesReadOnlyTargets) {
  TempDir dir;
  write_file_atomically(dir / "a.txt", "hello");
  EXPECT_EQ(read_text(dir / "a.txt"), "hello");
  write_file_atomically(dir / "a.txt", "");  // empty replaces
  EXPECT_EQ(read_text(dir / "a.txt"), "");
  write_text(dir / "ro.txt", "keep");
  fs::permissions(dir / "ro.txt", fs::perms::owner_read);
  EXPECT_THROW(write_file_atomically(dir / "ro.txt", "new"), std::runtime_error);
  EXPECT_EQ(read_text(dir / "ro.txt"), "keep");
  EXPECT_THROW(write_file_atomically(dir / "nodir/x.txt", "x"), std::runtime_error);
  EXPECT_EQ(files_under(dir.path), (std::vector<std::string>{"a.txt", "ro.txt"}));
  EXPECT_TRUE(pending_temporary_paths().empty());
}

TEST(AtomicFile, BatchCommitsTogetherOrLeavesNothing) {
  TempDir dir;
  write_text(dir / "old.txt", "old");
  {
    OutputBatch batch;
    write_file_atomically(dir / "old.txt", "new");
    const fs::path staged = batch.directory(dir / "made/deeper");
    write_file_atomically(staged / "inside.txt", "x");
    // Nothing visible yet: old content, no new directory (only hidden temporaries).
    EXPECT_EQ(read_text(dir / "old.txt"), "old");
    EXPECT_FALSE(fs::exists(dir / "made"));
    EXPECT_EQ(pending_temporary_paths().size(), 3u);  // two files and the staged directory
    // A batch opened inside joins the open one: it stages the same directory and commits nothing.
    {
      OutputBatch inner;
      EXPECT_EQ(inner.directory(dir / "made/deeper"), staged);
      write_file_atomically(inner.directory(dir / "made") / "sibling.txt", "y");
      inner.commit();
    }
    EXPECT_FALSE(fs::exists(dir / "made"));
    // Without commit(): everything goes.
  }
  EXPECT_EQ(files_under(dir.path), (std::vector<std::string>{"old.txt"}));
  EXPECT_EQ(read_text(dir / "old.txt"), "old");
  EXPECT_TRUE(pending_temporary_paths().empty());
  {
    OutputBatch batch;
    write_file_atomically(dir / "old.txt", "new");
    write_file_atomically(batch.directory(dir / "made") / "top.txt", "t");
    // A level below the staged directory that nothing made yet (demo --out D --report D/rep).
    write_file_atomically(batch.directory(dir / "made/deeper") / "inside.txt", "x");
    batch.commit();
  }
  EXPECT_EQ(read_text(dir / "old.txt"), "new");
  EXPECT_EQ(read_text(dir / "made/deeper/inside.txt"), "x");
  EXPECT_EQ(files_under(dir.path),
            (std::vector<std::string>{"made", "made/deeper", "made/deeper/inside.txt", "made/top.txt", "old.txt"}));
  EXPECT_TRUE(pending_temporary_paths().empty());
}

// An earlier run's file that the batch's files replace as a set goes at commit, not before and
// not without commit; a file the batch itself writes is never removed as stale.
TEST(AtomicFile, StaleFilesGoOnlyWhenTheBatchCommits) {
  TempDir dir;
  write_text(dir / "stale.txt", "old run");
  write_text(dir / "kept.txt", "old run");
  {
    OutputBatch batch;
    write_file_atomically(dir / "kept.txt", "new run");
    batch.remove_on_commit(dir / "stale.txt");
    batch.remove_on_commit(dir / "kept.txt");
    EXPECT_TRUE(fs::exists(dir / "stale.txt"));
    // Without commit(): the earlier run's files stay as they were.
  }
  EXPECT_EQ(files_under(dir.path), (std::vector<std::string>{"kept.txt", "stale.txt"}));
  EXPECT_EQ(read_text(dir / "kept.txt"), "old run");
  {
    OutputBatch batch;
    write_file_atomically(dir / "kept.txt", "new run");
    batch.remove_on_commit(dir / "stale.txt");
    batch.remove_on_commit(dir / "kept.txt");
    batch.remove_on_commit(dir / "gone-already.txt");  // nothing there: nothing to do
    batch.commit();
  }
  EXPECT_EQ(files_under(dir.path), (std::vector<std::string>{"kept.txt"}));
  EXPECT_EQ(read_text(dir / "kept.txt"), "new run");
}

// A directory the caller made for the batch (an MPI job's .pvti pieces folder, written by several
// processes): a batch that ends without commit removes it once empty, waiting for the other
// processes' temporary files to go (an empty folder was left when rank 0 ended first); anything
// else in it, or a commit, keeps it.
TEST(AtomicFile, AMadeDirectoryGoesWhenTheBatchFailsAndLeavesItEmpty) {
  TempDir dir;
  const fs::path pieces = dir / "pieces";
  fs::create_directories(pieces);
  const fs::path foreign = pieces / ".pieces_1.vti.tmp-99999-0";  // another rank's, still there
  write_text(foreign, "x");
  std::thread other_rank([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    fs::remove(foreign);
  });
  {
    OutputBatch batch;
    batch.made_directory(pieces);
    write_file_atomically(pieces / "pieces_0.vti", "piece");
  }
  other_rank.join();
  EXPECT_FALSE(fs::exists(pieces));
  const fs::path kept = dir / "kept";
  fs::create_directories(kept);
  write_text(kept / "notes.txt", "a user's file");
  {
    OutputBatch batch;
    batch.made_directory(kept);
  }
  EXPECT_TRUE(fs::exists(kept / "notes.txt"));
  fs::create_directories(dir / "committed");
  {
    OutputBatch batch;
    batch.made_directory(dir / "committed");
    batch.commit();
  }
  EXPECT_TRUE(fs::is_directory(dir / "committed"));
}

// A cancellation during a write (here: already requested) removes the temporary file and throws
// Cancelled, which no std::exception handler catches.
TEST(AtomicFile, CancellationRemovesTheTemporaryFile) {
  TempDir dir;
  request_cancel(2);
  bool cancelled = false;
  try {
    write_file_atomically(dir / "big.bin", std::string(size_t(9) << 20, 'x'));  // three blocks
  } catch (const std::exception&) {
    ADD_FAILURE() << "a std::exception handler caught the cancellation";
  } catch (const Cancelled& c) {
    cancelled = c.signal() == 2;
  }
  reset_cancel();
  EXPECT_TRUE(cancelled);
  EXPECT_TRUE(files_under(dir.path).empty());
  EXPECT_TRUE(pending_temporary_paths().empty());
}

// What the interrupt watchdog does when the working thread does not stop: every pending
// temporary path goes, and no new one can be made.
TEST(AtomicFile, AbandonRemovesPendingPathsAndRefusesNewOnes) {
  // In a child process: abandoning is final for the process.
  TempDir dir;
  const pid_t pid = fork();
  if (pid == 0) {
    OutputBatch batch;
    write_file_atomically(dir / "a.txt", "a");
    write_file_atomically(batch.directory(dir / "d") / "b.txt", "b");
    abandon_temporary_paths(15);
    bool refused = false;
    try {
      write_file_atomically(dir / "c.txt", "c");
    } catch (const Cancelled&) {
      refused = true;
    }
    _exit(refused && pending_temporary_paths().empty() ? 0 : 1);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
  EXPECT_TRUE(files_under(dir.path).empty());
}

}  // namespace
}  // namespace tfm
