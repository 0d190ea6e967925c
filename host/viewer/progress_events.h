// GET /api/progress without HTTP: one thread publishes the session's job and version to an
// EventHub, and each stream turns what the hub hands it into server-sent-event bytes.
#pragma once

#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "tfmatch/viewer/event_hub.h"
#include "tfmatch/viewer/view_session.h"

namespace tfm {

// Publishes "job" (session.job(): every 250 ms while a job runs, since its elapsed time changes,
// and once more at its end) and "version" ({"version": v}, when it changes) until stopped.
class ProgressPublisher {
 public:
  ProgressPublisher(const ViewSession& session, EventHub& hub,
                    std::chrono::milliseconds interval = std::chrono::milliseconds(250));
  ~ProgressPublisher();  // stop()
  ProgressPublisher(const ProgressPublisher&) = delete;
  ProgressPublisher& operator=(const ProgressPublisher&) = delete;

  void poke();  // publish now, not at the next interval (a job was just started)
  void stop();

 private:
  void run();
  const ViewSession& session_;
  EventHub& hub_;
  const std::chrono::milliseconds interval_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool poked_ = false, stopping_ = false;
  std::thread thread_;
};

// One event stream. Plain (follow = false): the job now, then every change while it runs, its
// end, and the stream ends (the page follows one job). Following: the job and the version now,
// then every change of either until the client goes away (a page learns of jobs and edits made
// from another page). Either ends with "event: replaced" when newer streams push it out.
class ProgressStream {
 public:
  ProgressStream(const ViewSession& session, EventHub& hub, bool follow,
                 std::chrono::milliseconds heartbeat = std::chrono::seconds(10));
  ~ProgressStream();  // unsubscribes
  ProgressStream(const ProgressStream&) = delete;
  ProgressStream& operator=(const ProgressStream&) = delete;

  struct Chunk {
    std::string bytes;  // to send (may be empty)
    bool last = false;  // the stream ends after them
  };
  // The next bytes: at once on the first call, else when something is published, or a comment
  // after `heartbeat` of silence (a client that went away shows as a failed write).
  Chunk next();

 private:
  const ViewSession& session_;
  EventHub& hub_;
  const bool follow_;
  const std::chrono::milliseconds heartbeat_;
  std::shared_ptr<EventHub::Subscription> subscription_;
  bool started_ = false;
  uint64_t first_job_id_ = 0;
};

}  // namespace tfm
