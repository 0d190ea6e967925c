// Progress lines: updating on a terminal, periodic plain lines elsewhere.
#include "tfmatch/model/progress.h"

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include <unistd.h>

namespace tfm {
namespace {
std::atomic<bool> g_enabled{true};
std::atomic<double> g_interval_s{0.0};  // 0: not set, read the environment

thread_local ProgressObserver t_observer;

double interval_from_environment() {
  const char* text = std::getenv("TFMATCH_PROGRESS_INTERVAL");
  if (!text || !*text) return 10.0;
  char* end = nullptr;
  const double s = std::strtod(text, &end);
  // A bad value is not worth failing a run over: the default then.
  return (*end == '\0' && s > 0 && std::isfinite(s)) ? s : 10.0;
}
}  // namespace

void set_progress_enabled(bool enabled) { g_enabled = enabled; }
bool progress_enabled() { return g_enabled; }

void set_progress_interval(double seconds) { g_interval_s = seconds; }
double progress_interval_s() {
  const double set = g_interval_s;
  return set > 0 ? set : interval_from_environment();
}

std::string format_duration(double s) {
  char buf[32];
  if (!(s >= 0) || !std::isfinite(s)) return "?";
  if (s < 60) {
    std::snprintf(buf, sizeof buf, "%.1fs", s);
  } else if (s < 3600) {
    const auto whole = static_cast<long long>(std::lround(s));
    std::snprintf(buf, sizeof buf, "%lldm%02llds", whole / 60, whole % 60);
  } else {
    const auto minutes = static_cast<long long>(std::lround(s / 60));
    std::snprintf(buf, sizeof buf, "%lldh%02lldm", minutes / 60, minutes % 60);
  }
  return buf;
}

double estimated_seconds_left(double elapsed_s, uint64_t done, uint64_t total) {
  if (done == 0 || total == 0) return -1.0;
  const double fraction = double(done) / double(total);
  return elapsed_s * (1.0 - fraction) / fraction;
}

ScopedProgressObserver::ScopedProgressObserver(ProgressObserver observer) : previous_(std::move(t_observer)) {
  t_observer = std::move(observer);
}
ScopedProgressObserver::~ScopedProgressObserver() { t_observer = std::move(previous_); }

void Progress::notify() const {
  if (t_observer) t_observer(label_, done_, total_);
}

Progress::Progress(std::string label, uint64_t total, ProgressClock clock)
    : label_(std::move(label)), total_(total), active_(progress_enabled()), terminal_(::isatty(STDERR_FILENO) == 1),
      clock_(clock ? std::move(clock) : ProgressClock([] { return std::chrono::steady_clock::now(); })),
      start_(clock_()),
      last_(start_) {
  notify();
  if (active_ && terminal_) draw(false);
}

Progress::~Progress() { finish(); }

void Progress::update(uint64_t done) {
  done_ = done;
  notify();
  if (!active_) return;
  const auto now = clock_();
  if (terminal_) {
    if (now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    draw(false);
  } else if (std::chrono::duration<double>(now - last_).count() >= progress_interval_s()) {
    last_ = now;
    print_plain_line();
  }
}

void Progress::set_label(std::string label) {
  label_ = std::move(label);
  notify();
  if (active_ && terminal_) draw(false);
}

void Progress::finish() {
  if (!active_) return;
  if (terminal_) draw(true);
  active_ = false;
}

void Progress::draw(bool final_line) {
  const double s = std::chrono::duration<double>(clock_() - start_).count();
  if (total_ > 0)
    std::fprintf(stderr, "\r\033[K%s %3.0f%% (%.1f s)", label_.c_str(), 100.0 * double(done_) / double(total_), s);
  else
    std::fprintf(stderr, "\r\033[K%s %llu (%.1f s)", label_.c_str(), static_cast<unsigned long long>(done_), s);
  if (final_line) std::fputs("\r\033[K", stderr);  // leave the terminal clean for the summary
  std::fflush(stderr);
}

// "diffdvr: 40% (20/50), 1m10s elapsed, ~1m45s left": one line a log keeps as it is.
void Progress::print_plain_line() {
  const double s = std::chrono::duration<double>(clock_() - start_).count();
  const auto done = static_cast<unsigned long long>(done_);
  if (total_ > 0) {
    const double fraction = double(done_) / double(total_);
    const double left_s = estimated_seconds_left(s, done_, total_);
    const std::string left = left_s >= 0 ? "~" + format_duration(left_s) : "?";
    std::fprintf(stderr, "%s: %.0f%% (%llu/%llu), %s elapsed, %s left\n", label_.c_str(), 100.0 * fraction, done,
                 static_cast<unsigned long long>(total_), format_duration(s).c_str(), left.c_str());
  } else {
    std::fprintf(stderr, "%s: %llu done, %s elapsed\n", label_.c_str(), done, format_duration(s).c_str());
  }
  std::fflush(stderr);
}

}  // namespace tfm
