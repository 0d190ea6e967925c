// load_volume() dispatch and selection syntax, format sniffing, .dat descriptors, base64,
// `tfmatch info` on every shared data file, and the info / convert commands end to end.
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <utility>
#include <vector>

#include "cli_runner.h"
#include "formats_test_util.h"
#include "slab_test_files.h"
#include "tfmatch/io/base64.h"
#include "tfmatch/io/volume_format_table.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/volume.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using formats_test::expect_error;
using formats_test::TempDir;

TEST(FormatsIo, Base64SegmentsWhitespaceAndErrors) {
  // RFC 4648 test vectors.
  EXPECT_EQ(base64_encode(""), "");
  EXPECT_EQ(base64_encode("f"), "Zg==");
  EXPECT_EQ(base64_encode("fo"), "Zm8=");
  EXPECT_EQ(base64_encode("foobar"), "Zm9vYmFy");
  EXPECT_EQ(base64_decode("Zm9v\n YmFy"), "foobar");
  // Independently padded segments one after another (as VTK writes header and data).
  EXPECT_EQ(base64_decode("Zg==Zm8=Zm9v"), "ffofoo");
  Base64Decoder d("Zg==Zm8=");
  std::string out;
  EXPECT_EQ(d.read(2, out), 2u);
  EXPECT_EQ(out, "ff");
  EXPECT_EQ(d.read(5, out), 1u);  // only one byte left
  expect_error([] { base64_decode("Zm9"); }, {"ends in the middle of a group"});
  expect_error([] { base64_decode("Z=9v"); }, {"misplaced base64 padding"});
  expect_error([] { base64_decode("Zm=v"); }, {"misplaced base64 padding"});
  expect_error([] { base64_decode("Zm9v!A=="); }, {"invalid base64 character at character 4"});
}

TEST(FormatsIo, SelectionSyntax) {
  VolumeOptions defaults;
  defaults.variable = "V";
  defaults.time_index = 5;
  VolumeSpec s = parse_volume_spec("/nonexistent/x.nc:U,time=2,member=1", defaults);
  EXPECT_EQ(s.path, "/nonexistent/x.nc");
  EXPECT_EQ(s.options.variable, "U");
  EXPECT_EQ(s.options.time_index, 2u);
  EXPECT_EQ(s.options.member_index, 1u);
  s = parse_volume_spec("/nonexistent/g.grib2:u@isobaricInhPa", defaults);
  EXPECT_EQ(s.options.variable, "u@isobaricInhPa");
  EXPECT_EQ(s.options.time_index, 5u);  // from the defaults
  s = parse_volume_spec("/nonexistent/x.nc:,member=3", defaults);
  EXPECT_EQ(s.options.variable, "V");
  EXPECT_EQ(s.options.member_index, 3u);
  expect_error([&] { parse_volume_spec("/n/x.nc:U,time=-1", {}); }, {"x.nc", "bad selection ',time=-1'"});
  expect_error([&] { parse_volume_spec("/n/x.nc:U,level=3", {}); }, {"bad selection"});
  expect_error([&] { parse_volume_spec("/n/x.nc:U,time=1,member=0,time=2", {}); }, {"x.nc", "bad selection: time is given twice"});
  // A file whose name contains ':' is taken whole.
  TempDir dir;
  const auto odd = dir / "a:b_2x1x1_uint8.raw";
  formats_test::write_bytes(odd, "\x01\x02");
  EXPECT_EQ(load_volume(odd.string()).values, (std::vector<float>{1, 2}));
}

TEST(FormatsIo, SniffsFormatsAndRejectsMisplacedOptions) {
  TempDir dir;
  std::string vtk = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 1 1\nPOINT_DATA 2\n"
                    "SCALARS s float\nLOOKUP_TABLE default\n1 2\n";
  formats_test::write_bytes(dir / "field.bin", vtk);
  EXPECT_EQ(detect_volume_format(dir / "field.bin"), "vtk");
  EXPECT_EQ(load_volume((dir / "field.bin").string()).values, (std::vector<float>{1, 2}));
  formats_test::write_bytes(dir / "h.hdr", "NRRD0004\ntype: uchar\ndimension: 1\nsizes: 2\nencoding: ascii\n\n3 4\n");
  EXPECT_EQ(load_volume((dir / "h.hdr").string()).values, (std::vector<float>{3, 4}));
  formats_test::write_bytes(dir / "mystery.xyz", "hello");
  expect_error([&] { load_volume((dir / "mystery.xyz").string()); }, {"mystery.xyz", "unknown volume format", ".nc"});
  expect_error([&] { load_volume((dir / "field.bin").string() + ":s,time=1"); }, {"field.bin", "NetCDF and GRIB files only"});
  formats_test::write_bytes(dir / "v_2x1x1_uint8.raw", "\x01\x02");
  expect_error([&] { load_volume((dir / "v_2x1x1_uint8.raw").string() + ":x"); }, {"holds one array"});
  expect_error([&] { load_volume((dir / "none.vti").string()); }, {"none.vti", "no such file"});
}

TEST(FormatsIo, DatDescriptors) {
  TempDir dir;
  formats_test::write_bytes(dir / "d.raw", std::string("\x00\x01\x00\x02", 4));
  formats_test::write_bytes(dir / "d.dat", "ObjectFileName: d.raw\nResolution: 2 1 1\nSliceThickness: 1 2 3\nFormat: USHORT\nEndianness: big\n");
  Volume v = load_volume((dir / "d.dat").string());
  EXPECT_EQ(v.values, (std::vector<float>{1, 2}));
  EXPECT_EQ(v.spacing, (std::array<double, 3>{1, 2, 3}));
  expect_error([] { parse_dat_descriptor("Resolution: 1 1 1\nFormat: UCHAR\n", "x.dat", false); }, {"x.dat", "no ObjectFileName"});
  expect_error([] { parse_dat_descriptor("ObjectFileName: a\nResolution: 1 -1 1\n", "x.dat", false); },
               {"x.dat", "line 2", "three positive integers"});
  expect_error([] { parse_dat_descriptor("ObjectFileName: a\nResolution: 1 1 1\nFormat: HALF\n", "x.dat", false); },
               {"unknown Format 'HALF'"});
  expect_error([] { parse_dat_descriptor("ObjectFileName: a\nResolution: 1 1 1\nSliceThickness: 1 0 1\n", "x.dat", false); },
               {"SliceThickness"});
  formats_test::write_bytes(dir / "e.dat", "ObjectFileName: missing.raw\nResolution: 2 1 1\nFormat: UCHAR\n");
  expect_error([&] { load_volume((dir / "e.dat").string()); }, {"missing.raw"});
  formats_test::write_bytes(dir / "f.dat", "ObjectFileName: d.raw\nResolution: 4 1 1\nFormat: USHORT\n");
  expect_error([&] { load_volume((dir / "f.dat").string()); }, {"d.raw", "has 4 bytes", "needs 8"});
}

// Two volumes loaded as a pair are what load_volume() gives for each, bit for bit, whether both
// are read side by side (raw, .dat, uncompressed VTI) or one after the other (NetCDF, a
// compressed VTI); errors name the file that is wrong, the first one's when both are.
TEST(FormatsIo, LoadsPairsAsLoadVolumeDoes) {
  TempDir dir;
  const Volume a = slab_test::test_field({13, 7, 11}, 1), b = slab_test::test_field({13, 7, 11}, 2);
  const std::string raw_a = slab_test::write_raw(dir.path(), "a", a).string();
  const std::string raw_b = slab_test::write_raw(dir.path(), "b", b).string();
  const std::string vti_b = slab_test::write_vti_file(dir.path(), "b", b, false).string() + ":scalars";
  const std::string vti_z = slab_test::write_vti_file(dir.path(), "b", b, true).string() + ":scalars";
  const std::string nc_b = slab_test::write_netcdf(dir.path(), "b", b).string() + ":T";
  formats_test::write_bytes(dir / "b.dat", "ObjectFileName: " + std::filesystem::path(raw_b).filename().string() +
                                               "\nResolution: 13 7 11\nFormat: FLOAT\n");
  const std::string dat_b = (dir / "b.dat").string();
  auto same = [](const Volume& got, const Volume& want) {
    EXPECT_EQ(got.name, want.name);
    EXPECT_EQ(got.dims, want.dims);
    EXPECT_EQ(got.spacing, want.spacing);
    EXPECT_EQ(got.origin, want.origin);
    ASSERT_EQ(got.values.size(), want.values.size());
    EXPECT_EQ(std::memcmp(got.values.data(), want.values.data(), got.values.size() * sizeof(float)), 0) << got.name;
  };
  for (const auto& [first, second] : std::vector<std::pair<std::string, std::string>>{
           {raw_a, raw_b}, {raw_a, dat_b}, {vti_b, raw_a}, {raw_a, vti_z}, {nc_b, raw_a}, {raw_a, nc_b}, {raw_a, raw_a}}) {
    SCOPED_TRACE(first + " and " + second);
    const auto [x, y] = load_volume_pair(first, second);
    same(x, load_volume(first));
    same(y, load_volume(second));
  }
  formats_test::write_bytes(dir / "short_13x7x11_float32.raw", std::string(100, '\0'));
  const std::string shorter = (dir / "short_13x7x11_float32.raw").string();
  expect_error([&] { load_volume_pair(raw_a, shorter); }, {"short_13x7x11_float32.raw"});
  expect_error([&] { load_volume_pair(shorter, raw_a); }, {"short_13x7x11_float32.raw"});
  expect_error([&] { load_volume_pair(raw_a, (dir / "none.raw").string()); }, {"none.raw", "no such file"});
  expect_error([&] { load_volume_pair((dir / "none.vti").string(), shorter); }, {"none.vti", "no such file"});
  expect_error([&] { load_volume_pair(shorter, nc_b); }, {"short_13x7x11_float32.raw"});
}

// Read side by side, neither reader sees the other's allocation: the pair is checked against the
// budget as a whole, as reading one after the other would check the second beside the first.
TEST(FormatsIo, LoadsPairsWithinTheMemoryBudgetOfBoth) {
  TempDir dir;
  Volume v;
  v.dims = {256, 256, 32};  // 8 MiB as float32
  v.values.assign(v.voxel_count(), 1.5f);
  const std::string a = slab_test::write_raw(dir.path(), "a", v).string();
  const std::string b = slab_test::write_raw(dir.path(), "b", v).string();
  v = Volume();
  set_memory_budget(resident_memory() + (uint64_t(12) << 20), "--max-memory test");
  EXPECT_NO_THROW(load_volume(a));  // one fits
  try {
    load_volume_pair(a, b);
    ADD_FAILURE() << "two volumes of 8 MiB passed a budget of 12 MiB";
  } catch (const MemoryBudgetExceeded& e) {
    const std::string m = e.what();
    for (const char* needle : {"a_256x256x32_float32.raw", "b_256x256x32_float32.raw", "needs 16.0 MiB", "--max-memory test"})
      EXPECT_NE(m.find(needle), std::string::npos) << m;
  }
  set_memory_budget(0, "");
}

// Every file of ../shared/data is described; loadable arrays have grids, ranges are finite.
// The caller has skipped when the data are absent.
void describe_all(const std::vector<std::string>& files) {
  const std::string dir = test::shared_data_dir();
  ASSERT_FALSE(dir.empty());
  for (const auto& f : files) {
    FileInfo info = describe_file(dir + "/" + f);
    EXPECT_FALSE(info.format.empty()) << f;
    EXPECT_FALSE(format_file_info(info).empty()) << f;
    if (info.arrays.empty()) {
      EXPECT_FALSE(info.notes.empty()) << f;  // a headerless raw file: size and hints
      continue;
    }
    bool loadable = false;
    for (const auto& a : info.arrays) {
      loadable |= a.grid[0] > 0;
      if (a.values > a.nan_count) {
        EXPECT_TRUE(a.min && a.max && *a.min <= *a.max) << f << " " << a.name;
      }
    }
    EXPECT_TRUE(loadable) << f;
  }
}

TEST(FormatsIoRealFiles, InfoDescribesNetcdfAndGribFiles) {
  if (test::shared_data_dir().empty()) GTEST_SKIP() << "../shared/data not present";
  describe_all({"wrf_katrina/ci_test_file.nc", "cam_uvt/uvt.nc", "eraint_uvz/eraint_uvz.nc",
                "gfs_grib2/gfs.t12z.pgrbf120.2p5deg.grib2", "era5_ensemble_grib1/era5-levels-members.grib",
                "ecmwf_multiparam_grib1/multi_param_on_multi_dims.grib"});
}

TEST(FormatsIoRealFiles, InfoDescribesVtkVtiNrrdAndRawFiles) {
  if (test::shared_data_dir().empty()) GTEST_SKIP() << "../shared/data not present";
  describe_all({"vtk_ironprot/ironProt.vtk", "vtk_carotid/carotid.vtk", "vti_hydrogen/hydrogen.vti",
                "isabel_vti/isabel_02.vti", "isabel_vti/isabel_30.vti", "isabel_vti/isabel_31.vti",
                "raw_fuel/fuel.raw", "raw_combustion/turbulent_combustion.raw", "nrrd_headsq/quarter.nhdr"});
  const std::string dir = test::shared_data_dir();
  // An empty headerless file is said to be empty, not to fit cubes of side 0.
  {
    formats_test::TempDir tmp;
    formats_test::write_bytes(tmp / "empty.raw", "");
    const std::string text = format_file_info(describe_file(tmp / "empty.raw"));
    EXPECT_NE(text.find("0 bytes (an empty file)"), std::string::npos) << text;
    EXPECT_EQ(text.find("cubes that fit"), std::string::npos) << text;
  }
  // A headerless raw file: its size, the cubes that fit; with --dims and --type its range.
  FileInfo fuel = describe_file(dir + "/raw_fuel/fuel.raw");
  EXPECT_NE(format_file_info(fuel).find("64^3 uint8"), std::string::npos);
  VolumeOptions o;
  o.dims = std::array<uint64_t, 3>{128, 256, 32};
  o.type = ScalarType::UInt8;
  FileInfo comb = describe_file(dir + "/raw_combustion/turbulent_combustion.raw", o);
  ASSERT_EQ(comb.arrays.size(), 1u);
  EXPECT_EQ(*comb.arrays[0].max, 254.0);  // SOURCES.md: 0..254
}

TEST(FormatsIoCli, InfoAndConvertCommands) {
  TempDir dir;
  std::string vtk = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 5 1 1\nPOINT_DATA 5\n"
                    "SCALARS density float\nLOOKUP_TABLE default\n1 nan 2 inf -inf\n";
  formats_test::write_bytes(dir / "f.vtk", vtk);
  const std::string f = (dir / "f.vtk").string();
  test::CliResult r = test::run_cli("info " + f);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("density"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("range [1, 2]"), std::string::npos) << r.output;
  // ±Inf is no data, as NaN (DESIGN.md): outside the range and counted with the NaN.
  EXPECT_NE(r.output.find("no data (NaN/Inf/fill/missing) 3 of 5"), std::string::npos) << r.output;
  r = test::run_cli("info " + f + " --json -");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(nlohmann::json::parse(r.output)["arrays"][0]["nan_count"], 3);
  // Errors: non-zero exit and the file named.
  r = test::run_cli("info " + (dir / "nothing.nc").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("nothing.nc: no such file"), std::string::npos) << r.output;
  // convert-volume writes a .vti that loads back; convert-tf between formats.
  r = test::run_cli("convert-volume " + f + " " + (dir / "f.vti").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(load_volume((dir / "f.vti").string() + ":density").values[2], 2.0f);
  EXPECT_NE(r.output.find("(1 array(s) of Float32: density)"), std::string::npos) << r.output;  // what it wrote, named
  formats_test::write_bytes(dir / "tf.json", "{\"rgba\": [[0,0,0,0],[1,0.5,0.25,1]]}");
  r = test::run_cli("convert-tf " + (dir / "tf.json").string() + " " + (dir / "tf.xml").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(formats_test::read_bytes(dir / "tf.xml").find("<TransferFunction"), std::string::npos);
}

}  // namespace
}  // namespace tfm
