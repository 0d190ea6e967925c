// NetCDF reader: files written here with netCDF-C (classic and netCDF-4) check the dimension
// mapping, time/member selection, fill values, packing, _Unsigned and coordinate spacing; the real
// files in ../shared/data are checked against values printed by ncdump.
#include <gtest/gtest.h>
#include <netcdf.h>

#include <cmath>
#include <cstdlib>
#include <fstream>

#include "formats_test_util.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/io/volume_vti.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/volume.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using formats_test::expect_error;
using formats_test::TempDir;

void ok(int status) { ASSERT_EQ(status, NC_NOERR) << nc_strerror(status); }

int def_var(int nc, const char* name, nc_type t, std::initializer_list<int> dims) {
  int v;
  std::vector<int> d(dims);
  EXPECT_EQ(nc_def_var(nc, name, t, int(d.size()), d.data(), &v), NC_NOERR);
  return v;
}

void text_att(int nc, int v, const char* name, const std::string& text) {
  EXPECT_EQ(nc_put_att_text(nc, v, name, text.size(), text.c_str()), NC_NOERR);
}

// A(time=2, lev=3, lat=4, lon=5) float, value 1000t + 100z + 10y + x, one fill value;
// P(lev, lat, lon) short packed with a negative scale and a missing_value;
// E(ens=2, time=2, lat, lon) double; B(lat, lon) byte with _Unsigned; W(step=2, lat, lon) whose
// time dimension is known only from its coordinate's units; C(zc, yc, xc) on a metre grid;
// N(ens, run=3, time, lat, lon) with two extra dimensions; name(lon) char.
std::filesystem::path make_file(const TempDir& dir, const std::string& file, int mode) {
  const auto path = dir / file;
  int nc;
  EXPECT_EQ(nc_create(path.c_str(), NC_CLOBBER | mode, &nc), NC_NOERR);
  int time, lev, lat, lon, ens, step, zc, yc, xc, run;
  ok(nc_def_dim(nc, "time", 2, &time));
  ok(nc_def_dim(nc, "lev", 3, &lev));
  ok(nc_def_dim(nc, "lat", 4, &lat));
  ok(nc_def_dim(nc, "lon", 5, &lon));
  ok(nc_def_dim(nc, "ens", 2, &ens));
  ok(nc_def_dim(nc, "step", 2, &step));
  ok(nc_def_dim(nc, "zc", 3, &zc));
  ok(nc_def_dim(nc, "yc", 2, &yc));
  ok(nc_def_dim(nc, "xc", 4, &xc));
  ok(nc_def_dim(nc, "run", 3, &run));
  const int vlon = def_var(nc, "lon", NC_FLOAT, {lon}), vlat = def_var(nc, "lat", NC_FLOAT, {lat});
  const int vlev = def_var(nc, "lev", NC_INT, {lev}), vstep = def_var(nc, "step", NC_DOUBLE, {step});
  const int vxc = def_var(nc, "xc", NC_FLOAT, {xc}), vyc = def_var(nc, "yc", NC_FLOAT, {yc}), vzc = def_var(nc, "zc", NC_FLOAT, {zc});
  text_att(nc, vlon, "units", "degrees_east");
  text_att(nc, vlat, "units", "degrees_north");
  text_att(nc, vlev, "units", "hPa");
  text_att(nc, vstep, "units", "hours since 2000-01-01 00:00");
  for (int v : {vxc, vyc, vzc}) text_att(nc, v, "units", "m");
  const int A = def_var(nc, "A", NC_FLOAT, {time, lev, lat, lon});
  const float fill = -999.0f;
  ok(nc_put_att_float(nc, A, "_FillValue", NC_FLOAT, 1, &fill));
  const int P = def_var(nc, "P", NC_SHORT, {lev, lat, lon});
  const double scale = -0.5, offset = 100.0, missing = -32767.0;
  ok(nc_put_att_double(nc, P, "scale_factor", NC_DOUBLE, 1, &scale));
  ok(nc_put_att_double(nc, P, "add_offset", NC_DOUBLE, 1, &offset));
  ok(nc_put_att_double(nc, P, "missing_value", NC_DOUBLE, 1, &missing));
  text_att(nc, P, "units", "Pa");
  const int E = def_var(nc, "E", NC_DOUBLE, {ens, time, lat, lon});
  const int B = def_var(nc, "B", NC_BYTE, {lat, lon});
  text_att(nc, B, "_Unsigned", "true");
  const int W = def_var(nc, "W", NC_FLOAT, {step, lat, lon});
  const int C = def_var(nc, "C", NC_FLOAT, {zc, yc, xc});
  const int N = def_var(nc, "N", NC_FLOAT, {ens, run, time, lat, lon});
  def_var(nc, "name", NC_CHAR, {lon});
  ok(nc_enddef(nc));

  const float lons[5] = {0, 2.5f, 5, 7.5f, 10}, lats[4] = {-60, -30.1f, 0, 30.1f};
  const int levs[3] = {1000, 850, 500};
  const double steps[2] = {0, 6};
  const float xs[4] = {0, 2, 4, 6}, ys[2] = {0, 3}, zs[3] = {10, 15, 20};
  ok(nc_put_var_float(nc, vlon, lons));
  ok(nc_put_var_float(nc, vlat, lats));
  ok(nc_put_var_int(nc, vlev, levs));
  ok(nc_put_var_double(nc, vstep, steps));
  ok(nc_put_var_float(nc, vxc, xs));
  ok(nc_put_var_float(nc, vyc, ys));
  ok(nc_put_var_float(nc, vzc, zs));
  std::vector<float> a(2 * 3 * 4 * 5);
  for (int t = 0; t < 2; ++t)
    for (int z = 0; z < 3; ++z)
      for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 5; ++x) a[((t * 3 + z) * 4 + y) * 5 + x] = float(1000 * t + 100 * z + 10 * y + x);
  a.back() = fill;
  size_t start[4] = {0, 0, 0, 0}, count[4] = {2, 3, 4, 5};
  ok(nc_put_vara_float(nc, A, start, count, a.data()));
  std::vector<short> p(60);
  for (int i = 0; i < 60; ++i) p[i] = short(i);
  p[7] = -32767;
  ok(nc_put_var_short(nc, P, p.data()));
  std::vector<double> e(2 * 2 * 4 * 5);
  for (size_t i = 0; i < e.size(); ++i) e[i] = double(i) + 0.5;
  size_t ecount[4] = {2, 2, 4, 5};
  ok(nc_put_vara_double(nc, E, start, ecount, e.data()));
  std::vector<signed char> b(20, 5);
  b[3] = -1;  // 255 when unsigned
  ok(nc_put_var_schar(nc, B, b.data()));
  std::vector<float> w(40);
  for (int i = 0; i < 40; ++i) w[i] = float(i);
  ok(nc_put_var_float(nc, W, w.data()));
  std::vector<float> c(24, 1.0f), n(2 * 3 * 2 * 20, 2.0f);
  ok(nc_put_var_float(nc, C, c.data()));
  ok(nc_put_var_float(nc, N, n.data()));
  ok(nc_close(nc));
  return path;
}

class NetcdfGenerated : public ::testing::TestWithParam<int> {};

TEST_P(NetcdfGenerated, MapsDimensionsTimeFillPackingAndSpacing) {
  TempDir dir;
  const auto path = make_file(dir, "gen.nc", GetParam());
  const std::string f = path.string();

  // x = lon (last), y = lat, z = lev; time picks the record.
  Volume v = load_volume(f + ":A,time=1");
  EXPECT_EQ(v.dims, (std::array<uint64_t, 3>{5, 4, 3}));
  EXPECT_EQ(v.at(4, 2, 1), 1000 + 100 * 1 + 10 * 2 + 4);
  EXPECT_EQ(v.at(0, 3, 2), 1000 + 200 + 30);
  EXPECT_TRUE(std::isnan(v.at(4, 3, 2)));  // the _FillValue
  EXPECT_EQ(load_volume(f + ":A").at(1, 1, 1), 111);  // time defaults to 0
  // lon regular: 2.5; lat within 1% of regular: mean step (30.1 + 60) / 3; lev irregular: 1.
  EXPECT_DOUBLE_EQ(v.spacing[0], 2.5);
  EXPECT_NEAR(v.spacing[1], (30.1 + 60.0) / 3.0, 1e-5);
  EXPECT_EQ(v.spacing[2], 1.0);
  // The origin: the first latitude where the mean step keeps every latitude within half a step of
  // its own (-60 + 30.03 i against -30.1, 0, 30.1); the irregular levels are in index units.
  EXPECT_EQ(v.origin[1], -60.0);
  EXPECT_EQ(v.origin[2], 0.0);
  // --var / --time through VolumeOptions; the spec's selection wins.
  VolumeOptions o;
  o.variable = "P";
  o.time_index = 1;
  EXPECT_EQ(load_volume(f + ":A", o).at(0, 0, 0), 1000);

  // Packing with a negative scale, missing_value in the packed domain.
  Volume p = load_volume(f + ":P");
  EXPECT_EQ(p.dims, (std::array<uint64_t, 3>{5, 4, 3}));
  EXPECT_DOUBLE_EQ(p.at(1, 2, 2), (40 + 10 + 1) * -0.5 + 100.0);
  EXPECT_TRUE(std::isnan(p.at(2, 1, 0)));  // stored -32767 at index 7

  // A leading non-time dimension is the member; two spatial dimensions make one slice.
  Volume e = load_volume(f + ":E,member=1,time=1");
  EXPECT_EQ(e.dims, (std::array<uint64_t, 3>{5, 4, 1}));
  EXPECT_EQ(e.at(3, 2, 0), ((1 * 2 + 1) * 4 + 2) * 5 + 3 + 0.5);

  Volume b = load_volume(f + ":B");
  EXPECT_EQ(b.at(3, 0, 0), 255.0f);
  EXPECT_EQ(b.at(0, 0, 0), 5.0f);

  // "step" is a time dimension because its coordinate's units are "hours since ...".
  Volume w = load_volume(f + ":W,time=1");
  EXPECT_EQ(w.dims, (std::array<uint64_t, 3>{5, 4, 1}));
  EXPECT_EQ(w.at(0, 0, 0), 20.0f);

  // A Cartesian grid: z takes its step too because its units match x's.
  Volume c = load_volume(f + ":C");
  EXPECT_EQ(c.spacing, (std::array<double, 3>{2, 3, 5}));
}

// A grid stored the way many files store it: latitudes north to south, pressure levels from the
// top, and a depth axis from the surface down. Value 100 z + 10 y + x in the file's order.
std::filesystem::path make_upside_down_file(const TempDir& dir) {
  const auto path = dir / "flipped.nc";
  int nc;
  EXPECT_EQ(nc_create(path.c_str(), NC_CLOBBER, &nc), NC_NOERR);
  int plev, lat, lon, depth, height;
  ok(nc_def_dim(nc, "plev", 3, &plev));
  ok(nc_def_dim(nc, "lat", 3, &lat));
  ok(nc_def_dim(nc, "lon", 4, &lon));
  ok(nc_def_dim(nc, "depth", 2, &depth));
  ok(nc_def_dim(nc, "height", 2, &height));
  const int vp = def_var(nc, "plev", NC_DOUBLE, {plev}), vlat = def_var(nc, "lat", NC_DOUBLE, {lat});
  const int vlon = def_var(nc, "lon", NC_DOUBLE, {lon}), vd = def_var(nc, "depth", NC_DOUBLE, {depth});
  const int vh = def_var(nc, "height", NC_DOUBLE, {height});
  text_att(nc, vp, "units", "Pa");
  text_att(nc, vlat, "units", "degrees_north");
  text_att(nc, vlon, "units", "degrees_east");
  text_att(nc, vd, "units", "m");
  text_att(nc, vd, "positive", "down");
  text_att(nc, vh, "units", "m");
  text_att(nc, vh, "positive", "up");
  const int T = def_var(nc, "T", NC_FLOAT, {plev, lat, lon});
  const int S = def_var(nc, "S", NC_FLOAT, {depth, lat, lon});
  const int H = def_var(nc, "H", NC_FLOAT, {height, lat, lon});
  ok(nc_enddef(nc));
  const double ps[3] = {1000, 50000, 100000}, lats[3] = {60, 0, -60}, lons[4] = {0, 90, 180, 270};
  const double ds[2] = {0, 100}, hs[2] = {0, 1000};
  ok(nc_put_var_double(nc, vp, ps));
  ok(nc_put_var_double(nc, vlat, lats));
  ok(nc_put_var_double(nc, vlon, lons));
  ok(nc_put_var_double(nc, vd, ds));
  ok(nc_put_var_double(nc, vh, hs));
  std::vector<float> t(36);
  for (int z = 0; z < 3; ++z)
    for (int y = 0; y < 3; ++y)
      for (int x = 0; x < 4; ++x) t[(z * 3 + y) * 4 + x] = float(100 * z + 10 * y + x);
  ok(nc_put_var_float(nc, T, t.data()));
  ok(nc_put_var_float(nc, S, t.data()));  // its first 24 values
  ok(nc_put_var_float(nc, H, t.data()));
  ok(nc_close(nc));
  return path;
}

TEST(NetcdfOrientation, LoadsNorthUpAndSurfaceDown) {
  TempDir dir;
  const std::string f = make_upside_down_file(dir).string();
  // Latitude reversed (-60 at y = 0), pressure reversed (100000 Pa, the surface, at z = 0).
  Volume t = load_volume(f + ":T");
  ASSERT_EQ(t.dims, (std::array<uint64_t, 3>{4, 3, 3}));
  for (int z = 0; z < 3; ++z)
    for (int y = 0; y < 3; ++y)
      for (int x = 0; x < 4; ++x) ASSERT_EQ(t.at(x, y, z), float(100 * (2 - z) + 10 * (2 - y) + x)) << x << y << z;
  EXPECT_EQ(t.axes[1].coordinates, (std::vector<double>{-60, 0, 60}));
  EXPECT_EQ(t.axes[2].coordinates, (std::vector<double>{100000, 50000, 1000}));
  EXPECT_EQ(t.axes[0].coordinates, (std::vector<double>{0, 90, 180, 270}));
  EXPECT_EQ(t.origin, (std::array<double, 3>{0, -60, 0}));  // pressure levels: index units (spacing 1)
  EXPECT_EQ(t.spacing, (std::array<double, 3>{90, 60, 1}));  // positive; pressure levels: 1
  // Depth (positive = "down") reversed: the deepest level at z = 0. Height stays as stored.
  Volume s = load_volume(f + ":S");
  EXPECT_EQ(s.axes[2].coordinates, (std::vector<double>{100, 0}));
  EXPECT_EQ(s.at(1, 0, 0), float(100 + 20 + 1));
  Volume h = load_volume(f + ":H");
  EXPECT_EQ(h.axes[2].coordinates, (std::vector<double>{0, 1000}));
  EXPECT_EQ(h.at(1, 0, 0), float(20 + 1));
  // `info` says so, with the origin and the coordinate ranges as loaded.
  const FileInfo info = describe_file(f);
  const ArrayInfo* a = nullptr;
  for (const auto& x : info.arrays)
    if (x.name == "T") a = &x;
  ASSERT_NE(a, nullptr);
  EXPECT_EQ(a->origin, t.origin);
  ASSERT_EQ(a->orientation.size(), 3u);
  EXPECT_EQ(a->orientation[0], "x (lon): 0 .. 270 degrees_east, east");
  EXPECT_EQ(a->orientation[1], "y (lat): -60 .. 60 degrees_north, north, reversed from the file's order");
  EXPECT_EQ(a->orientation[2],
            "z (plev): 100000 .. 1000 Pa, up (pressure decreasing, surface at z = 0), reversed from the file's order");
  const std::string text = format_file_info(info);
  EXPECT_NE(text.find("origin 0 -60 0"), std::string::npos) << text;  // levels: index units
}

// The oriented grid written as .vti keeps origin, spacing and coordinates: read back by tfmatch
// and by VTK's own reader (python3-vtk9; the test skips visibly without it).
TEST(NetcdfOrientation, VtiOutputCarriesOriginSpacingAndCoordinates) {
  TempDir dir;
  const Volume t = load_volume(make_upside_down_file(dir).string() + ":T");
  const std::filesystem::path vti = dir.path() / "t.vti";
  write_vti(vti, t, "T");
  const Volume back = load_volume(vti.string());
  EXPECT_EQ(back.origin, t.origin);
  EXPECT_EQ(back.spacing, t.spacing);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(back.axes[size_t(k)].coordinates, t.axes[size_t(k)].coordinates) << k;
    EXPECT_EQ(back.axes[size_t(k)].name, t.axes[size_t(k)].name) << k;
    EXPECT_EQ(back.axes[size_t(k)].units, t.axes[size_t(k)].units) << k;
  }
  EXPECT_EQ(back.values, t.values);

  const std::string python = std::filesystem::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
  if (std::system((python + " -c 'import vtk' >/dev/null 2>&1").c_str()) != 0)
    GTEST_SKIP() << "VTK's Python package is not installed (Debian python3-vtk9): no independent read-back";
  const std::string script = std::string(TFMATCH_SOURCE_DIR) + "/tests/host/io/vti_with_vtk.py";
  const std::filesystem::path out = dir.path() / "vtk.json";
  ASSERT_EQ(std::system((python + " " + script + " " + vti.string() + " T 1,0,0 3,2,2 > " + out.string()).c_str()), 0);
  std::ifstream in(out);
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["dims"], nlohmann::json({4, 3, 3}));
  // Pressure levels in index units: VTK puts them at z = 0, 1, 2 (not 100000, 100001, ...), their
  // values in z_coordinates.
  EXPECT_EQ(j["origin"], nlohmann::json({0.0, -60.0, 0.0}));
  EXPECT_EQ(j["spacing"], nlohmann::json({90.0, 60.0, 1.0}));
  // North up and surface down as VTK sees it: (1, 0, 0) is the file's last latitude and level.
  EXPECT_EQ(j["points"]["1,0,0"].get<double>(), 100 * 2 + 10 * 2 + 1);
  EXPECT_EQ(j["points"]["3,2,2"].get<double>(), 3);
  EXPECT_EQ(j["field_data"]["y_coordinates"], nlohmann::json({-60.0, 0.0, 60.0}));
  EXPECT_EQ(j["field_data"]["z_coordinates"], nlohmann::json({100000.0, 50000.0, 1000.0}));
  EXPECT_EQ(j["field_data"]["x_coordinates"], nlohmann::json({0.0, 90.0, 180.0, 270.0}));
}

TEST_P(NetcdfGenerated, ErrorsNameFileAndProblem) {
  TempDir dir;
  const auto path = make_file(dir, "gen.nc", GetParam());
  const std::string f = path.string();
  expect_error([&] { load_volume(f + ":nope"); }, {f, "no variable 'nope'", "A"});
  expect_error([&] { load_volume(f); }, {f, "choose a variable"});
  expect_error([&] { load_volume(f + ":A,time=2"); }, {f, "time 2 is out of range", "time has 2"});
  expect_error([&] { load_volume(f + ":E,member=2"); }, {f, "member 2 is out of range", "ens"});
  expect_error([&] { load_volume(f + ":P,time=1"); }, {f, "has no time dimension"});
  expect_error([&] { load_volume(f + ":N"); }, {f, "two leading dimensions", "ens", "run"});
  expect_error([&] { load_volume(f + ":name"); }, {f, "not a numeric type"});
  expect_error([&] { load_volume(f + ":A,when=1"); }, {f, "bad selection"});
  // Two variables of one file on different grids.
  Volume a = load_volume(f + ":A"), e = load_volume(f + ":E");
  expect_error([&] { require_same_grid(a, e); },
               {"different grids", "5x4x3", "5x4x1", e.name + " has one level: a 2-D field", "grid of 3 levels"});
}

INSTANTIATE_TEST_SUITE_P(Formats, NetcdfGenerated, ::testing::Values(0, NC_64BIT_OFFSET, NC_NETCDF4),
                         [](const auto& info) {
                           return std::string(info.param == 0 ? "classic" : info.param == NC_NETCDF4 ? "netcdf4" : "offset64");
                         });

TEST(NetcdfMalformed, GarbageAndTruncatedFilesFailCleanly) {
  TempDir dir;
  formats_test::write_bytes(dir / "garbage.nc", "this is not a netCDF file at all");
  expect_error([&] { load_volume((dir / "garbage.nc").string() + ":A"); }, {"garbage.nc", "cannot open as NetCDF"});
  const auto path = make_file(dir, "cut.nc", 0);
  const std::string bytes = formats_test::read_bytes(path);
  // netCDF-C itself would read the missing bytes as zeros: the header's sizes catch it. The bound
  // leaves out alignment padding (3 bytes after the byte variable B here), so cut 4 or more.
  for (size_t cut : {size_t(4), bytes.size() / 2}) {
    formats_test::write_bytes(path, bytes.substr(0, bytes.size() - cut));
    expect_error([&] { load_volume(path.string() + ":A,time=1"); }, {"cut.nc: truncated", "header describes at least"});
  }
  formats_test::write_bytes(path, bytes.substr(0, 40));
  expect_error([&] { load_volume(path.string() + ":A"); }, {"cut.nc"});
}

// A CDF-5 header may claim 2^62 records: its size (2^62 x 256 bytes) wraps a 64-bit sum, which
// must still read as "more than the file holds", never as a small size that passes, or the read
// would walk the records netCDF-C fills with zeros (for ever, for `info`).
TEST(NetcdfMalformed, RecordCountPastAnyFileIsTruncated) {
  std::string h = "CDF\x05";
  const auto u32 = [&](uint32_t v) { for (int b = 3; b >= 0; --b) h += char(v >> (8 * b)); };
  const auto u64 = [&](uint64_t v) { for (int b = 7; b >= 0; --b) h += char(v >> (8 * b)); };
  const auto name = [&](const std::string& n) { u64(n.size()); h += n; h.append((4 - n.size() % 4) % 4, '\0'); };
  u64(uint64_t(1) << 62);  // numrecs
  u32(0x0A), u64(4);       // four dimensions: t (unlimited), z, y, x
  for (const auto& [n, len] : std::vector<std::pair<std::string, uint64_t>>{{"t", 0}, {"z", 4}, {"y", 4}, {"x", 4}})
    name(n), u64(len);
  u32(0), u64(0);                                     // no global attributes
  u32(0x0B), u64(1), name("T"), u64(4);               // one variable T(t, z, y, x)
  for (uint64_t d = 0; d < 4; ++d) u64(d);
  u32(0), u64(0), u32(5), u64(256), u64(h.size() + 8);  // no attributes; float; 256 bytes a record; begin
  h.append(256, '\0');                                 // one record of the 2^62
  TempDir dir;
  formats_test::write_bytes(dir / "records.nc", h);
  expect_error([&] { load_volume((dir / "records.nc").string() + ":T,time=7"); },
               {"records.nc: truncated", "more than 2^62 bytes"});
  expect_error([&] { describe_file(dir / "records.nc"); }, {"records.nc: truncated"});
}

TEST(NetcdfInfo, ListsVariablesWithRangesAndNoData) {
  TempDir dir;
  const auto path = make_file(dir, "gen.nc", 0);
  FileInfo info = describe_file(path);
  const ArrayInfo* a = nullptr;
  for (const auto& x : info.arrays)
    if (x.name == "A") a = &x;
  ASSERT_NE(a, nullptr);
  EXPECT_EQ(a->grid, (std::array<uint64_t, 3>{5, 4, 3}));
  EXPECT_EQ(a->values, 120u);  // both times
  EXPECT_EQ(a->nan_count, 1u);
  EXPECT_EQ(*a->min, 0.0);
  EXPECT_EQ(*a->max, 1000 + 200 + 30 + 3);  // the largest value is the fill's neighbour
  EXPECT_NE(format_file_info(info).find("time = 2 (--time)"), std::string::npos);
  // The range is over both times, and says so (one time's own range is another: a range copied
  // into --range from here mapped that field differently without a word).
  EXPECT_NE(format_file_info(info).find("range over all 2 times [0, 1233]"), std::string::npos) << format_file_info(info);
  for (const auto& x : file_info_json(info)["arrays"])
    if (x["name"] == "A") EXPECT_EQ(x["fields_examined"], 2u);
  // One selected field's range is its own.
  const std::string at_time = format_file_info(describe_selection(path.string() + ":A,time=1", {}));
  EXPECT_NE(at_time.find("      range ["), std::string::npos) << at_time;
  // Attribute values as numbers are written elsewhere ("-32767", not "-32767.000000").
  const std::string text = format_file_info(info);
  EXPECT_NE(text.find("missing_value -32767\n"), std::string::npos) << text;
  // One selected variable (info FILE:VAR) names its units too.
  const std::string one = format_file_info(describe_selection(path.string() + ":P", {}));
  EXPECT_NE(one.find("units: Pa"), std::string::npos) << one;
}

// Packing attributes that cannot be what they say are errors naming the variable and attribute
// (a text scale_factor left the data unscaled, a second value was dropped, _Unsigned "maybe" was
// read as false); info lists such a variable saying why and goes on with the others.
TEST(NetcdfMalformed, PackingAttributesMustBeWhatTheySay) {
  TempDir dir;
  const auto path = dir / "packing.nc";
  int nc, x;
  ASSERT_EQ(nc_create(path.c_str(), NC_CLOBBER, &nc), NC_NOERR);
  ok(nc_def_dim(nc, "x", 4, &x));
  const int text = def_var(nc, "text", NC_SHORT, {x}), two = def_var(nc, "two", NC_SHORT, {x});
  const int inf = def_var(nc, "inf", NC_SHORT, {x}), maybe = def_var(nc, "maybe", NC_SHORT, {x});
  const int fine = def_var(nc, "fine", NC_SHORT, {x});
  ok(nc_put_att_text(nc, text, "scale_factor", 3, "abc"));
  const double pair[2] = {1, 2}, infinite = INFINITY, half = 0.5;
  ok(nc_put_att_double(nc, two, "add_offset", NC_DOUBLE, 2, pair));
  ok(nc_put_att_double(nc, inf, "scale_factor", NC_DOUBLE, 1, &infinite));
  ok(nc_put_att_text(nc, maybe, "_Unsigned", 5, "maybe"));
  ok(nc_put_att_double(nc, fine, "scale_factor", NC_DOUBLE, 1, &half));
  ok(nc_put_att_text(nc, fine, "_Unsigned", 5, "false"));
  ok(nc_enddef(nc));
  const short stored[4] = {2, 4, 6, 8};
  for (int v : {text, two, inf, maybe, fine}) ok(nc_put_var_short(nc, v, stored));
  ok(nc_close(nc));
  const std::string f = path.string();
  expect_error([&] { load_volume(f + ":text"); }, {f, "variable text: attribute scale_factor is text, not a number"});
  expect_error([&] { load_volume(f + ":two"); }, {"variable two: attribute add_offset has 2 values, not one"});
  expect_error([&] { load_volume(f + ":inf"); }, {"variable inf: attribute scale_factor is not a finite number"});
  expect_error([&] { load_volume(f + ":maybe"); }, {"variable maybe: attribute _Unsigned is 'maybe', not \"true\" or \"false\""});
  EXPECT_EQ(load_volume(f + ":fine").values, (std::vector<float>{1, 2, 3, 4}));
  const std::string listing = format_file_info(describe_file(path));
  EXPECT_NE(listing.find("not loadable: variable text: attribute scale_factor is text"), std::string::npos) << listing;
  EXPECT_NE(listing.find("packed: value = stored * 0.5 + 0"), std::string::npos) << listing;
  // netCDF-4 text attributes may be one NC_STRING (as some Python writers store them): read as
  // text, _Unsigned and units alike (both were ignored).
  const auto path4 = dir / "strings.nc";
  ASSERT_EQ(nc_create(path4.c_str(), NC_CLOBBER | NC_NETCDF4, &nc), NC_NOERR);
  ok(nc_def_dim(nc, "x", 2, &x));
  const int b = def_var(nc, "b", NC_BYTE, {x});
  const char* yes[1] = {"true"};
  const char* kelvin[1] = {"K"};
  ok(nc_put_att_string(nc, b, "_Unsigned", 1, yes));
  ok(nc_put_att_string(nc, b, "units", 1, kelvin));
  ok(nc_enddef(nc));
  const signed char bytes[2] = {-1, 5};
  ok(nc_put_var_schar(nc, b, bytes));
  ok(nc_close(nc));
  const Volume u = load_volume(path4.string() + ":b");
  EXPECT_EQ(u.values, (std::vector<float>{255, 5}));
  EXPECT_EQ(u.units, "K");
}

// `info` reads a variable's slabs a block of rows at a time (a 2048 x 1024 one under a budget
// with 16 MiB left: whole slabs of double and float took 24 MiB), and lists a variable too large to
// scan (an unwritten 10 x 10^5 x 10^5 one in a netCDF-4 file of a few KiB) without its range
// instead of streaming 10^11 fill values or failing the whole file.
TEST(NetcdfInfo, ReadsRowsAndSkipsVariablesTooLargeToScan) {
  TempDir dir;
  const auto path = dir / "wide.nc";
  int nc;
  ASSERT_EQ(nc_create(path.c_str(), NC_CLOBBER | NC_NETCDF4, &nc), NC_NOERR);
  int y, x, Z, Y, X;
  ok(nc_def_dim(nc, "y", 1024, &y));
  ok(nc_def_dim(nc, "x", 2048, &x));
  ok(nc_def_dim(nc, "Z", 10, &Z));
  ok(nc_def_dim(nc, "Y", 100000, &Y));
  ok(nc_def_dim(nc, "X", 100000, &X));
  const int wide = def_var(nc, "wide", NC_FLOAT, {y, x});
  def_var(nc, "huge", NC_FLOAT, {Z, Y, X});
  ok(nc_enddef(nc));
  std::vector<float> values(1024 * 2048);
  for (size_t i = 0; i < values.size(); ++i) values[i] = float(i % 3001) - 7.0f;
  values[1024 * 2048 - 1] = 5000.0f;  // in the last block of rows
  ok(nc_put_var_float(nc, wide, values.data()));
  ok(nc_close(nc));
  set_memory_budget(resident_memory() + (uint64_t(16) << 20), "--max-memory test");
  FileInfo info;
  ASSERT_NO_THROW(info = describe_file(path));
  set_memory_budget(0, "");
  ASSERT_EQ(info.arrays.size(), 2u);
  const ArrayInfo& w = info.arrays[0];
  EXPECT_EQ(w.values, 1024u * 2048u);
  EXPECT_EQ(w.min, -7.0);
  EXPECT_EQ(w.max, 5000.0);
  const ArrayInfo& h = info.arrays[1];
  EXPECT_FALSE(h.min.has_value());
  ASSERT_FALSE(h.notes.empty());
  EXPECT_NE(h.notes.back().find("range not computed: 100000000000 values"), std::string::npos) << h.notes.back();
  // Loaded, the rows arrive in order: the same values as written.
  const Volume v = load_volume(path.string() + ":wide");
  ASSERT_EQ(v.values.size(), values.size());
  EXPECT_EQ(v.at(2047, 1023, 0), 5000.0f);
  EXPECT_EQ(v.at(5, 700, 0), values[700 * 2048 + 5]);
}

// ---- real files (../shared/data/SOURCES.md) ----

std::string data(const std::string& rel) {
  const std::string d = test::shared_data_dir();
  return d.empty() ? "" : d + "/" + rel;
}

TEST(NetcdfRealFiles, CamUvtWindsMatchNcdump) {
  if (data("").empty()) GTEST_SKIP() << "../shared/data not present";
  // Expected values: `ncdump -v U cam_uvt/uvt.nc`, element [time][lev][lat][lon].
  Volume u = load_volume(data("cam_uvt/uvt.nc:U"));
  EXPECT_EQ(u.dims, (std::array<uint64_t, 3>{128, 64, 14}));
  EXPECT_FLOAT_EQ(u.at(0, 0, 0), -7.200147f);
  EXPECT_FLOAT_EQ(u.at(20, 10, 2), 11.29383f);
  EXPECT_FLOAT_EQ(u.at(127, 63, 13), 2.967923f);
  EXPECT_FLOAT_EQ(u.at(64, 32, 7), 2.221278f);
  EXPECT_DOUBLE_EQ(u.spacing[0], 2.8125);   // regular longitudes
  EXPECT_NEAR(u.spacing[1], 2.7893, 1e-3);  // Gaussian latitudes: nearly regular, mean step
  EXPECT_EQ(u.spacing[2], 1.0);             // pressure levels
  Volume v = load_volume(data("cam_uvt/uvt.nc:V"));
  EXPECT_NO_THROW(require_same_grid(u, v));
}

TEST(NetcdfRealFiles, EraInterimPackedShortsWithNanFillValue) {
  if (data("").empty()) GTEST_SKIP() << "../shared/data not present";
  // `ncdump -v u eraint_uvz/eraint_uvz.nc` prints the stored shorts: [0][0][0][0] = 16333,
  // [1][2][120][240] = 17386; u = stored * -0.00157270493804553 + 26.96875 (ncdump -h).
  const double scale = -0.00157270493804553, offset = 26.96875;
  Volume u0 = load_volume(data("eraint_uvz/eraint_uvz.nc:u"));
  EXPECT_EQ(u0.dims, (std::array<uint64_t, 3>{480, 241, 3}));
  // Stored latitude 90 -> -90 and levels 200, 500, 850 hPa: loaded north up and surface down, so
  // [level 0][lat 0] is y = 240, z = 2 and [level 2][lat 120] is y = 120, z = 0.
  EXPECT_FLOAT_EQ(u0.at(0, 240, 2), float(16333 * scale + offset));
  EXPECT_EQ(u0.axes[2].coordinates, (std::vector<double>{850, 500, 200}));
  Volume u1 = load_volume(data("eraint_uvz/eraint_uvz.nc:u,member=1"));  // month 7
  EXPECT_FLOAT_EQ(u1.at(240, 120, 0), float(17386 * scale + offset));
  // The NaN _FillValue (a double on an int16 variable) matches nothing: no value is lost.
  for (float x : u1.values) ASSERT_FALSE(std::isnan(x));
  EXPECT_DOUBLE_EQ(u0.spacing[0], 0.75);
}

TEST(NetcdfRealFiles, WrfNetcdf4TimeStepsAndStaggeredGrids) {
  if (data("").empty()) GTEST_SKIP() << "../shared/data not present";
  // `ncdump -v QVAPOR wrf_katrina/ci_test_file.nc`: [3][0][0][0] = 0.02134872,
  // [3][5][20][30] = 0.01894741, [0][13][47][47] = 0.006199233.
  Volume q3 = load_volume(data("wrf_katrina/ci_test_file.nc:QVAPOR,time=3"));
  EXPECT_EQ(q3.dims, (std::array<uint64_t, 3>{48, 48, 14}));
  EXPECT_FLOAT_EQ(q3.at(0, 0, 0), 0.02134872f);
  EXPECT_FLOAT_EQ(q3.at(30, 20, 5), 0.01894741f);
  EXPECT_FLOAT_EQ(load_volume(data("wrf_katrina/ci_test_file.nc:QVAPOR")).at(47, 47, 13), 0.006199233f);
  EXPECT_EQ(q3.units, "kg kg-1");  // the variable's units attribute (report plots label with it)
  EXPECT_EQ(open_volume_slabs(data("wrf_katrina/ci_test_file.nc:T"))->grid().units, "K");
  // U is staggered in x: a clear error against a mass-grid field.
  Volume u = load_volume(data("wrf_katrina/ci_test_file.nc:U"));
  EXPECT_EQ(u.dims, (std::array<uint64_t, 3>{49, 48, 14}));
  expect_error([&] { require_same_grid(q3, u); }, {"different grids", "48x48x14", "49x48x14"});
  try {  // not taken for a 2-D field: that note is for one level beside many on one horizontal grid
    require_same_grid(q3, u);
  } catch (const std::runtime_error& err) {
    EXPECT_EQ(std::string(err.what()).find("one level"), std::string::npos) << err.what();
  }
}

}  // namespace
}  // namespace tfm
