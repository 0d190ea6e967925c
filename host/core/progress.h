// Progress on the terminal for long runs: a single updating line on stderr, only when stderr
// is a terminal (never in logs, pipes or tests) and not switched off.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

namespace tfm {

// Process-wide switch (the CLI turns it off for --quiet); on by default.
void set_progress_enabled(bool enabled);
bool progress_enabled();  // the switch and isatty(stderr)

class Progress {
 public:
  // `total` units of work; 0 means unknown (only the count is shown).
  Progress(std::string label, uint64_t total);
  ~Progress();  // finishes the line
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  void update(uint64_t done);  // redraws at most every 100 ms
  void set_label(std::string label);
  void finish();

 private:
  void draw(bool final_line);
  std::string label_;
  uint64_t total_ = 0, done_ = 0;
  bool active_ = false;
  std::chrono::steady_clock::time_point start_, last_;
};

}  // namespace tfm
