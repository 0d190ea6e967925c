// Where a process spends its wall-clock time: start-up, pipeline creation, reading, uploading,
// device compute, downloading, writing. Process-wide, so the command line's `--json` can report
// every phase of a run ("timings") and show what remains outside them.
#pragma once

#include <array>
#include <cstddef>
#include <string_view>

namespace tfm {

enum class Phase : std::size_t {
  Startup,    // Vulkan instance and device creation (Context::create)
  Pipelines,  // shader modules and compute pipelines (the driver's compiler, or its cache)
  Read,       // input files into host memory
  Upload,     // host memory to device buffers
  Compute,    // waiting for device work other than transfers
  Download,   // device buffers to host memory
  Write,      // encoding and writing output files
  Count
};
inline constexpr std::size_t kPhaseCount = static_cast<std::size_t>(Phase::Count);
// "startup", "pipelines", "read", "upload", "compute", "download", "write".
std::string_view phase_name(Phase phase);

// Times the enclosing scope as `phase`. Scopes nest on a thread and count exclusively: while an
// inner scope runs, its outer one's clock stops, so an upload's own waits for the device count as
// upload, not as compute, and phases on one thread never add up to more than its wall time.
// Scopes on several threads at once (reading two files side by side) each count, so the sum over
// phases may then exceed the process's wall time.
class PhaseScope {
 public:
  // YieldToOuter: count only when no other scope is open on this thread; inside one, that one
  // keeps counting (a wait for the device inside an upload is the upload's time, not compute).
  enum class Nesting { Count, YieldToOuter };
  explicit PhaseScope(Phase phase, Nesting nesting = Nesting::Count);
  ~PhaseScope();
  PhaseScope(const PhaseScope&) = delete;
  PhaseScope& operator=(const PhaseScope&) = delete;

 private:
  Phase phase_;
  bool counts_;
  PhaseScope* outer_;
  double resumed_at_s_;  // when this scope's clock last started (seconds since process start)
  friend struct PhaseClock;
};

// While one lives, PhaseScopes on this thread count nothing: for a helper thread whose work
// overlaps a scope of the thread that waits for it (a second file read side by side), so the
// overlap is counted once, as the waiting thread's wall time.
class UntimedThread {
 public:
  UntimedThread();
  ~UntimedThread();
  UntimedThread(const UntimedThread&) = delete;
  UntimedThread& operator=(const UntimedThread&) = delete;

 private:
  bool was_untimed_;
};

struct PhaseTimes {
  std::array<double, kPhaseCount> seconds{};  // per phase, summed over the process's scopes
  double since_start_s = 0;                   // wall time since the program started
};
// The time each phase has taken so far, and the time since the program started (its static
// initialization: the dynamic loader's work before it is not seen). Thread-safe.
PhaseTimes phase_times();
// Seconds since the program started, as phase_times() counts them.
double seconds_since_start();

}  // namespace tfm
