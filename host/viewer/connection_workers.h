// The threads that serve `tfmatch view`'s connections: one per open connection, up to a cap, so a
// connection that waits (an event stream, an idle keep-alive socket, a client that sent half a
// request) never holds up another one, as it did in a fixed pool of 8 threads.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace tfm {

class ConnectionWorkers {
 public:
  // Connections beyond `max_connections` open ones are still served (so they can be told to come
  // back: current_over_capacity()), on at most `spare_threads` more threads; past that they wait
  // in a queue for a thread to free up.
  explicit ConnectionWorkers(size_t max_connections, size_t spare_threads = 8);
  ~ConnectionWorkers();  // shutdown()
  ConnectionWorkers(const ConnectionWorkers&) = delete;
  ConnectionWorkers& operator=(const ConnectionWorkers&) = delete;

  // Serves one accepted connection: `serve` runs on an idle thread, or on a new one while there
  // are fewer than max_connections + spare_threads, else when a thread frees up.
  void enqueue(std::function<void()> serve);
  // Lets every queued and running connection finish, then joins the threads. Idempotent.
  void shutdown();

  // On a thread running a connection: whether it was accepted while max_connections others were
  // open. False on any other thread.
  static bool current_over_capacity();

  size_t open_connections() const;  // accepted and not yet finished (queued ones included)
  size_t threads() const;           // started so far (they stay until shutdown)

 private:
  struct Job {
    std::function<void()> serve;
    bool over_capacity = false;
  };
  void work();

  const size_t max_connections_, max_threads_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<Job> jobs_;
  std::vector<std::thread> threads_;
  size_t open_ = 0, idle_ = 0;
  bool stopping_ = false;
};

}  // namespace tfm
