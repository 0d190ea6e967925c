// Stopping long work early: one process-wide flag that the command line sets from its SIGINT and
// SIGTERM handlers (and an embedding host from any thread), and that long loops (solver
// iterations, DiffDVR steps, render bands, volume reading and file writing) check between steps.
// A check that finds it set throws Cancelled; unwinding removes temporary files and partial
// outputs (host/io/atomic_file.h), and the command line exits with 128 + the signal number.
#pragma once

namespace tfm {

// Thrown by check_cancelled(). Deliberately not a std::exception: code that turns errors into a
// message or a table row (a solver comparison, a self-test case) catches std::exception, and a
// cancellation must pass through all of it to the top.
class Cancelled {
 public:
  explicit Cancelled(int signal) : signal_(signal) {}
  int signal() const { return signal_; }  // 0 when requested by a call, not a signal
  const char* what() const { return "cancelled"; }

 private:
  int signal_;
};

// Sets the flag (async-signal-safe: one lock-free atomic store). `signal` is reported by
// Cancelled::signal(); a later request does not overwrite the first one's.
void request_cancel(int signal = 0) noexcept;
bool cancel_requested() noexcept;
// Clears the flag (tests, or a host that runs again after an interrupt).
void reset_cancel() noexcept;
// Throws Cancelled when the flag is set.
void check_cancelled();
// True once a check has thrown Cancelled since the last reset: the work has stopped and is
// unwinding (freeing device objects, removing temporary files). The command line's watchdog
// gives such a process longer to exit than one still inside a step.
bool cancel_acknowledged() noexcept;

// check_cancelled() at a named point of a long phase ("load", "solve", "render", "write",
// "report"). Two environment variables make phases observable, for tests and for finding where a
// run spends its time: TFMATCH_TRACE_PHASES=1 prints "tfmatch: phase NAME (at T s)" on stderr the
// first time each phase is reached (T: seconds since the program started), and
// TFMATCH_PAUSE_AT=NAME[#K][!] waits at that phase's first (K-th) checkpoint, after printing
// "tfmatch: paused in phase NAME", until cancellation is requested, so a test can send a signal
// while the phase is under way; with "!" it waits without looking at the flag (up to a minute),
// as a step without checkpoints would.
void checkpoint(const char* phase);

// The pause of TFMATCH_PAUSE_AT for a host or a test in this process, which has read the
// environment at its first checkpoint: `spec` as that variable's value, its K counting the
// checkpoints passed from this call on; nullptr or "" removes the pause (the environment's too).
void set_pause_point(const char* spec);
// True while a checkpoint waits at the pause point: the work is held there for certain.
bool paused_at_checkpoint() noexcept;

}  // namespace tfm
