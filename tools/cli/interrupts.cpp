// Signal handlers and the interrupt watchdog of the command line.
#include "interrupts.h"

#include <atomic>

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <thread>

#include <fcntl.h>
#include <poll.h>
#include <unistd.h>

#include "tfmatch/io/atomic_file.h"
#include "tfmatch/model/cancellation.h"

namespace tfm::cli {
namespace {

int g_wake[2] = {-1, -1};
std::atomic<int64_t> g_grace_ms{kGrace.count()};  // the handler writes the signal number; the watchdog reads it
std::atomic<bool> g_ending_reported{false};

// Async-signal-safe: an atomic store and a write(2).
void on_signal(int signal) {
  const int saved = errno;
  request_cancel(signal);
  const char byte = char(signal);
  [[maybe_unused]] const ssize_t n = ::write(g_wake[1], &byte, 1);
  errno = saved;
}

void watchdog() {
  char byte = 0;
  while (::read(g_wake[0], &byte, 1) != 1)
    if (errno != EINTR) return;
  const int signal = byte;
  // Give the work kGrace to reach a checkpoint and unwind (main() then exits and this thread
  // with it); a second signal cuts the wait short.
  pollfd wake{g_wake[0], POLLIN, 0};
  int woken = 0;
  while ((woken = ::poll(&wake, 1, int(g_grace_ms.load()))) < 0 && errno == EINTR) {
  }
  // Stopped at a checkpoint and unwinding: more time to free the device, unless a second signal
  // came meanwhile.
  if (woken == 0 && cancel_acknowledged())
    while (::poll(&wake, 1, int(kTeardownGrace.count())) < 0 && errno == EINTR) {
    }
  abandon_temporary_paths(signal);
  if (!g_ending_reported.load()) {
    std::fprintf(stderr, "\ntfmatch: interrupted (%s): stopped without waiting for the current step; "
                         "temporary files removed, no output written\n", signal_name(signal));
    std::fflush(stderr);
  }
  ::_exit(128 + signal);
}

}  // namespace

const char* signal_name(int signal) {
  switch (signal) {
    case SIGINT: return "SIGINT";
    case SIGTERM: return "SIGTERM";
    default: return "a signal";
  }
}

void set_interrupt_grace(std::chrono::milliseconds grace) { g_grace_ms = grace.count(); }

void note_ending_reported() { g_ending_reported = true; }

void install_interrupt_handlers() {
  if (::pipe2(g_wake, O_CLOEXEC) != 0) return;  // no watchdog: checkpoints still stop the work
  struct sigaction action{};
  action.sa_handler = on_signal;
  sigemptyset(&action.sa_mask);
  // Interrupted system calls resume: the work notices the request at its next checkpoint.
  action.sa_flags = SA_RESTART;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  std::thread(watchdog).detach();
}

}  // namespace tfm::cli
