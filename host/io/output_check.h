// Checks every file a command reads and writes before any work starts: no output may replace an
// input or another output, and an output that cannot be written fails the run in its first
// second, not after an hour's solve. A command declares its files in one statement:
//
//   FilePlan().input_spec(a.ref, "--ref").input_spec(a.ref_tf, "--ref-tf")
//             .output(a.out, "--out").output(a.json, "--json")
//             .output_directory(a.report, "--report", report_file_names())
//             .check();
//
// then writes inside an OutputBatch (atomic_file.h) so that a failed or interrupted run leaves
// nothing behind. Empty paths (options not given) are skipped.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace tfm {

class FilePlan {
 public:
  // A file the command reads; `role` names it in messages (an option, "input 2", ...).
  FilePlan& input(const std::filesystem::path& path, std::string role);
  // "FILE" or "FILE:SELECTION" (a volume's variable, a preset of a TF file): FILE is the input.
  FilePlan& input_spec(const std::string& spec, std::string role);
  // A file the command writes (replacing it if it exists).
  FilePlan& output(const std::filesystem::path& path, std::string role);
  // A directory the command fills with `files` (names inside it; other files there are kept).
  FilePlan& output_directory(const std::filesystem::path& dir, std::string role, std::vector<std::string> files);

  // Throws std::runtime_error "ROLE PATH: <problem>" for the first problem found:
  // - an output that is an existing directory, a read-only file, or whose directory is missing,
  //   not a directory, or not writable;
  // - an output directory that is a file, or that neither exists nor can be created (its first
  //   existing ancestor must be a writable directory);
  // - an output that is the same file as an input or another output, compared by resolved path
  //   (symbolic links followed) and, for existing files, by device and inode (hard links).
  void check() const;

 private:
  struct Entry {
    std::filesystem::path path;
    std::string role;
    bool output = false;
  };
  std::vector<Entry> files_;
  struct Directory {
    std::filesystem::path path;
    std::string role;
    std::vector<std::string> files;
  };
  std::vector<Directory> directories_;
};

}  // namespace tfm
