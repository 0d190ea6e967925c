// Progress of long runs on stderr. On a terminal: one updating line. Elsewhere (logs, pipes,
// batch jobs): a plain line every interval (10 s unless TFMATCH_PROGRESS_INTERVAL says otherwise)
// with percent, elapsed time and an estimate of the time left, so a run that lasts under one
// interval prints nothing and a long one is never silent.
#pragma once

#include <chrono>
#include <functional>
#include <cstdint>
#include <string>

namespace tfm {

// Process-wide switch (the CLI turns it off for --quiet); on by default.
void set_progress_enabled(bool enabled);
bool progress_enabled();  // the switch

// Seconds between plain lines when stderr is not a terminal: set_progress_interval's value if
// called, else the environment variable TFMATCH_PROGRESS_INTERVAL (seconds, > 0; tests set it
// small), else 10.
void set_progress_interval(double seconds);
double progress_interval_s();

// "1m10s", "3.2s", "2h05m": a duration for people.
std::string format_duration(double seconds);

// The time left that a plain line states, `elapsed_s` after `done` of `total` units: the rate so
// far holds (20 of 50 done after T: 1.5 T left). Negative when unknown: nothing done yet, or no
// total.
double estimated_seconds_left(double elapsed_s, uint64_t done, uint64_t total);

// Where a Progress reads the time: std::chrono::steady_clock::now unless given (tests step it).
using ProgressClock = std::function<std::chrono::steady_clock::time_point()>;

// Something other than stderr that follows progress on this thread: a server that streams a job's
// progress to a web page (host/viewer). Called on every update() and set_label() of a Progress
// made on the thread that installed it, whether or not progress lines are enabled, with the
// label, the units done and the total (0: unknown).
using ProgressObserver = std::function<void(const std::string& label, uint64_t done, uint64_t total)>;
// Installs `observer` for the current thread while it lives; the previous one comes back after.
class ScopedProgressObserver {
 public:
  explicit ScopedProgressObserver(ProgressObserver observer);
  ~ScopedProgressObserver();
  ScopedProgressObserver(const ScopedProgressObserver&) = delete;
  ScopedProgressObserver& operator=(const ScopedProgressObserver&) = delete;

 private:
  ProgressObserver previous_;
};

class Progress {
 public:
  // `total` units of work; 0 means unknown (only the count is shown).
  Progress(std::string label, uint64_t total, ProgressClock clock = {});
  ~Progress();  // finishes the line
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  void update(uint64_t done);  // terminal: redraws at most every 100 ms; else a line per interval
  void set_label(std::string label);
  void finish();

 private:
  void draw(bool final_line);
  void print_plain_line();
  void notify() const;
  std::string label_;
  uint64_t total_ = 0, done_ = 0;
  bool active_ = false;
  bool terminal_ = false;
  ProgressClock clock_;
  std::chrono::steady_clock::time_point start_, last_;
};

}  // namespace tfm
