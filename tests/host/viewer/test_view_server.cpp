// `tfmatch view`'s server in-process (a server on port 0 and an HTTP client): the token, images
// equal to the renderer's, slices, plots, jobs, bad requests answered with 4xx while the server
// keeps serving, the device held by a job answering 503.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <thread>

#include "cli_runner.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/model/camera.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/synthetic.h"
#include "tfmatch/model/synthetic_ensemble.h"
#include "tfmatch/report/png_io.h"
#include "tfmatch/viewer/tf_points.h"
#include "tfmatch/viewer/view_page.h"
#include "tfmatch/viewer/view_server.h"
#include "tfmatch/viewer/view_session.h"
#include "view_server_fixture.h"
#include "vk_test_env.h"
// After Eigen (through the project headers): OpenSSL's headers, which httplib.h includes, define
// macros that break Eigen's product kernels when they come first.
#include <httplib.h>

namespace tfm {
namespace {

using test::GpuTest;

using test::small_view_config;

class ViewServerTest : public test::ViewServerFixture {
 protected:
  httplib::Result post(const std::string& path, const nlohmann::json& body) {
    return client_->Post(with_token(path), body.dump(), "application/json");
  }
  nlohmann::json get_json(const std::string& path) {
    auto r = get(path);
    EXPECT_TRUE(r);
    if (!r) return {};
    EXPECT_EQ(r->status, 200) << path << ": " << r->body;
    return nlohmann::json::parse(r->body);
  }
  void wait_for_job() {
    for (int i = 0; i < 6000 && session_->job_running(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    session_->wait_for_job();
  }
};

TEST_F(ViewServerTest, EveryRequestNeedsTheToken) {
  for (const char* path : {"/", "/api/state", "/api/render?view=reference", "/api/download?what=optimized-tf.json"}) {
    auto none = client_->Get(path);
    ASSERT_TRUE(none);
    EXPECT_EQ(none->status, 403) << path;
    auto wrong = client_->Get(std::string(path) + (std::string(path).find('?') == std::string::npos ? "?" : "&") +
                              "token=" + std::string(server_->token().size(), '0'));
    ASSERT_TRUE(wrong);
    EXPECT_EQ(wrong->status, 403) << path;
  }
  auto header = client_->Get("/api/state", {{"X-Tfmatch-Token", server_->token()}});
  ASSERT_TRUE(header);
  EXPECT_EQ(header->status, 200);
  EXPECT_EQ(server_->token().size(), 32u);
  EXPECT_NE(random_token(), random_token());
  EXPECT_NE(server_->url().find("http://127.0.0.1:" + std::to_string(server_->port()) + "/?token="), std::string::npos);
}

// The page from its source folder (TFMATCH_VIEW_ASSETS, for editing without a rebuild) is the page
// built in, byte for byte; every script file of the folder is one of the parts joined, so a new
// part cannot be left out of the page; a folder that lacks a part is an error naming it.
TEST(ViewPage, TheSourceFolderGivesTheBuiltInPageFromEveryScriptPart) {
  const std::filesystem::path page = std::filesystem::path(TFMATCH_SOURCE_DIR) / "host" / "viewer" / "page";
  EXPECT_EQ(view_page_html(page.string()), view_page_html());
  std::vector<std::string> scripts;
  for (const auto& entry : std::filesystem::directory_iterator(page))
    if (entry.path().extension() == ".js") scripts.push_back(entry.path().filename().string());
  std::vector<std::string> parts = view_page_script_parts();
  ASSERT_FALSE(parts.empty());
  EXPECT_EQ(parts.front(), "viewer_core.js");
  EXPECT_EQ(parts.back(), "viewer_start.js");
  std::sort(scripts.begin(), scripts.end());
  std::sort(parts.begin(), parts.end());
  EXPECT_EQ(scripts, parts);

  test::TempDir dir;
  for (const char* name : {"index.html", "viewer.css", "viewer_core.js"})
    std::filesystem::copy_file(page / name, std::filesystem::path(dir.path) / name);
  try {
    view_page_html(dir.path.string());
    ADD_FAILURE() << "a folder without viewer_views.js gave a page";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("viewer_views.js: cannot read the viewer page file"), std::string::npos)
        << e.what();
  }
}

// A server stopped right after it started stops: httplib's stop() does nothing until its listening
// thread has begun, so a stop() that came first left that thread in accept() and the join waiting
// forever (found when a test that made no request hung on a loaded machine).
TEST_F(ViewServerTest, StopsRightAfterItStarts) {
  for (int i = 0; i < 200; ++i) {
    ViewServer server(*session_, ViewServerOptions{});
    server.start();
    server.stop();
  }
}

// The library refuses an address that is none, as the command line does: an empty one listened
// on an interface of httplib's choosing while url() named 127.0.0.1.
TEST_F(ViewServerTest, AnEmptyAddressIsRefused) {
  for (const char* bind : {"", " ", "127.0.0.1 "}) {
    ViewServerOptions o;
    o.bind = bind;
    EXPECT_THROW(ViewServer(*session_, o), std::invalid_argument) << "'" << bind << "'";
  }
}

TEST_F(ViewServerTest, ServesThePageWithItsScriptAndStyleInlined) {
  auto r = get("/");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_NE(r->get_header_value("Content-Type").find("text/html"), std::string::npos);
  EXPECT_NE(r->body.find("<script>"), std::string::npos);
  EXPECT_NE(r->body.find("<style>"), std::string::npos);
  EXPECT_EQ(r->body.find("<!-- viewer script -->"), std::string::npos);
  // Nothing from the network: no external script, style or font.
  EXPECT_EQ(r->body.find("src=\"http"), std::string::npos);
  EXPECT_EQ(r->body.find("href=\"http"), std::string::npos);
  EXPECT_EQ(r->body, view_page_html());
}

TEST_F(ViewServerTest, StateDescribesFieldsTfsSolversAndMetrics) {
  const nlohmann::json s = get_json("/api/state");
  EXPECT_EQ(s["mode"], "pair");
  EXPECT_EQ(s["grid"]["dims"], nlohmann::json({13, 11, 9}));
  EXPECT_EQ(s["ref_tf"]["size"], 16);
  EXPECT_GE(s["ref_tf"]["points"]["opacity"].size(), 2u);
  EXPECT_EQ(s["optimized_tf"]["solver"], "normal-equations");
  EXPECT_LT(s["metrics"]["voxel_rmse_optimized_tf"].get<double>(), s["metrics"]["voxel_rmse_reference_tf"].get<double>());
  bool has_cgls = false;
  for (const auto& solver : s["solvers"]) has_cgls |= solver["name"] == "cgls" && !solver["options"].empty();
  EXPECT_TRUE(has_cgls);
  EXPECT_EQ(s["job"]["state"], "idle");
  EXPECT_NE(s["render_command"].get<std::string>().find("tfmatch render --volume reference.vti"), std::string::npos);
}

// The page's pictures are the renderer's: the same pixels as render_volume with the outline,
// for every view and an arbitrary camera.
TEST_F(ViewServerTest, RenderEqualsTheRendererForTheSameCamera) {
  auto r = get("/api/render?view=reference&az=47.5&el=-12&dist=3.5&fov=35&w=37&h=29");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  EXPECT_EQ(r->get_header_value("Content-Type"), "image/png");
  const Image served = decode_png(r->body, "served");
  RenderSettings s = small_view_config().render;
  s.camera = {47.5, -12.0, 3.5, 35.0};
  s.width = 37;
  s.height = 29;
  const nlohmann::json state = get_json("/api/state");
  const FieldRange range{state["fields"]["reference"]["range"][0].get<double>(),
                         state["fields"]["reference"]["range"][1].get<double>()};
  Image expected = composite_over(render_volume(ctx(), ref_, demo_transfer_function(16), range, s), s.background);
  draw_box_outline(expected, VolumeGeometry::from(ref_.dims, ref_.spacing, s.z_scale), s);
  ASSERT_EQ(served.width, expected.width);
  ASSERT_EQ(served.height, expected.height);
  EXPECT_EQ(served.rgb, expected.rgb);
  EXPECT_DOUBLE_EQ(std::stod(r->get_header_value("X-Tfmatch-Distance")), 3.5);

  // A framed camera reports the distance it used; every view renders.
  for (const char* view : {"field-ref-tf", "field-opt-tf", "residual", "residual-before"}) {
    auto v = get(std::string("/api/render?view=") + view + "&dist=0&w=24&h=20");
    ASSERT_TRUE(v);
    EXPECT_EQ(v->status, 200) << view << ": " << v->body;
    EXPECT_GT(std::stod(v->get_header_value("X-Tfmatch-Distance")), 1.0);
  }
  auto download = get("/api/render?view=residual&w=24&h=20&download=1");
  ASSERT_TRUE(download);
  EXPECT_NE(download->get_header_value("Content-Disposition").find("residual.png"), std::string::npos);
}

TEST_F(ViewServerTest, BadRequestsGet4xxAndTheServerKeepsServing) {
  const std::pair<const char*, int> cases[] = {
      {"/api/render?view=reference&w=100000&h=64", 413},
      {"/api/render?view=reference&w=4096&h=64", 413},
      {"/api/render?view=reference&w=8&h=64", 400},
      {"/api/render?view=reference&az=abc", 400},
      {"/api/render?view=reference&az=nan", 400},
      {"/api/render?view=reference&el=100", 400},
      {"/api/render?view=reference&dist=0.5", 400},
      {"/api/render?view=nothing", 400},
      {"/api/render?view=reference&w=-5", 400},
      {"/api/slice?view=reference&axis=q", 400},
      {"/api/slice?view=reference&axis=z&index=9", 400},
      {"/api/slice?view=reference&axis=z&size=5000", 413},
      {"/api/tf-plot?which=reference&w=10", 400},
      {"/api/tf-plot?which=reference&histogram=cubic", 400},
      {"/api/download?what=../../etc/passwd", 400},
      {"/api/no-such-thing", 404},
  };
  for (const auto& [path, status] : cases) {
    auto r = get(path);
    ASSERT_TRUE(r) << path;
    EXPECT_EQ(r->status, status) << path << ": " << r->body;
    EXPECT_TRUE(nlohmann::json::parse(r->body, nullptr, false).contains("error")) << path << ": " << r->body;
  }
  const std::pair<nlohmann::json, const char*> posts[] = {
      {{{"solver", "no-such-solver"}}, "no-such-solver"},
      {{{"solver", "normal-equations"}, {"options", {{"lr", "0.1"}}}}, "gradient-descent"},
      {{{"solver", "gradient-descent"}, {"options", {{"iterations", "100000"}}}}, "limit"},
      // Spellings the solver reads as whole numbers pass no bound either (they did: a 1e6-iteration
      // job held the device).
      {{{"solver", "diffdvr"}, {"options", {{"iterations", "1e6"}}}}, "limit"},
      {{{"solver", "diffdvr"}, {"options", {{"iterations", "5001.0"}}}}, "limit"},
      {{{"solver", "cgls"}, {"options", {{"max-iterations", "+10001"}}}}, "limit"},
      {{{"solver", "cgls"}, {"options", {{"tolerance", "2"}}}}, "tolerance"},
      {{{"solver", "cgls"}, {"ridge", -1}}, "ridge"},
      {{{"options", {}}}, "solver"},
  };
  for (const auto& [body, says] : posts) {
    auto r = post("/api/optimize", body);
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 400) << body.dump() << ": " << r->body;
    EXPECT_NE(r->body.find(says), std::string::npos) << r->body;
  }
  // A path's other method: 405 naming the one it takes. Errors the HTTP library makes itself
  // (a body over 1 MiB) carry a message too. Several byte ranges of a download: refused (the
  // library built each range's copy in memory); one range is served.
  auto wrong_method = client_->Post(with_token("/api/state"), "{}", "application/json");
  ASSERT_TRUE(wrong_method);
  EXPECT_EQ(wrong_method->status, 405);
  EXPECT_EQ(wrong_method->get_header_value("Allow"), "GET");
  EXPECT_NE(wrong_method->body.find("/api/state takes GET, not POST"), std::string::npos) << wrong_method->body;
  auto too_large = client_->Post(with_token("/api/ref-tf"), std::string(size_t(2) << 20, ' '), "application/json");
  ASSERT_TRUE(too_large);
  EXPECT_EQ(too_large->status, 413);
  EXPECT_TRUE(nlohmann::json::parse(too_large->body, nullptr, false).contains("error")) << too_large->body;
  auto ranges = client_->Get(with_token("/api/download?what=field.vti"), {{"Range", "bytes=0-,0-,0-"}});
  ASSERT_TRUE(ranges);
  EXPECT_EQ(ranges->status, 416);
  auto one_range = client_->Get(with_token("/api/download?what=field.vti"), {{"Range", "bytes=0-9"}});
  ASSERT_TRUE(one_range);
  EXPECT_EQ(one_range->status, 206);
  EXPECT_EQ(one_range->body.size(), 10u);
  auto not_json = client_->Post(with_token("/api/optimize"), "{solver", "application/json");
  ASSERT_TRUE(not_json);
  EXPECT_EQ(not_json->status, 400);
  auto point = post("/api/point", {{"point", {1, 2, 3}}});
  ASSERT_TRUE(point);
  EXPECT_EQ(point->status, 409) << point->body;  // pair mode
  auto bad_tf = post("/api/ref-tf", {{"opacity", {{{"x", 0}, {"a", 0.5}}}}, {"color", nlohmann::json::array()}});
  ASSERT_TRUE(bad_tf);
  EXPECT_EQ(bad_tf->status, 400);
  // Still serving, and nothing changed.
  const nlohmann::json s = get_json("/api/state");
  EXPECT_EQ(s["version"], 1);
  EXPECT_EQ(s["job"]["state"], "idle");
  auto fine = get("/api/render?view=reference&w=32&h=32");
  ASSERT_TRUE(fine);
  EXPECT_EQ(fine->status, 200);
}

TEST_F(ViewServerTest, TooManyPicturesASecondGet429) {
  ViewServerOptions slow;
  slow.device_requests_per_second = 4;
  ViewServer server(*session_, slow);
  server.start();
  httplib::Client client("127.0.0.1", server.port());
  const std::string path = "/api/tf-plot?which=reference&w=160&h=140&token=" + server.token();
  int too_many = 0, served = 0;
  for (int i = 0; i < 12 && too_many == 0; ++i) {
    auto r = client.Get(path);
    ASSERT_TRUE(r);
    if (r->status == 429) {
      ++too_many;
    } else {
      EXPECT_EQ(r->status, 200);
      ++served;
    }
  }
  EXPECT_EQ(too_many, 1);
  EXPECT_GE(served, 4);
  std::this_thread::sleep_for(std::chrono::milliseconds(600));  // the bucket refills
  auto r = client.Get(path);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_EQ(get("/api/state")->status, 200);  // state is not a picture: never limited
}

TEST_F(ViewServerTest, SlicesPlotsMetricsAndDownloads) {
  auto slice = get("/api/slice?view=field-opt-tf&axis=y&index=3&size=64");
  ASSERT_TRUE(slice);
  ASSERT_EQ(slice->status, 200) << slice->body;
  const Image img = decode_png(slice->body, "slice");
  EXPECT_EQ(std::max(img.width, img.height), 64u);
  auto other = get("/api/slice?view=field-opt-tf&axis=y&index=8&size=64");
  ASSERT_TRUE(other);
  EXPECT_NE(other->body, slice->body);  // another plane
  auto plot = get("/api/tf-plot?which=field-opt-tf&w=320&h=160&histogram=linear");
  ASSERT_TRUE(plot);
  ASSERT_EQ(plot->status, 200);
  EXPECT_EQ(decode_png(plot->body, "plot").width, 320u);
  const nlohmann::json m = get_json("/api/metrics?w=48&h=40");
  EXPECT_GT(m["optimized_tf"]["psnr"].get<double>(), m["reference_tf"]["psnr"].get<double>());
  auto tf = get("/api/download?what=optimized-tf.json");
  ASSERT_TRUE(tf);
  EXPECT_EQ(tf->status, 200);
  EXPECT_NE(tf->body.find("\"rgba\""), std::string::npos);
  EXPECT_NE(tf->get_header_value("Content-Disposition").find("optimized-tf.json"), std::string::npos);
  auto preset = get("/api/download?what=optimized-tf.paraview.json");
  ASSERT_TRUE(preset);
  EXPECT_NE(preset->body.find("RGBPoints"), std::string::npos);
  auto vti = get("/api/download?what=residual.vti");
  ASSERT_TRUE(vti);
  EXPECT_EQ(vti->body.rfind("<?xml", 0), 0u);
  EXPECT_NE(vti->body.find("WholeExtent=\"0 12 0 10 0 8\""), std::string::npos);
}

TEST_F(ViewServerTest, OptimizeJobReplacesTheTfAndReportsProgressAsEvents) {
  const std::string before = get("/api/render?view=field-opt-tf&w=32&h=32")->body;
  auto r = post("/api/optimize", {{"solver", "gradient-descent"}, {"options", {{"iterations", 40}, {"lr", "0.05"}}}});
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 202) << r->body;
  // The event stream delivers the job until it ends, then closes.
  std::string events;
  auto stream = client_->Get(with_token("/api/progress"), [&](const char* data, size_t n) {
    events.append(data, n);
    return true;
  });
  ASSERT_TRUE(stream);
  EXPECT_EQ(stream->status, 200);
  EXPECT_EQ(stream->get_header_value("Content-Type"), "text/event-stream");
  EXPECT_EQ(events.rfind("data: {", 0), 0u) << events;
  const std::string last = events.substr(events.rfind("data: ") + 6);
  const nlohmann::json final_job = nlohmann::json::parse(last);
  EXPECT_EQ(final_job["state"], "done") << last;
  EXPECT_EQ(final_job["result"]["solver"], "gradient-descent");
  wait_for_job();
  const nlohmann::json s = get_json("/api/state");
  EXPECT_EQ(s["optimized_tf"]["solver"], "gradient-descent");
  EXPECT_EQ(s["solver"]["name"], "gradient-descent");
  EXPECT_EQ(s["solver"]["options"]["iterations"], "40");
  EXPECT_EQ(s["version"], 2);
  EXPECT_NE(get("/api/render?view=field-opt-tf&w=32&h=32")->body, before);
}

// A page that goes away while its job runs (the event stream closed after its first event)
// cancels nothing: the job ends normally and its result is installed.
TEST_F(ViewServerTest, AClientLeavingMidJobCancelsNothing) {
  auto r = post("/api/optimize", {{"solver", "gradient-descent"}, {"options", {{"iterations", 3000}}}});
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 202) << r->body;
  {
    httplib::Client leaving("127.0.0.1", server_->port());
    int events = 0;
    leaving.Get(with_token("/api/progress"), [&](const char*, size_t) { return ++events < 1; });  // hangs up
    EXPECT_EQ(events, 1);
  }
  wait_for_job();
  const nlohmann::json job = get_json("/api/job");
  EXPECT_EQ(job["state"], "done") << job.dump();
  EXPECT_EQ(get_json("/api/state")["optimized_tf"]["solver"], "gradient-descent");
  EXPECT_EQ(get("/api/render?view=field-opt-tf&w=32&h=32")->status, 200);
}

TEST_F(ViewServerTest, ReferenceTfEditsChangeTheReferenceViewsAndCanReoptimize) {
  const nlohmann::json s0 = get_json("/api/state");
  const std::string before = get("/api/render?view=reference&w=32&h=32")->body;
  // Unchanged points give the same table; a raised opacity point gives another picture.
  nlohmann::json points = s0["ref_tf"]["points"];
  auto same = post("/api/ref-tf", points);
  ASSERT_TRUE(same);
  ASSERT_EQ(same->status, 200) << same->body;
  EXPECT_EQ(get("/api/render?view=reference&w=32&h=32")->body, before);
  for (auto& p : points["opacity"]) p["a"] = std::min(1.0, p["a"].get<double>() * 0.3);
  auto lower = post("/api/ref-tf", points);
  ASSERT_TRUE(lower);
  ASSERT_EQ(lower->status, 200);
  EXPECT_NE(get("/api/render?view=reference&w=32&h=32")->body, before);
  const nlohmann::json s1 = get_json("/api/state");
  EXPECT_EQ(s1["optimized_tf"]["solver"], "normal-equations");
  EXPECT_NE(s1["metrics"]["voxel_rmse_reference_tf"], s0["metrics"]["voxel_rmse_reference_tf"]);
  points["reoptimize"] = true;
  points["color"][0]["rgb"] = "#ff0000";
  auto job = post("/api/ref-tf", points);
  ASSERT_TRUE(job);
  ASSERT_EQ(job->status, 202) << job->body;
  wait_for_job();
  const nlohmann::json s2 = get_json("/api/state");
  EXPECT_EQ(s2["job"]["state"], "done");
  EXPECT_EQ(s2["ref_tf"]["points"]["color"][0]["rgb"], "#ff0000");
}

// Holds the next solve at its first checkpoint until cancellation (set_pause_point); at scope exit,
// whatever failed, removes the pause, lets a job held there end and clears the flag, so the
// session's teardown does not wait out the pause and later tests in this process run normally.
class HoldNextSolve {
 public:
  explicit HoldNextSolve(ViewSession& session) : session_(session) { set_pause_point("solve"); }
  ~HoldNextSolve() {
    set_pause_point(nullptr);
    if (session_.job_running()) request_cancel();
    session_.wait_for_job();
    reset_cancel();
  }
  HoldNextSolve(const HoldNextSolve&) = delete;
  HoldNextSolve& operator=(const HoldNextSolve&) = delete;

 private:
  ViewSession& session_;
};

// A job holds the device: pictures get 503 with Retry-After, state and job keep answering, and
// a second job is refused; when it ends, pictures come again.
TEST_F(ViewServerTest, DeviceRequestsDuringAJobGet503) {
  HoldNextSolve hold(*session_);
  auto r = post("/api/optimize", {{"solver", "cgls"}});
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 202) << r->body;
  // Until the job's solve waits at its checkpoint, or the job ended without getting there (a
  // broken pause or job path: a failure, not a skip). The bound is only against a hang: a job
  // reaches its solve within seconds on a loaded two-core machine.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (!paused_at_checkpoint() && session_->job_running() && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_TRUE(paused_at_checkpoint()) << "the job never reached its solve: " << session_->job().dump();
  ASSERT_TRUE(session_->job_running());
  auto busy = get("/api/render?view=reference&w=32&h=32");
  ASSERT_TRUE(busy);
  EXPECT_EQ(busy->status, 503);
  EXPECT_EQ(busy->get_header_value("Retry-After"), "1");
  EXPECT_EQ(get("/api/slice?view=reference")->status, 503);
  EXPECT_EQ(get("/api/state")->status, 200);
  EXPECT_EQ(get_json("/api/job")["state"], "running");
  auto second = post("/api/optimize", {{"solver", "normal-equations"}});
  ASSERT_TRUE(second);
  EXPECT_EQ(second->status, 409);
  request_cancel();  // lets the paused solve go on to its cancellation check
  wait_for_job();
  reset_cancel();
  const nlohmann::json job = get_json("/api/job");
  EXPECT_EQ(job["state"], "failed");
  EXPECT_NE(job["error"].get<std::string>().find("cancelled"), std::string::npos);
  EXPECT_EQ(get_json("/api/state")["version"], 1);  // a failed job changes nothing
  EXPECT_EQ(get("/api/render?view=reference&w=32&h=32")->status, 200);
}

TEST(ViewTfPoints, SimplifiedPointsReproduceTheTableWithinTolerance) {
  const TransferFunction tf = demo_transfer_function(64);
  const ControlPointTf cp = editor_points(tf);
  EXPECT_LT(cp.opacity.size(), 64u);
  EXPECT_LT(cp.color.size(), 64u);
  EXPECT_EQ(cp.opacity.front().position, 0.0);
  EXPECT_EQ(cp.opacity.back().position, 1.0);
  const TransferFunction back = table_from_control_points(parse_editor_points(editor_points_json(cp)), 64);
  for (size_t j = 0; j < 64; ++j)
    for (int c = 0; c < 4; ++c) EXPECT_NEAR(back.rgba[j][size_t(c)], tf.rgba[j][size_t(c)], 1.0 / 255.0 + 1e-12) << j;
  // A small table keeps every entry, exactly.
  const TransferFunction small = demo_transfer_function(9);
  const TransferFunction same = table_from_control_points(parse_editor_points(editor_points_json(editor_points(small))), 9);
  for (size_t j = 0; j < 9; ++j)
    for (int c = 0; c < 4; ++c) EXPECT_NEAR(same.rgba[j][size_t(c)], small.rgba[j][size_t(c)], 1e-12);
}

TEST(ViewTfPoints, BadPointsAreRefusedSayingWhy) {
  auto refuse = [](const nlohmann::json& j, const std::string& says) {
    try {
      parse_editor_points(j);
      ADD_FAILURE() << "accepted " << j.dump();
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  };
  const nlohmann::json colour = {{{"x", 0}, {"rgb", "#000000"}}, {{"x", 1}, {"rgb", "#ffffff"}}};
  const nlohmann::json opacity = {{{"x", 0}, {"a", 0}}, {{"x", 1}, {"a", 1}}};
  refuse({{"opacity", opacity}}, "expected");
  refuse({{"opacity", {{{"x", 0}, {"a", 0}}}}, {"color", colour}}, "2 to 256");
  refuse({{"opacity", {{{"x", 0.5}, {"a", 0}}, {{"x", 0.2}, {"a", 1}}}}, {"color", colour}}, "ascending");
  refuse({{"opacity", {{{"x", 0}, {"a", 0}}, {{"x", 1}, {"a", 1.5}}}}, {"color", colour}}, "[0, 1]");
  refuse({{"opacity", opacity}, {"color", {{{"x", 0}, {"rgb", "red"}}, {{"x", 1}, {"rgb", "#fff"}}}}}, "#rrggbb");
  refuse({{"opacity", {{{"x", "0"}, {"a", 0}}, {{"x", 1}, {"a", 1}}}}, {"color", colour}}, "number");
  const ControlPointTf ok = parse_editor_points({{"opacity", opacity}, {"color", colour}});
  EXPECT_EQ(ok.color[1].srgb[0], 1.0);
}

// Series mode: the page shows one field of several at a time; choosing another loads it and fits
// its TF as a job; the other modes refuse the request.
TEST_F(GpuTest, ViewSeriesChoosingAFieldFitsItsTf) {
  const Volume ref = synthetic_reference(13, 11, 9);
  const std::vector<Volume> fields = {synthetic_remapped(ref), synthetic_changed(ref), synthetic_remapped(ref, false)};
  ViewSeries series;
  series.labels = {"remapped", "changed", "remapped, no sphere"};
  size_t loads = 0;
  series.load = [&](size_t i) {
    ++loads;
    Volume v = fields[i];
    v.name = series.labels[i];
    return v;
  };
  ViewSession session(ctx(), ref, series, small_view_config());
  EXPECT_EQ(loads, 1u) << "only the field shown is loaded";
  ViewServer server(session, ViewServerOptions{});
  server.start();
  httplib::Client client("127.0.0.1", server.port());
  client.set_read_timeout(120);
  const std::string t = "token=" + server.token();
  const nlohmann::json s0 = nlohmann::json::parse(client.Get("/api/state?" + t)->body);
  EXPECT_EQ(s0["mode"], "series");
  EXPECT_EQ(s0["series"]["count"], 3);
  EXPECT_EQ(s0["series"]["index"], 0);
  EXPECT_EQ(s0["fields"]["field"]["name"], "remapped");
  const std::string before = client.Get("/api/render?view=field-opt-tf&w=32&h=32&" + t)->body;
  auto past = client.Post("/api/field?" + t, R"({"index": 3})", "application/json");
  ASSERT_TRUE(past);
  EXPECT_EQ(past->status, 400) << past->body;
  auto point = client.Post("/api/point?" + t, R"({"point": [1, 1, 1]})", "application/json");
  ASSERT_TRUE(point);
  EXPECT_EQ(point->status, 409) << point->body;
  auto r = client.Post("/api/field?" + t, R"({"index": 1})", "application/json");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 202) << r->body;
  session.wait_for_job();
  const nlohmann::json s1 = nlohmann::json::parse(client.Get("/api/state?" + t)->body);
  EXPECT_EQ(s1["job"]["state"], "done") << s1["job"].dump();
  EXPECT_EQ(s1["job"]["kind"], "field");
  EXPECT_EQ(s1["series"]["index"], 1);
  EXPECT_EQ(s1["fields"]["field"]["name"], "changed");
  EXPECT_GT(s1["version"].get<uint64_t>(), s0["version"].get<uint64_t>());
  // The same fit as optimize gives that field.
  OptimizeRequest req;
  req.ref = &ref;
  req.field = &fields[1];
  req.ref_tf = small_view_config().ref_tf;
  req.tf_size = 16;
  EXPECT_NEAR(s1["metrics"]["voxel_rmse_optimized_tf"].get<double>(), run_optimize(ctx(), req).after.rmse(), 1e-12);
  EXPECT_NE(client.Get("/api/render?view=field-opt-tf&w=32&h=32&" + t)->body, before);
  EXPECT_THROW(session.set_field(7), std::invalid_argument);
}

TEST_F(ViewServerTest, PairModeRefusesChoosingASeriesField) {
  auto r = client_->Post(with_token("/api/field"), R"({"index": 0})", "application/json");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 409) << r->body;
}

// Ensemble mode: a new reference point recomputes both correlation fields and optimizes again.
TEST_F(GpuTest, ViewEnsembleNewReferencePointRecomputesTheFields) {
  ViewEnsemble e;
  e.ensemble = synthetic_ensemble(12, 10, 6, 16);
  e.params.measure = CorrelationMeasure::MiCoefficient;
  e.versus = CorrelationMeasure::Pearson;
  e.point = synthetic_ensemble_reference(e.ensemble);
  ViewConfig config = small_view_config();
  config.ref_tf = correlation_transfer_function(16);
  ViewSession session(ctx(), std::move(e), config);
  ViewServer server(session, ViewServerOptions{});
  server.start();
  httplib::Client client("127.0.0.1", server.port());
  client.set_read_timeout(120);
  const std::string t = "token=" + server.token();
  const nlohmann::json s0 = nlohmann::json::parse(client.Get("/api/state?" + t)->body);
  EXPECT_EQ(s0["mode"], "ensemble");
  EXPECT_EQ(s0["ensemble"]["measure"], "mi-coefficient");
  EXPECT_EQ(s0["ensemble"]["members"], 16);
  EXPECT_EQ(s0["fields"]["reference"]["range"], nlohmann::json({0.0, 1.0}));  // the measure's own scale
  const std::string before = client.Get("/api/render?view=field-ref-tf&w=32&h=32&" + t)->body;
  auto outside = client.Post("/api/point?" + t, R"({"point": [12, 0, 0]})", "application/json");
  ASSERT_TRUE(outside);
  EXPECT_EQ(outside->status, 400) << outside->body;
  auto r = client.Post("/api/point?" + t, R"({"point": [2, 3, 1]})", "application/json");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 202) << r->body;
  for (int i = 0; i < 6000 && session.job_running(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  session.wait_for_job();
  const nlohmann::json s1 = nlohmann::json::parse(client.Get("/api/state?" + t)->body);
  EXPECT_EQ(s1["job"]["state"], "done") << s1["job"].dump();
  EXPECT_EQ(s1["ensemble"]["point"], nlohmann::json({2, 3, 1}));
  EXPECT_EQ(s1["markers"], nlohmann::json::array({{2, 3, 1}}));
  EXPECT_NE(client.Get("/api/render?view=field-ref-tf&w=32&h=32&" + t)->body, before);
  // The point is a red dot on the slices through it, as on the renderings: plane z = 1 of the
  // 12 x 10 grid at 120 pixels is 10 pixels a voxel, so voxel (2, 3) is centred on pixel (25, 65)
  // (the top row is y = 9); plane z = 0 does not hold it.
  for (const std::string view : {"reference", "field-opt-tf", "residual"}) {
    const Image through = decode_png(client.Get("/api/slice?view=" + view + "&axis=z&index=1&size=120&" + t)->body, view);
    const Image beside = decode_png(client.Get("/api/slice?view=" + view + "&axis=z&index=0&size=120&" + t)->body, view);
    ASSERT_EQ(through.width, 120u);
    ASSERT_EQ(through.height, 100u);
    const auto rgb = [](const Image& img, uint32_t x, uint32_t y) {
      const uint8_t* p = img.at(x, y);
      return std::array<int, 3>{p[0], p[1], p[2]};
    };
    EXPECT_EQ(rgb(through, 25, 65), (std::array<int, 3>{220, 20, 20})) << view;
    EXPECT_EQ(rgb(through, 25, 62), (std::array<int, 3>{255, 255, 255})) << view << ": the dot's white ring";
    EXPECT_NE(rgb(beside, 25, 65), (std::array<int, 3>{220, 20, 20})) << view << ": a dot on a plane without the point";
  }
}

}  // namespace
}  // namespace tfm

namespace tfm {
namespace {

// Too few members for any correlation: refused before any field is computed, saying why.
TEST_F(GpuTest, ViewEnsembleWithTwoMembersIsRefused) {
  ViewEnsemble e;
  e.ensemble.grid = empty_like(synthetic_reference(4, 4, 4));
  e.ensemble.grid.name = "two.nc:t";
  e.ensemble.member_count = 2;
  e.ensemble.values.assign(2 * 64, 1.0f);
  e.ensemble.values[70] = 2.0f;
  try {
    ViewSession session(ctx(), std::move(e), small_view_config());
    ADD_FAILURE() << "a 2-member ensemble was accepted";
  } catch (const std::runtime_error& err) {
    EXPECT_NE(std::string(err.what()).find("two.nc:t: 2 member(s); a correlation over members needs at least 3"),
              std::string::npos)
        << err.what();
  }
}

}  // namespace
}  // namespace tfm
