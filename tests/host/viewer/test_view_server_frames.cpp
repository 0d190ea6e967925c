// `tfmatch view`'s interactive frames in-process: fast-encoded frames carry the downloads'
// pixels, every picture says where its time went (Server-Timing), and a picture or metrics
// request for a camera its page has moved past is dropped (410) without touching other pages.
#include <gtest/gtest.h>

#include <map>

#include "tfmatch/report/png_io.h"
#include "view_server_fixture.h"

namespace tfm {
namespace {

using ViewServerFramesTest = test::ViewServerFixture;

// Server-Timing: "name;dur=ms, ..." as a map.
std::map<std::string, double> server_timing(const std::string& header) {
  std::map<std::string, double> parts;
  size_t at = 0;
  while (at < header.size()) {
    const size_t end = std::min(header.find(',', at), header.size());
    std::string part = header.substr(at, end - at);
    part.erase(0, part.find_first_not_of(' '));
    const size_t semi = part.find(";dur=");
    if (semi != std::string::npos) parts[part.substr(0, semi)] = std::stod(part.substr(semi + 5));
    at = end + 1;
  }
  return parts;
}

TEST_F(ViewServerFramesTest, FastFramesShowTheDownloadsPixels) {
  for (const char* view : {"reference", "field-opt-tf", "residual"}) {
    const std::string camera = std::string("/api/render?view=") + view + "&az=21&el=33&w=57&h=45";
    auto fast = get(camera + "&frame=fast&client=a&seq=1");
    auto download = get(camera + "&download=1");
    auto plain = get(camera);
    ASSERT_TRUE(fast && download && plain);
    ASSERT_EQ(fast->status, 200) << fast->body;
    ASSERT_EQ(download->status, 200) << download->body;
    // Downloads stay the PNG `tfmatch render` writes (other tests compare those bytes).
    EXPECT_EQ(download->body, plain->body) << view;
    EXPECT_NE(fast->body, download->body) << view;
    const Image a = decode_png(fast->body, "fast"), b = decode_png(download->body, "download");
    EXPECT_EQ(a.width, b.width);
    EXPECT_EQ(a.rgb, b.rgb) << view;
    // frame=fast never applies to a download.
    auto both = get(camera + "&frame=fast&download=1");
    ASSERT_TRUE(both);
    EXPECT_EQ(both->body, download->body);

    const auto parts = server_timing(fast->get_header_value("Server-Timing"));
    for (const char* name : {"wait", "render", "readback", "compose", "decorate", "encode"}) {
      ASSERT_TRUE(parts.count(name)) << name << " in " << fast->get_header_value("Server-Timing");
      EXPECT_GE(parts.at(name), 0.0) << name;
    }
    EXPECT_GT(parts.at("render"), 0.0);
  }
}

// Sequence numbers are noted when a request arrives and checked when the device is its turn: a
// picture for seq 1 after one for seq 5 from the same page is dropped, deterministically.
TEST_F(ViewServerFramesTest, PicturesForACameraThePageMovedPastAreDropped) {
  auto newer = get("/api/render?view=reference&w=24&h=20&frame=fast&client=page1&seq=5");
  ASSERT_TRUE(newer);
  EXPECT_EQ(newer->status, 200);
  for (const char* path : {"/api/render?view=field-opt-tf&w=24&h=20&frame=fast&client=page1&seq=1",
                           "/api/metrics?w=24&h=20&client=page1&seq=4"}) {
    auto older = get(path);
    ASSERT_TRUE(older);
    EXPECT_EQ(older->status, 410) << path << ": " << older->body;
    EXPECT_NE(older->body.find("newer camera"), std::string::npos) << older->body;
  }
  // The same camera (the other views of its set), another page, or no page id: rendered.
  for (const char* path : {"/api/render?view=residual&w=24&h=20&frame=fast&client=page1&seq=5",
                           "/api/render?view=reference&w=24&h=20&frame=fast&client=page2&seq=1",
                           "/api/metrics?w=24&h=20&client=page1&seq=5", "/api/render?view=reference&w=24&h=20"}) {
    auto r = get(path);
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 200) << path << ": " << r->body;
  }
  auto bad = get("/api/render?view=reference&client=&seq=1");
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->status, 400);
}

// The metrics a page asks for after showing a camera's pictures use those pictures: nothing is
// rendered again, and the numbers are those of fresh renders. Another camera, a view not shown,
// or a new state (an optimization ran) renders again.
TEST_F(ViewServerFramesTest, MetricsUseThePicturesJustShown) {
  RenderSettings s = session_->default_render();
  s.width = 40;
  s.height = 36;
  s.camera.azimuth_deg = 47;
  s.camera.elevation_deg = 12;
  const nlohmann::json fresh = session_->image_metrics(s);
  EXPECT_EQ(fresh["rendered"], 3);
  for (ViewKind view : {ViewKind::Reference, ViewKind::FieldRefTf, ViewKind::FieldOptTf}) session_->render(view, s);
  const nlohmann::json reused = session_->image_metrics(s);
  EXPECT_EQ(reused["rendered"], 0);
  EXPECT_EQ(reused["reference_tf"], fresh["reference_tf"]);
  EXPECT_EQ(reused["optimized_tf"], fresh["optimized_tf"]);
  // A reference picture at another camera (a second page) is kept beside the one at `s`: metrics
  // there render the two views it lacks, and at `s` nothing.
  RenderSettings other = s;
  other.camera.azimuth_deg = 48;
  session_->render(ViewKind::Reference, other);
  EXPECT_EQ(session_->image_metrics(other)["rendered"], 2);
  EXPECT_EQ(session_->image_metrics(s)["rendered"], 0);
  s.box_outline = false;  // drawn after rendering: the same pictures
  EXPECT_EQ(session_->image_metrics(s)["rendered"], 0);
  // Two pages at their own cameras, taking turns: each finds its own pictures. Four cameras later
  // the first is gone (at most four kept per view).
  RenderSettings third = s, fourth = s, fifth = s;
  third.camera.azimuth_deg = 49, fourth.camera.azimuth_deg = 50, fifth.camera.azimuth_deg = 51;
  for (const RenderSettings* c : {&third, &fourth})
    for (ViewKind view : {ViewKind::Reference, ViewKind::FieldRefTf, ViewKind::FieldOptTf}) session_->render(view, *c);
  EXPECT_EQ(session_->image_metrics(third)["rendered"], 0);
  EXPECT_EQ(session_->image_metrics(fourth)["rendered"], 0);
  EXPECT_EQ(session_->image_metrics(s)["rendered"], 0);
  for (ViewKind view : {ViewKind::Reference, ViewKind::FieldRefTf, ViewKind::FieldOptTf}) session_->render(view, fifth);
  EXPECT_EQ(session_->image_metrics(fifth)["rendered"], 0);
  // The reference view saw five cameras (s, other, third, fourth, fifth): s's is gone; the other
  // two views saw four and still hold theirs.
  EXPECT_EQ(session_->image_metrics(s)["rendered"], 1);
  // A byte budget per view: large pictures keep fewer (always the newest). 1200² is 4.1 MiB: three
  // fit the 16 MiB of a view, four do not.
  std::vector<RenderSettings> large(4, s);
  for (size_t i = 0; i < large.size(); ++i) {
    large[i].width = large[i].height = 1200;
    large[i].camera.azimuth_deg = 60.0 + double(i);
    session_->render(ViewKind::Reference, large[i]);
  }
  EXPECT_EQ(session_->image_metrics(large[0])["rendered"], 3);
  EXPECT_EQ(session_->image_metrics(large[1])["rendered"], 2);
  // After an optimization (a new state) nothing earlier is used.
  for (ViewKind view : {ViewKind::Reference, ViewKind::FieldRefTf, ViewKind::FieldOptTf}) session_->render(view, s);
  EXPECT_EQ(session_->image_metrics(s)["rendered"], 0);
  session_->optimize("normal-equations", SolverSettings{});
  session_->wait_for_job();
  EXPECT_EQ(session_->image_metrics(s)["rendered"], 3);
}

}  // namespace
}  // namespace tfm
