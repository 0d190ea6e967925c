// Writes the starting corpora of the library-backed fuzz targets (tools/fuzz.sh runs it before
// fuzzing; nothing binary is kept in the repository): small NetCDF files in each format with the
// features the reader maps (time and member dimensions, coordinates, fill values, packing,
// _Unsigned), GRIB 1 and 2 messages on several levels, times and members with missing points,
// and PNGs of every colour type. Usage: fuzz_make_seeds OUTDIR (creates OUTDIR/{netcdf,grib,png}).
#include <eccodes.h>
#include <netcdf.h>
#include <png.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

void nc(int status, const char* what) {
  if (status != NC_NOERR) throw std::runtime_error(std::string(what) + ": " + nc_strerror(status));
}

// time(unlimited) x member x lev x lat x lon with coordinates, a float variable with _FillValue
// and valid_range, and a packed unsigned short variable.
void write_netcdf(const fs::path& path, int mode) {
  int id;
  nc(nc_create(path.c_str(), mode | NC_CLOBBER, &id), "create");
  int time, member, lev, lat, lon;
  nc(nc_def_dim(id, "time", NC_UNLIMITED, &time), "dim");
  nc(nc_def_dim(id, "member", 2, &member), "dim");
  nc(nc_def_dim(id, "lev", 3, &lev), "dim");
  nc(nc_def_dim(id, "lat", 4, &lat), "dim");
  nc(nc_def_dim(id, "lon", 5, &lon), "dim");
  int v_time, v_lev, v_lat, v_lon, v_t, v_p;
  nc(nc_def_var(id, "time", NC_DOUBLE, 1, &time, &v_time), "var");
  nc(nc_put_att_text(id, v_time, "units", 24, "hours since 2000-01-01 0"), "att");
  nc(nc_def_var(id, "lev", NC_FLOAT, 1, &lev, &v_lev), "var");
  nc(nc_put_att_text(id, v_lev, "units", 3, "hPa"), "att");
  nc(nc_def_var(id, "lat", NC_FLOAT, 1, &lat, &v_lat), "var");
  nc(nc_put_att_text(id, v_lat, "units", 13, "degrees_north"), "att");
  nc(nc_def_var(id, "lon", NC_FLOAT, 1, &lon, &v_lon), "var");
  nc(nc_put_att_text(id, v_lon, "units", 12, "degrees_east"), "att");
  const int t_dims[] = {time, member, lev, lat, lon};  // classic formats: the unlimited one first
  nc(nc_def_var(id, "T", NC_FLOAT, 5, t_dims, &v_t), "var");
  const float fill = -999.0f, valid[] = {-100.0f, 400.0f};
  nc(nc_put_att_float(id, v_t, "_FillValue", NC_FLOAT, 1, &fill), "att");
  nc(nc_put_att_float(id, v_t, "valid_range", NC_FLOAT, 2, valid), "att");
  const int p_dims[] = {time, lev, lat, lon};
  nc(nc_def_var(id, "P", NC_SHORT, 4, p_dims, &v_p), "var");
  const double scale = 0.5, offset = 1000.0;
  nc(nc_put_att_double(id, v_p, "scale_factor", NC_DOUBLE, 1, &scale), "att");
  nc(nc_put_att_double(id, v_p, "add_offset", NC_DOUBLE, 1, &offset), "att");
  nc(nc_put_att_text(id, v_p, "_Unsigned", 4, "true"), "att");
  nc(nc_put_att_text(id, NC_GLOBAL, "title", 10, "fuzz seed"), "att");
  nc(nc_enddef(id), "enddef");
  const double times[] = {0, 6};
  const size_t t0 = 0, t2 = 2;
  nc(nc_put_vara_double(id, v_time, &t0, &t2, times), "put");
  const float levs[] = {1000, 850, 500}, lats[] = {-30, -10, 10, 30}, lons[] = {0, 90, 180, 270, 360};
  nc(nc_put_var_float(id, v_lev, levs), "put");
  nc(nc_put_var_float(id, v_lat, lats), "put");
  nc(nc_put_var_float(id, v_lon, lons), "put");
  std::vector<float> t(2 * 2 * 3 * 4 * 5);
  for (size_t i = 0; i < t.size(); ++i) t[i] = i % 11 == 3 ? fill : float(i % 37) * 7.5f - 50.0f;
  const size_t t_start[] = {0, 0, 0, 0, 0}, t_count[] = {2, 2, 3, 4, 5};
  nc(nc_put_vara_float(id, v_t, t_start, t_count, t.data()), "put");
  std::vector<short> p(2 * 3 * 4 * 5);
  for (size_t i = 0; i < p.size(); ++i) p[i] = short(int(i * 1237) - 30000);
  const size_t p_start[] = {0, 0, 0, 0}, p_count[] = {2, 3, 4, 5};
  nc(nc_put_vara_short(id, v_p, p_start, p_count, p.data()), "put");
  nc(nc_close(id), "close");
}

void codes(int status, const char* what) {
  if (status != CODES_SUCCESS) throw std::runtime_error(std::string(what) + ": " + codes_get_error_message(status));
}

// Messages from ecCodes' built-in GRIB 1 and 2 sample handles: parameters t and u on three
// isobaric levels, two times, two members, a 4 x 3 regular lat/lon grid with missing points.
void write_grib(const fs::path& path, const char* sample, bool ensemble) {
  std::FILE* out = std::fopen(path.c_str(), "wb");
  if (!out) throw std::runtime_error("cannot write " + path.string());
  for (const char* name : {"t", "u"})
    for (long level : {850L, 500L, 1000L})
      for (long step : {0L, 6L})
        for (long member = 0; member < (ensemble ? 2 : 1); ++member) {
          codes_handle* h = codes_grib_handle_new_from_samples(nullptr, sample);
          if (!h) throw std::runtime_error(std::string("no sample ") + sample);
          if (ensemble && std::strcmp(sample, "GRIB2") == 0) {
            codes(codes_set_long(h, "productDefinitionTemplateNumber", 1), "template");
            codes(codes_set_long(h, "perturbationNumber", member), "number");
          }
          size_t len = std::strlen(name);
          codes(codes_set_string(h, "shortName", name, &len), "shortName");
          len = std::strlen("isobaricInhPa");
          codes(codes_set_string(h, "typeOfLevel", "isobaricInhPa", &len), "typeOfLevel");
          codes(codes_set_long(h, "level", level), "level");
          codes(codes_set_long(h, "stepRange", step), "step");
          codes(codes_set_long(h, "Ni", 4), "Ni");
          codes(codes_set_long(h, "Nj", 3), "Nj");
          codes(codes_set_double(h, "latitudeOfFirstGridPointInDegrees", 10), "grid");
          codes(codes_set_double(h, "latitudeOfLastGridPointInDegrees", -10), "grid");
          codes(codes_set_double(h, "longitudeOfFirstGridPointInDegrees", 0), "grid");
          codes(codes_set_double(h, "longitudeOfLastGridPointInDegrees", 30), "grid");
          codes(codes_set_double(h, "iDirectionIncrementInDegrees", 10), "grid");
          codes(codes_set_double(h, "jDirectionIncrementInDegrees", 10), "grid");
          codes(codes_set_long(h, "bitmapPresent", 1), "bitmap");
          codes(codes_set_double(h, "missingValue", 9999), "missing");
          double values[12];
          for (int i = 0; i < 12; ++i) values[i] = i == 5 ? 9999 : 200.0 + level / 10.0 + i + step + member;
          codes(codes_set_double_array(h, "values", values, 12), "values");
          const void* message = nullptr;
          size_t size = 0;
          codes(codes_get_message(h, &message, &size), "message");
          std::fwrite(message, 1, size, out);
          codes_handle_delete(h);
        }
  std::fclose(out);
}

// A w x h PNG in `format` (libpng simplified API), pixels from a pattern.
void write_png(const fs::path& path, uint32_t w, uint32_t h, uint32_t format) {
  png_image p;
  std::memset(&p, 0, sizeof p);
  p.version = PNG_IMAGE_VERSION;
  p.width = w;
  p.height = h;
  p.format = format;
  std::vector<uint8_t> pixels(PNG_IMAGE_SIZE(p));
  for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = uint8_t(i * 37 + i / 7);
  std::vector<uint8_t> colormap(PNG_IMAGE_COLORMAP_SIZE(p) ? PNG_IMAGE_COLORMAP_SIZE(p) : 1);
  for (size_t i = 0; i < colormap.size(); ++i) colormap[i] = uint8_t(i * 11);
  if (format & PNG_FORMAT_FLAG_COLORMAP) {
    p.colormap_entries = 16;
    for (auto& px : pixels) px %= 16;
  }
  if (!png_image_write_to_file(&p, path.c_str(), 0, pixels.data(), 0, colormap.data()))
    throw std::runtime_error("png: " + std::string(p.message));
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s OUTDIR\n", argv[0]);
    return 2;
  }
  const fs::path out = argv[1];
  try {
    for (const char* sub : {"netcdf", "grib", "png"}) fs::create_directories(out / sub);
    write_netcdf(out / "netcdf/classic.nc", 0);
    write_netcdf(out / "netcdf/offset64.nc", NC_64BIT_OFFSET);
    write_netcdf(out / "netcdf/cdf5.nc", NC_64BIT_DATA);
    write_netcdf(out / "netcdf/netcdf4.nc", NC_NETCDF4);
    write_grib(out / "grib/levels.grib2", "GRIB2", false);
    write_grib(out / "grib/members.grib2", "GRIB2", true);
    write_grib(out / "grib/levels.grib1", "GRIB1", false);
    write_png(out / "png/rgb.png", 7, 5, PNG_FORMAT_RGB);
    write_png(out / "png/gray.png", 3, 9, PNG_FORMAT_GRAY);
    write_png(out / "png/rgba.png", 4, 4, PNG_FORMAT_RGBA);
    write_png(out / "png/linear16.png", 5, 3, PNG_FORMAT_LINEAR_RGB_ALPHA);
    write_png(out / "png/palette.png", 6, 6, PNG_FORMAT_RGB_COLORMAP);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_make_seeds: %s\n", e.what());
    return 1;
  }
  return 0;
}
