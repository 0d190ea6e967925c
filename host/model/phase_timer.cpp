// Process-wide per-phase wall-clock accounting (host/model/phase_timer.h).
#include "tfmatch/model/phase_timer.h"

#include <atomic>
#include <chrono>
#include <utility>

namespace tfm {
namespace {

const auto g_start = std::chrono::steady_clock::now();

// Nanoseconds per phase; atomics so scopes on any thread add without a lock.
std::array<std::atomic<int64_t>, kPhaseCount> g_nanoseconds{};

// The innermost open scope of this thread, and whether an UntimedThread lives on it.
thread_local PhaseScope* t_innermost = nullptr;
thread_local bool t_untimed = false;

void add(Phase phase, double seconds) {
  g_nanoseconds[static_cast<std::size_t>(phase)].fetch_add(static_cast<int64_t>(seconds * 1e9),
                                                           std::memory_order_relaxed);
}

}  // namespace

// The clock operations PhaseScope's constructor and destructor share.
struct PhaseClock {
  static void pause(PhaseScope& s, double now) { add(s.phase_, now - s.resumed_at_s_); }
  static void resume(PhaseScope& s, double now) { s.resumed_at_s_ = now; }
};

std::string_view phase_name(Phase phase) {
  switch (phase) {
    case Phase::Startup: return "startup";
    case Phase::Pipelines: return "pipelines";
    case Phase::Read: return "read";
    case Phase::Upload: return "upload";
    case Phase::Compute: return "compute";
    case Phase::Download: return "download";
    case Phase::Write: return "write";
    case Phase::Count: break;
  }
  return "?";
}

double seconds_since_start() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - g_start).count();
}

UntimedThread::UntimedThread() : was_untimed_(std::exchange(t_untimed, true)) {}
UntimedThread::~UntimedThread() { t_untimed = was_untimed_; }

PhaseScope::PhaseScope(Phase phase, Nesting nesting)
    : phase_(phase), counts_(!t_untimed && !(nesting == Nesting::YieldToOuter && t_innermost)), outer_(t_innermost) {
  if (!counts_) return;
  const double now = seconds_since_start();
  if (outer_) PhaseClock::pause(*outer_, now);
  PhaseClock::resume(*this, now);
  t_innermost = this;
}

PhaseScope::~PhaseScope() {
  if (!counts_) return;
  const double now = seconds_since_start();
  PhaseClock::pause(*this, now);
  if (outer_) PhaseClock::resume(*outer_, now);
  t_innermost = outer_;
}

PhaseTimes phase_times() {
  PhaseTimes t;
  for (std::size_t i = 0; i < kPhaseCount; ++i)
    t.seconds[i] = double(g_nanoseconds[i].load(std::memory_order_relaxed)) * 1e-9;
  t.since_start_s = seconds_since_start();
  return t;
}

}  // namespace tfm
