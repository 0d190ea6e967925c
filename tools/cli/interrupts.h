// SIGINT and SIGTERM for the command line. The first signal requests cancellation
// (host/model/cancellation.h) and wakes a watchdog thread: the work stops at its next checkpoint
// and unwinds, which removes its temporary files and staged outputs (host/io/atomic_file.h), and
// main() exits with 128 + the signal (130, 143). If the work has not stopped within kGrace (a
// long GPU submission or library call has no checkpoint), or a second signal comes, the watchdog
// removes every pending temporary path itself and exits at once with the same code. Work that did
// stop at a checkpoint and is still unwinding then gets kTeardownGrace more: freeing a Vulkan
// device takes most of a second on some drivers (NVIDIA 580 with the validation layer).
#pragma once

#include <chrono>

namespace tfm::cli {

constexpr std::chrono::milliseconds kGrace{800};
constexpr std::chrono::milliseconds kTeardownGrace{4000};

// Installs the handlers and starts the watchdog; call once, before any work.
void install_interrupt_handlers();

// For a command whose normal end is a signal (`tfmatch view`): the watchdog waits `grace`
// instead of kGrace for it to stop by itself (closing its server, letting a running job reach
// its next checkpoint) before it exits on its own. A second signal still ends it at once.
void set_interrupt_grace(std::chrono::milliseconds grace);

// main() has printed how the command ended (an interrupt's message among them): should the
// watchdog still end the process (a teardown that outlasts its grace, such as MPI_Finalize waiting
// for a rank that has not stopped yet), it exits without a second message.
void note_ending_reported();

// "SIGINT", "SIGTERM" or "signal N".
const char* signal_name(int signal);

}  // namespace tfm::cli
