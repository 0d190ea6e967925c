// One producer, many event streams, newest value per topic (event_hub.h).
#include "tfmatch/viewer/event_hub.h"

#include <algorithm>

namespace tfm {

EventHub::EventHub(size_t max_streams) : max_streams_(std::max<size_t>(1, max_streams)) {}

void EventHub::publish(const std::string& topic, std::string data) {
  {
    std::lock_guard lock(mutex_);
    values_[topic] = {++seq_, std::move(data)};
  }
  changed_.notify_all();
}

std::shared_ptr<EventHub::Subscription> EventHub::subscribe() {
  auto s = std::make_shared<Subscription>();
  bool replaced_one = false;
  {
    std::lock_guard lock(mutex_);
    s->seen = seq_;
    if (open_.size() >= max_streams_) {
      open_.front()->replaced = true;
      open_.pop_front();
      replaced_one = true;
    }
    open_.push_back(s);
  }
  if (replaced_one) changed_.notify_all();
  return s;
}

void EventHub::unsubscribe(const std::shared_ptr<Subscription>& s) {
  std::lock_guard lock(mutex_);
  open_.remove(s);
}

EventHub::Wake EventHub::wait(Subscription& s, std::chrono::milliseconds timeout, std::vector<Update>& updates) {
  updates.clear();
  std::unique_lock lock(mutex_);
  const bool woken = changed_.wait_for(lock, timeout, [&] { return closed_ || s.replaced || seq_ > s.seen; });
  if (closed_) return Wake::Closed;
  if (s.replaced) return Wake::Replaced;
  if (!woken) return Wake::Timeout;
  std::vector<std::pair<uint64_t, const std::pair<const std::string, Value>*>> newer;
  for (const auto& entry : values_)
    if (entry.second.seq > s.seen) newer.push_back({entry.second.seq, &entry});
  std::sort(newer.begin(), newer.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& [seq, entry] : newer) updates.push_back({entry->first, entry->second.data});
  s.seen = seq_;
  return Wake::Updates;
}

void EventHub::close() {
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
  }
  changed_.notify_all();
}

size_t EventHub::streams() const {
  std::lock_guard lock(mutex_);
  return open_.size();
}

}  // namespace tfm
