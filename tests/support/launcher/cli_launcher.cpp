// tfmatch_cli_launcher PROGRAM [ARGS...]: runs PROGRAM as its child and ends as the child did (the
// same exit status, or killed by the same signal), passing SIGINT and SIGTERM on to it; before it
// ends, writes the child's peak resident set size in bytes, as a decimal line, to the file
// descriptor named by TFMATCH_LAUNCHER_RSS_FD when that is set.
//
// Why (tests/support/cli_runner.h): the kernel keeps a process's ru_maxrss across exec and records
// there the memory it was forked with, so a program forked straight from the test binary reports
// at least the test binary's resident memory, hundreds of MiB after many GPU tests in one process.
// This launcher is small when it forks: the program's own peak is what it reports.
#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace {

volatile sig_atomic_t g_child = 0;

void pass_on(int signal) {
  if (g_child > 0) kill(pid_t(g_child), signal);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s PROGRAM [ARGS...]\n", argv[0]);
    return 127;
  }
  int rss_fd = -1;
  if (const char* fd = std::getenv("TFMATCH_LAUNCHER_RSS_FD")) {
    rss_fd = std::atoi(fd);
    fcntl(rss_fd, F_SETFD, FD_CLOEXEC);  // the launcher's alone: the program does not inherit it
    unsetenv("TFMATCH_LAUNCHER_RSS_FD");
  }
  // Blocked until the child's id is known, so a signal that comes meanwhile is passed on too.
  sigset_t forwarded, previous;
  sigemptyset(&forwarded);
  sigaddset(&forwarded, SIGINT);
  sigaddset(&forwarded, SIGTERM);
  sigprocmask(SIG_BLOCK, &forwarded, &previous);
  struct sigaction action{};
  action.sa_handler = pass_on;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  const pid_t launcher = getpid();
  const pid_t child = fork();
  if (child < 0) {
    std::perror("tfmatch_cli_launcher: fork");
    return 127;
  }
  if (child == 0) {
    // Killed with the launcher (a test's deadline kills the launcher).
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != launcher) _exit(127);
    sigprocmask(SIG_SETMASK, &previous, nullptr);  // exec restores the default handlers
    execv(argv[1], argv + 1);
    std::fprintf(stderr, "tfmatch_cli_launcher: %s: %s\n", argv[1], std::strerror(errno));
    _exit(127);
  }
  g_child = child;
  sigprocmask(SIG_SETMASK, &previous, nullptr);
  int status = 0;
  rusage usage{};
  while (wait4(child, &status, 0, &usage) < 0)
    if (errno != EINTR) return 127;
  if (rss_fd >= 0) {
    char line[32];
    const int n = std::snprintf(line, sizeof line, "%llu\n", static_cast<unsigned long long>(usage.ru_maxrss) * 1024);
    [[maybe_unused]] const ssize_t written = write(rss_fd, line, size_t(n));
    close(rss_fd);
  }
  if (WIFSIGNALED(status)) {
    const int signal = WTERMSIG(status);
    ::signal(signal, SIG_DFL);
    sigset_t only;
    sigemptyset(&only);
    sigaddset(&only, signal);
    sigprocmask(SIG_UNBLOCK, &only, nullptr);
    // No core file of the launcher: the child's crash is what the caller is told about.
    const rlimit no_core{0, 0};
    setrlimit(RLIMIT_CORE, &no_core);
    raise(signal);
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 127;
}
