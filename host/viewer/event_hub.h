// Server-sent events from one producer to many streams (GET /api/progress): the producer publishes
// the newest value of each topic ("job", "version"), every stream waits on the hub and sends what
// is newer than what it sent. A slow stream skips to the newest value instead of queueing, a
// waiting stream costs no work, and the JSON is made once per change, not once per stream.
// At most max_streams are open: a new one replaces the oldest, which is told so and ends.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace tfm {

class EventHub {
 public:
  explicit EventHub(size_t max_streams);

  struct Update {
    std::string topic, data;
  };
  struct Subscription {
    uint64_t seen = 0;  // the newest publication this stream has received
    bool replaced = false;
  };

  // Replaces the topic's value; every stream receives it (or a newer one).
  void publish(const std::string& topic, std::string data);
  // A new stream that receives what is published from now on. Past max_streams, the oldest
  // open stream is marked replaced (its wait returns Replaced) and no longer counted.
  std::shared_ptr<Subscription> subscribe();
  // The stream ended (its client went away, or it ended itself).
  void unsubscribe(const std::shared_ptr<Subscription>& s);

  enum class Wake { Updates, Timeout, Replaced, Closed };
  // Waits up to `timeout` for publications newer than the stream's last; on Updates, `updates`
  // holds the newest value of each topic that changed, oldest publication first.
  Wake wait(Subscription& s, std::chrono::milliseconds timeout, std::vector<Update>& updates);
  // Every wait returns Closed from now on (the server stops).
  void close();

  size_t streams() const;

 private:
  struct Value {
    uint64_t seq = 0;
    std::string data;
  };
  const size_t max_streams_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::map<std::string, Value> values_;
  std::list<std::shared_ptr<Subscription>> open_;  // oldest first
  uint64_t seq_ = 0;
  bool closed_ = false;
};

}  // namespace tfm
