// The producer and the streams of GET /api/progress (progress_events.h).
#include "tfmatch/viewer/progress_events.h"

#include "tfmatch/io/json.h"

namespace tfm {
namespace {

std::string version_json(uint64_t version) { return nlohmann::json{{"version", version}}.dump(); }

// Server-sent-event framing: the job as the default ("message") event, as the page has always
// read it; other topics as named events.
std::string frame(const std::string& topic, const std::string& data) {
  if (topic == "job") return "data: " + data + "\n\n";
  return "event: " + topic + "\ndata: " + data + "\n\n";
}

struct JobEvent {
  uint64_t id = 0;
  bool running = false;
};
JobEvent parse_job_event(const std::string& data) {
  const nlohmann::json job = nlohmann::json::parse(data, nullptr, false);
  if (!job.is_object()) return {};
  return {job.value("id", uint64_t(0)), job.value("state", "") == "running"};
}

}  // namespace

ProgressPublisher::ProgressPublisher(const ViewSession& session, EventHub& hub, std::chrono::milliseconds interval)
    : session_(session), hub_(hub), interval_(interval), thread_([this] { run(); }) {}

ProgressPublisher::~ProgressPublisher() { stop(); }

void ProgressPublisher::poke() {
  {
    std::lock_guard lock(mutex_);
    poked_ = true;
  }
  wake_.notify_one();
}

void ProgressPublisher::stop() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_one();
  if (thread_.joinable()) thread_.join();
}

void ProgressPublisher::run() {
  std::string last_job;
  uint64_t last_version = 0;
  std::unique_lock lock(mutex_);
  while (!stopping_) {
    poked_ = false;
    lock.unlock();
    std::string job = json_text(session_.job());
    if (job != last_job) hub_.publish("job", last_job = std::move(job));
    const uint64_t version = session_.version();
    if (version != last_version) hub_.publish("version", version_json(last_version = version));
    lock.lock();
    wake_.wait_for(lock, interval_, [&] { return stopping_ || poked_; });
  }
}

ProgressStream::ProgressStream(const ViewSession& session, EventHub& hub, bool follow,
                               std::chrono::milliseconds heartbeat)
    : session_(session), hub_(hub), follow_(follow), heartbeat_(heartbeat), subscription_(hub.subscribe()) {}

ProgressStream::~ProgressStream() { hub_.unsubscribe(subscription_); }

ProgressStream::Chunk ProgressStream::next() {
  if (!started_) {
    // Read after subscribing, so whatever changes after this read is published to this stream.
    started_ = true;
    const bool running = session_.job_running();  // before the job: its last state follows
    const nlohmann::json job = session_.job();
    first_job_id_ = job.value("id", uint64_t(0));
    Chunk first{frame("job", job.dump()), !running && !follow_};
    if (follow_) first.bytes += frame("version", version_json(session_.version()));
    return first;
  }
  std::vector<EventHub::Update> updates;
  switch (hub_.wait(*subscription_, heartbeat_, updates)) {
    case EventHub::Wake::Closed: return {"", true};
    case EventHub::Wake::Replaced: return {frame("replaced", "{}"), true};
    case EventHub::Wake::Timeout: return {": keep-alive\n\n", false};
    case EventHub::Wake::Updates: break;
  }
  Chunk chunk;
  for (const EventHub::Update& u : updates) {
    if (!follow_) {
      if (u.topic != "job") continue;
      // The publisher may hand on a state it read before this stream's first event: an older
      // job's end must not end the stream that follows the newer one.
      const JobEvent job = parse_job_event(u.data);
      if (job.id < first_job_id_) continue;
      chunk.last = !job.running;
    }
    chunk.bytes += frame(u.topic, u.data);
  }
  return chunk;
}

}  // namespace tfm
