// GRIB reader: files built here from ecCodes' own samples check stacking by level, parameter and
// level-type selection, time/member choice, bitmaps and grid checks; the real files in
// ../shared/data are checked against grib_get_data output.
#include <gtest/gtest.h>
#include <eccodes.h>

#include <cmath>

#include "formats_test_util.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/volume.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using formats_test::expect_error;
using formats_test::TempDir;

constexpr int kNi = 16, kNj = 31;  // the regular_ll_pl_grib2 sample's grid

// Integer values, exact under simple packing: (i + 16 j) % 97 + level/50 + 10 member + 300 time.
double expected(int i, int j, long level, long member, int time) {
  return (i + kNi * j) % 97 + level / 50 + 10 * member + 300 * time;
}

struct MessageSpec {
  const char* short_name = "t";
  long level = 500;
  long member = 0;
  int time = 0;             // 0: 2020-01-01, 1: 2020-01-02
  bool missing_corner = false;
  double lat_shift = 0.0;   // moves the grid
  bool surface = false;
};

std::string encode(const MessageSpec& m) {
  codes_handle* h = codes_grib_handle_new_from_samples(nullptr, m.surface ? "GRIB2" : "regular_ll_pl_grib2");
  EXPECT_NE(h, nullptr);
  EXPECT_EQ(codes_set_long(h, "productDefinitionTemplateNumber", 1), 0);  // ensemble: has "number"
  size_t len = std::strlen(m.short_name);
  EXPECT_EQ(codes_set_string(h, "shortName", m.short_name, &len), 0);
  EXPECT_EQ(codes_set_long(h, "number", m.member), 0);
  EXPECT_EQ(codes_set_long(h, "dataDate", 20200101 + m.time), 0);
  if (!m.surface) {
    EXPECT_EQ(codes_set_long(h, "level", m.level), 0);
  }
  if (m.lat_shift != 0.0) {
    double lat = 0;
    codes_get_double(h, "latitudeOfFirstGridPointInDegrees", &lat);
    EXPECT_EQ(codes_set_double(h, "latitudeOfFirstGridPointInDegrees", lat + m.lat_shift), 0);
  }
  std::vector<double> v(kNi * kNj);
  for (int j = 0; j < kNj; ++j)
    for (int i = 0; i < kNi; ++i) v[j * kNi + i] = expected(i, j, m.level, m.member, m.time);
  if (m.missing_corner) {
    EXPECT_EQ(codes_set_long(h, "bitmapPresent", 1), 0);
    EXPECT_EQ(codes_set_double(h, "missingValue", 9999), 0);
    v[0] = 9999;
  }
  EXPECT_EQ(codes_set_double_array(h, "values", v.data(), v.size()), 0);
  const void* buf = nullptr;
  size_t size = 0;
  EXPECT_EQ(codes_get_message(h, &buf, &size), 0);
  std::string out(static_cast<const char*>(buf), size);
  codes_handle_delete(h);
  return out;
}

std::filesystem::path write_grib(const TempDir& dir, const std::string& name, const std::vector<MessageSpec>& ms) {
  std::string bytes;
  for (const auto& m : ms) bytes += encode(m);
  formats_test::write_bytes(dir / name, bytes);
  return dir / name;
}

TEST(GribGenerated, StacksLevelsSortedAndSelectsTimeMember) {
  TempDir dir;
  std::vector<MessageSpec> ms;
  for (int time : {1, 0})
    for (long member : {2, 0, 1})
      for (long level : {850, 300, 500}) ms.push_back({"t", level, member, time, level == 300 && member == 1});
  ms.push_back({"u", 500});
  ms.push_back({.short_name = "t", .surface = true});
  const std::string f = write_grib(dir, "gen.grib2", ms).string();

  // t: isobaricInhPa (3 levels) wins over surface (1). World orientation: the surface down (850,
  // 500, 300 hPa up z) and north up (the sample's rows run 60 N -> 0 N: row j is y = kNj - 1 - j).
  Volume t = load_volume(f + ":t,time=1,member=1");
  EXPECT_EQ(t.dims, (std::array<uint64_t, 3>{kNi, kNj, 3}));
  EXPECT_NE(t.name.find("t@isobaricInhPa"), std::string::npos);
  EXPECT_EQ(t.axes[2].coordinates, (std::vector<double>{850, 500, 300}));
  EXPECT_EQ(t.axes[1].coordinates.front(), 0.0);
  EXPECT_EQ(t.axes[1].coordinates.back(), 60.0);
  EXPECT_EQ(t.origin[1], 0.0);
  // Levels 850, 500, 300 hPa are no even axis in spacing 1: index units, origin 0 (a .vti with
  // origin 850 and spacing 1 put 500 hPa at z = 851); the levels are the axis's coordinates.
  EXPECT_EQ(t.origin[2], 0.0);
  for (int z = 0; z < 3; ++z) {
    const long level = z == 0 ? 850 : z == 1 ? 500 : 300;
    for (int j : {0, 7, kNj - 1})
      for (int i : {0, 5, kNi - 1}) {
        if (z == 2 && i == 0 && j == 0) continue;
        EXPECT_NEAR(t.at(i, kNj - 1 - j, z), expected(i, j, level, 1, 1), 1e-3) << i << "," << j << "," << z;
      }
  }
  EXPECT_TRUE(std::isnan(t.at(0, kNj - 1, 2)));  // bitmap: missing (file row 0 at 300 hPa)
  // Defaults: the first time and member; members are sorted numbers, times sorted dates.
  EXPECT_NEAR(load_volume(f + ":t").at(3, 4, 1), expected(3, kNj - 1 - 4, 500, 0, 0), 1e-3);
  VolumeOptions o;
  o.member_index = 2;
  EXPECT_NEAR(load_volume(f + ":t", o).at(3, 4, 0), expected(3, kNj - 1 - 4, 850, 2, 0), 1e-3);
  // An explicit level type.
  Volume sfc = load_volume(f + ":t@surface");
  EXPECT_EQ(sfc.dims[2], 1u);
  EXPECT_EQ(t.spacing[2], 1.0);
  EXPECT_GT(t.spacing[0], 0.0);

  expect_error([&] { load_volume(f + ":q"); }, {f, "no parameter 'q'", "t", "u"});
  expect_error([&] { load_volume(f); }, {f, "choose a parameter"});
  expect_error([&] { load_volume(f + ":t@sigma"); }, {f, "no level type 'sigma'", "isobaricInhPa", "surface"});
  expect_error([&] { load_volume(f + ":t,time=2"); }, {f, "time 2 is out of range", "2 reference time"});
  expect_error([&] { load_volume(f + ":t,member=3"); }, {f, "member 3 is out of range", "3 ensemble members"});

  FileInfo info = describe_file(f);
  ASSERT_FALSE(info.arrays.empty());
  EXPECT_EQ(info.arrays[0].name, "t@isobaricInhPa");
  EXPECT_EQ(info.arrays[0].grid, (std::array<uint64_t, 3>{kNi, kNj, 3}));
  EXPECT_EQ(info.arrays[0].nan_count, 2u);  // one missing corner per time
  // info: the axes as loaded, with their direction and what was reversed.
  ASSERT_EQ(info.arrays[0].orientation.size(), 3u);
  EXPECT_EQ(info.arrays[0].orientation[1], "y (latitude): 0 .. 60 degrees_north, north, reversed from the file's order");
  EXPECT_EQ(info.arrays[0].orientation[2],
            "z (isobaricInhPa): 850 .. 300 hPa, up (pressure decreasing, surface at z = 0), reversed from the file's order");
  EXPECT_EQ(info.arrays[0].origin[2], 0.0);
}

TEST(GribGenerated, DifferentGridsAndDuplicateLevelsAreErrors) {
  TempDir dir;
  const std::string g = write_grib(dir, "grids.grib2", {{"t", 500}, {.short_name = "t", .level = 850, .lat_shift = -1.0}}).string();
  expect_error([&] { load_volume(g + ":t"); }, {g, "do not share one grid", "regular_ll"});
  const std::string d = write_grib(dir, "dup.grib2", {{"t", 500}, {"t", 500}}).string();
  expect_error([&] { load_volume(d + ":t"); }, {d, "both at level 500"});
}

TEST(GribGenerated, GarbageAndTruncatedFilesFailCleanly) {
  TempDir dir;
  formats_test::write_bytes(dir / "junk.grib2", "plain text, nothing else");
  expect_error([&] { load_volume((dir / "junk.grib2").string() + ":t"); }, {"junk.grib2", "no GRIB messages"});
  // The magic word followed by garbage: ecCodes' reason, with the file and message number.
  formats_test::write_bytes(dir / "bad.grib2", "GRIB\x01\x02\x03\x09 and then garbage");
  expect_error([&] { load_volume((dir / "bad.grib2").string() + ":t"); }, {"bad.grib2", "GRIB message 1 is unreadable"});
  std::string bytes = encode({"t", 500}) + encode({"t", 850});
  formats_test::write_bytes(dir / "cut.grib2", bytes.substr(0, bytes.size() - 100));
  expect_error([&] { load_volume((dir / "cut.grib2").string() + ":t"); }, {"cut.grib2"});
}

// Section 5 stating more coded values than the grid has points, in a message with a bitmap (so
// the values still number the grid's points): ecCodes allocated by the stated count (2 GiB for
// 268435467, what fuzz_grib found); tfmatch refuses the message first.
TEST(GribGenerated, MoreCodedValuesThanGridPointsAreRefused) {
  TempDir dir;
  std::string bytes = encode({.short_name = "t", .level = 500, .missing_corner = true});
  size_t at = 16;  // GRIB 2 sections: 4-byte length, 1-byte number
  auto be32 = [&](size_t i) {
    return uint32_t(uint8_t(bytes[i])) << 24 | uint32_t(uint8_t(bytes[i + 1])) << 16 | uint32_t(uint8_t(bytes[i + 2])) << 8 |
           uint32_t(uint8_t(bytes[i + 3]));
  };
  while (at + 5 < bytes.size() && bytes[at + 4] != 5) at += be32(at);
  ASSERT_EQ(bytes[at + 4], 5);
  ASSERT_EQ(be32(at + 5), uint32_t(kNi * kNj - 1));  // numberOfValues, octets 6-9: all but the corner
  const uint32_t hostile = 268435467;
  for (int k = 0; k < 4; ++k) bytes[at + 5 + size_t(k)] = char((hostile >> (24 - 8 * k)) & 0xff);
  formats_test::write_bytes(dir / "coded.grib2", bytes);
  const std::string g = (dir / "coded.grib2").string();
  expect_error([&] { load_volume(g + ":t"); }, {g, "states 268435467 coded values for a grid of 496 points"});
}

std::string data(const std::string& rel) {
  const std::string d = test::shared_data_dir();
  return d.empty() ? "" : d + "/" + rel;
}

TEST(GribRealFiles, GfsWindsStackedOver26Levels) {
  if (data("").empty()) GTEST_SKIP() << "../shared/data not present";
  // `grib_get_data -w shortName=u,typeOfLevel=isobaricInhPa,level=L` row r = point r-2:
  // level 10: first -18.5, (lat 0, lon 180) -3.31 ... see the values below.
  Volume u = load_volume(data("gfs_grib2/gfs.t12z.pgrbf120.2p5deg.grib2:u"));
  Volume v = load_volume(data("gfs_grib2/gfs.t12z.pgrbf120.2p5deg.grib2:v"));
  EXPECT_EQ(u.dims, (std::array<uint64_t, 3>{144, 73, 26}));
  EXPECT_NO_THROW(require_same_grid(u, v));
  EXPECT_EQ(u.spacing, (std::array<double, 3>{2.5, 2.5, 1.0}));
  // World orientation: the file stores latitudes 90 -> -90 and levels sort 10 -> 1000 hPa; loaded,
  // y runs south to north and z from the surface up (1000 hPa at z = 0, 10 hPa at z = 25).
  ASSERT_EQ(u.axes[1].coordinates.size(), 73u);
  EXPECT_EQ(u.axes[1].coordinates.front(), -90.0);
  EXPECT_EQ(u.axes[1].coordinates.back(), 90.0);
  ASSERT_EQ(u.axes[2].coordinates.size(), 26u);
  EXPECT_EQ(u.axes[2].coordinates.front(), 1000.0);
  EXPECT_EQ(u.axes[2].coordinates.back(), 10.0);
  EXPECT_EQ(u.origin, (std::array<double, 3>{0.0, -90.0, 0.0}));  // even lon/lat; levels in index units
  // The file's (lon, lat, level) points: level 10 first point (0, 90) -18.5, (180, 0) -18.3,
  // last point (357.5, -90) 2.4; level 500 (0, 90) -25.31, (180, 0) -3.31; level 1000 (180, 0) -10.26.
  EXPECT_FLOAT_EQ(u.at(0, 72, 25), -18.5f);
  EXPECT_FLOAT_EQ(u.at(72, 36, 25), -18.3f);
  EXPECT_FLOAT_EQ(u.at(143, 0, 25), 2.4f);
  EXPECT_FLOAT_EQ(u.at(0, 72, 12), -25.31f);
  EXPECT_FLOAT_EQ(u.at(72, 36, 12), -3.31f);
  EXPECT_FLOAT_EQ(u.at(72, 36, 0), -10.26f);
  EXPECT_FLOAT_EQ(v.at(72, 36, 12), 0.33f);
  EXPECT_EQ(axis_coordinate(u, 2, 12), 500.0);
  // `tfmatch info` says the same.
  const FileInfo info = describe_file(data("gfs_grib2/gfs.t12z.pgrbf120.2p5deg.grib2"));
  bool found = false;
  for (const ArrayInfo& a : info.arrays) {
    if (a.name != "u@isobaricInhPa") continue;
    found = true;
    ASSERT_EQ(a.orientation.size(), 3u);
    EXPECT_EQ(a.orientation[0], "x (longitude): 0 .. 357.5 degrees_east, east");
    EXPECT_EQ(a.orientation[1], "y (latitude): -90 .. 90 degrees_north, north, reversed from the file's order");
    EXPECT_EQ(a.orientation[2],
              "z (isobaricInhPa): 1000 .. 10 hPa, up (pressure decreasing, surface at z = 0), reversed from the file's order");
    EXPECT_EQ(a.origin, u.origin);
  }
  EXPECT_TRUE(found);
  // GRIB2 levels in sign and magnitude: -2 PVU is scaled value 0x800007D0 (ecCodes' level key
  // read it as 2147486), +2 PVU is 2000.
  const Volume pv = load_volume(data("gfs_grib2/gfs.t12z.pgrbf120.2p5deg.grib2:u@potentialVorticity"));
  std::vector<double> levels = pv.axes[2].coordinates;
  std::sort(levels.begin(), levels.end());
  EXPECT_EQ(levels, (std::vector<double>{-2.0, 2.0}));
  // Bitmap: `grib_get -p numberOfMissing -w shortName=u,typeOfLevel=heightAboveSea` = 1161+794+452.
  Volume h = load_volume(data("gfs_grib2/gfs.t12z.pgrbf120.2p5deg.grib2:u@heightAboveSea"));
  size_t nan = 0;
  for (float x : h.values) nan += std::isnan(x);
  EXPECT_EQ(nan, 1161u + 794u + 452u);
}

TEST(GribRealFiles, Era5MembersAndTimesAndMultiParamSteps) {
  if (data("").empty()) GTEST_SKIP() << "../shared/data not present";
  // `grib_get_data -w shortName=t,number=3,dataDate=20170102,dataTime=0,level=850`: first point
  // 250.8110352, (lat 0, lon 180) 291.5043945. That date/time is the 3rd of 4 (time=2), 850 hPa
  // the lower of 500 and 850 hPa: z = 0 (surface down). Latitude 90 -> -90 in the file: the first
  // point (90 N) is y = 60, -90 at y = 0.
  Volume t = load_volume(data("era5_ensemble_grib1/era5-levels-members.grib:t,member=3,time=2"));
  EXPECT_EQ(t.dims, (std::array<uint64_t, 3>{120, 61, 2}));
  EXPECT_EQ(t.units, "K");  // ecCodes' units key
  EXPECT_EQ(t.axes[1].coordinates.front(), -90.0);
  EXPECT_EQ(t.axes[2].coordinates, (std::vector<double>{850, 500}));
  EXPECT_NEAR(t.at(0, 60, 0), 250.8110352, 1e-4);
  EXPECT_NEAR(t.at(60, 30, 0), 291.5043945, 1e-4);
  // `grib_get_data -w shortName=t,step=24,level=500`: point 10*72+5 = 256.3386688 (row 10 from
  // the north of 37: y = 26); step 24 is the 3rd of steps 0, 12, 24, 36; 500 hPa the 3rd from the
  // surface of 1000, 850, 500, 300 (z = 2).
  Volume m = load_volume(data("ecmwf_multiparam_grib1/multi_param_on_multi_dims.grib:t,time=2"));
  EXPECT_EQ(m.dims, (std::array<uint64_t, 3>{72, 37, 4}));
  EXPECT_NEAR(m.at(5, 26, 2), 256.3386688, 1e-4);
}

}  // namespace
}  // namespace tfm
