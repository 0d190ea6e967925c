// Small volume files of awkward sizes for the streaming tests: raw, .dat, NetCDF classic (with
// axes stored against world orientation, a fill value, a time axis) and VTI (uncompressed raw
// appended, compressed), each holding a known field with a few NaN voxels.
#pragma once

#include <gtest/gtest.h>
#include <netcdf.h>

#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "formats_test_util.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/io/volume_vti.h"
#include "tfmatch/model/volume.h"

namespace tfm::slab_test {

// A smooth field with structure in every axis and NaN at every 97th voxel; `seed` varies it.
inline Volume test_field(std::array<uint64_t, 3> dims, int seed) {
  Volume v;
  v.dims = dims;
  v.name = "field" + std::to_string(seed);
  v.values.resize(v.voxel_count());
  for (uint64_t z = 0; z < dims[2]; ++z)
    for (uint64_t y = 0; y < dims[1]; ++y)
      for (uint64_t x = 0; x < dims[0]; ++x) {
        const uint64_t i = (z * dims[1] + y) * dims[0] + x;
        const double s = std::sin(0.37 * double(x) * (seed + 1)) + std::cos(0.23 * double(y) + seed) +
                         0.05 * double(z) * double(z % 7) + 0.5 * seed;
        v.values[i] = (i + seed) % 97 == 0 ? NAN : float(300.0 + 20.0 * s);
      }
  return v;
}

// `v` as name_XxYxZ_float32.raw in `dir`.
inline std::filesystem::path write_raw(const std::filesystem::path& dir, const std::string& stem, const Volume& v) {
  const auto path = dir / (stem + "_" + std::to_string(v.dims[0]) + "x" + std::to_string(v.dims[1]) + "x" +
                           std::to_string(v.dims[2]) + "_float32.raw");
  write_raw_float32(path, v);
  return path;
}

inline void nc_ok(int status) { ASSERT_EQ(status, NC_NOERR) << nc_strerror(status); }

// NetCDF classic: T(time=2, lev, lat, lon) float with _FillValue where `v` is NaN, levels in hPa
// stored from the top (loaded reversed in z) and latitudes north to south (reversed in y);
// time step 1 holds `v` as it loads, step 0 holds v + 1.
inline std::filesystem::path write_netcdf(const std::filesystem::path& dir, const std::string& stem, const Volume& v) {
  const auto path = dir / (stem + ".nc");
  int nc = -1, time, lev, lat, lon;
  nc_ok(nc_create(path.c_str(), NC_CLOBBER, &nc));
  const auto& d = v.dims;
  nc_ok(nc_def_dim(nc, "time", 2, &time));
  nc_ok(nc_def_dim(nc, "lev", d[2], &lev));
  nc_ok(nc_def_dim(nc, "lat", d[1], &lat));
  nc_ok(nc_def_dim(nc, "lon", d[0], &lon));
  int vlev, vlat, vlon, vt;
  nc_ok(nc_def_var(nc, "lev", NC_DOUBLE, 1, &lev, &vlev));
  nc_ok(nc_def_var(nc, "lat", NC_DOUBLE, 1, &lat, &vlat));
  nc_ok(nc_def_var(nc, "lon", NC_DOUBLE, 1, &lon, &vlon));
  nc_ok(nc_put_att_text(nc, vlev, "units", 3, "hPa"));
  nc_ok(nc_put_att_text(nc, vlat, "units", 13, "degrees_north"));
  nc_ok(nc_put_att_text(nc, vlon, "units", 12, "degrees_east"));
  const int dims4[4] = {time, lev, lat, lon};
  nc_ok(nc_def_var(nc, "T", NC_FLOAT, 4, dims4, &vt));
  const float fill = -999.0f;
  nc_ok(nc_put_att_float(nc, vt, "_FillValue", NC_FLOAT, 1, &fill));
  nc_ok(nc_enddef(nc));
  std::vector<double> levs(d[2]), lats(d[1]), lons(d[0]);
  for (uint64_t k = 0; k < d[2]; ++k) levs[k] = 100.0 + 900.0 * double(k) / double(d[2]);  // top first
  for (uint64_t k = 0; k < d[1]; ++k) lats[k] = 80.0 - 10.0 * double(k);                     // north first
  for (uint64_t k = 0; k < d[0]; ++k) lons[k] = 2.5 * double(k);
  nc_ok(nc_put_var_double(nc, vlev, levs.data()));
  nc_ok(nc_put_var_double(nc, vlat, lats.data()));
  nc_ok(nc_put_var_double(nc, vlon, lons.data()));
  std::vector<float> stored(2 * v.voxel_count());
  for (uint64_t t = 0; t < 2; ++t)
    for (uint64_t z = 0; z < d[2]; ++z)
      for (uint64_t y = 0; y < d[1]; ++y)
        for (uint64_t x = 0; x < d[0]; ++x) {
          const float value = v.values[((d[2] - 1 - z) * d[1] + (d[1] - 1 - y)) * d[0] + x];
          stored[((t * d[2] + z) * d[1] + y) * d[0] + x] = std::isnan(value) ? fill : value + (t == 0 ? 1.0f : 0.0f);
        }
  nc_ok(nc_put_var_float(nc, vt, stored.data()));
  nc_ok(nc_close(nc));
  return path;
}

// VTI with `v` as point data, uncompressed raw appended (streams) or compressed (loads whole).
inline std::filesystem::path write_vti_file(const std::filesystem::path& dir, const std::string& stem, const Volume& v,
                                            bool compress) {
  const auto path = dir / (stem + (compress ? "_z" : "") + ".vti");
  Volume w = v;
  w.spacing = {0.5, 2.0, 1.5};
  w.origin = {-1.0, 3.0, 7.0};
  write_vti(path, {{"scalars", &w}, {"other", &w}}, VtiWriteOptions{compress});
  return path;
}

}  // namespace tfm::slab_test
