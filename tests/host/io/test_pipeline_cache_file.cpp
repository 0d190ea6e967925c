// The on-disk pipeline cache (host/io/pipeline_cache_file.h): where it lives, round trips, every
// kind of damaged file ignored with a note, and readers never seeing a half-written file while
// other writers replace it.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <fstream>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "cli_runner.h"
#include "scoped_env.h"
#include "tfmatch/io/pipeline_cache_file.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;
using test::TempDir;

using test::ScopedEnv;

std::vector<uint8_t> bytes_of(size_t n, uint8_t seed) {
  std::vector<uint8_t> v(n);
  for (size_t i = 0; i < n; ++i) v[i] = uint8_t(seed + i * 7);
  return v;
}

std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}
void write_all(const fs::path& p, const std::string& s) { std::ofstream(p, std::ios::binary) << s; }

TEST(PipelineCacheFile, DirectoryFollowsTheEnvironment) {
  {
    ScopedEnv own("TFMATCH_PIPELINE_CACHE", "/some/where");
    EXPECT_EQ(pipeline_cache_directory(), fs::path("/some/where"));
  }
  for (const char* off : {"off", "0"}) {
    ScopedEnv own("TFMATCH_PIPELINE_CACHE", off);
    EXPECT_EQ(pipeline_cache_directory(), std::nullopt) << off;
  }
  ScopedEnv own("TFMATCH_PIPELINE_CACHE", std::nullopt);
  {
    ScopedEnv xdg("XDG_CACHE_HOME", "/xdg/cache");
    EXPECT_EQ(pipeline_cache_directory(), fs::path("/xdg/cache/tfmatch/pipelines"));
  }
  {
    // The XDG specification ignores a relative XDG_CACHE_HOME.
    ScopedEnv xdg("XDG_CACHE_HOME", "relative");
    ScopedEnv home("HOME", "/home/someone");
    EXPECT_EQ(pipeline_cache_directory(), fs::path("/home/someone/.cache/tfmatch/pipelines"));
  }
  ScopedEnv xdg("XDG_CACHE_HOME", std::nullopt);
  ScopedEnv home("HOME", std::nullopt);
  EXPECT_EQ(pipeline_cache_directory(), std::nullopt);
}

TEST(PipelineCacheFile, PathNamesDeviceAndShaders) {
  const fs::path p = pipeline_cache_path("/c", "10de-2335-12345678-00ff", 0x1234abcdull);
  EXPECT_EQ(p, fs::path("/c/10de-2335-12345678-00ff-000000001234abcd.bin"));
  EXPECT_NE(pipeline_cache_path("/c", "a", 1), pipeline_cache_path("/c", "a", 2));
  EXPECT_NE(pipeline_cache_path("/c", "a", 1), pipeline_cache_path("/c", "b", 1));
}

TEST(PipelineCacheFile, RoundTripCreatesTheDirectory) {
  TempDir dir;
  const fs::path file = dir.path / "new" / "deeper" / "cache.bin";
  EXPECT_TRUE(read_pipeline_cache(file).data.empty());  // missing: nothing, and nothing to note
  EXPECT_TRUE(read_pipeline_cache(file).note.empty());
  for (size_t n : {size_t(0), size_t(1), size_t(32), size_t(100003)}) {
    const auto data = bytes_of(n, uint8_t(n));
    ASSERT_EQ(write_pipeline_cache(file, data), "");
    const StoredPipelineCache back = read_pipeline_cache(file);
    EXPECT_EQ(back.note, "") << n;
    EXPECT_EQ(back.data, data) << n;
  }
  // No temporary file is left beside it.
  EXPECT_EQ(test::files_under(dir.path / "new" / "deeper").size(), 1u);
}

TEST(PipelineCacheFile, DamagedFilesAreIgnoredWithANote) {
  TempDir dir;
  const fs::path file = dir.path / "cache.bin";
  const auto data = bytes_of(1000, 3);
  ASSERT_EQ(write_pipeline_cache(file, data), "");
  const std::string good = read_all(file);
  ASSERT_EQ(good.size(), 8u + 8u + 4u + data.size());  // magic, length, CRC-32, data

  struct Case {
    std::string name, bytes, needle;
  };
  std::string flipped = good;
  flipped[good.size() / 2] ^= 0x10;
  std::string other_magic = good;
  other_magic[0] = 'X';
  std::string longer_length = good;
  longer_length[8] = char(longer_length[8] + 1);
  const std::vector<Case> cases = {
      {"a flipped data bit", flipped, "checksum"},
      {"truncated", good.substr(0, good.size() - 10), "truncated"},
      {"extended", good + "xx", "truncated or extended"},
      {"another magic", other_magic, "not a tfmatch pipeline cache"},
      {"a length field that lies", longer_length, "header says"},
      {"shorter than the header", good.substr(0, 12), "size"},
      {"empty", "", "size"},
  };
  for (const Case& c : cases) {
    write_all(file, c.bytes);
    const StoredPipelineCache r = read_pipeline_cache(file);
    EXPECT_TRUE(r.data.empty()) << c.name;
    EXPECT_NE(r.note.find(c.needle), std::string::npos) << c.name << ": " << r.note;
    EXPECT_NE(r.note.find(file.string()), std::string::npos) << c.name << ": " << r.note;
  }
  // A directory where the file should be: a note, no exception.
  fs::remove(file);
  fs::create_directory(file);
  const std::string note = read_pipeline_cache(file).note;
  EXPECT_NE(note.find("a directory, not a file"), std::string::npos) << note;
  EXPECT_EQ(note.find("size"), std::string::npos) << "a directory has no size to report: " << note;
  EXPECT_NE(write_pipeline_cache(file, data), "");
}

TEST(PipelineCacheFile, ReadersNeverSeeAHalfWrittenFile) {
  TempDir dir;
  const fs::path file = dir.path / "cache.bin";
  // Sizes far apart, so a reader that caught a file mid-write would see a length or checksum
  // mismatch rather than another valid payload.
  const std::vector<std::vector<uint8_t>> payloads = {bytes_of(1 << 20, 1), bytes_of(5000, 2), bytes_of(3 << 20, 3)};
  ASSERT_EQ(write_pipeline_cache(file, payloads[0]), "");
  std::atomic<bool> stop{false};
  std::vector<std::thread> writers;
  for (size_t w = 0; w < 3; ++w)
    writers.emplace_back([&, w] {
      for (int i = 0; i < 30 && !stop; ++i) EXPECT_EQ(write_pipeline_cache(file, payloads[(w + i) % 3]), "");
    });
  int reads = 0;
  for (; reads < 200; ++reads) {
    const StoredPipelineCache r = read_pipeline_cache(file);
    ASSERT_EQ(r.note, "") << "read " << reads;
    ASSERT_TRUE(r.data == payloads[0] || r.data == payloads[1] || r.data == payloads[2]) << "read " << reads;
  }
  stop = true;
  for (auto& t : writers) t.join();
  EXPECT_EQ(test::files_under(dir.path).size(), 1u);  // every temporary file renamed into place
}

}  // namespace
}  // namespace tfm
