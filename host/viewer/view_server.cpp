// The viewer's HTTP endpoints (host/viewer/http_api.md) on cpp-httplib.
#include "tfmatch/viewer/view_server.h"

#include <httplib.h>
#include <sys/socket.h>

#include <algorithm>
#include <atomic>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <random>
#include <thread>

#include "tfmatch/engine/vk_check.h"
#include "tfmatch/io/json.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/report/png_io.h"
#include "tfmatch/solvers/solver.h"
#include "tfmatch/viewer/connection_workers.h"
#include "tfmatch/viewer/progress_events.h"
#include "tfmatch/viewer/tf_points.h"
#include "tfmatch/viewer/view_page.h"

namespace tfm {
namespace {

// Failures a request can cause, each with its status (http_api.md "Errors").
struct HttpError : std::runtime_error {
  HttpError(int status, const std::string& what) : std::runtime_error(what), status(status) {}
  int status;
};
HttpError bad_request(const std::string& what) { return {400, what}; }

void send_json(httplib::Response& res, const nlohmann::json& body, int status = 200) {
  res.status = status;
  res.set_content(json_text(body), "application/json");
}

void send_error(httplib::Response& res, int status, const std::string& message) {
  send_json(res, {{"error", message}}, status);
  if (status == 503) res.set_header("Retry-After", "1");
}

// Runs `handler`, turning what it throws into the status http_api.md gives it.
template <class Handler>
void guarded(httplib::Response& res, Handler&& handler) {
  try {
    handler();
  } catch (const HttpError& e) {
    send_error(res, e.status, e.what());
  } catch (const BusyError& e) {
    send_error(res, 503, e.what());
  } catch (const ConflictError& e) {
    send_error(res, 409, e.what());
  } catch (const SupersededError& e) {
    send_error(res, 410, e.what());
  } catch (const VulkanError& e) {
    send_error(res, 500, std::string("device failure: ") + e.what());
  } catch (const Cancelled&) {
    send_error(res, 503, "tfmatch view is stopping");
  } catch (const nlohmann::json::exception& e) {
    send_error(res, 400, std::string("bad JSON: ") + e.what());
  } catch (const std::exception& e) {
    // Everything else a request can reach is a value the library refused (a render size the
    // device cannot hold, a solver option out of range, a point outside the grid).
    send_error(res, 400, e.what());
  }
}

double number_param(const httplib::Request& req, const char* name, double fallback) {
  if (!req.has_param(name)) return fallback;
  const std::string text = req.get_param_value(name);
  double v = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(v))
    throw bad_request(std::string("parameter ") + name + ": not a finite number: '" + text + "'");
  return v;
}

uint64_t integer_param(const httplib::Request& req, const char* name, uint64_t fallback, uint64_t lo, uint64_t hi,
                       int status_above = 400) {
  if (!req.has_param(name)) return fallback;
  const std::string text = req.get_param_value(name);
  uint64_t v = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || end != text.data() + text.size())
    throw bad_request(std::string("parameter ") + name + ": not a whole number: '" + text + "'");
  if (v > hi)
    throw HttpError(status_above, std::string("parameter ") + name + " = " + text + " is above its limit " +
                                      std::to_string(hi));
  if (v < lo) throw bad_request(std::string("parameter ") + name + " = " + text + " is below " + std::to_string(lo));
  return v;
}

ViewKind view_param(const httplib::Request& req, const char* name = "view") {
  const std::string text = req.has_param(name) ? req.get_param_value(name) : "";
  const auto view = parse_view_kind(text);
  if (!view)
    throw bad_request(std::string("parameter ") + name +
                      ": one of reference, field-ref-tf, field-opt-tf, residual, residual-before (got '" + text + "')");
  return *view;
}

// The camera and image size of a request, over the session's defaults.
RenderSettings camera_params(const httplib::Request& req, const RenderSettings& defaults) {
  RenderSettings s = defaults;
  s.camera.azimuth_deg = number_param(req, "az", s.camera.azimuth_deg);
  s.camera.elevation_deg = number_param(req, "el", s.camera.elevation_deg);
  s.camera.distance = number_param(req, "dist", s.camera.distance);
  s.camera.fov_deg = number_param(req, "fov", s.camera.fov_deg);
  s.width = uint32_t(integer_param(req, "w", s.width, 16, 2048, 413));
  s.height = uint32_t(integer_param(req, "h", s.height, 16, 2048, 413));
  validate(s);  // angles and distance in range (std::runtime_error: 400)
  return s;
}

// Option values as the command line types them: JSON strings, numbers and booleans.
std::string option_text(const nlohmann::json& v, const std::string& name) {
  if (v.is_string()) return v.get<std::string>();
  if (v.is_boolean()) return v.get<bool>() ? "true" : "false";
  if (v.is_number_integer() || v.is_number_unsigned()) return v.dump();
  if (v.is_number()) {
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.17g", v.get<double>());
    return buf;
  }
  throw bad_request("option " + name + ": expected a string, number or true/false");
}

// The viewer's bounds on what one request may make the device do (http_api.md "Jobs").
void check_viewer_bounds(const std::map<std::string, std::string>& extra) {
  static const std::pair<const char*, uint64_t> kBounds[] = {
      {"iterations", 5000}, {"max-iterations", 10000}, {"views-per-iteration", 64}, {"view-pool", 256}, {"image-size", 1024},
      {"weight-views", 64}};
  for (const auto& [name, limit] : kBounds) {
    auto it = extra.find(name);
    if (it == extra.end()) continue;
    // Read as the solver reads it ("1e6", "+5001", "5001.0" are whole numbers to it); what it
    // cannot read as one it refuses itself.
    uint64_t v = 0;
    if (parse_option_integer(it->second, v) && v > limit)
      throw bad_request(std::string("option ") + name + " = " + it->second + " is above the viewer's limit " +
                        std::to_string(limit) + " (the command line has no such limit)");
  }
}

nlohmann::json parse_body(const httplib::Request& req) {
  nlohmann::json body = nlohmann::json::parse(req.body, nullptr, false);
  if (body.is_discarded() || !body.is_object()) throw bad_request("the request body must be a JSON object");
  return body;
}

// The picture's breakdown as a Server-Timing header (milliseconds; shown by browsers' developer
// tools, read by the page and tests/browser/camera_latency.mjs).
std::string server_timing(const PictureTiming& t, double encode_ms) {
  std::string out;
  char part[64];
  for (const auto& [name, ms] : {std::pair{"wait", t.wait_ms}, std::pair{"render", t.render_ms},
                                 std::pair{"readback", t.readback_ms}, std::pair{"compose", t.compose_ms},
                                 std::pair{"decorate", t.decorate_ms}, std::pair{"encode", encode_ms}}) {
    std::snprintf(part, sizeof part, "%s%s;dur=%.2f", out.empty() ? "" : ", ", name, ms);
    out += part;
  }
  return out;
}

bool same_token(const std::string& a, const std::string& b) {
  // Constant time in the length of the expected token: no early exit reveals a prefix.
  unsigned diff = unsigned(a.size() != b.size());
  for (size_t i = 0; i < b.size(); ++i) diff |= unsigned(uint8_t(i < a.size() ? a[i] : 0) ^ uint8_t(b[i]));
  return diff == 0;
}

// httplib's queue of accepted connections on ConnectionWorkers: a thread per open connection up
// to the cap, instead of a fixed pool whose threads every waiting connection holds.
class ConnectionQueue : public httplib::TaskQueue {
 public:
  ConnectionQueue(size_t max_connections, double request_timeout_s, int port) : workers_(max_connections) {
    workers_.set_request_deadline(request_timeout_s, port);
  }
  void enqueue(std::function<void()> fn) override { workers_.enqueue(std::move(fn)); }
  void shutdown() override { workers_.shutdown(); }

 private:
  ConnectionWorkers workers_;
};

}  // namespace

std::string random_token() {
  std::random_device device;
  std::string token;
  static const char* kHex = "0123456789abcdef";
  for (int i = 0; i < 8; ++i) {
    const uint32_t word = device();  // 16 bits of each of 8 words: 128 bits
    for (int k = 0; k < 4; ++k) token.push_back(kHex[(word >> (4 * k)) & 0xf]);
  }
  return token;
}

struct ViewServer::Impl {
  ViewSession& session;
  ViewServerOptions options;
  EventHub events;
  ProgressPublisher publisher;
  httplib::Server server;
  std::thread thread;
  std::atomic<bool> listen_returned{false};
  int port = 0;
  std::string page;  // assembled once (built in) or per request (assets_dir)

  // Token bucket of device requests.
  std::mutex rate_mutex;
  double tokens = 0.0;
  std::chrono::steady_clock::time_point refilled = std::chrono::steady_clock::now();

  Impl(ViewSession& s, ViewServerOptions o)
      : session(s), options(std::move(o)), events(options.max_event_streams), publisher(session, events) {
    // An empty address lets the library choose the interface ([::1] on some machines) while url()
    // names 127.0.0.1, and a page at that URL is refused.
    if (options.bind.empty() || options.bind.find_first_of(" \t\r\n") != std::string::npos)
      throw std::invalid_argument("tfmatch view: expected an address to listen on such as 127.0.0.1 or 0.0.0.0, got '" +
                                  options.bind + "'");
    if (options.token.empty()) options.token = random_token();
    tokens = options.device_requests_per_second;
    if (options.assets_dir.empty()) page = view_page_html();
    else view_page_html(options.assets_dir);  // a missing file fails now, not on the first request
    routes();
    server.set_payload_max_length(1 << 20);
    // Made when serving starts, after the port is bound.
    server.new_task_queue = [this] { return new ConnectionQueue(options.max_connections, options.request_timeout_s, port); };
    server.set_keep_alive_timeout(options.idle_timeout_s);
    server.set_read_timeout(options.read_timeout_s);
    server.set_write_timeout(30);
    // httplib listens with its compiled-in backlog of 5: a burst of connections (a page's six, a
    // few tabs, clients that connect and wait) overflows it, and the kernel drops SYNs that a
    // client sends again only a second later (150 connects took 20 s). The socket-options hook
    // sees the listening socket; a second listen() after binding raises the backlog in place.
    int listening = -1;
    server.set_socket_options([&listening](socket_t sock) {
      const int yes = 1;  // SO_REUSEADDR (restart at once after a stop), not httplib's SO_REUSEPORT (port sharing)
      ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
      listening = sock;
    });
    port = options.port == 0 ? server.bind_to_any_port(options.bind) : (server.bind_to_port(options.bind, options.port) ? options.port : -1);
    if (port >= 0 && listening >= 0) ::listen(listening, SOMAXCONN);
    if (port < 0)
      throw std::runtime_error("tfmatch view: cannot listen on " + options.bind + ":" + std::to_string(options.port) +
                               " (address not on this machine, or port in use)");
  }

  void take_device_slot() {
    std::lock_guard lock(rate_mutex);
    const auto now = std::chrono::steady_clock::now();
    const double rate = options.device_requests_per_second;
    tokens = std::min(rate, tokens + rate * std::chrono::duration<double>(now - refilled).count());
    refilled = now;
    if (tokens < 1.0) throw HttpError(429, "too many requests: at most " + std::to_string(options.device_requests_per_second) + " pictures a second");
    tokens -= 1.0;
  }

  // The newest camera each page (client=) has asked for (seq=): a picture still waiting for the
  // device for an older one is dropped when its turn comes, not rendered.
  std::mutex camera_mutex;
  std::map<std::string, uint64_t> newest_camera;

  // The request's camera sequence, noted as its client's newest; and a test, for when the device
  // is the request's, of whether it still is. Requests without client= are always wanted.
  std::function<bool()> camera_wanted(const httplib::Request& req) {
    if (!req.has_param("client")) return {};
    const std::string client = req.get_param_value("client");
    if (client.empty() || client.size() > 32) throw bad_request("parameter client: 1 to 32 characters");
    const uint64_t seq = integer_param(req, "seq", 0, 0, uint64_t(1) << 53);
    std::lock_guard lock(camera_mutex);
    if (newest_camera.size() > 256 && !newest_camera.count(client)) newest_camera.clear();  // bounded
    uint64_t& newest = newest_camera[client];
    newest = std::max(newest, seq);
    return [this, client, seq] {
      std::lock_guard lock(camera_mutex);
      auto it = newest_camera.find(client);
      return it == newest_camera.end() || it->second <= seq;
    };
  }

  void send_png(httplib::Response& res, const Image& img, const httplib::Request& req, const std::string& name) {
    // Interactive frames (frame=fast) trade size for encoding time; anything else, downloads
    // included, is the PNG `tfmatch render` writes, byte for byte.
    const bool fast = req.has_param("frame") && req.get_param_value("frame") == "fast" &&
                      !(req.has_param("download") && req.get_param_value("download") == "1");
    res.set_content(fast ? encode_png_fast(img) : encode_png(img), "image/png");
    res.set_header("Cache-Control", "no-store");
    if (req.has_param("download") && req.get_param_value("download") == "1")
      res.set_header("Content-Disposition", "attachment; filename=\"" + name + ".png\"");
  }

  // Each path and the method it takes (one per path), for the 405 of another method.
  std::map<std::string, std::string> route_methods;
  template <class Handler>
  void get(const std::string& path, Handler&& handler) {
    route_methods[path] = "GET";
    server.Get(path, std::forward<Handler>(handler));
  }
  template <class Handler>
  void post(const std::string& path, Handler&& handler) {
    route_methods[path] = "POST";
    server.Post(path, std::forward<Handler>(handler));
  }

  void routes() {
    // Every request, the page included, must carry the token (http_api.md "Access").
    server.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
      ConnectionWorkers::request_read();  // handled now: no request deadline (an event stream lasts)
      const auto handled = [] {
        ConnectionWorkers::response_sent();
        return httplib::Server::HandlerResponse::Handled;
      };
      if (ConnectionWorkers::current_over_capacity()) {
        send_error(res, 503, "too many open connections (" + std::to_string(options.max_connections) +
                                 "): try again shortly");
        res.set_header("Connection", "close");
        return handled();
      }
      const std::string given = req.has_param("token") ? req.get_param_value("token") : req.get_header_value("X-Tfmatch-Token");
      if (!same_token(given, options.token)) {
        send_error(res, 403, "missing or wrong token: open the URL tfmatch view printed");
        return handled();
      }
      // The library answers several byte ranges with a multipart body built in memory, the
      // ranges may overlap: 1000 of a download made a response 1000 times its size. The page asks
      // for none; one range (a resumed download) costs at most the file.
      if (req.ranges.size() > 1) {
        send_error(res, 416, "at most one byte range per request");
        return handled();
      }
      return httplib::Server::HandlerResponse::Unhandled;
    });
    server.set_post_routing_handler([](const httplib::Request&, httplib::Response& res) {
      // Called before the response is written. A whole response goes at once: the next
      // request's deadline starts. A streamed one (an event stream, for hours) keeps its
      // connection out of the deadline; cpp-httplib 0.11 keeps the provider in a public member.
      if (!res.content_provider_) ConnectionWorkers::response_sent();
    });
    // Errors the library makes itself (no route for the path or method, a malformed request, a
    // body or URI too long) come with an empty body: given one, as every error of http_api.md.
    server.set_error_handler([this](const httplib::Request& req, httplib::Response& res) {
      if (!res.body.empty()) return;  // a handler's own error
      if (res.status == 404) {
        if (const auto it = route_methods.find(req.path); it != route_methods.end()) {
          send_error(res, 405, req.path + " takes " + it->second + ", not " + req.method);
          res.set_header("Allow", it->second);
        } else {
          send_error(res, 404, "no such endpoint: " + req.path);
        }
        return;
      }
      const int status = res.status;
      send_error(res, status, status == 413   ? "request body too large (at most 1 MiB) or a bad Content-Length"
                              : status == 414 ? "request URI too long"
                              : status == 400 ? "malformed HTTP request"
                                              : "the request failed (HTTP " + std::to_string(status) + ")");
    });
    server.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr) {
      send_error(res, 500, "internal error");
    });

    get("/", [this](const httplib::Request&, httplib::Response& res) {
      guarded(res, [&] {
        res.set_content(options.assets_dir.empty() ? page : view_page_html(options.assets_dir), "text/html; charset=utf-8");
        res.set_header("Cache-Control", "no-store");
      });
    });
    get("/api/state", [this](const httplib::Request&, httplib::Response& res) {
      guarded(res, [&] { send_json(res, session.state()); });
    });
    get("/api/job", [this](const httplib::Request&, httplib::Response& res) {
      guarded(res, [&] { send_json(res, session.job()); });
    });
    get("/api/progress", [this](const httplib::Request& req, httplib::Response& res) {
      // Server-sent events (progress_events.h): the stream waits on the hub between events, on
      // a thread of its own, so open streams neither poll the session nor hold up requests.
      res.set_header("Cache-Control", "no-store");
      const bool follow = req.has_param("follow") && req.get_param_value("follow") == "1";
      auto stream = std::make_shared<ProgressStream>(session, events, follow,
                                                     std::chrono::milliseconds(options.event_heartbeat_ms));
      res.set_chunked_content_provider("text/event-stream", [stream](size_t, httplib::DataSink& sink) {
        const ProgressStream::Chunk chunk = stream->next();
        // A failed write is a client that went away: nothing else changes.
        if (!chunk.bytes.empty() && !sink.write(chunk.bytes.data(), chunk.bytes.size())) return false;
        if (chunk.last) sink.done();
        return true;
      });
    });
    get("/api/render", [this](const httplib::Request& req, httplib::Response& res) {
      guarded(res, [&] {
        const ViewKind view = view_param(req);
        const RenderSettings s = camera_params(req, session.default_render());
        take_device_slot();
        double distance = 0.0;
        PictureTiming timing;
        const Image img = session.render(view, s, &distance, &timing, camera_wanted(req));
        const auto encode_start = std::chrono::steady_clock::now();
        send_png(res, img, req, view_kind_name(view));
        const double encode_ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - encode_start).count();
        res.set_header("X-Tfmatch-Distance", std::to_string(distance));
        res.set_header("X-Tfmatch-Render-Ms", std::to_string(timing.picture_ms()));
        res.set_header("Server-Timing", server_timing(timing, encode_ms));
        res.set_header("Access-Control-Expose-Headers", "X-Tfmatch-Distance, X-Tfmatch-Render-Ms, Server-Timing");
      });
    });
    get("/api/metrics", [this](const httplib::Request& req, httplib::Response& res) {
      guarded(res, [&] {
        const RenderSettings s = camera_params(req, session.default_render());
        take_device_slot();
        send_json(res, session.image_metrics(s, camera_wanted(req)));
      });
    });
    get("/api/slice", [this](const httplib::Request& req, httplib::Response& res) {
      guarded(res, [&] {
        const ViewKind view = view_param(req);
        const std::string axis_text = req.has_param("axis") ? req.get_param_value("axis") : "z";
        if (axis_text != "x" && axis_text != "y" && axis_text != "z")
          throw bad_request("parameter axis: x, y or z (got '" + axis_text + "')");
        const int axis = axis_text[0] - 'x';
        const uint64_t n = session.grid().dims[size_t(axis)];
        const uint64_t index = integer_param(req, "index", n / 2, 0, n - 1);
        const uint32_t size = uint32_t(integer_param(req, "size", 384, 64, 1024, 413));
        const std::string shade = req.has_param("shade") ? req.get_param_value("shade") : "colour";
        if (shade != "colour" && shade != "opacity") throw bad_request("parameter shade: colour or opacity");
        take_device_slot();
        send_png(res, session.slice(view, axis, index, size, shade == "opacity" ? SliceShading::Opacity : SliceShading::Colour),
                 req, std::string(view_kind_name(view)) + "_slice_" + axis_text);
      });
    });
    get("/api/tf-plot", [this](const httplib::Request& req, httplib::Response& res) {
      guarded(res, [&] {
        const ViewKind view = view_param(req, "which");
        const uint32_t w = uint32_t(integer_param(req, "w", 512, 160, 2048, 413));
        const uint32_t h = uint32_t(integer_param(req, "h", 240, 140, 1024, 413));
        const std::string scale = req.has_param("histogram") ? req.get_param_value("histogram") : "log";
        if (scale != "log" && scale != "linear") throw bad_request("parameter histogram: log or linear");
        take_device_slot();
        send_png(res, session.tf_plot(view, w, h, scale == "log"), req, std::string("tf_") + view_kind_name(view));
      });
    });
    post("/api/optimize", [this](const httplib::Request& req, httplib::Response& res) {
      guarded(res, [&] {
        const nlohmann::json body = parse_body(req);
        if (!body.contains("solver") || !body["solver"].is_string()) throw bad_request("\"solver\" must name a solver");
        SolverSettings settings;
        if (body.contains("options")) {
          if (!body["options"].is_object()) throw bad_request("\"options\" must be an object");
          for (const auto& [name, value] : body["options"].items()) {
            if (value.is_null() || (value.is_string() && value.get<std::string>().empty())) continue;  // default
            if (value.is_boolean() && !value.get<bool>()) continue;  // a flag left off
            settings.extra[name] = option_text(value, name);
          }
        }
        for (const char* key : {"ridge", "smooth"}) {
          if (!body.contains(key) || body[key].is_null()) continue;
          if (!body[key].is_number() || !(body[key].get<double>() >= 0) || !std::isfinite(body[key].get<double>()))
            throw bad_request(std::string("\"") + key + "\" must be a number >= 0");
          (std::string(key) == "ridge" ? settings.solve.ridge : settings.solve.smooth) = body[key].get<double>();
        }
        check_viewer_bounds(settings.extra);
        const std::string solver = body["solver"].get<std::string>();
        check_options_apply(settings, {solver});  // throws naming the solver an option belongs to
        send_json(res, {{"job", session.optimize(solver, settings)}}, 202);
        publisher.poke();
      });
    });
    post("/api/ref-tf", [this](const httplib::Request& req, httplib::Response& res) {
      guarded(res, [&] {
        const nlohmann::json body = parse_body(req);
        ControlPointTf points;
        try {
          points = parse_editor_points(body);
        } catch (const std::invalid_argument& e) {
          throw bad_request(e.what());
        }
        const bool reoptimize = body.value("reoptimize", false);
        const uint64_t job = session.set_reference_tf(points, reoptimize);
        const uint64_t version = session.version();
        if (job) send_json(res, {{"job", job}, {"version", version}}, 202);
        else send_json(res, {{"version", version}});
        publisher.poke();
      });
    });
    post("/api/point", [this](const httplib::Request& req, httplib::Response& res) {
      guarded(res, [&] {
        const nlohmann::json body = parse_body(req);
        const nlohmann::json& p = body.contains("point") ? body["point"] : nlohmann::json();
        if (!p.is_array() || p.size() != 3 || !p[0].is_number_unsigned() || !p[1].is_number_unsigned() ||
            !p[2].is_number_unsigned())
          throw bad_request("\"point\" must be [i, j, k], three grid indices >= 0");
        const GridIndex point{p[0].get<uint64_t>(), p[1].get<uint64_t>(), p[2].get<uint64_t>()};
        send_json(res, {{"job", session.set_point(point)}}, 202);
        publisher.poke();
      });
    });
    post("/api/field", [this](const httplib::Request& req, httplib::Response& res) {
      guarded(res, [&] {
        const nlohmann::json body = parse_body(req);
        if (!body.contains("index") || !body["index"].is_number_unsigned())
          throw bad_request("\"index\" must be a field index >= 0");
        size_t index = body["index"].get<size_t>();
        uint64_t job = 0;
        try {
          job = session.set_field(index);
        } catch (const std::invalid_argument& e) {
          throw bad_request(e.what());
        }
        send_json(res, {{"job", job}}, 202);
        publisher.poke();
      });
    });
    get("/api/download", [this](const httplib::Request& req, httplib::Response& res) {
      guarded(res, [&] {
        const std::string what = req.has_param("what") ? req.get_param_value("what") : "";
        ViewSession::Download d;
        try {
          d = session.download(what);
        } catch (const std::invalid_argument& e) {
          throw bad_request(e.what());
        }
        res.set_content(std::move(d.bytes), d.content_type);
        res.set_header("Content-Disposition", "attachment; filename=\"" + d.filename + "\"");
      });
    });
  }
};

ViewServer::ViewServer(ViewSession& session, ViewServerOptions options)
    : impl_(std::make_unique<Impl>(session, std::move(options))) {}

ViewServer::~ViewServer() { stop(); }

void ViewServer::start() {
  if (impl_->thread.joinable()) return;
  impl_->listen_returned = false;
  impl_->thread = std::thread([impl = impl_.get()] {
    impl->server.listen_after_bind();
    impl->listen_returned = true;
  });
  // httplib's stop() does nothing until the listening thread has begun (is_running()): a stop()
  // that came first left that thread blocked in accept() and stop()'s join waiting forever. So
  // start() returns once it listens, or once listening has ended (a failure).
  while (!impl_->server.is_running() && !impl_->listen_returned)
    std::this_thread::sleep_for(std::chrono::microseconds(200));
}

void ViewServer::stop() {
  // Streams first: httplib joins the connection threads, and a stream's thread waits on the hub.
  impl_->events.close();
  impl_->publisher.stop();
  impl_->server.stop();
  if (impl_->thread.joinable()) impl_->thread.join();
}

int ViewServer::port() const { return impl_->port; }
size_t ViewServer::event_streams() const { return impl_->events.streams(); }
const std::string& ViewServer::token() const { return impl_->options.token; }

std::string ViewServer::url() const {
  std::string host = impl_->options.bind;
  if (host == "0.0.0.0" || host.empty()) host = "127.0.0.1";
  if (host == "::") host = "[::1]";
  else if (host.find(':') != std::string::npos) host = "[" + host + "]";
  return "http://" + host + ":" + std::to_string(impl_->port) + "/?token=" + impl_->options.token;
}

}  // namespace tfm
