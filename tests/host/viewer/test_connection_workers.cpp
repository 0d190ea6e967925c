// The viewer's connection threads and event hub without HTTP: every open connection runs at once
// up to the cap, connections over it are marked, threads stay bounded; the hub hands every stream
// the newest value of each topic, replaces the oldest stream past its bound and wakes all on close.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "tfmatch/viewer/connection_workers.h"
#include "tfmatch/viewer/event_hub.h"

namespace tfm {
namespace {

using namespace std::chrono_literals;

// Holds every job that waits on it until released.
class Gate {
 public:
  void wait() {
    std::unique_lock lock(mutex_);
    ++waiting_;
    changed_.notify_all();
    changed_.wait(lock, [&] { return open_; });
  }
  void open() {
    std::lock_guard lock(mutex_);
    open_ = true;
    changed_.notify_all();
  }
  // True once `n` jobs wait, false after `timeout`.
  bool wait_for_waiting(int n, std::chrono::milliseconds timeout = 10s) {
    std::unique_lock lock(mutex_);
    return changed_.wait_for(lock, timeout, [&] { return waiting_ >= n; });
  }
  int waiting() {
    std::lock_guard lock(mutex_);
    return waiting_;
  }

 private:
  std::mutex mutex_;
  std::condition_variable changed_;
  int waiting_ = 0;
  bool open_ = false;
};

TEST(ConnectionWorkers, EveryOpenConnectionRunsAtOnce) {
  ConnectionWorkers workers(64);
  Gate gate;
  std::atomic<int> done{0};
  for (int i = 0; i < 40; ++i) workers.enqueue([&] {
      gate.wait();
      ++done;
    });
  // 40 connections that wait (streams, idle sockets) are all being served at the same time.
  EXPECT_TRUE(gate.wait_for_waiting(40)) << gate.waiting() << " of 40 running";
  EXPECT_EQ(workers.open_connections(), 40u);
  EXPECT_LE(workers.threads(), 40u);
  gate.open();
  workers.shutdown();
  EXPECT_EQ(done, 40);
  EXPECT_EQ(workers.open_connections(), 0u);
}

TEST(ConnectionWorkers, ConnectionsOverTheCapAreMarkedAndServed) {
  ConnectionWorkers workers(2, 4);
  Gate gate;
  std::mutex mutex;
  std::vector<bool> over;
  auto job = [&] {
    {
      std::lock_guard lock(mutex);
      over.push_back(ConnectionWorkers::current_over_capacity());
    }
    gate.wait();
  };
  for (int i = 0; i < 4; ++i) {
    workers.enqueue(job);
    ASSERT_TRUE(gate.wait_for_waiting(i + 1));  // in order, so the marks follow the order
  }
  EXPECT_EQ(over, (std::vector<bool>{false, false, true, true}));
  EXPECT_FALSE(ConnectionWorkers::current_over_capacity());  // not a connection thread
  gate.open();
  // Once they have finished, a new connection is under the cap again.
  for (int i = 0; i < 500 && workers.open_connections() > 0; ++i) std::this_thread::sleep_for(10ms);
  std::atomic<bool> later_over{true};
  workers.enqueue([&] { later_over = ConnectionWorkers::current_over_capacity(); });
  workers.shutdown();
  EXPECT_FALSE(later_over);
}

TEST(ConnectionWorkers, ThreadsAreBoundedAndTheRestWait) {
  ConnectionWorkers workers(1, 1);  // at most 2 threads
  Gate gate;
  std::atomic<int> done{0};
  for (int i = 0; i < 3; ++i) workers.enqueue([&] {
      gate.wait();
      ++done;
    });
  ASSERT_TRUE(gate.wait_for_waiting(2));
  EXPECT_FALSE(gate.wait_for_waiting(3, 200ms));  // the third waits for a thread
  EXPECT_EQ(workers.threads(), 2u);
  EXPECT_EQ(workers.open_connections(), 3u);
  gate.open();
  workers.shutdown();  // the queued one runs before the threads end
  EXPECT_EQ(done, 3);
}

TEST(ConnectionWorkers, AfterShutdownAConnectionIsServedWhereItArrives) {
  ConnectionWorkers workers(4);
  workers.shutdown();
  bool served = false;
  workers.enqueue([&] { served = true; });  // e.g. closes the socket
  EXPECT_TRUE(served);
}

TEST(EventHub, StreamsReceiveTheNewestValuePerTopicInOrder) {
  EventHub hub(8);
  hub.publish("job", "old");  // before the stream: not received
  auto s = hub.subscribe();
  std::vector<EventHub::Update> updates;
  EXPECT_EQ(hub.wait(*s, 10ms, updates), EventHub::Wake::Timeout);
  hub.publish("job", "1");
  hub.publish("version", "v1");
  hub.publish("job", "2");  // a slow stream skips "1"
  ASSERT_EQ(hub.wait(*s, 1s, updates), EventHub::Wake::Updates);
  ASSERT_EQ(updates.size(), 2u);
  EXPECT_EQ(updates[0].topic, "version");
  EXPECT_EQ(updates[0].data, "v1");
  EXPECT_EQ(updates[1].topic, "job");
  EXPECT_EQ(updates[1].data, "2");
  EXPECT_EQ(hub.wait(*s, 10ms, updates), EventHub::Wake::Timeout);
  EXPECT_TRUE(updates.empty());
}

TEST(EventHub, AWaitingStreamWakesOnPublish) {
  EventHub hub(8);
  auto s = hub.subscribe();
  std::thread producer([&] {
    std::this_thread::sleep_for(50ms);
    hub.publish("job", "x");
  });
  std::vector<EventHub::Update> updates;
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(hub.wait(*s, 10s, updates), EventHub::Wake::Updates);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 5s);
  producer.join();
}

TEST(EventHub, PastItsBoundANewStreamReplacesTheOldest) {
  EventHub hub(3);
  std::vector<std::shared_ptr<EventHub::Subscription>> subs;
  for (int i = 0; i < 5; ++i) subs.push_back(hub.subscribe());
  EXPECT_EQ(hub.streams(), 3u);
  std::vector<EventHub::Update> updates;
  EXPECT_EQ(hub.wait(*subs[0], 1s, updates), EventHub::Wake::Replaced);
  EXPECT_EQ(hub.wait(*subs[1], 1s, updates), EventHub::Wake::Replaced);
  EXPECT_EQ(hub.wait(*subs[2], 10ms, updates), EventHub::Wake::Timeout);
  hub.unsubscribe(subs[4]);
  EXPECT_EQ(hub.streams(), 2u);
  hub.unsubscribe(subs[0]);  // already gone: nothing changes
  EXPECT_EQ(hub.streams(), 2u);
}

TEST(EventHub, CloseWakesEveryStream) {
  EventHub hub(8);
  auto a = hub.subscribe(), b = hub.subscribe();
  std::atomic<int> closed{0};
  std::thread waiter([&] {
    std::vector<EventHub::Update> updates;
    if (hub.wait(*a, 30s, updates) == EventHub::Wake::Closed) ++closed;
  });
  std::this_thread::sleep_for(20ms);
  hub.close();
  waiter.join();
  std::vector<EventHub::Update> updates;
  EXPECT_EQ(hub.wait(*b, 30s, updates), EventHub::Wake::Closed);
  EXPECT_EQ(closed, 1);
}

}  // namespace
}  // namespace tfm
