// `tfmatch view` as a user runs it: the URL printed, the page served, Ctrl-C ending it with exit
// 0 and no file written; its pictures equal `tfmatch render`'s from the page's own command line
// and downloads; --report reopening a report; the ERA5 ensemble; usage errors.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <cmath>
#include <regex>
#include <thread>
#include <set>

#include "cli_runner.h"
#include "tfmatch/io/json.h"
#include "tfmatch/report/png_io.h"
#include "vk_test_env.h"
// After Eigen (through the project headers): OpenSSL's headers, which httplib.h includes, define
// macros that break Eigen's product kernels when they come first.
#include <httplib.h>

namespace tfm {
namespace {

namespace fs = std::filesystem;
using test::CliProcess;
using test::run_cli;

// A temporary directory that the spawned process runs in (its cwd), removed at the end.
struct TempDir {
  fs::path path;
  fs::path previous = fs::current_path();
  TempDir() {
    char name[] = "/tmp/tfmatch_view_XXXXXX";
    path = mkdtemp(name);
  }
  ~TempDir() {
    fs::current_path(previous);
    fs::remove_all(path);
  }
  std::vector<std::string> entries() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(path)) names.push_back(e.path().filename().string());
    return names;
  }
};

// A running `tfmatch view`: its port and token from the printed URL.
struct RunningView {
  std::unique_ptr<CliProcess> process;
  int port = 0;
  std::string token;

  explicit RunningView(const std::string& args) : process(std::make_unique<CliProcess>("view --port 0 " + args)) {
    if (!process->wait_for("?token=", std::chrono::seconds(180))) return;
    process->wait_for("\n", std::chrono::seconds(5));
    std::smatch m;
    const std::string out = process->output();
    if (std::regex_search(out, m, std::regex(R"(http://127\.0\.0\.1:(\d+)/\?token=([0-9a-f]{32}))"))) {
      port = std::stoi(m[1]);
      token = m[2];
    }
  }
  std::string get(const std::string& path, int* status = nullptr) const {
    httplib::Client client("127.0.0.1", port);
    client.set_read_timeout(120);
    auto r = client.Get(path + (path.find('?') == std::string::npos ? "?" : "&") + "token=" + token);
    if (status) *status = r ? r->status : -1;
    return r ? r->body : std::string();
  }
  nlohmann::json state() const { return nlohmann::json::parse(get("/api/state")); }
};

TEST(ViewCli, ServesTheDemoAndCtrlCEndsItWithExitZeroWritingNothing) {
  TempDir dir;
  fs::current_path(dir.path);
  RunningView view("--demo --size 20");
  ASSERT_GT(view.port, 0) << view.process->output();
  int status = 0;
  const std::string page = view.get("/", &status);
  EXPECT_EQ(status, 200);
  EXPECT_NE(page.find("<script>"), std::string::npos);
  const nlohmann::json s = view.state();
  EXPECT_EQ(s["mode"], "pair");
  EXPECT_EQ(s["grid"]["dims"], nlohmann::json({20, 20, 20}));
  // The demo pair opens with tfmatch demo's own fit of it.
  EXPECT_EQ(s["solver"]["name"], "irls") << s.dump();
  // Without the token: 403.
  httplib::Client anonymous("127.0.0.1", view.port);
  auto r = anonymous.Get("/api/state");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 403);
  view.process->signal(SIGINT);
  const test::CliResult done = view.process->finish(std::chrono::seconds(30));
  EXPECT_EQ(done.exit_code, 0) << done.output;
  EXPECT_NE(done.output.find("tfmatch view: stopped"), std::string::npos) << done.output;
  EXPECT_TRUE(dir.entries().empty());
}

// The page's render command line, with the page's downloads, reproduces its pictures exactly.
TEST(ViewCli, RenderCommandOfThePageReproducesItsImages) {
  TempDir dir;
  RunningView view("--demo --size 20 --opacity-scale 30 --step 0.7");
  ASSERT_GT(view.port, 0) << view.process->output();
  const nlohmann::json s = view.state();
  for (const char* file : {"reference.vti", "field.vti", "reference-tf.json", "optimized-tf.json"}) {
    int status = 0;
    const std::string bytes = view.get(std::string("/api/download?what=") + file, &status);
    ASSERT_EQ(status, 200) << file;
    std::ofstream(dir.path / file, std::ios::binary) << bytes;
  }
  const std::string camera = "--azimuth 63 --elevation 28 --distance 2.5 --fov 31 --width 48 --height 40";
  for (const char* v : {"reference", "field-opt-tf"}) {
    const std::string served = view.get(std::string("/api/render?view=") + v + "&az=63&el=28&dist=2.5&fov=31&w=48&h=40");
    std::string command = s["render_commands"][v].get<std::string>();
    ASSERT_EQ(command.rfind("tfmatch render ", 0), 0u) << command;
    command = command.substr(std::string("tfmatch ").size());
    for (const char* file : {"reference.vti", "field.vti", "reference-tf.json", "optimized-tf.json"}) {
      const size_t at = command.find(file);
      if (at != std::string::npos) command.replace(at, std::strlen(file), (dir.path / file).string());
    }
    const fs::path out = dir.path / (std::string(v) + ".png");
    const test::CliResult rendered = run_cli(command + " " + camera + " --out " + out.string());
    ASSERT_EQ(rendered.exit_code, 0) << command << "\n" << rendered.output;
    std::ifstream in(out, std::ios::binary);
    const std::string cli_png((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_EQ(cli_png, served) << v << ": " << command;
  }
  view.process->signal(SIGINT);
  EXPECT_EQ(view.process->finish(std::chrono::seconds(30)).exit_code, 0);
}

TEST(ViewCli, ReopensAReportsInputs) {
  TempDir dir;
  const fs::path demo = dir.path / "demo";
  const test::CliResult made = run_cli("demo --size 16 --width 64 --height 64 -q --out " + demo.string());
  ASSERT_EQ(made.exit_code, 0) << made.output;
  ASSERT_TRUE(fs::exists(demo / "inputs.json"));
  RunningView view("--report " + demo.string());
  ASSERT_GT(view.port, 0) << view.process->output();
  const nlohmann::json s = view.state();
  EXPECT_NE(s["fields"]["reference"]["name"].get<std::string>().find("reference_16x16x16_float32.raw"),
            std::string::npos);
  EXPECT_EQ(s["grid"]["dims"], nlohmann::json({16, 16, 16}));
  view.process->signal(SIGINT);
  EXPECT_EQ(view.process->finish(std::chrono::seconds(30)).exit_code, 0);
  // A directory without inputs.json says so.
  const test::CliResult missing = run_cli("view --port 0 --report " + dir.path.string());
  EXPECT_EQ(missing.exit_code, 1) << missing.output;
  EXPECT_NE(missing.output.find("inputs.json"), std::string::npos) << missing.output;
}

// The session's own buffers (both fields and both residual maps on the device, the residual maps
// on the host) are checked against --max-memory before they are made: a budget that holds the two
// loaded fields but not the session stops with the size, not a process at three times the budget.
TEST(ViewCli, ASessionBeyondTheBudgetIsRefusedBeforeItIsMade) {
  test::TempDir dir;
  std::vector<float> v(size_t(256) * 256 * 128);
  for (size_t i = 0; i < v.size(); ++i) v[i] = float(i % 1000) / 999.0f;
  const std::string a = (dir.path / "a_256x256x128_float32.raw").string(), b = (dir.path / "b_256x256x128_float32.raw").string();
  test::write_floats(a, v);
  test::write_floats(b, v);
  const test::CliResult r = run_cli("--max-memory 230M view --port 0 --ref " + a + " --ref-tf viridis --field " + b);
  ASSERT_EQ(r.exit_code, 1) << r.output;
  if (r.output.find("both fields and the residual maps on the device") == std::string::npos)
    // A machine whose start-up takes more leaves less: the load itself may be what is refused.
    EXPECT_NE(r.output.find("needs 64.0 MiB"), std::string::npos) << r.output;
  else
    EXPECT_NE(r.output.find("needs 128 MiB"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("http://"), std::string::npos) << r.output;
}

// How much of a picture shows data: the share of pixels away from the white background, and how
// many colours (5 bits a channel) they take.
struct Visibility {
  double shown = 0.0;
  size_t colours = 0;
};
Visibility visibility(const Image& img) {
  size_t shown = 0;
  std::set<int> colours;
  for (size_t i = 0; i < size_t(img.width) * img.height; ++i) {
    const uint8_t* p = &img.rgb[3 * i];
    if (std::max({255 - p[0], 255 - p[1], 255 - p[2]}) <= 8) continue;
    ++shown;
    colours.insert((p[0] >> 3) << 10 | (p[1] >> 3) << 5 | (p[2] >> 3));
  }
  return {double(shown) / double(size_t(img.width) * img.height), colours.size()};
}

// Issue 29: the README's ERA5 recipe (a 120 x 61 x 2 grid) opened with four blank slabs seen at
// 20 degrees, and nearly white slices. With the defaults it opens as a map seen from above, north
// up, every view and slice showing the fields in colour.
TEST(ViewCli, Era5EnsembleFromTheSharedData) {
  const std::string d = test::shared_data_dir();
  if (d.empty()) GTEST_SKIP() << "needs ../shared/data (ERA5 ensemble)";
  RunningView view("--ensemble " + d + "/era5_ensemble_grib1/era5-levels-members.grib:t --measure mi-coefficient "
                   "--versus pearson --point lon=9,lat=45,level=850");
  ASSERT_GT(view.port, 0) << view.process->output();
  const nlohmann::json s = view.state();
  EXPECT_EQ(s["mode"], "ensemble");
  EXPECT_EQ(s["ensemble"]["members"], 10);
  EXPECT_EQ(s["ensemble"]["point"], nlohmann::json({3, 45, 0}));
  EXPECT_EQ(s["grid"]["dims"], nlohmann::json({120, 61, 2}));
  EXPECT_EQ(s["grid"]["axes"][0]["first"], 0.0);
  EXPECT_EQ(s["grid"]["axes"][0]["last"], 357.0);
  EXPECT_EQ(s["grid"]["axes"][1]["last"], 90.0);
  const nlohmann::json& r = s["render"];
  EXPECT_EQ(r["camera"]["elevation_deg"], 90.0);  // from above
  EXPECT_EQ(r["camera"]["azimuth_deg"], -90.0);   // north up
  EXPECT_EQ(r["width"], 512);
  EXPECT_NEAR(r["height"].get<double>(), 512.0 * 61 / 120, 2.0);  // the map's aspect
  for (const char* v : {"reference", "field-ref-tf", "field-opt-tf", "residual"}) {
    int status = 0;
    const std::string png = view.get(std::string("/api/render?view=") + v, &status);
    ASSERT_EQ(status, 200) << v;
    const Visibility seen = visibility(decode_png(png, v));
    EXPECT_GT(seen.shown, 0.6) << v;
    EXPECT_GE(seen.colours, 20u) << v;
    std::printf("[ era5 ] %-13s %.0f %% of pixels shown, %zu colours\n", v, 100 * seen.shown, seen.colours);
  }
  for (const char* v : {"reference", "field-ref-tf", "field-opt-tf", "residual"}) {
    int status = 0;
    const std::string png = view.get(std::string("/api/slice?view=") + v + "&axis=z&index=0", &status);
    ASSERT_EQ(status, 200) << v;
    const Visibility seen = visibility(decode_png(png, v));
    EXPECT_GT(seen.shown, 0.6) << v << " slice";
    EXPECT_GE(seen.colours, 20u) << v << " slice";
  }
  view.process->signal(SIGINT);
  EXPECT_EQ(view.process->finish(std::chrono::seconds(30)).exit_code, 0);
}

// Series mode on the shared ERA5 ensemble: three temperature members against member 0's
// geopotential; choosing another member loads it and fits its TF, and the pictures show it.
TEST(ViewCli, Era5MembersAsASeries) {
  const std::string d = test::shared_data_dir();
  if (d.empty()) GTEST_SKIP() << "needs ../shared/data (ERA5 ensemble)";
  const std::string grib = d + "/era5_ensemble_grib1/era5-levels-members.grib";
  RunningView view("--ref " + grib + ":z,member=0 --ref-tf viridis --field " + grib + ":t,member=0..2 --width 96 --height 48");
  ASSERT_GT(view.port, 0) << view.process->output();
  const nlohmann::json s0 = view.state();
  EXPECT_EQ(s0["mode"], "series");
  EXPECT_EQ(s0["series"]["count"], 3);
  EXPECT_EQ(s0["series"]["labels"][2], "era5-levels-members.grib:t,member=2");
  const std::string before = view.get("/api/render?view=field-opt-tf");
  httplib::Client client("127.0.0.1", view.port);
  client.set_read_timeout(120);
  auto r = client.Post("/api/field?token=" + view.token, R"({"index": 2})", "application/json");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 202) << r->body;
  nlohmann::json s1;
  for (int i = 0; i < 600; ++i) {
    s1 = view.state();
    if (s1["job"]["state"] != "running") break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_EQ(s1["job"]["state"], "done") << s1["job"].dump();
  EXPECT_EQ(s1["series"]["index"], 2);
  EXPECT_NE(s1["fields"]["field"]["name"].get<std::string>().find("member=2"), std::string::npos) << s1["fields"].dump();
  EXPECT_LT(s1["metrics"]["voxel_rmse_optimized_tf"].get<double>(), 0.6 * s1["metrics"]["voxel_rmse_reference_tf"].get<double>());
  int status = 0;
  const std::string after = view.get("/api/render?view=field-opt-tf", &status);
  EXPECT_EQ(status, 200);
  EXPECT_NE(after, before);
  view.process->signal(SIGINT);
  EXPECT_EQ(view.process->finish(std::chrono::seconds(30)).exit_code, 0);
}

// Without --ref-tf a pair starts from a built-in map, chosen by the reference's range and said on
// stderr and in the page's title; --ref-tf takes a built-in name as well.
TEST(ViewCli, StartsFromABuiltInTfWithoutRefTf) {
  TempDir dir;
  std::vector<float> signed_values(10 * 10 * 10), positive(signed_values.size());
  for (size_t i = 0; i < signed_values.size(); ++i) {
    signed_values[i] = float(std::sin(0.37 * double(i)));  // in [-1, 1]: a correlation-like field
    positive[i] = 2.0f + signed_values[i] * signed_values[i];
  }
  const std::string a = (dir.path / "a_10x10x10_float32.raw").string(), b = (dir.path / "b_10x10x10_float32.raw").string();
  test::write_floats(a, signed_values);
  test::write_floats(b, positive);
  const std::string small = " --width 32 --height 32";
  {
    RunningView view("--ref " + a + " --field " + b + small);
    ASSERT_GT(view.port, 0) << view.process->output();
    const std::string title = view.state()["title"].get<std::string>();
    EXPECT_NE(title.find("built-in diverging"), std::string::npos) << title;
    view.process->signal(SIGINT);
    const test::CliResult done = view.process->finish(std::chrono::seconds(30));
    EXPECT_EQ(done.exit_code, 0) << done.output;
    EXPECT_NE(done.output.find("note: no --ref-tf"), std::string::npos) << done.output;
    EXPECT_NE(done.output.find("'diverging'"), std::string::npos) << done.output;
  }
  {
    RunningView view("--ref " + b + " --field " + a + small);  // a positive reference: viridis
    ASSERT_GT(view.port, 0) << view.process->output();
    EXPECT_NE(view.state()["title"].get<std::string>().find("built-in viridis"), std::string::npos);
    view.process->signal(SIGINT);
    EXPECT_EQ(view.process->finish(std::chrono::seconds(30)).exit_code, 0);
  }
  {
    RunningView view("--ref " + b + " --field " + a + " --ref-tf inferno,opacity=tent" + small);
    ASSERT_GT(view.port, 0) << view.process->output();
    EXPECT_EQ(view.state()["title"].get<std::string>().find("built-in"), std::string::npos);
    view.process->signal(SIGINT);
    const test::CliResult done = view.process->finish(std::chrono::seconds(30));
    EXPECT_EQ(done.exit_code, 0) << done.output;
    EXPECT_NE(done.output.find("opacity tent"), std::string::npos) << done.output;
  }
  EXPECT_EQ(dir.entries().size(), 2u);  // nothing written beside the two fields
}

// Each refused for its own reason (the message says which) before anything is served. Every run
// has --port 0 and a deadline: an option wrongly accepted starts a server, which must fail the
// test (timed out) rather than hang it or take a fixed port another run may hold.
TEST(ViewCli, UsageErrors) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"view --port 0", "view: give one of: --ref/--ref-tf/--field (a pair of fields), --report DIR"},
      {"view --port 0 --demo --ref a.raw", "view: give one of:"},
      {"view --port 0 --ref a.raw", "view: a pair of fields needs --ref and --field (and --ref-tf, else a built-in map)"},
      {"view --demo --port 70000", "--port: Value 70000 not in range 0 to 65535"},
      {"view --port 0 --demo --bind ''", "--bind: expected an address such as 127.0.0.1 or 0.0.0.0, got ''"},
      {"view --port 0 --demo --solver nothing", "unknown solver 'nothing' (available: "},
      {"view --port 0 --demo --lr 0.1", "--lr applies to solvers diffdvr, gradient-descent, not to irls"},
  };
  for (const auto& [args, message] : cases) {
    const test::CliResult r = run_cli(args, test::kQuickCliTimeout);
    EXPECT_FALSE(r.timed_out) << args << ": accepted and serving\n" << r.output;
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.output;
    EXPECT_NE(r.output.find(message), std::string::npos) << args << ": no '" << message << "' in\n" << r.output;
    EXPECT_EQ(r.output.find("?token="), std::string::npos) << args << ": served\n" << r.output;
  }
  // An address that is not this machine's cannot be bound: a clear error, exit 1.
  const test::CliResult r = run_cli("view --demo --size 8 --port 0 --bind 192.0.2.1", test::kQuickCliTimeout);
  EXPECT_FALSE(r.timed_out) << r.output;
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("cannot listen on 192.0.2.1"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("warning: listening on 192.0.2.1"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace tfm
