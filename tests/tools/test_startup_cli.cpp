// Start-up and where a run's time goes, as a user sees them: the pipeline cache a run leaves for
// the next (stored only when it changed, damaged files noted and replaced, switched off by
// TFMATCH_PIPELINE_CACHE=off), and the `timings` object of `--json`.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>

#include "cli_runner.h"
#include "scoped_env.h"
#include "slab_test_files.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/pipeline_cache_file.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;
using test::run_cli;
using test::run_cli_split;

using test::ScopedEnv;
// Points the CLI's pipeline cache somewhere for the scope.
struct CacheDirectory : ScopedEnv {
  explicit CacheDirectory(const std::string& value) : ScopedEnv("TFMATCH_PIPELINE_CACHE", value) {}
};

using test::read_text;

class StartupCli : public ::testing::Test {
 protected:
  void SetUp() override {
    ref = slab_test::write_raw(dir.path(), "ref", slab_test::test_field({21, 17, 13}, 0)).string();
    field = slab_test::write_raw(dir.path(), "field", slab_test::test_field({21, 17, 13}, 6)).string();
    std::ofstream(dir / "tf.json") << R"({"rgba": [[0,0,0,0],[1,0.5,0.2,0.8],[0.2,0.4,1,1]]})";
  }
  std::string optimize(const std::string& extra = "") const {
    return "optimize --ref " + ref + " --field " + field + " --ref-tf " + (dir / "tf.json").string() + " --out " +
           (dir / "out.json").string() + " --tf-size 16 " + extra;
  }
  std::vector<fs::path> cache_files(const fs::path& cache) const {
    std::vector<fs::path> out;
    if (fs::exists(cache))
      for (const auto& e : fs::directory_iterator(cache)) out.push_back(e.path());
    return out;
  }
  formats_test::TempDir dir;
  std::string ref, field;
};

TEST_F(StartupCli, ARunLeavesItsPipelinesForTheNext) {
  const fs::path cache = dir.path() / "cache";
  CacheDirectory env(cache.string());
  const auto first = run_cli(optimize());
  ASSERT_EQ(first.exit_code, 0) << first.output;
  const auto files = cache_files(cache);
  ASSERT_EQ(files.size(), 1u) << "one file per device and shader build";
  const StoredPipelineCache stored = read_pipeline_cache(files[0]);
  EXPECT_EQ(stored.note, "");
  EXPECT_GE(stored.data.size(), 32u);  // at least the driver's header
  const auto written = fs::last_write_time(files[0]);

  // The same work again: the cache is read, and not rewritten when the run added nothing.
  const auto second = run_cli(optimize());
  ASSERT_EQ(second.exit_code, 0) << second.output;
  EXPECT_EQ(second.output.find("pipeline cache"), std::string::npos) << second.output;
  EXPECT_EQ(cache_files(cache).size(), 1u);
  // A driver may serialize the same pipelines in another order; the same bytes, though, must not
  // have been written again.
  if (read_pipeline_cache(files[0]).data == stored.data) EXPECT_EQ(fs::last_write_time(files[0]), written);
}

TEST_F(StartupCli, ADamagedCacheIsNotedAndReplaced) {
  const fs::path cache = dir.path() / "cache";
  CacheDirectory env(cache.string());
  ASSERT_EQ(run_cli(optimize()).exit_code, 0);
  const auto files = cache_files(cache);
  ASSERT_EQ(files.size(), 1u);
  const std::string good = read_text(files[0]);
  const std::string tf = read_text(dir / "out.json");
  std::string damaged = good;
  damaged[damaged.size() - 1] ^= 0x5a;
  std::ofstream(files[0], std::ios::binary) << damaged;

  const auto r = run_cli_split(optimize());
  ASSERT_EQ(r.exit_code, 0) << r.errors;
  EXPECT_NE(r.errors.find("tfmatch: note: pipeline cache " + files[0].string() + " ignored: damaged"),
            std::string::npos) << r.errors;
  EXPECT_EQ(read_text(dir / "out.json"), tf);  // the same result, compiled afresh
  const StoredPipelineCache replaced = read_pipeline_cache(files[0]);
  EXPECT_EQ(replaced.note, "");
  EXPECT_FALSE(replaced.data.empty());

  // -q keeps even the note to itself.
  std::ofstream(files[0], std::ios::binary) << "not a cache";
  const auto quiet = run_cli_split("-q " + optimize());
  ASSERT_EQ(quiet.exit_code, 0) << quiet.errors;
  EXPECT_EQ(quiet.errors, "");
}

TEST_F(StartupCli, OffWritesNothing) {
  const fs::path home_cache = dir.path() / "home";
  const ScopedEnv xdg("XDG_CACHE_HOME", home_cache.string());  // where it goes unless off
  {
    const CacheDirectory off("off");
    const auto r = run_cli(optimize());
    ASSERT_EQ(r.exit_code, 0) << r.output;
    // (The driver may keep a cache of its own there: Mesa's mesa_shader_cache.)
    EXPECT_FALSE(fs::exists(home_cache / "tfmatch"));
  }
  const ScopedEnv unset("TFMATCH_PIPELINE_CACHE", std::nullopt);
  const auto on = run_cli(optimize());
  ASSERT_EQ(on.exit_code, 0) << on.output;
  EXPECT_EQ(cache_files(home_cache / "tfmatch" / "pipelines").size(), 1u);
}

TEST_F(StartupCli, JsonSaysWhereTheTimeWent) {
  CacheDirectory env((dir.path() / "cache").string());
  const auto start = std::chrono::steady_clock::now();
  const auto r = run_cli_split(optimize("--json -"));
  const double wall_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  ASSERT_EQ(r.exit_code, 0) << r.errors;
  const nlohmann::json j = nlohmann::json::parse(r.output);
  ASSERT_TRUE(j.contains("timings")) << r.output;
  const nlohmann::json& t = j["timings"];
  double phases = 0;
  for (const char* phase : {"startup", "pipelines", "read", "upload", "compute", "download", "write"}) {
    const std::string key = std::string(phase) + "_ms";
    ASSERT_TRUE(t.contains(key) && t[key].is_number()) << key << " in " << t.dump();
    EXPECT_GE(t[key].get<double>(), 0.0) << key;
    phases += t[key].get<double>();
  }
  // Phases that certainly ran: a device was created, two files read, fields uploaded, the
  // system assembled on the device and its words read back.
  for (const char* ran : {"startup_ms", "read_ms", "upload_ms", "download_ms"})
    EXPECT_GT(t[ran].get<double>(), 0.0) << ran << " in " << t.dump();
  // One thread's phases never add up to more than its wall time (the second file's reader is
  // not counted twice), and the rest is what they leave.
  const double total = t["total_ms"].get<double>();
  EXPECT_GT(total, 0.0);
  EXPECT_LE(phases, total + 1e-3) << t.dump();
  EXPECT_NEAR(t["other_ms"].get<double>(), total - phases, 1e-3) << t.dump();
  // The program's own clock starts after it was launched and stops before it exits.
  EXPECT_LT(total, wall_ms);
}

}  // namespace
}  // namespace tfm
