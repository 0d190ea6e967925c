// The HTTP server of `tfmatch view` (cpp-httplib): the page and the endpoints of
// host/viewer/http_api.md over one ViewSession, guarded by a random token, with bounded sizes,
// request rates, connections and event streams.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "tfmatch/viewer/view_session.h"

namespace tfm {

struct ViewServerOptions {
  std::string bind = "127.0.0.1";  // address to listen on; another than loopback reaches others
  int port = 0;                    // 0: any free port
  std::string token;               // empty: 128 random bits as hex
  // Serve index.html, viewer.css and viewer_*.js from this directory instead of the copies built
  // into the binary (editing the page without rebuilding); empty: built in.
  std::string assets_dir;
  uint32_t device_requests_per_second = 40;  // renders, slices, plots, metrics: more get 429
  // Every open connection is served by a thread of its own, so event streams and idle or slow
  // clients never hold up pictures; more open connections than this get 503 with Retry-After.
  size_t max_connections = 256;
  // Open GET /api/progress streams (a page holds one); a new one replaces the oldest.
  size_t max_event_streams = 16;
  // A connection that sends no request for this long is closed; one whose request stops
  // arriving for this long is answered 400 and closed.
  int idle_timeout_s = 2;
  int read_timeout_s = 2;
  // A request must arrive whole within this long of the connection's start or of the previous
  // response, however it trickles in; else the connection is closed (ConnectionWorkers).
  double request_timeout_s = 10.0;
  // Silence after which an event stream sends a comment: how soon a stream whose client went
  // away finds out (a failed write) and frees its connection.
  int event_heartbeat_ms = 10000;
};

class ViewServer {
 public:
  // Binds the port (not yet serving). Throws std::invalid_argument for an empty address (or one
  // with spaces), std::runtime_error when the address or port cannot be bound, naming them.
  ViewServer(ViewSession& session, ViewServerOptions options);
  ~ViewServer();  // stops serving and waits for the listening thread
  ViewServer(const ViewServer&) = delete;
  ViewServer& operator=(const ViewServer&) = delete;

  void start();  // serves on a thread of its own until stop(); returns once it listens
  void stop();

  int port() const;
  const std::string& token() const;
  size_t event_streams() const;  // GET /api/progress streams open now
  // http://ADDRESS:PORT/?token=TOKEN (loopback for a wildcard address).
  std::string url() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// 128 bits from std::random_device as 32 lowercase hex digits.
std::string random_token();

}  // namespace tfm
