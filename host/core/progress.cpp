// Terminal progress lines.
#include "progress.h"

#include <atomic>
#include <cstdio>

#include <unistd.h>

namespace tfm {
namespace {
std::atomic<bool> g_enabled{true};
}

void set_progress_enabled(bool enabled) { g_enabled = enabled; }
bool progress_enabled() { return g_enabled && ::isatty(STDERR_FILENO); }

Progress::Progress(std::string label, uint64_t total)
    : label_(std::move(label)), total_(total), active_(progress_enabled()),
      start_(std::chrono::steady_clock::now()), last_(start_) {
  if (active_) draw(false);
}

Progress::~Progress() { finish(); }

void Progress::update(uint64_t done) {
  done_ = done;
  if (!active_) return;
  auto now = std::chrono::steady_clock::now();
  if (now - last_ < std::chrono::milliseconds(100)) return;
  last_ = now;
  draw(false);
}

void Progress::set_label(std::string label) {
  label_ = std::move(label);
  if (active_) draw(false);
}

void Progress::finish() {
  if (!active_) return;
  draw(true);
  active_ = false;
}

void Progress::draw(bool final_line) {
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  if (total_ > 0)
    std::fprintf(stderr, "\r\033[K%s %3.0f%% (%.1f s)", label_.c_str(), 100.0 * double(done_) / double(total_), s);
  else
    std::fprintf(stderr, "\r\033[K%s %llu (%.1f s)", label_.c_str(), static_cast<unsigned long long>(done_), s);
  if (final_line) std::fputs("\r\033[K", stderr);  // leave the terminal clean for the summary
  std::fflush(stderr);
}

}  // namespace tfm
