// One thread per open connection, up to a cap, and the deadline for a request (connection_workers.h).
#include "tfmatch/viewer/connection_workers.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <tuple>

namespace tfm {
namespace {
thread_local bool t_over_capacity = false;
}  // namespace

thread_local ConnectionWorkers* ConnectionWorkers::current_workers_ = nullptr;
thread_local ConnectionWorkers::Connection* ConnectionWorkers::current_connection_ = nullptr;

ConnectionWorkers::ConnectionWorkers(size_t max_connections, size_t spare_threads)
    : max_connections_(max_connections), max_threads_(max_connections + spare_threads) {}

ConnectionWorkers::~ConnectionWorkers() { shutdown(); }

void ConnectionWorkers::set_request_deadline(double seconds, int port) {
  std::lock_guard lock(mutex_);
  deadline_s_ = seconds;
  port_ = port;
  if (seconds > 0 && !watcher_.joinable() && !stopping_) watcher_ = std::thread([this] { watch(); });
}

// The socket the listening thread has just accepted. The HTTP library (cpp-httplib) hands
// enqueue() a closure over it, not the descriptor; it is the one open socket on the listening
// port that is neither listening nor a connection already known (by descriptor and inode: a
// connection's socket closed a moment ago may have left its number to this one). The list of
// open descriptors comes from /proc (one directory read, not a probe of every number).
std::pair<int, unsigned long> ConnectionWorkers::accepted_socket() const {
  if (port_ <= 0) return {-1, 0};
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/proc/self/fd", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.empty() || !std::all_of(name.begin(), name.end(), [](char c) { return c >= '0' && c <= '9'; })) continue;
    const int fd = std::stoi(name);
    struct stat st {};
    if (fstat(fd, &st) != 0 || !S_ISSOCK(st.st_mode)) continue;
    const unsigned long inode = st.st_ino;
    if (std::any_of(connections_.begin(), connections_.end(),
                    [&](const auto& c) { return c->fd == fd && c->inode == inode; }))
      continue;
    int listening = 0;
    socklen_t length = sizeof listening;
    if (getsockopt(fd, SOL_SOCKET, SO_ACCEPTCONN, &listening, &length) != 0 || listening) continue;
    sockaddr_storage local{};
    socklen_t size = sizeof local;
    if (getsockname(fd, reinterpret_cast<sockaddr*>(&local), &size) != 0) continue;
    const int port = local.ss_family == AF_INET    ? ntohs(reinterpret_cast<const sockaddr_in&>(local).sin_port)
                     : local.ss_family == AF_INET6 ? ntohs(reinterpret_cast<const sockaddr_in6&>(local).sin6_port)
                                                   : -1;
    if (port == port_) return {fd, inode};
  }
  return {-1, 0};
}

void ConnectionWorkers::shut_down(Connection& c) {
  if (c.shut || c.fd < 0) return;
  c.shut = true;
  struct stat st {};
  if (fstat(c.fd, &st) != 0 || st.st_ino != c.inode) return;  // closed already: the number is another's
  ::shutdown(c.fd, SHUT_RDWR);  // the library's poll or recv returns; it closes the socket
}

void ConnectionWorkers::enqueue(std::function<void()> serve) {
  std::unique_lock lock(mutex_);
  if (stopping_) {  // no thread will take it: serve (and so close) it here
    lock.unlock();
    serve();
    return;
  }
  ++open_;
  Job job{std::move(serve), open_ > max_connections_, nullptr};
  if (deadline_s_ > 0) {
    // At the cap, the connection that has waited longest for a request makes room (a client
    // trickling one in, or an idle keep-alive socket, which its browser reopens): clients that
    // hold connections open without a request cannot shut out one that sends its request at once.
    if (job.over_capacity) {
      Connection* oldest = nullptr;
      for (const auto& c : connections_)
        if (c->reading && !c->shut && (!oldest || c->since < oldest->since)) oldest = c.get();
      if (oldest) {
        shut_down(*oldest);
        job.over_capacity = false;
      }
    }
    job.connection = std::make_shared<Connection>();
    std::tie(job.connection->fd, job.connection->inode) = accepted_socket();
    if (job.connection->fd >= 0) connections_.push_back(job.connection);
  }
  jobs_.push_back(std::move(job));
  // Compare with the idle threads rather than test for one: an idle thread that has been woken
  // but has not yet taken its job is still counted idle, and two connections must not both
  // count on it.
  if (jobs_.size() > idle_ && threads_.size() < max_threads_) threads_.emplace_back([this] { work(); });
  wake_.notify_one();
}

void ConnectionWorkers::work() {
  std::unique_lock lock(mutex_);
  for (;;) {
    ++idle_;
    wake_.wait(lock, [&] { return !jobs_.empty() || stopping_; });
    --idle_;
    if (jobs_.empty()) return;  // stopping, and nothing left to serve
    Job job = std::move(jobs_.front());
    jobs_.pop_front();
    lock.unlock();
    t_over_capacity = job.over_capacity;
    current_workers_ = this;
    current_connection_ = job.connection.get();
    job.serve();
    current_connection_ = nullptr;
    current_workers_ = nullptr;
    t_over_capacity = false;
    lock.lock();
    --open_;
    // Closed by now (the library closes the socket when serve returns): its descriptor may be
    // the next accept's.
    if (job.connection) std::erase(connections_, job.connection);
  }
}

void ConnectionWorkers::request_read() {
  if (!current_workers_ || !current_connection_) return;
  std::lock_guard lock(current_workers_->mutex_);
  current_connection_->reading = false;
}

void ConnectionWorkers::response_sent() {
  if (!current_workers_ || !current_connection_) return;
  std::lock_guard lock(current_workers_->mutex_);
  current_connection_->reading = true;
  current_connection_->since = std::chrono::steady_clock::now();
}

void ConnectionWorkers::watch() {
  std::unique_lock lock(mutex_);
  while (!stopping_) {
    watcher_wake_.wait_for(lock, std::chrono::milliseconds(200));
    const auto now = std::chrono::steady_clock::now();
    for (const auto& c : connections_)
      if (c->reading && std::chrono::duration<double>(now - c->since).count() > deadline_s_) shut_down(*c);
  }
}

void ConnectionWorkers::shutdown() {
  std::vector<std::thread> threads;
  std::thread watcher;
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    threads.swap(threads_);
    watcher.swap(watcher_);
    // A connection between requests would keep its thread until its client sent one, or gave
    // up: the stop does not wait for that.
    for (const auto& c : connections_)
      if (c->reading) shut_down(*c);
  }
  wake_.notify_all();
  watcher_wake_.notify_all();
  if (watcher.joinable()) watcher.join();
  for (std::thread& t : threads) t.join();
}

bool ConnectionWorkers::current_over_capacity() { return t_over_capacity; }

size_t ConnectionWorkers::open_connections() const {
  std::lock_guard lock(mutex_);
  return open_;
}

size_t ConnectionWorkers::threads() const {
  std::lock_guard lock(mutex_);
  return threads_.size();
}

}  // namespace tfm
