// Built-in transfer functions from the command line, with no TF file anywhere: convert-tf writes
// one out for editing, optimize and render take a name where they take a TF file, a report
// records the name, and a name that is neither a file nor a built-in fails listing the names.
#include <fstream>

#include <gtest/gtest.h>

#include "cli_runner.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/io/tf_json.h"
#include "tfmatch/model/builtin_tf.h"
#include "tfmatch/report/png_io.h"

namespace tfm {
namespace {

using test::run_cli;
using test::TempDir;
using test::write_floats;

class BuiltinTfCli : public ::testing::Test {
 protected:
  void SetUp() override {
    std::vector<float> a(8 * 8 * 8), b(a.size());
    for (size_t i = 0; i < a.size(); ++i) {
      a[i] = float(i % 29) / 28.0f;
      b[i] = 5.0f + 3.0f * a[i] * a[i];
    }
    write_floats(ref, a);
    write_floats(field, b);
  }
  TempDir dir;
  const std::string ref = dir / "ref_8x8x8_float32.raw", field = dir / "field_8x8x8_float32.raw";
};

// A note (here: an XML TF's colours outside [0,1], clamped as the framework does) goes to stderr,
// and -q, "only errors and warnings", keeps it back wherever a TF is read.
TEST_F(BuiltinTfCli, NotesAreQuietUnderQ) {
  std::ofstream(dir / "loud.xml")
      << "<TransferFunction colorspace=\"sRGB\">\n<OpacityPoints>\n<OpacityPoint position=\"0\" opacity=\"0\"/>\n"
         "<OpacityPoint position=\"1\" opacity=\"1\"/>\n</OpacityPoints>\n<ColorPoints>\n"
         "<ColorPoint position=\"0.5\" r=\"300\" g=\"0\" b=\"0\"/>\n</ColorPoints>\n</TransferFunction>\n";
  const std::string note = "tfmatch: note: " + dir / "loud.xml" + ": 1 opacity or colour value outside [0,1] clamped";
  for (const std::string& command :
       {"convert-tf " + dir / "loud.xml" + " " + dir / "loud.json",
        "optimize --ref " + ref + " --ref-tf " + dir / "loud.xml" + " --field " + field + " --out " + dir / "t.json"}) {
    const auto loud = test::run_cli_split(command);
    ASSERT_EQ(loud.exit_code, 0) << loud.errors;
    EXPECT_NE(loud.errors.find(note), std::string::npos) << loud.errors;
    const auto quiet = test::run_cli_split("-q " + command);
    ASSERT_EQ(quiet.exit_code, 0) << quiet.errors;
    EXPECT_EQ(quiet.errors.find("note:"), std::string::npos) << quiet.errors;
  }
}

TEST_F(BuiltinTfCli, ConvertTfWritesABuiltInMapForEditing) {
  auto r = run_cli("convert-tf viridis " + dir / "viridis.json");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const TransferFunction written = read_tf_json(dir / "viridis.json");
  const TransferFunction expected = builtin_transfer_function({"viridis", OpacityShape::Ramp}, 64);
  ASSERT_EQ(written.size(), 64u);
  for (size_t j = 0; j < 64; ++j) EXPECT_EQ(written.rgba[j], expected.rgba[j]) << "entry " << j;
  // Any format, any size, any opacity; the ParaView preset reads back through the same loader.
  r = run_cli("convert-tf diverging,opacity=flat " + dir / "d.paraview.json" + " --size 16");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const TransferFunction preset = read_transfer_function(dir / "d.paraview.json", TfReadOptions{16, ""});
  ASSERT_EQ(preset.size(), 16u);
  const TransferFunction flat = builtin_transfer_function({"diverging", OpacityShape::Flat}, 16);
  for (size_t j = 0; j < 16; ++j) {
    EXPECT_DOUBLE_EQ(preset.rgba[j][3], 0.5);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(preset.rgba[j][c], flat.rgba[j][c], 1e-9) << j;
  }
}

TEST_F(BuiltinTfCli, OptimizeAndRenderTakeANameWhereTheyTakeATfFile) {
  auto r = run_cli("optimize --ref " + ref + " --field " + field + " --ref-tf inferno --out " + dir / "opt.json" +
                   " --report " + dir / "report" + " --width 32 --height 32");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("built-in matplotlib's inferno"), std::string::npos) << r.output;
  EXPECT_EQ(read_tf_json(dir / "opt.json").size(), 64u);
  // The report records the name, not a path under the working directory, so that
  // `view --report` finds the same map.
  std::ifstream inputs(dir / "report/inputs.json");
  ASSERT_TRUE(inputs) << r.output;
  EXPECT_EQ(nlohmann::json::parse(inputs)["ref_tf"], "inferno");

  r = run_cli("render --volume " + ref + " --tf cool-warm,opacity=tent --out " + dir / "r.png" +
              " --width 24 --height 20");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Image img = read_png(dir / "r.png");
  EXPECT_EQ(img.width, 24u);
  EXPECT_EQ(img.height, 20u);
  // residual takes names for both TFs.
  r = run_cli("residual --ref " + ref + " --ref-tf grey --field " + field + " --field-tf " + dir / "opt.json" +
              " --out " + dir / "res.raw");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

// A diverging map laid over a signed field's own range says where its middle falls, and how to
// centre it; a range given, a centred one or another map say nothing.
TEST_F(BuiltinTfCli, DivergingMapsSayWhereTheirMiddleFalls) {
  std::vector<float> signed_values(8 * 8 * 8);
  for (size_t i = 0; i < signed_values.size(); ++i) signed_values[i] = -1.0f + 4.0f * float(i % 29) / 28.0f;  // -1..3
  write_floats(dir / "u_8x8x8_float32.raw", signed_values);
  const std::string u = dir / "u_8x8x8_float32.raw", note = "its neutral middle lies at 1, not at 0";
  const std::string render = "render --volume " + u + " --out " + dir / "u.png" + " --width 16 --height 16 --tf ";
  auto r = test::run_cli_split(render + "cool-warm");
  ASSERT_EQ(r.exit_code, 0) << r.errors;
  EXPECT_NE(r.errors.find(note), std::string::npos) << r.errors;
  EXPECT_NE(r.errors.find("--range -3,3 centres it on 0"), std::string::npos) << r.errors;
  for (const std::string& quiet : {render + "cool-warm --range -3,3", render + "viridis", "-q " + render + "diverging"}) {
    r = test::run_cli_split(quiet);
    ASSERT_EQ(r.exit_code, 0) << quiet << "\n" << r.errors;
    EXPECT_EQ(r.errors.find("neutral middle"), std::string::npos) << quiet << "\n" << r.errors;
  }
  r = test::run_cli_split("optimize --ref " + u + " --ref-tf diverging --field " + field + " --out " + dir / "d.json");
  ASSERT_EQ(r.exit_code, 0) << r.errors;
  EXPECT_NE(r.errors.find(note), std::string::npos) << r.errors;
  EXPECT_NE(r.errors.find("--ref-range -3,3"), std::string::npos) << r.errors;
}

TEST_F(BuiltinTfCli, UnknownNamesFailListingTheBuiltInMaps) {
  // Neither a file nor a built-in: exit 1, as for a missing TF file, naming what was typed and
  // every name there is.
  auto r = run_cli("optimize --ref " + ref + " --field " + field + " --ref-tf magma --out " + dir / "o.json");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  for (const char* part : {"magma: no such file", "viridis", "inferno", "cool-warm", "grey", "diverging", "opacity="})
    EXPECT_NE(r.output.find(part), std::string::npos) << part << " in:\n" << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "o.json"));
  r = run_cli("render --volume " + ref + " --tf viridis,opacity=round --out " + dir / "r.png");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("ramp|flat|tent|vee"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "r.png"));
  // --help says how to name one.
  r = run_cli("render --help");
  EXPECT_NE(r.output.find("cool-warm"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace tfm
