// Atomic outputs: temporary files renamed into place, output batches, and the registry of
// temporary paths an interrupt removes.
#include "tfmatch/io/atomic_file.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cerrno>
#include <cstring>
#include <mutex>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/phase_timer.h"

namespace fs = std::filesystem;

namespace tfm {
namespace {

// Written in blocks, with a cancellation checkpoint after each: a 1 GB file stops in well under
// a second.
constexpr size_t kWriteBlock = size_t(4) << 20;

std::mutex g_registry_mutex;
std::vector<fs::path> g_pending;  // guarded by g_registry_mutex
int g_abandoned_signal = -1;      // >= 0 once abandon_temporary_paths() ran; guarded likewise
std::atomic<uint64_t> g_counter{0};

// A fresh name beside `path`: ".NAME.tmp-PID-K".
fs::path temporary_name(const fs::path& path) {
  return path.parent_path() / ("." + path.filename().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                               std::to_string(g_counter++));
}

// Creates the temporary path with `create` and registers it, both under the registry lock, so the
// interrupt watchdog either sees it (and removes it) or stops it from being created.
template <class Create>
void create_registered(const fs::path& path, Create create) {
  std::lock_guard lock(g_registry_mutex);
  if (g_abandoned_signal >= 0) throw Cancelled(g_abandoned_signal);
  create();
  g_pending.push_back(path);
}

void unregister(const fs::path& path) {
  std::lock_guard lock(g_registry_mutex);
  auto it = std::find(g_pending.begin(), g_pending.end(), path);
  if (it != g_pending.end()) g_pending.erase(it);
}

void remove_registered(const fs::path& path) {
  std::error_code ec;
  fs::remove_all(path, ec);
  unregister(path);
}

std::string errno_text() { return std::strerror(errno); }

// An existing target must be a file that may be replaced: a read-only file stays as it is (the
// owner's write bit decides, since root may write anything).
}  // namespace

fs::path output_target(const fs::path& path) {
  std::error_code ec;
  fs::path p = path;
  // Link by link (weakly_canonical stops at a dangling one), at most as deep as the kernel goes.
  for (int hop = 0; hop < 40 && fs::is_symlink(fs::symlink_status(p, ec)); ++hop) {
    const fs::path next = fs::read_symlink(p, ec);
    if (ec) return path;
    p = next.is_absolute() ? next : p.parent_path() / next;
  }
  if (p == path) return path;
  const fs::path target = fs::weakly_canonical(fs::absolute(p, ec), ec);
  return ec ? p.lexically_normal() : target;
}

void check_replaceable_target(const fs::path& path, const fs::path& target) {
  struct stat st{};
  if (::stat(target.c_str(), &st) != 0) return;  // does not exist (or is unreachable: open says why)
  const std::string via = target == path ? std::string() : " (a link to " + target.string() + ")";
  if (S_ISDIR(st.st_mode)) throw std::runtime_error(path.string() + via + ": is a directory, not a file");
  if (!S_ISREG(st.st_mode))
    throw std::runtime_error(path.string() + via + ": is a device, pipe or socket, not a file; outputs are files, "
                             "written whole through a temporary name");
  // The owner's write bit decides (root may write anything, yet a read-only file stays so).
  if ((st.st_mode & (S_IWUSR | S_IWGRP | S_IWOTH)) == 0)
    throw std::runtime_error(path.string() + via + ": exists and is read-only; refusing to replace it");
}

struct OutputBatchState {
  std::vector<std::pair<fs::path, fs::path>> files;        // temporary -> final
  std::vector<std::pair<fs::path, fs::path>> directories;  // staged top -> final top
  std::vector<fs::path> made;                              // made_directory()
  std::vector<fs::path> stale;                             // remove_on_commit()
  bool committed = false;
};

namespace {
OutputBatchState* g_batch = nullptr;  // the outermost open batch's (single-threaded, see the header)
}  // namespace

void write_file_atomically(const fs::path& given, std::string_view bytes) {
  PhaseScope timing(Phase::Write);
  const fs::path path = output_target(given);
  check_replaceable_target(given, path);
  const fs::path tmp = temporary_name(path);
  int fd = -1;
  create_registered(tmp, [&] {
    fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0) throw std::runtime_error(path.string() + ": cannot open for writing (" + errno_text() + ")");
  });
  try {
    size_t done = 0;
    while (done < bytes.size()) {
      const size_t n = std::min(kWriteBlock, bytes.size() - done);
      const ssize_t wrote = ::write(fd, bytes.data() + done, n);
      if (wrote < 0 && errno == EINTR) continue;  // a signal arrived: the checkpoint below decides
      if (wrote <= 0) throw std::runtime_error(path.string() + ": write failed (" + errno_text() + ")");
      done += size_t(wrote);
      checkpoint("write");
    }
    if (bytes.empty()) checkpoint("write");
    if (::close(fd) != 0) {
      fd = -1;
      throw std::runtime_error(path.string() + ": write failed (" + errno_text() + ")");
    }
    fd = -1;
    if (g_batch) {
      // A second write of one path in a batch replaces the first.
      auto& files = g_batch->files;
      auto old = std::find_if(files.begin(), files.end(), [&](const auto& f) { return f.second == path; });
      if (old != files.end()) {
        remove_registered(old->first);
        files.erase(old);
      }
      files.emplace_back(tmp, path);
      return;
    }
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) throw std::runtime_error(path.string() + ": cannot rename into place (" + ec.message() + ")");
    unregister(tmp);
  } catch (...) {
    if (fd >= 0) ::close(fd);
    remove_registered(tmp);
    throw;
  }
}

namespace {

// Removes `dir` once it is empty. Other processes writing into it (an MPI job's ranks) remove
// their temporary files as they fail too, a moment later: while it holds nothing else, their
// removal is waited for, for up to 2 s; anything else in it keeps it.
void remove_when_left_empty(const fs::path& dir) {
  for (int attempt = 0; attempt < 100; ++attempt) {
    std::error_code ec;
    if (fs::remove(dir, ec) || !fs::exists(dir, ec)) return;
    bool temporaries_only = true;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      const std::string name = entry.path().filename().string();
      temporaries_only = temporaries_only && name.starts_with(".") && name.find(".tmp-") != std::string::npos;
    }
    if (ec || !temporaries_only) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

}  // namespace

OutputBatch::OutputBatch() : state_(nullptr), outermost_(g_batch == nullptr) {
  if (outermost_) g_batch = state_ = new OutputBatchState;
  else state_ = g_batch;
}

OutputBatch::~OutputBatch() {
  if (!outermost_) return;
  g_batch = nullptr;
  for (const auto& [tmp, final] : state_->files) remove_registered(tmp);
  for (const auto& [staged, final] : state_->directories) remove_registered(staged);
  if (!state_->committed)
    for (auto it = state_->made.rbegin(); it != state_->made.rend(); ++it) remove_when_left_empty(*it);
  delete state_;
}

fs::path OutputBatch::directory(const fs::path& dir) {
  std::error_code ec;
  if (fs::is_directory(dir, ec)) return dir;
  if (fs::exists(dir, ec)) throw std::runtime_error(dir.string() + ": exists and is not a directory");
  // The first missing level: everything below it is created inside the staged directory.
  // Absolute, so that one directory named two ways is staged once.
  fs::path full = fs::absolute(dir, ec).lexically_normal();
  if (!full.has_filename()) full = full.parent_path();  // "dir/"
  fs::path top = full;
  while (top.has_parent_path() && top.parent_path() != top && !fs::exists(top.parent_path(), ec)) top = top.parent_path();
  const fs::path rest = full.lexically_relative(top);
  for (const auto& [staged, final] : state_->directories)
    if (final == top) {
      // A level below a directory this batch already stages (demo --out D --report D/rep): made
      // inside it.
      if (rest.empty() || rest == ".") return staged;
      fs::create_directories(staged / rest, ec);
      if (ec) throw std::runtime_error(dir.string() + ": cannot create the directory (" + ec.message() + ")");
      return staged / rest;
    }
  const fs::path parent = top.parent_path();
  if (!fs::is_directory(parent, ec)) throw std::runtime_error(dir.string() + ": " + parent.string() + " is not a directory");
  const fs::path staged = temporary_name(top);
  create_registered(staged, [&] {
    if (::mkdir(staged.c_str(), 0777) != 0)
      throw std::runtime_error(dir.string() + ": cannot create the directory (" + errno_text() + ")");
  });
  state_->directories.emplace_back(staged, top);
  const fs::path inside = rest.empty() || rest == "." ? staged : staged / rest;
  fs::create_directories(inside, ec);
  if (ec) throw std::runtime_error(dir.string() + ": cannot create the directory (" + ec.message() + ")");
  return inside;
}

void OutputBatch::made_directory(const fs::path& dir) { state_->made.push_back(dir); }

void OutputBatch::remove_on_commit(const fs::path& file) { state_->stale.push_back(file); }

void OutputBatch::commit() {
  if (!outermost_ || state_->committed) return;
  std::vector<fs::path> written;  // what the batch puts in place is never stale
  for (const auto& [temporary, final] : state_->files) written.push_back(fs::absolute(final).lexically_normal());
  // Files first (some live inside staged directories), then the directories. Each renamed entry
  // leaves the list at once, so that a failure leaves the destructor only what is still pending.
  auto rename_all = [](std::vector<std::pair<fs::path, fs::path>>& list, const char* what) {
    while (!list.empty()) {
      const auto [temporary, final] = list.front();
      std::error_code ec;
      fs::rename(temporary, final, ec);
      if (ec) throw std::runtime_error(final.string() + ": cannot rename " + what + " into place (" + ec.message() + ")");
      unregister(temporary);
      list.erase(list.begin());
    }
  };
  rename_all(state_->files, "the file");
  rename_all(state_->directories, "the directory");
  for (const fs::path& file : state_->stale) {
    if (std::find(written.begin(), written.end(), fs::absolute(file).lexically_normal()) != written.end()) continue;
    std::error_code ec;
    fs::remove(file, ec);
    if (ec) throw std::runtime_error(file.string() + ": cannot remove this file of an earlier run (" + ec.message() + ")");
  }
  state_->committed = true;
}

std::vector<fs::path> pending_temporary_paths() {
  std::lock_guard lock(g_registry_mutex);
  return g_pending;
}

void abandon_temporary_paths(int signal) {
  std::lock_guard lock(g_registry_mutex);
  g_abandoned_signal = signal;
  for (const fs::path& p : g_pending) {
    std::error_code ec;
    fs::remove_all(p, ec);
  }
  g_pending.clear();
}

}  // namespace tfm
