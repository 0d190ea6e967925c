// The threads that serve `tfmatch view`'s connections: one per open connection, up to a cap, so a
// connection that waits (an event stream, an idle keep-alive socket, a client that sent half a
// request) never holds up another one, as it did in a fixed pool of 8 threads.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <set>
#include <thread>
#include <utility>
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
  // Lets every queued and running connection finish, then joins the threads. Idempotent. With a
  // request deadline, connections still waiting for a request are shut down first, so that a
  // client trickling one in holds up no stop.
  void shutdown();

  // A connection must deliver each request whole within `seconds` of its accept or of the
  // previous response (request_read() .. response_sent()), else its socket is shut down and the
  // HTTP library's read fails and closes it: a per-read timeout alone let a client that sends a
  // byte a second hold a thread for hours, and a few hundred of them every thread. `port` is the
  // listening port, by which enqueue() finds the socket just accepted (see there). With it, a
  // connection accepted at the cap shuts down the one that has waited longest for a request, if
  // any, and is served rather than marked over capacity. Call before serving.
  void set_request_deadline(double seconds, int port);
  // On a connection's thread: its request has been read (no deadline while it is handled, an
  // event stream's hours included), and its response has been sent (the next request's deadline
  // starts).
  static void request_read();
  static void response_sent();

  // On a thread running a connection: whether it was accepted while max_connections others were
  // open. False on any other thread.
  static bool current_over_capacity();

  size_t open_connections() const;  // accepted and not yet finished (queued ones included)
  size_t threads() const;           // started so far (they stay until shutdown)

 private:
  // A connection's socket and whether (since when) it waits for a request.
  struct Connection {
    int fd = -1;
    unsigned long inode = 0;  // the socket's: a closed socket's descriptor may be reused at once
    bool reading = true;
    bool shut = false;
    std::chrono::steady_clock::time_point since = std::chrono::steady_clock::now();
  };
  struct Job {
    std::function<void()> serve;
    bool over_capacity = false;
    std::shared_ptr<Connection> connection;
  };
  void work();
  void watch();                     // the deadline's thread
  // mutex_ held: the socket just accepted as {descriptor, inode}, or {-1, 0}.
  std::pair<int, unsigned long> accepted_socket() const;
  void shut_down(Connection& c);    // mutex_ held
  const size_t max_connections_, max_threads_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<Job> jobs_;
  std::vector<std::thread> threads_;
  size_t open_ = 0, idle_ = 0;
  bool stopping_ = false;
  // The deadline (0: none), the listening port, the open connections whose socket is known.
  double deadline_s_ = 0.0;
  int port_ = -1;
  std::vector<std::shared_ptr<Connection>> connections_;
  std::condition_variable watcher_wake_;
  std::thread watcher_;
  // The workers and connection of the calling thread while it serves one.
  static thread_local ConnectionWorkers* current_workers_;
  static thread_local Connection* current_connection_;
};

}  // namespace tfm
