// One thread per open connection, up to a cap (connection_workers.h).
#include "tfmatch/viewer/connection_workers.h"

namespace tfm {
namespace {
thread_local bool t_over_capacity = false;
}  // namespace

ConnectionWorkers::ConnectionWorkers(size_t max_connections, size_t spare_threads)
    : max_connections_(max_connections), max_threads_(max_connections + spare_threads) {}

ConnectionWorkers::~ConnectionWorkers() { shutdown(); }

void ConnectionWorkers::enqueue(std::function<void()> serve) {
  std::unique_lock lock(mutex_);
  if (stopping_) {  // no thread will take it: serve (and so close) it here
    lock.unlock();
    serve();
    return;
  }
  ++open_;
  jobs_.push_back({std::move(serve), open_ > max_connections_});
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
    job.serve();
    t_over_capacity = false;
    lock.lock();
    --open_;
  }
}

void ConnectionWorkers::shutdown() {
  std::vector<std::thread> threads;
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    threads.swap(threads_);
  }
  wake_.notify_all();
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
