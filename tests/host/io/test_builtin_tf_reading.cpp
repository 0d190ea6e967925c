// read_transfer_function() and built-in names: a name gives the built-in table (every command
// reads TFs through it), a file of the same name wins, written tables read back, and a string
// that is neither a file nor a built-in name fails listing the names.
#include <gtest/gtest.h>

#include <filesystem>

#include "formats_test_util.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/io/tf_json.h"

namespace tfm {
namespace {

using formats_test::expect_error;
using formats_test::TempDir;
using formats_test::write_bytes;

// Runs in `dir` (relative names resolve there) and returns to the previous directory.
struct InDirectory {
  std::filesystem::path previous = std::filesystem::current_path();
  explicit InDirectory(const std::filesystem::path& dir) { std::filesystem::current_path(dir); }
  ~InDirectory() { std::filesystem::current_path(previous); }
};

void expect_same_table(const TransferFunction& a, const TransferFunction& b, double tol) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t j = 0; j < a.size(); ++j)
    for (int c = 0; c < 4; ++c) EXPECT_NEAR(a.rgba[j][c], b.rgba[j][c], tol) << "entry " << j << " channel " << c;
}

TEST(BuiltinTfReading, NamesGiveTheBuiltInTableAndSayWhatTheyAre) {
  TempDir dir;
  InDirectory here(dir.path());
  std::vector<std::string> notes;
  const TransferFunction v = read_transfer_function("viridis", {}, &notes);
  expect_same_table(v, builtin_transfer_function({"viridis", OpacityShape::Ramp}, 64), 0.0);
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes[0].find("matplotlib"), std::string::npos) << notes[0];
  EXPECT_NE(notes[0].find("opacity ramp"), std::string::npos) << notes[0];
  // The option and the reader's table size apply.
  const TransferFunction t = read_transfer_function("cool-warm,opacity=tent", TfReadOptions{17, ""});
  expect_same_table(t, builtin_transfer_function({"cool-warm", OpacityShape::Tent}, 17), 0.0);
  EXPECT_FALSE(t.range.has_value());
  EXPECT_TRUE(builtin_tf_named_by("diverging"));
  EXPECT_FALSE(builtin_tf_named_by("tf.json"));
}

TEST(BuiltinTfReading, AFileOfTheSameNameWins) {
  TempDir dir;
  InDirectory here(dir.path());
  write_bytes(dir / "viridis", R"({"rgba": [[1,0,0,1],[0,0,1,0.5]]})");
  EXPECT_FALSE(builtin_tf_named_by("viridis"));
  const TransferFunction f = read_transfer_function("viridis");
  ASSERT_EQ(f.size(), 2u);
  EXPECT_EQ(f.rgba[0], (Rgba{1, 0, 0, 1}));
  EXPECT_EQ(read_transfer_function(dir / "viridis").size(), 2u);  // and by its full path
}

TEST(BuiltinTfReading, WrittenTablesReadBackInEveryFormat) {
  TempDir dir;
  const TransferFunction inferno = read_transfer_function("inferno,opacity=flat");
  write_transfer_function(dir / "inferno.json", inferno);
  expect_same_table(read_transfer_function(dir / "inferno.json"), inferno, 1e-15);
  // The framework's XML stores sRGB at 17 digits: back in linear RGB to rounding.
  write_transfer_function(dir / "inferno.xml", inferno);
  expect_same_table(read_transfer_function(dir / "inferno.xml", TfReadOptions{64, ""}), inferno, 1e-12);
}

TEST(BuiltinTfReading, NeitherAFileNorANameFailsListingTheNames) {
  TempDir dir;
  InDirectory here(dir.path());
  expect_error([] { read_transfer_function("magma"); },
               {"magma", "no such file", "viridis", "inferno", "cool-warm", "grey", "diverging", "opacity="});
  expect_error([] { read_transfer_function("viridis,opacity=round"); }, {"viridis,opacity=round", "ramp|flat|tent|vee"});
  // FILE:PRESET keeps working, and a missing FILE of it is still a missing file.
  expect_error([] { read_transfer_function("presets.json:Cool"); }, {"presets.json:Cool", "no such file"});
}

}  // namespace
}  // namespace tfm
