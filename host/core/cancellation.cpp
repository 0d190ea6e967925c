// The cancellation flag and the phase checkpoints.
#include "cancellation.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

namespace tfm {
namespace {

// -1: not requested; else the signal number (0 for a call). Lock-free, so a signal handler may
// set it.
std::atomic<int> g_signal{-1};
static_assert(std::atomic<int>::is_always_lock_free);
// Set when a check throws Cancelled (the watchdog thread reads it).
std::atomic<bool> g_acknowledged{false};

// Longest a TFMATCH_PAUSE_AT pause waits for the cancellation it is there for.
constexpr auto kMaxPause = std::chrono::seconds(60);

// When the program started, about: TFMATCH_TRACE_PHASES prints each phase's first checkpoint
// with the seconds since then.
const auto g_start = std::chrono::steady_clock::now();

}  // namespace

void request_cancel(int signal) noexcept {
  int none = -1;
  g_signal.compare_exchange_strong(none, signal);
}

bool cancel_requested() noexcept { return g_signal.load() >= 0; }

void reset_cancel() noexcept {
  g_signal.store(-1);
  g_acknowledged.store(false);
}

void check_cancelled() {
  const int s = g_signal.load();
  if (s < 0) return;
  g_acknowledged.store(true);
  throw Cancelled(s);
}

bool cancel_acknowledged() noexcept { return g_acknowledged.load(); }

namespace {

// TFMATCH_PAUSE_AT=NAME[#K][!], parsed once.
struct PausePoint {
  std::string phase;
  uint64_t nth = 1;
  bool ignore_flag = false;
};

std::optional<PausePoint> pause_point() {
  const char* text = std::getenv("TFMATCH_PAUSE_AT");
  if (!text || !*text) return std::nullopt;
  PausePoint p{text};
  if (!p.phase.empty() && p.phase.back() == '!') p.ignore_flag = true, p.phase.pop_back();
  if (const auto hash = p.phase.find('#'); hash != std::string::npos) {
    p.nth = std::max<uint64_t>(1, std::strtoull(p.phase.c_str() + hash + 1, nullptr, 10));
    p.phase.resize(hash);
  }
  return p;
}

}  // namespace

void checkpoint(const char* phase) {
  static const bool trace = std::getenv("TFMATCH_TRACE_PHASES") != nullptr;
  static const std::optional<PausePoint> pause = pause_point();
  if (trace || pause) {
    static std::mutex mutex;
    static std::map<std::string, uint64_t> reached;  // checkpoints passed per phase
    uint64_t count = 0;
    {
      std::lock_guard lock(mutex);
      count = ++reached[phase];
    }
    if (count == 1 && trace)
      std::fprintf(stderr, "tfmatch: phase %s (at %.3f s)\n", phase,
                   std::chrono::duration<double>(std::chrono::steady_clock::now() - g_start).count());
    if (pause && count == pause->nth && pause->phase == phase) {
      std::fprintf(stderr, "tfmatch: paused in phase %s\n", phase);
      std::fflush(stderr);
      const auto end = std::chrono::steady_clock::now() + kMaxPause;
      while ((pause->ignore_flag || !cancel_requested()) && std::chrono::steady_clock::now() < end)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    if (trace && cancel_requested()) std::fprintf(stderr, "tfmatch: stopping at a checkpoint of phase %s\n", phase);
  }
  check_cancelled();
}

}  // namespace tfm
