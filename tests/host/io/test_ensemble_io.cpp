// Ensembles from files: a NetCDF member dimension (named or chosen with --member-dim), GRIB
// `number`, one file per member (with patterns); grids, coordinates and clear errors.
#include <gtest/gtest.h>
#include <netcdf.h>

#include <bit>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "formats_test_util.h"
#include "slab_test_files.h"
#include "test_data.h"
#include "tfmatch/io/ensemble_io.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/io/volume_vti.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using formats_test::expect_error;
using formats_test::TempDir;

void ok(int status) { ASSERT_EQ(status, NC_NOERR) << nc_strerror(status); }

// t(realization=4, lev=2, lat=3, lon=5) = 1000 m + 100 z + 10 y + x with coordinates;
// u(run=3, lev, lat, lon) = 7 m + x (member dimension named only with --member-dim);
// w(ens=2, run=3, lev, lat, lon) with two candidate member dimensions; one NaN at member 2 of t.
std::filesystem::path make_ensemble_file(const TempDir& dir) {
  const auto path = dir / "ens.nc";
  int nc, real, lev, lat, lon, run, ens;
  ok(nc_create(path.c_str(), NC_CLOBBER, &nc));
  ok(nc_def_dim(nc, "realization", 4, &real));
  ok(nc_def_dim(nc, "lev", 2, &lev));
  ok(nc_def_dim(nc, "lat", 3, &lat));
  ok(nc_def_dim(nc, "lon", 5, &lon));
  ok(nc_def_dim(nc, "run", 3, &run));
  ok(nc_def_dim(nc, "ens", 2, &ens));
  int vlon, vlat, vlev, vt, vu, vw;
  ok(nc_def_var(nc, "lon", NC_DOUBLE, 1, &lon, &vlon));
  ok(nc_def_var(nc, "lat", NC_DOUBLE, 1, &lat, &vlat));
  ok(nc_def_var(nc, "lev", NC_DOUBLE, 1, &lev, &vlev));
  ok(nc_put_att_text(nc, vlon, "units", 12, "degrees_east"));
  ok(nc_put_att_text(nc, vlev, "units", 3, "hPa"));
  const int td[] = {real, lev, lat, lon}, ud[] = {run, lev, lat, lon}, wd[] = {ens, run, lev, lat, lon};
  ok(nc_def_var(nc, "t", NC_FLOAT, 4, td, &vt));
  ok(nc_def_var(nc, "u", NC_FLOAT, 4, ud, &vu));
  ok(nc_def_var(nc, "w", NC_FLOAT, 5, wd, &vw));
  ok(nc_enddef(nc));
  const double lons[] = {10, 20, 30, 40, 50}, lats[] = {-10, 0, 10}, levs[] = {850, 500};
  ok(nc_put_var_double(nc, vlon, lons));
  ok(nc_put_var_double(nc, vlat, lats));
  ok(nc_put_var_double(nc, vlev, levs));
  std::vector<float> t(4 * 2 * 3 * 5), u(3 * 2 * 3 * 5), w(2 * 3 * 2 * 3 * 5, 1.0f);
  for (size_t m = 0, i = 0; m < 4; ++m)
    for (size_t z = 0; z < 2; ++z)
      for (size_t y = 0; y < 3; ++y)
        for (size_t x = 0; x < 5; ++x, ++i) t[i] = float(1000 * m + 100 * z + 10 * y + x);
  t[2 * 30 + 7] = NAN;
  for (size_t i = 0; i < u.size(); ++i) u[i] = float(7 * (i / 30) + i % 5);
  ok(nc_put_var_float(nc, vt, t.data()));
  ok(nc_put_var_float(nc, vu, u.data()));
  ok(nc_put_var_float(nc, vw, w.data()));
  ok(nc_close(nc));
  return path;
}

TEST(EnsembleIo, NetcdfMemberDimensionByNameOrFlag) {
  TempDir dir;
  const auto path = make_ensemble_file(dir);
  const Ensemble e = load_ensemble(path.string() + ":t");
  ASSERT_EQ(e.member_count, 4u);
  EXPECT_EQ(e.grid.dims, (std::array<uint64_t, 3>{5, 3, 2}));
  for (uint32_t m = 0; m < 4; ++m)
    for (uint64_t v = 0; v < 30; ++v) {
      const float want = (m == 2 && v == 7) ? NAN : float(1000 * m + 100 * (v / 15) + 10 * ((v / 5) % 3) + v % 5);
      if (std::isnan(want)) EXPECT_TRUE(std::isnan(e.view().at(m, v)));
      else EXPECT_EQ(e.view().at(m, v), want) << m << " " << v;
    }
  // Coordinates travel with the grid.
  EXPECT_EQ(e.grid.axes[0].name, "lon");
  EXPECT_EQ(e.grid.axes[0].units, "degrees_east");
  EXPECT_EQ(e.grid.axes[2].coordinates, (std::vector<double>{850, 500}));
  EXPECT_EQ(e.grid.origin[0], 10.0);
  EXPECT_EQ(e.member(3).values[0], 3000.0f);

  // "run" is no member name: as the only extra dimension it is the member axis anyway, and
  // --member-dim names it explicitly.
  VolumeOptions o;
  o.member_dim = "run";
  const Ensemble u = load_ensemble(path.string() + ":u", o);
  ASSERT_EQ(u.member_count, 3u);
  EXPECT_EQ(u.view().at(2, 4), 18.0f);
  EXPECT_EQ(load_ensemble(path.string() + ":u").member_count, 3u);
  // Two candidate dimensions: say which.
  expect_error([&] { load_ensemble(path.string() + ":w"); }, {"ens.nc", "ens, run", "--member-dim"});
  VolumeOptions pick_ens;
  pick_ens.member_dim = "ens";
  expect_error([&] { load_ensemble(path.string() + ":w", pick_ens); }, {"ens.nc", "two leading dimensions"});
  VolumeOptions wrong;
  wrong.member_dim = "members";
  expect_error([&] { load_ensemble(path.string() + ":t", wrong); }, {"ens.nc", "no dimension 'members'", "realization=4"});
  expect_error([&] { load_ensemble(path.string() + ":t,member=1"); }, {"ens.nc", "picks one member"});
}

TEST(EnsembleIo, MemberFilesAndPatterns) {
  TempDir dir;
  for (int m = 0; m < 3; ++m) {
    Volume v = test::make_volume({4, 3, 2}, {1, 1, 1}, "member",
                                 [m](uint64_t x, uint64_t y, uint64_t z, uint64_t) { return float(m * 100 + x + 10 * y + z); });
    v.origin = {100, 80, 1};
    v.spacing = {0.5, 0.5, 2};
    write_vti(dir / ("member_" + std::to_string(m) + ".vti"), v, "f");
  }
  const auto files = expand_member_patterns({(dir / "member_*.vti").string()});
  ASSERT_EQ(files.size(), 3u);
  EXPECT_NE(files[2].find("member_2.vti"), std::string::npos);
  const Ensemble e = load_ensemble_members(files);
  EXPECT_EQ(e.member_count, 3u);
  EXPECT_EQ(e.grid.origin, (std::array<double, 3>{100, 80, 1}));
  EXPECT_EQ(e.grid.spacing, (std::array<double, 3>{0.5, 0.5, 2}));
  EXPECT_EQ(e.view().at(2, 5), 200.0f + 1 + 10);

  write_vti(dir / "odd.vti", test::make_volume({3, 3, 2}, {1, 1, 1}, "odd", [](uint64_t, uint64_t, uint64_t, uint64_t) { return 1.0f; }),
            "f");
  expect_error([&] { load_ensemble_members({files[0], (dir / "odd.vti").string()}); },
               {"different grids", "member_0.vti", "4x3x2", "odd.vti", "3x3x2"});
  expect_error([&] { expand_member_patterns({(dir / "none_*.vti").string()}); }, {"none_*.vti", "matches no file"});
  expect_error([&] { load_ensemble(files[0]); }, {"member_0.vti", "no member axis", "--members"});
}

// A pattern's files in natural order (numbers as numbers: step2 before step10, as ParaView orders a
// file series), leading zeros aside, and in text order where numbers are equal.
TEST(EnsembleIo, PatternsMatchInNaturalOrder) {
  TempDir dir;
  for (const char* name :
       {"step10.raw", "step2.raw", "step1.raw", "step02.raw", "step100a.raw", "step100.raw", "stepx.raw"})
    std::ofstream(dir / name) << "x";
  std::vector<std::string> names;
  for (const std::string& f : match_files((dir / "step*.raw").string()))
    names.push_back(std::filesystem::path(f).filename().string());
  EXPECT_EQ(names, (std::vector<std::string>{"step1.raw", "step02.raw", "step2.raw", "step10.raw", "step100.raw",
                                             "step100a.raw", "stepx.raw"}));
  EXPECT_TRUE(match_files((dir / "none*.raw").string()).empty());
  EXPECT_EQ(expand_member_patterns({(dir / "step1*.raw").string()}).size(), 4u);
}

// Members after the first are read straight into the ensemble where their format streams, and
// loaded whole where it does not: either way each member holds what load_volume() gives it, bit
// for bit (NaN included), and a member on another grid is refused naming both files.
TEST(EnsembleIo, MembersReadInPlaceOrLoadedHoldTheirLoadedValues) {
  TempDir dir;
  const std::array<uint64_t, 3> dims{7, 5, 3};
  std::vector<std::string> specs;
  specs.push_back(slab_test::write_raw(dir.path(), "a", slab_test::test_field(dims, 0)).string());
  specs.push_back(slab_test::write_vti_file(dir.path(), "b", slab_test::test_field(dims, 1), /*compressed=*/true).string());
  specs.push_back(slab_test::write_raw(dir.path(), "c", slab_test::test_field(dims, 2)).string());
  // Four-byte integers (decoded in place) and two-byte ones (through a block buffer).
  std::string int32_bytes, uint16_bytes;
  for (int i = 0; i < 7 * 5 * 3; ++i) {
    formats_test::put<int32_t>(int32_bytes, int32_t(i * 7919) - 200000, false);
    formats_test::put<uint16_t>(uint16_bytes, uint16_t(i * 613), false);
  }
  formats_test::write_bytes(dir / "d_7x5x3_int32.raw", int32_bytes);
  formats_test::write_bytes(dir / "e_7x5x3_uint16.raw", uint16_bytes);
  specs.push_back((dir / "d_7x5x3_int32.raw").string());
  specs.push_back((dir / "e_7x5x3_uint16.raw").string());
  specs.push_back(slab_test::write_vti_file(dir.path(), "f", slab_test::test_field(dims, 3), /*compressed=*/false).string());

  const Ensemble e = load_ensemble_members(specs);
  ASSERT_EQ(e.member_count, specs.size());
  EXPECT_EQ(e.values.size(), specs.size() * 7 * 5 * 3);
  for (uint32_t m = 0; m < e.member_count; ++m) {
    const Volume want = load_volume(specs[m]);
    EXPECT_EQ(e.member_names[m], want.name);
    for (uint64_t v = 0; v < want.voxel_count(); ++v)
      ASSERT_EQ(std::bit_cast<uint32_t>(e.view().at(m, v)), std::bit_cast<uint32_t>(want.values[v]))
          << specs[m] << ", voxel " << v;
  }

  const auto odd = slab_test::write_raw(dir.path(), "odd", slab_test::test_field({7, 5, 4}, 4));
  expect_error([&] { load_ensemble_members({specs[0], specs[2], odd.string()}); },
               {"different grids", "a_7x5x3_float32.raw", "7x5x3", "odd_7x5x4_float32.raw", "7x5x4"});
}

TEST(EnsembleIo, Era5GribMembersWithCoordinates) {
  const std::string d = test::shared_data_dir();
  if (d.empty()) GTEST_SKIP() << "../shared/data not present";
  const std::string file = d + "/era5_ensemble_grib1/era5-levels-members.grib";
  const Ensemble e = load_ensemble(file + ":t");
  ASSERT_EQ(e.member_count, 10u);
  EXPECT_EQ(e.grid.dims, (std::array<uint64_t, 3>{120, 61, 2}));
  // Member 3 equals the single-member read (grib_get_data checks of that read are in the GRIB tests).
  VolumeOptions o;
  o.member_index = 3;
  const Volume m3 = load_volume(file + ":t", o);
  EXPECT_EQ(e.member(3).values, m3.values);
  EXPECT_EQ(e.grid.axes[0].coordinates.front(), 0.0);
  EXPECT_DOUBLE_EQ(e.grid.axes[0].coordinates.back(), 357.0);
  // North up and the surface down, as every loader orients geographic grids.
  EXPECT_EQ(e.grid.axes[1].coordinates.front(), -90.0);
  EXPECT_EQ(e.grid.axes[1].coordinates.back(), 90.0);
  EXPECT_EQ(e.grid.axes[2].coordinates, (std::vector<double>{850, 500}));
  EXPECT_EQ(e.grid.axes[2].units, "hPa");
  // The name carries the time step read, however it was chosen.
  EXPECT_EQ(load_ensemble(file + ":t,time=3").grid.name, file + ":t,time=3");
  VolumeOptions at3;
  at3.time_index = 3;
  EXPECT_EQ(open_ensemble_slabs(file + ":t", at3).name, file + ":t,time=3");
  EXPECT_EQ(e.grid.name, file + ":t");
}

// A NetCDF variable without a member dimension (time and the grid only) is one member: the error
// says so and names --member-dim, not only "fewer than 3 members" later.
TEST(EnsembleIo, AVariableWithoutMembersNamesMemberDim) {
  TempDir dir;
  const std::string nc = slab_test::write_netcdf(dir.path(), "t", slab_test::test_field({5, 4, 3}, 1)).string();
  expect_error([&] { load_ensemble(nc + ":T"); },
               {nc + ":T: one member only", "--member-dim names the one that holds the members", "--members"});
  VolumeOptions by_time;
  by_time.member_dim = "time";
  EXPECT_EQ(load_ensemble(nc + ":T", by_time).member_count, 2u);  // the two time steps as members
}

}  // namespace
}  // namespace tfm
