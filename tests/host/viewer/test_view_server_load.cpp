// `tfmatch view`'s server under clients that wait (in-process, port 0): open event streams, idle
// sockets and half-sent requests hold no thread that pictures need; idle and stalled connections
// are closed; connections beyond the cap get 503 with Retry-After; streams are bounded, and a
// following stream tells a page of another page's edits.
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <thread>

#include "tfmatch/model/synthetic.h"
#include "tfmatch/viewer/view_server.h"
#include "tfmatch/viewer/view_session.h"
#include "vk_test_env.h"
// After Eigen (through the project headers): see test_view_server.cpp.
#include <httplib.h>

namespace tfm {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;
using test::GpuTest;

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// A client socket that writes and reads raw HTTP: it can stop halfway, or never read.
class RawConnection {
 public:
  explicit RawConnection(int port) {
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(uint16_t(port));
    ::inet_pton(AF_INET, "127.0.0.1", &address.sin_addr);
    connected_ = fd_ >= 0 && ::connect(fd_, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0;
  }
  ~RawConnection() {
    if (fd_ >= 0) ::close(fd_);
  }
  RawConnection(const RawConnection&) = delete;
  RawConnection& operator=(const RawConnection&) = delete;

  bool connected() const { return connected_; }
  bool send_text(const std::string& text) { return ::send(fd_, text.data(), text.size(), MSG_NOSIGNAL) == ssize_t(text.size()); }
  // What arrived until `marker` did (true), or until the server closed or `timeout` passed.
  bool read_until(const std::string& marker, std::chrono::milliseconds timeout) {
    const auto end = Clock::now() + timeout;
    while (received_.find(marker) == std::string::npos) {
      if (!read_some(end)) return false;
    }
    return true;
  }
  // True when the server closes the connection within `timeout` (what it sent before is kept).
  bool closed_within(std::chrono::milliseconds timeout) {
    const auto end = Clock::now() + timeout;
    while (read_some(end)) {
    }
    return eof_;
  }
  const std::string& received() const { return received_; }

 private:
  bool read_some(Clock::time_point end) {
    const auto left = std::chrono::duration_cast<std::chrono::microseconds>(end - Clock::now());
    if (left.count() <= 0 || eof_) return false;
    timeval tv{time_t(left.count() / 1000000), suseconds_t(left.count() % 1000000)};
    fd_set fds;
    FD_ZERO(&fds);
    FD_SET(fd_, &fds);
    if (::select(fd_ + 1, &fds, nullptr, nullptr, &tv) <= 0) return false;
    char buffer[4096];
    const ssize_t n = ::recv(fd_, buffer, sizeof buffer, 0);
    if (n <= 0) {
      eof_ = true;
      return false;
    }
    received_.append(buffer, size_t(n));
    return true;
  }
  int fd_ = -1;
  bool connected_ = false, eof_ = false;
  std::string received_;
};

class ViewServerLoadTest : public GpuTest {
 protected:
  void SetUp() override {
    ref_ = synthetic_reference(13, 11, 9);
    field_ = synthetic_remapped(ref_);
    ViewConfig c;
    c.ref_tf = demo_transfer_function(16);
    c.tf_size = 16;
    c.render.width = 40;
    c.render.height = 32;
    session_ = std::make_unique<ViewSession>(ctx(), ref_, field_, c);
  }
  void TearDown() override {
    server_.reset();
    session_.reset();
    GpuTest::TearDown();
  }
  void start(ViewServerOptions options) {
    server_ = std::make_unique<ViewServer>(*session_, options);
    server_->start();
  }
  std::string path(const std::string& p) const {
    return p + (p.find('?') == std::string::npos ? "?" : "&") + "token=" + server_->token();
  }
  std::string request_line(const std::string& p) const {
    return "GET " + path(p) + " HTTP/1.1\r\nHost: 127.0.0.1\r\n";
  }
  // A request on a new connection, as a browser's first one: {status, milliseconds}.
  std::pair<int, double> timed_get(const std::string& p) {
    httplib::Client client("127.0.0.1", server_->port());
    client.set_read_timeout(30);
    const auto t0 = Clock::now();
    auto r = client.Get(path(p));
    return {r ? r->status : -1, ms_since(t0)};
  }

  Volume ref_, field_;
  std::unique_ptr<ViewSession> session_;
  std::unique_ptr<ViewServer> server_;
};

// Issue 29: with 8 open event streams /api/state took 3.5 s, with 16 it did not answer in 5 s;
// 60 half-sent requests stalled it the same way. Now 50 streams and 100 half-open connections
// leave state under 100 ms and pictures at their usual time.
TEST_F(ViewServerLoadTest, FiftyStreamsAndAHundredHalfOpenConnectionsStallNothing) {
  ViewServerOptions options;
  options.idle_timeout_s = 60;  // the waiting connections stay open for the whole test
  options.read_timeout_s = 60;
  start(options);
  const std::string picture = "/api/render?view=reference&w=64&h=64";
  std::vector<double> usual;
  for (int i = 0; i < 5; ++i) {
    const auto [status, ms] = timed_get(picture);
    ASSERT_EQ(status, 200);
    usual.push_back(ms);
  }

  std::vector<std::unique_ptr<RawConnection>> streams, half_open;
  const auto setup = Clock::now();
  for (int i = 0; i < 50; ++i) {
    streams.push_back(std::make_unique<RawConnection>(server_->port()));
    ASSERT_TRUE(streams.back()->connected());
    ASSERT_TRUE(streams.back()->send_text(request_line("/api/progress?follow=1") + "\r\n"));
    ASSERT_TRUE(streams.back()->read_until("event: version", 20s)) << "stream " << i << ": " << streams.back()->received();
  }
  for (int i = 0; i < 100; ++i) {
    half_open.push_back(std::make_unique<RawConnection>(server_->port()));
    ASSERT_TRUE(half_open.back()->connected());
    ASSERT_TRUE(half_open.back()->send_text(request_line("/api/state")));  // no blank line: never ends
  }
  // A backlog of 5 (httplib's) made the kernel drop connects in bursts: each resent a second
  // later, and these 150 took 15 s.
  EXPECT_LT(ms_since(setup), 5000.0);
  std::this_thread::sleep_for(200ms);  // every connection accepted and waiting

  std::vector<double> state_ms, picture_ms;
  for (int i = 0; i < 7; ++i) {
    const auto [status, ms] = timed_get("/api/state");
    EXPECT_EQ(status, 200);
    state_ms.push_back(ms);
  }
  for (int i = 0; i < 5; ++i) {
    const auto [status, ms] = timed_get(picture);
    EXPECT_EQ(status, 200);
    picture_ms.push_back(ms);
  }
  EXPECT_LE(median(state_ms), 100.0);
  // "Its usual time", with room for a machine shared with other work.
  EXPECT_LE(median(picture_ms), 2.0 * median(usual) + 50.0) << "usual " << median(usual) << " ms";
  std::printf("[ load ] state %.1f ms, picture %.1f ms (usual %.1f ms), median of 7 / 5 / 5\n", median(state_ms),
              median(picture_ms), median(usual));

  // At most 16 streams stay open: the 34 oldest were told they were replaced and ended.
  EXPECT_EQ(server_->event_streams(), 16u);
  for (int i = 0; i < 34; ++i)
    EXPECT_TRUE(streams[size_t(i)]->read_until("event: replaced", 5s)) << "stream " << i;
  // The 16 newest were not: read what the server sent them (a replacement would have been sent
  // during the set-up, seconds ago, so it would be waiting in the socket by now).
  for (int i = 34; i < 50; ++i)
    EXPECT_FALSE(streams[size_t(i)]->read_until("event: replaced", i == 34 ? 300ms : 20ms))
        << "stream " << i << ": " << streams[size_t(i)]->received();
}

TEST_F(ViewServerLoadTest, IdleAndStalledConnectionsAreClosed) {
  ViewServerOptions options;
  options.idle_timeout_s = 1;
  options.read_timeout_s = 1;
  start(options);
  RawConnection silent(server_->port()), half(server_->port());
  ASSERT_TRUE(half.send_text(request_line("/api/state")));
  const auto t0 = Clock::now();
  EXPECT_TRUE(silent.closed_within(10s));
  EXPECT_TRUE(half.closed_within(10s));
  EXPECT_LT(ms_since(t0), 5000.0);
  EXPECT_EQ(half.received().rfind("HTTP/1.1 400", 0), 0u) << half.received();
  EXPECT_EQ(timed_get("/api/state").first, 200);
}

// Clients that trickle a request in, a byte every 0.3 s (under the per-read timeout), without the
// token: each is closed at the request deadline, a request on a keep-alive connection gets a
// fresh one, pictures are served meanwhile, and a stop does not wait for the trickling clients
// (a few hundred of them held every thread, and one held a Ctrl-C for the 20 s grace).
TEST_F(ViewServerLoadTest, ClientsTricklingARequestAreClosedAtTheDeadline) {
  ViewServerOptions options;
  options.request_timeout_s = 1.5;
  options.max_connections = 8;  // the tricklers outnumber it
  start(options);
  std::vector<std::unique_ptr<RawConnection>> slow;
  for (int i = 0; i < 12; ++i) {
    slow.push_back(std::make_unique<RawConnection>(server_->port()));
    ASSERT_TRUE(slow.back()->connected());
    ASSERT_TRUE(slow.back()->send_text("GET /api/state?token=0 HTTP/1.1\r\nHost: x\r\n"));
  }
  // A keep-alive client whose requests each arrive at once: served past the deadline's length.
  RawConnection steady(server_->port());
  const auto t0 = Clock::now();
  bool all_closed = false;
  for (int round = 0; round < 12 && !all_closed; ++round) {
    std::this_thread::sleep_for(300ms);
    all_closed = true;
    for (auto& c : slow)
      if (c->send_text("X")) all_closed = false;
    if (round == 2) {  // 0.9 s in: served, though the tricklers hold more connections than the cap
      ASSERT_TRUE(steady.send_text(request_line("/api/state") + "\r\n"));
      ASSERT_TRUE(steady.read_until("\"version\"", 5s)) << steady.received();
      EXPECT_EQ(steady.received().rfind("HTTP/1.1 200", 0), 0u) << steady.received();
      EXPECT_EQ(timed_get("/api/state").first, 200);
    }
  }
  const double closed_ms = ms_since(t0);
  EXPECT_TRUE(all_closed) << "trickling clients still open after " << closed_ms << " ms";
  EXPECT_GT(closed_ms, 1200.0);
  EXPECT_LT(closed_ms, 3500.0);
  ASSERT_TRUE(steady.send_text(request_line("/api/state") + "\r\n"));  // 2.4+ s after its start
  EXPECT_TRUE(steady.read_until("\"version\"", 5s)) << steady.received();
  EXPECT_EQ(timed_get("/api/render?view=reference&w=32&h=32").first, 200);
  // A stop while a client trickles: prompt.
  RawConnection last(server_->port());
  ASSERT_TRUE(last.send_text("GET /api/state HTTP/1.1\r\n"));
  std::this_thread::sleep_for(200ms);
  const auto t1 = Clock::now();
  server_.reset();
  EXPECT_LT(ms_since(t1), 1000.0);
}

TEST_F(ViewServerLoadTest, ConnectionsBeyondTheCapGet503WithRetryAfter) {
  ViewServerOptions options;
  options.max_connections = 3;
  options.idle_timeout_s = 60;
  options.event_heartbeat_ms = 200;  // a stream whose client left finds out within 0.2 s
  start(options);
  // Connections busy with a request (event streams): at the cap, a new one is told to come back.
  // (A connection that waits for a request would make room instead: the trickling test.)
  std::vector<std::unique_ptr<RawConnection>> idle;
  for (int i = 0; i < 3; ++i) {
    idle.push_back(std::make_unique<RawConnection>(server_->port()));
    // A stream's answer proves the connection was accepted before the next one.
    ASSERT_TRUE(idle.back()->send_text(request_line("/api/progress?follow=1") + "\r\n"));
    ASSERT_TRUE(idle.back()->read_until("HTTP/1.1 200", 10s)) << idle.back()->received();
  }
  httplib::Client client("127.0.0.1", server_->port());
  auto r = client.Get(path("/api/state"));
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 503) << r->body;
  EXPECT_EQ(r->get_header_value("Retry-After"), "1");
  EXPECT_NE(r->body.find("too many open connections"), std::string::npos) << r->body;
  idle.clear();  // the server sees them close and frees their places
  int status = 0;
  for (int i = 0; i < 100 && status != 200; ++i) {
    std::this_thread::sleep_for(20ms);
    status = timed_get("/api/state").first;
  }
  EXPECT_EQ(status, 200);
}

// Two pages on one server: a following stream (each page holds one) hears of the other page's
// reference-TF edit as a new version; a plain stream with no job running ends after one event.
TEST_F(ViewServerLoadTest, AFollowingStreamHearsOfAnotherPagesEdits) {
  start({});
  RawConnection follow(server_->port());
  ASSERT_TRUE(follow.send_text(request_line("/api/progress?follow=1") + "\r\n"));
  ASSERT_TRUE(follow.read_until("event: version\ndata: {\"version\":1}", 10s)) << follow.received();

  httplib::Client other("127.0.0.1", server_->port());
  auto state = other.Get(path("/api/state"));
  ASSERT_TRUE(state);
  nlohmann::json points = nlohmann::json::parse(state->body)["ref_tf"]["points"];
  for (auto& p : points["opacity"]) p["a"] = p["a"].get<double>() * 0.5;
  auto edit = other.Post(path("/api/ref-tf"), points.dump(), "application/json");
  ASSERT_TRUE(edit);
  ASSERT_EQ(edit->status, 200) << edit->body;
  EXPECT_TRUE(follow.read_until("event: version\ndata: {\"version\":2}", 10s)) << follow.received();

  RawConnection plain(server_->port());
  ASSERT_TRUE(plain.send_text(request_line("/api/progress") + "Connection: close\r\n\r\n"));
  EXPECT_TRUE(plain.closed_within(10s));
  EXPECT_NE(plain.received().find("data: {"), std::string::npos) << plain.received();
  EXPECT_EQ(plain.received().find("event: version"), std::string::npos) << plain.received();
}

}  // namespace
}  // namespace tfm
