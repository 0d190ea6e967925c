// `tfmatch correlate`, markers and `demo --ensemble` as a user runs them: outputs equal the CPU
// references, grids keep their place, bad ensembles fail clearly and leave nothing behind, and
// the ERA5 recipe of the README works on the shared data.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <netcdf.h>

#include "cli_runner.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/io/volume_vti.h"
#include "tfmatch/model/ensemble.h"
#include "tfmatch/model/synthetic_ensemble.h"
#include "tfmatch/reference/correlation_cpu.h"
#include "tfmatch/report/png_io.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using test::run_cli;
using test::TempDir;

class CorrelateCli : public ::testing::Test {
 protected:
  void SetUp() override {
    ens = synthetic_ensemble(11, 8, 5, 12, 7);
    ens.grid.origin = {100, 80, 1};
    ens.grid.spacing = {2, 2, 3};
    for (uint32_t m = 0; m < ens.member_count; ++m) {
      Volume v = ens.member(m);
      v.origin = ens.grid.origin;
      v.spacing = ens.grid.spacing;
      write_vti(dir / ("member_" + std::to_string(100 + m) + ".vti"), v, "t");
    }
    members = "'" + dir / "member_*.vti" + "'";
  }
  // The CPU reference field of `params` for the voxel (x, y, z) of `ens`.
  std::vector<double> reference(const GridIndex& p, const CorrelationParams& params) const {
    const uint64_t v = (p[2] * ens.grid.dims[1] + p[1]) * ens.grid.dims[0] + p[0];
    return correlation_field_reference(ens.view(), ensemble_series(ens.view(), v), params);
  }
  TempDir dir;
  Ensemble ens;
  std::string members;
};

TEST_F(CorrelateCli, FieldsEqualTheCpuReferenceAndKeepTheGrid) {
  for (const std::string measure : {"pearson", "kendall", "mi-kraskov"}) {
    const std::string out = dir / (measure + ".vti");
    auto r = run_cli("correlate --members " + members + " --point 3,4,2 --measure " + measure + " --out " + out +
                     " --json " + dir / "c.json");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find("12 members on 11x8x5"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("(3, 4, 2)"), std::string::npos) << r.output;
    const Volume c = load_volume(out);
    EXPECT_EQ(c.dims, ens.grid.dims);
    EXPECT_EQ(c.origin, ens.grid.origin);
    EXPECT_EQ(c.spacing, ens.grid.spacing);
    CorrelationParams params;
    params.measure = parse_correlation_measure(measure);
    const std::vector<double> want = reference({3, 4, 2}, params);
    for (size_t i = 0; i < want.size(); ++i) ASSERT_NEAR(c.values[i], want[i], 2e-5) << measure << " voxel " << i;
    const auto j = nlohmann::json::parse(std::ifstream(dir / "c.json"));
    EXPECT_EQ(j["members"], 12);
    EXPECT_EQ(j["measure"], measure);
    EXPECT_EQ(j["point"], (std::vector<int>{3, 4, 2}));
  }
  // The reference voxel correlates perfectly with itself.
  const Volume p = load_volume(dir / "pearson.vti");
  EXPECT_NEAR(p.values[(2 * 8 + 4) * 11 + 3], 1.0, 1e-6);
}

TEST_F(CorrelateCli, DifferenceOfTwoPointsAndMagnitudeAsRaw) {
  auto r = run_cli("correlate --members " + members + " --point 3,4,2 --point2 x=118,y=90,z=7 --abs --measure spearman --out " +
                   dir / "d.raw");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // x=118 is index 9, y=90 index 5, z=7 index 2 (origin 100, 80, 1; spacing 2, 2, 3).
  EXPECT_NE(r.output.find("minus point     (9, 5, 2)"), std::string::npos) << r.output;
  VolumeOptions o;
  o.dims = ens.grid.dims;
  o.type = ScalarType::Float32;
  const Volume d = load_volume(dir / "d.raw", o);
  CorrelationParams params;
  params.measure = CorrelationMeasure::Spearman;
  const auto a = reference({3, 4, 2}, params), b = reference({9, 5, 2}, params);
  for (size_t i = 0; i < a.size(); ++i) ASSERT_NEAR(d.values[i], std::abs(a[i] - b[i]), 4e-5) << i;
}

TEST_F(CorrelateCli, BadEnsemblesFailClearlyAndWriteNothing) {
  const std::string out = dir / "bad.vti";
  auto fails = [&](const std::string& args, std::initializer_list<std::string> parts) {
    auto r = run_cli("correlate " + args + " --out " + out);
    EXPECT_NE(r.exit_code, 0) << args << "\n" << r.output;
    for (const auto& p : parts) EXPECT_NE(r.output.find(p), std::string::npos) << args << "\n" << r.output << "\nmissing: " << p;
    EXPECT_FALSE(std::filesystem::exists(out)) << args;
  };
  fails("--members " + dir / "member_100.vti" + " " + dir / "member_101.vti" + " --point 0,0,0", {"2 member(s)", "at least 3"});
  Volume odd = ens.member(0);
  odd.dims = {11, 8, 4};
  odd.values.resize(11 * 8 * 4);
  write_vti(dir / "odd.vti", odd, "t");
  fails("--members " + members + " " + dir / "odd.vti" + " --point 0,0,0", {"different grids", "odd.vti", "11x8x4"});
  // A reference point without data in one member.
  Volume holed = ens.member(5);
  holed.values[0] = NAN;
  write_vti(dir / "member_105.vti", holed, "t");
  fails("--members " + members + " --point 0,0,0", {"no data in member 5"});
  // An infinite one: refused by the measures it leaves without a value, named as what it is; the
  // rank measures order it and write a field.
  holed.values[0] = -INFINITY;
  write_vti(dir / "member_105.vti", holed, "t");
  fails("--members " + members + " --point 0,0,0", {"member 5 is -inf", "pearson", "spearman"});
  // It suggests only measures that take the point: not the Kraskov ones, which refuse it too.
  const auto suggested = run_cli("correlate --members " + members + " --point 0,0,0 --out " + out);
  EXPECT_EQ(suggested.output.find("mi-kraskov"), std::string::npos) << suggested.output;
  fails("--members " + members + " --point 0,0,0 --measure mi-kraskov", {"member 5 is -inf", "mi-kraskov"});
  fails("--members " + members + " --point 0,0,0 --measure mi-binned", {"member 5 is -inf", "mi-binned"});
  const auto ranked = run_cli("correlate --members " + members + " --point 0,0,0 --measure kendall --out " + out);
  EXPECT_EQ(ranked.exit_code, 0) << ranked.output;
  EXPECT_TRUE(std::filesystem::exists(out));
  std::filesystem::remove(out);
  fails("--members " + members + " --point 11,0,0", {"--point", "outside the grid 11x8x5"});
  fails("--members " + members + " --point 1,1,1 --measure mi-kraskov --k 12", {"k"});
  fails("--members " + members + " --point 1,1,1 --measure cosine", {"--measure", "pearson"});
  fails("--members '" + dir / "none_*.vti" + "' --point 1,1,1", {"matches no file"});
  fails("--ensemble " + dir / "member_100.vti" + " --point 1,1,1", {"no member axis"});
  fails("--point 1,1,1", {"--ensemble", "--members"});
}

// Read slab by slab (--stream on), the field is the one of the members loaded whole, bit for bit.
TEST_F(CorrelateCli, SlabBySlabGivesTheLoadedField) {
  for (const char* measure : {"pearson", "kendall", "mi-kraskov"}) {
    SCOPED_TRACE(measure);
    const std::string args = "correlate --members " + members + " --point 3,4,2 --point2 7,1,4 --measure " + measure;
    const auto on = run_cli(args + " --stream on --out " + dir / "on.raw" + " --json " + dir / "on.json");
    ASSERT_EQ(on.exit_code, 0) << on.output;
    const auto off = run_cli(args + " --stream off --out " + dir / "off.raw");
    ASSERT_EQ(off.exit_code, 0) << off.output;
    std::ifstream a(dir / "on.raw", std::ios::binary), b(dir / "off.raw", std::ios::binary);
    const std::string bytes_on((std::istreambuf_iterator<char>(a)), {}), bytes_off((std::istreambuf_iterator<char>(b)), {});
    EXPECT_EQ(bytes_on, bytes_off);
    nlohmann::json j;
    std::ifstream(dir / "on.json") >> j;
    EXPECT_TRUE(j.contains("stream")) << j.dump();
  }
}

// --out x.pvti writes its pieces into the folder x beside it: a file named x is refused before any
// work, naming the option; pieces an earlier run with more ranks left there (x_3.vti) go, while
// files that are not this run's pieces stay.
TEST_F(CorrelateCli, ParallelImageDataChecksAndTidiesItsPiecesFolder) {
  const std::string args = "correlate --members " + members + " --point 3,4,2 --quiet --out " + dir / "x.pvti";
  { std::ofstream(dir / "x") << "a file"; }
  const auto clash = run_cli(args + " --json " + dir / "clash.json");
  EXPECT_EQ(clash.exit_code, 1) << clash.output;
  EXPECT_NE(clash.output.find("--out (its pieces' folder) " + dir / "x" + ": exists and is not a directory"),
            std::string::npos)
      << clash.output;
  EXPECT_EQ(clash.output.find("ensemble"), std::string::npos) << clash.output;  // nothing was read
  EXPECT_FALSE(std::filesystem::exists(dir / "clash.json"));
  std::filesystem::remove(dir / "x");
  std::filesystem::create_directories(dir / "x");
  for (const char* name : {"x_3.vti", "x_1.vti", "x_01.vti", "x_b.vti", "notes.txt"})
    std::ofstream(std::filesystem::path(dir / "x") / name) << "old";
  const auto r = run_cli(args);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::vector<std::string> left;
  for (const auto& e : std::filesystem::directory_iterator(dir / "x")) left.push_back(e.path().filename().string());
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left, (std::vector<std::string>{"notes.txt", "x_0.vti", "x_01.vti", "x_b.vti"}));
}

// A NetCDF variable with a member dimension, read slab by slab (each member through its own
// reader): the field of the members loaded whole, bit for bit.
TEST(CorrelateStreamed, NetcdfMemberDimensionGivesTheLoadedField) {
  TempDir dir;
  const std::string file = dir / "ens.nc";
  const size_t members = 6, lev = 9, lat = 7, lon = 11;
  int nc = -1, dm, dz, dy, dx, var;
  ASSERT_EQ(nc_create(file.c_str(), NC_CLOBBER, &nc), NC_NOERR);
  ASSERT_EQ(nc_def_dim(nc, "member", members, &dm), NC_NOERR);
  ASSERT_EQ(nc_def_dim(nc, "lev", lev, &dz), NC_NOERR);
  ASSERT_EQ(nc_def_dim(nc, "lat", lat, &dy), NC_NOERR);
  ASSERT_EQ(nc_def_dim(nc, "lon", lon, &dx), NC_NOERR);
  const int dims[4] = {dm, dz, dy, dx};
  ASSERT_EQ(nc_def_var(nc, "T", NC_FLOAT, 4, dims, &var), NC_NOERR);
  ASSERT_EQ(nc_enddef(nc), NC_NOERR);
  std::vector<float> values(members * lev * lat * lon);
  for (size_t i = 0; i < values.size(); ++i)
    values[i] = float(std::sin(0.37 * double(i % 693)) * std::cos(0.9 * double(i / 693)) + 0.01 * double(i % 17));
  ASSERT_EQ(nc_put_var_float(nc, var, values.data()), NC_NOERR);
  ASSERT_EQ(nc_close(nc), NC_NOERR);
  const std::string args = "correlate --ensemble " + file + ":T --point 4,3,2 --measure mi-kraskov --out ";
  const auto on = run_cli(args + dir / "on.raw --stream on --slab-slices 2");
  ASSERT_EQ(on.exit_code, 0) << on.output;
  const auto off = run_cli(args + dir / "off.raw --stream off");
  ASSERT_EQ(off.exit_code, 0) << off.output;
  std::ifstream a(dir / "on.raw", std::ios::binary), b(dir / "off.raw", std::ios::binary);
  const std::string bytes_on((std::istreambuf_iterator<char>(a)), {}), bytes_off((std::istreambuf_iterator<char>(b)), {});
  EXPECT_EQ(bytes_on.size(), lev * lat * lon * sizeof(float));
  EXPECT_EQ(bytes_on, bytes_off);
}

// `count` raw float32 members of `dims` in `dir` (member100_XxYxZ_float32.raw, ...), member m's
// value i being value(m, i); returns their paths, each after a space, for --members.
template <class Value>
std::string write_raw_members(const TempDir& dir, int count, const std::array<uint64_t, 3>& dims, Value value) {
  const std::string grid = std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]);
  std::vector<float> values(dims[0] * dims[1] * dims[2]);
  std::string members;
  for (int m = 0; m < count; ++m) {
    for (size_t i = 0; i < values.size(); ++i) values[i] = value(m, i);
    const std::string path = dir / ("member" + std::to_string(100 + m) + "_" + grid + "_float32.raw");
    std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(values.data()),
                                                std::streamsize(values.size() * sizeof(float)));
    members += " " + path;
  }
  return members;
}

// Whether two files hold the same bytes, and `size` of them.
void expect_same_file(const std::string& a_path, const std::string& b_path, uint64_t size) {
  std::ifstream a(a_path, std::ios::binary), b(b_path, std::ios::binary);
  const std::string bytes_a((std::istreambuf_iterator<char>(a)), {}), bytes_b((std::istreambuf_iterator<char>(b)), {});
  EXPECT_EQ(bytes_a.size(), size);
  EXPECT_EQ(bytes_a, bytes_b);
}

// An ensemble larger than --max-memory (48 members of 128x128x80: 252 MB) is correlated within it,
// slab by slab (auto), where loading it whole is refused; the field is the loaded one.
TEST(CorrelateStreamed, AnEnsembleLargerThanTheBudgetStaysWithinIt) {
  TempDir dir;
  const std::string members = write_raw_members(dir, 48, {128, 128, 80}, [](int m, size_t i) {
    return float(std::sin(0.001 * double(i) * (1 + m % 5)) + 0.1 * std::cos(0.37 * m + double(i % 101)));
  });
  const std::string args = "correlate --members" + members + " --point 5,6,7 --out ";
  // Shader caches empty, as on a machine's first run: the driver compiles the kernel in this
  // process (lavapipe's compiler took 14 MB more than the slabs were planned with).
  const test::CliEnvironment cold{{"MESA_SHADER_CACHE_DIR", dir / "mesa-cache"},
                                  {"__GL_SHADER_DISK_CACHE_PATH", dir / "nvidia-cache"},
                                  {"TFMATCH_PIPELINE_CACHE", "off"}};
  const auto budget = run_cli("--max-memory 240M " + args + dir / "streamed.raw", test::kCliTimeout, cold);
  ASSERT_EQ(budget.exit_code, 0) << budget.output;
  EXPECT_NE(budget.output.find("slab by slab"), std::string::npos) << budget.output;
  EXPECT_LT(budget.peak_rss_bytes, uint64_t(240) << 20) << "peak RSS " << budget.peak_rss_bytes;
  const auto refused = run_cli("--max-memory 240M " + args + dir / "x.raw --stream off");
  EXPECT_EQ(refused.exit_code, 1) << refused.output;
  EXPECT_NE(refused.output.find("memory budget"), std::string::npos) << refused.output;
  const auto whole = run_cli(args + dir / "whole.raw --stream off");
  ASSERT_EQ(whole.exit_code, 0) << whole.output;
  expect_same_file(dir / "streamed.raw", dir / "whole.raw", 128 * 128 * 80 * sizeof(float));
}

// A loaded ensemble beyond one texel view (24 members of 128x128x96: 151 MB) goes to the device in
// chunks; where device memory is the host's those take what the budget leaves, not a fixed 256 MiB
// (which took this run to 365 MiB under --max-memory 300M). The field is the one without a budget.
TEST(CorrelateWhole, ChunksStayWithinTheBudget) {
  TempDir dir;
  const std::string members = write_raw_members(dir, 24, {128, 128, 96}, [](int m, size_t i) {
    return float(std::cos(0.002 * double(i) * (1 + m % 7)) + 0.2 * std::sin(0.11 * m + double(i % 97)));
  });
  const std::string args = "correlate --stream off --members" + members + " --point 5,6,7 --out ";
  const test::CliEnvironment cold{{"MESA_SHADER_CACHE_DIR", dir / "mesa-cache"},
                                  {"__GL_SHADER_DISK_CACHE_PATH", dir / "nvidia-cache"},
                                  {"TFMATCH_PIPELINE_CACHE", "off"}};
  const auto budget = run_cli("--max-memory 300M " + args + dir / "budget.raw", test::kCliTimeout, cold);
  ASSERT_EQ(budget.exit_code, 0) << budget.output;
  EXPECT_LT(budget.peak_rss_bytes, uint64_t(300) << 20) << "peak RSS " << budget.peak_rss_bytes;
  const auto free = run_cli(args + dir / "free.raw");
  ASSERT_EQ(free.exit_code, 0) << free.output;
  expect_same_file(dir / "budget.raw", dir / "free.raw", 128 * 128 * 96 * sizeof(float));
}

TEST_F(CorrelateCli, MarkersAreRedDotsOnRenderings) {
  std::ofstream(dir / "tf.json") << R"({"rgba": [[0,0,1,0.0],[0,1,0,0.0]]})";
  auto r = run_cli("render --volume " + dir / "member_100.vti" + " --tf " + dir / "tf.json" + " --out " + dir / "m.png" +
                   " --width 64 --height 64 --elevation 90 --azimuth 0 --marker 5,4,2");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Image img = read_png(dir / "m.png");
  // Seen from above the box centre, the centre voxel projects near the image centre: red there.
  size_t red = 0;
  for (uint32_t y = 24; y < 40; ++y)
    for (uint32_t x = 24; x < 40; ++x) red += img.at(x, y)[0] > 200 && img.at(x, y)[1] < 80;
  EXPECT_GT(red, 4u);
  r = run_cli("render --volume " + dir / "member_100.vti" + " --tf " + dir / "tf.json" + " --out " + dir / "m2.png" +
              " --marker 5,4");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--marker"), std::string::npos) << r.output;
  r = run_cli("optimize --ref " + dir / "member_100.vti" + " --ref-tf " + dir / "tf.json" + " --field " +
              dir / "member_101.vti" + " --out " + dir / "o.json --marker 1,1,1");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--report"), std::string::npos) << r.output;
}

TEST(EnsembleDemo, WritesCorrelationFieldsAndAReportWithTheMarker) {
  TempDir dir;
  auto r = run_cli("demo --ensemble --size 20 --members 16 --width 96 --height 96 --out " + dir / "demo");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* f : {"mi-coefficient.vti", "pearson.vti", "index.html", "reference.png", "residual_optimized_tf.png"})
    EXPECT_TRUE(std::filesystem::exists(dir / ("demo/" + std::string(f)))) << f;
  const auto j = nlohmann::json::parse(std::ifstream(dir / "demo/metrics.json"));
  ASSERT_EQ(j["markers"].size(), 1u);
  std::ifstream html(dir / "demo/index.html");
  const std::string page((std::istreambuf_iterator<char>(html)), std::istreambuf_iterator<char>());
  EXPECT_NE(page.find("Red dot: reference point ("), std::string::npos);  // one marker: one dot
}

// The README's ERA5 recipe (temperature, 10 members): MI and Pearson fields of one point, the
// Pearson TF optimized against MI, a report with the marker.
TEST(EnsembleRecipe, Era5MutualInformationVersusPearson) {
  const std::string d = test::shared_data_dir();
  if (d.empty()) GTEST_SKIP() << "../shared/data not present";
  TempDir dir;
  const std::string ens = d + "/era5_ensemble_grib1/era5-levels-members.grib:t";
  auto r = run_cli("correlate --ensemble " + ens + " --point lon=9,lat=45,level=850 --measure mi-kraskov --k 3 --out " +
                   dir / "mi.vti");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("10 members on 120x61x2"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("(3, 45, 0) at longitude=9, latitude=45, isobaricInhPa=850"), std::string::npos) << r.output;
  r = run_cli("correlate --ensemble " + ens + " --point lon=9,lat=45,level=850 --measure pearson --out " + dir / "p.vti");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ofstream(dir / "tf.json") << R"({"rgba": [[0.2,0,0.4,0],[0.9,0.3,0.3,0.3],[1,0.9,0.5,0.9]]})";
  r = run_cli("optimize --ref " + dir / "mi.vti" + " --ref-tf " + dir / "tf.json" + " --field " + dir / "p.vti" +
              " --out " + dir / "p_tf.json --report " + dir / "report --marker 3,45,0 --width 96 --height 96");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(dir / "report/index.html"));
}

}  // namespace
}  // namespace tfm
