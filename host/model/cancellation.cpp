// The cancellation flag and the phase checkpoints.
#include "tfmatch/model/cancellation.h"

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

// TFMATCH_PAUSE_AT=NAME[#K][!] (or set_pause_point's value) and the checkpoints of its phase passed
// since it was set.
struct PausePoint {
  std::string phase;
  uint64_t nth = 1;
  bool ignore_flag = false;
  uint64_t reached = 0;
};

std::optional<PausePoint> parse_pause_point(const char* text) {
  if (!text || !*text) return std::nullopt;
  PausePoint p{text};
  if (!p.phase.empty() && p.phase.back() == '!') p.ignore_flag = true, p.phase.pop_back();
  if (const auto hash = p.phase.find('#'); hash != std::string::npos) {
    p.nth = std::max<uint64_t>(1, std::strtoull(p.phase.c_str() + hash + 1, nullptr, 10));
    p.phase.resize(hash);
  }
  return p;
}

std::mutex g_pause_mutex;
std::optional<PausePoint> g_pause;  // guarded by g_pause_mutex
// Whether g_pause may hold a pause: checkpoints without one (the usual case) take no lock.
std::atomic<bool> g_pause_set{false};
std::atomic<int> g_paused{0};  // checkpoints waiting at the pause point now

// The environment's pause, read at the first checkpoint of the process (before: a
// set_pause_point call replaces it).
std::once_flag g_environment_read;
void read_environment_once() {
  std::call_once(g_environment_read, [] {
    std::lock_guard lock(g_pause_mutex);
    g_pause = parse_pause_point(std::getenv("TFMATCH_PAUSE_AT"));
    g_pause_set = g_pause.has_value();
  });
}

// Counts a checkpoint of `phase` and tells whether it is the pause point's (and whether that
// pause ignores the flag).
bool at_pause_point(const char* phase, bool& ignore_flag) {
  if (!g_pause_set.load()) return false;
  std::lock_guard lock(g_pause_mutex);
  if (!g_pause || g_pause->phase != phase) return false;
  ignore_flag = g_pause->ignore_flag;
  return ++g_pause->reached == g_pause->nth;
}

}  // namespace

void set_pause_point(const char* spec) {
  read_environment_once();  // so that the environment's value cannot replace this one later
  std::lock_guard lock(g_pause_mutex);
  g_pause = parse_pause_point(spec);
  g_pause_set = g_pause.has_value();
}

bool paused_at_checkpoint() noexcept { return g_paused.load() > 0; }

void checkpoint(const char* phase) {
  static const bool trace = std::getenv("TFMATCH_TRACE_PHASES") != nullptr;
  read_environment_once();
  if (trace) {
    static std::mutex mutex;
    static std::map<std::string, uint64_t> reached;  // checkpoints passed per phase
    uint64_t count = 0;
    {
      std::lock_guard lock(mutex);
      count = ++reached[phase];
    }
    if (count == 1)
      std::fprintf(stderr, "tfmatch: phase %s (at %.3f s)\n", phase,
                   std::chrono::duration<double>(std::chrono::steady_clock::now() - g_start).count());
  }
  bool ignore_flag = false;
  if (at_pause_point(phase, ignore_flag)) {
    std::fprintf(stderr, "tfmatch: paused in phase %s\n", phase);
    std::fflush(stderr);
    ++g_paused;
    const auto end = std::chrono::steady_clock::now() + kMaxPause;
    while ((ignore_flag || !cancel_requested()) && std::chrono::steady_clock::now() < end)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    --g_paused;
  }
  if (trace && cancel_requested()) std::fprintf(stderr, "tfmatch: stopping at a checkpoint of phase %s\n", phase);
  check_cancelled();
}

}  // namespace tfm
