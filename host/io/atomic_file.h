// Outputs appear whole or not at all. Each file is written to a temporary name beside it and
// renamed into place when complete; while an OutputBatch is open (a command opens one around its
// work), the renames wait until the batch commits, so a run that fails or is interrupted changes
// no output at all. Every temporary path is registered until it is renamed or removed, so an
// interrupt can remove them even when the writing thread cannot unwind in time.
#pragma once

#include <filesystem>
#include <map>
#include <string_view>
#include <utility>
#include <vector>

namespace tfm {

struct OutputBatchState;  // atomic_file.cpp

// Where a write of `path` lands: `path`, or where a symbolic link there leads (followed to the end,
// a dangling link to the file it names), so that a link is written through, as other tools do,
// rather than replaced by a file of its own.
std::filesystem::path output_target(const std::filesystem::path& path);

// Throws std::runtime_error naming `path` (as given) when `target` (its output_target) exists and
// is not a file that can be replaced: a directory, a device, pipe or socket (a write through a
// temporary name would replace the device's node, or, to /dev/full, report success), or a
// read-only file.
void check_replaceable_target(const std::filesystem::path& path, const std::filesystem::path& target);

// Writes `bytes` to `path` (its output_target) through ".NAME.tmp-PID-K" in the same directory, in blocks with a
// cancellation checkpoint ("write", host/model/cancellation.h) after each. Renames it over `path`
// at once, or when the open OutputBatch commits. On any error or cancellation the temporary file
// is removed. Throws std::runtime_error naming `path` when it is a directory, an existing
// read-only file, or cannot be written.
void write_file_atomically(const std::filesystem::path& path, std::string_view bytes);

// The outputs of one piece of work, committed together. Single-threaded: open, write and commit
// on one thread. A batch opened while another is open joins it: its directory() works the same,
// its commit() does nothing and the outermost batch commits everything.
class OutputBatch {
 public:
  OutputBatch();
  // Without commit(): removes every temporary file and staged directory of the batch.
  ~OutputBatch();
  OutputBatch(const OutputBatch&) = delete;
  OutputBatch& operator=(const OutputBatch&) = delete;

  // Where to write the files of directory `dir`: `dir` itself when it exists, else a staged
  // directory (".NAME.tmp-PID-K" beside the first missing ancestor, which holds the missing
  // levels) that commit() renames into place. Throws std::runtime_error when `dir` or an ancestor
  // is a file, or the staged directory cannot be created.
  std::filesystem::path directory(const std::filesystem::path& dir);

  // A directory the caller created itself for the batch's files where directory() does not serve
  // (several processes write into it: an MPI job's .pvti pieces): removed, if it is empty then,
  // when the batch ends without commit().
  void made_directory(const std::filesystem::path& dir);

  // A file of an earlier run that this batch's files replace as a set (a report's file that this
  // run's report does not write again): commit() removes it after the renames, unless the batch
  // itself wrote it; without commit() it stays, like everything else the batch would change.
  void remove_on_commit(const std::filesystem::path& file);

  // Renames every file, then every staged directory, into place, then removes the files given to
  // remove_on_commit(). Throws std::runtime_error naming the path when a rename or removal fails
  // (what is not renamed yet is removed by the destructor).
  void commit();

 private:
  OutputBatchState* state_;  // the outermost batch's (shared by the batches that join it)
  bool outermost_;
};

// Temporary files and staged directories created and not yet renamed into place or removed.
std::vector<std::filesystem::path> pending_temporary_paths();

// Removes every pending temporary path and makes any later attempt to create one throw
// Cancelled(signal). For the command line's interrupt watchdog when the working thread does not
// stop in time; callable from any thread.
void abandon_temporary_paths(int signal);

}  // namespace tfm
