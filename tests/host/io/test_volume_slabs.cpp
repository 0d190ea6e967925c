// Slab readers (host/io/volume_io.h open_volume_slabs): every slab of every streaming format
// holds exactly what load_volume() gives there; the other encodings do not stream; truncated
// files fail naming the file.
#include <gtest/gtest.h>

#include <bit>
#include <filesystem>

#include "formats_test_util.h"
#include "slab_test_files.h"
#include "tfmatch/io/volume_io.h"

namespace tfm {
namespace {

using formats_test::expect_error;
using formats_test::TempDir;

// Reads `spec` through its slab reader `slab` slices at a time and compares with load_volume().
void expect_slabs_match_load(const std::string& spec, uint64_t slab, const VolumeOptions& options = {}) {
  SCOPED_TRACE(spec + ", " + std::to_string(slab) + " slices per slab");
  const Volume whole = load_volume(spec, options);
  std::unique_ptr<VolumeSlabReader> r = open_volume_slabs(spec, options);
  ASSERT_TRUE(r);
  EXPECT_TRUE(r->streams());
  const Volume& g = r->grid();
  EXPECT_EQ(g.dims, whole.dims);
  EXPECT_EQ(g.spacing, whole.spacing);
  EXPECT_EQ(g.origin, whole.origin);
  EXPECT_EQ(g.name, whole.name);
  EXPECT_TRUE(g.values.empty());
  const uint64_t s = r->slice_voxels();
  std::vector<float> got(whole.values.size());
  // Backwards, so that every read seeks.
  for (uint64_t z0 = ((g.dims[2] - 1) / slab) * slab;; z0 -= slab) {
    const uint64_t n = std::min(slab, g.dims[2] - z0);
    r->read_slices(z0, n, got.data() + z0 * s);
    if (z0 == 0) break;
  }
  for (size_t i = 0; i < got.size(); ++i)
    ASSERT_EQ(std::bit_cast<uint32_t>(got[i]), std::bit_cast<uint32_t>(whole.values[i])) << "voxel " << i;
}

TEST(VolumeSlabs, RawDatNetcdfAndVtiSlabsAreTheLoadedValues) {
  TempDir dir;
  const Volume v = slab_test::test_field({13, 7, 11}, 1);
  const auto raw = slab_test::write_raw(dir.path(), "a", v);
  const auto nc = slab_test::write_netcdf(dir.path(), "a", v);
  const auto vti = slab_test::write_vti_file(dir.path(), "a", v, false);
  formats_test::write_bytes(dir / "a.dat", "ObjectFileName: " + raw.filename().string() +
                                               "\nResolution: 13 7 11\nFormat: FLOAT\nSliceThickness: 1 2 3\n");
  for (uint64_t slab : {1, 3, 4, 11}) {
    expect_slabs_match_load(raw.string(), slab);
    expect_slabs_match_load((dir / "a.dat").string(), slab);
    expect_slabs_match_load(nc.string() + ":T,time=1", slab);
    expect_slabs_match_load(nc.string() + ":T", slab);
    expect_slabs_match_load(vti.string(), slab);
    expect_slabs_match_load(vti.string() + ":other", slab);
  }
  // Slabs of the NetCDF file are the file's slices in reverse (pressure levels stored top first).
  const Volume t1 = load_volume(nc.string() + ":T,time=1");
  for (size_t i = 0; i < v.values.size(); ++i)
    ASSERT_EQ(std::bit_cast<uint32_t>(t1.values[i]), std::bit_cast<uint32_t>(v.values[i])) << i;
}

TEST(VolumeSlabs, OtherElementTypesAndByteOrders) {
  TempDir dir;
  std::string bytes;
  for (int i = 0; i < 5 * 3 * 7; ++i) formats_test::put<uint16_t>(bytes, uint16_t(i * 613), true);
  formats_test::write_bytes(dir / "b_5x3x7_uint16.raw", bytes);
  VolumeOptions big;
  big.big_endian = true;
  expect_slabs_match_load((dir / "b_5x3x7_uint16.raw").string(), 2, big);
  bytes.clear();
  for (int i = 0; i < 4 * 4 * 3; ++i) formats_test::put<double>(bytes, i * 0.1 - 2.0, false);
  formats_test::write_bytes(dir / "c.bin.raw", bytes);
  VolumeOptions o;
  o.dims = std::array<uint64_t, 3>{4, 4, 3};
  o.type = ScalarType::Float64;
  expect_slabs_match_load((dir / "c.bin.raw").string(), 2, o);
}

TEST(VolumeSlabs, CompressedInlineAndOtherFormatsDoNotStream) {
  TempDir dir;
  const Volume v = slab_test::test_field({6, 5, 4}, 2);
  EXPECT_FALSE(open_volume_slabs(slab_test::write_vti_file(dir.path(), "z", v, true).string()));
  formats_test::write_bytes(dir / "ascii.vti",
                            "<VTKFile type=\"ImageData\"><ImageData WholeExtent=\"0 1 0 0 0 0\"><Piece>"
                            "<PointData><DataArray type=\"Float32\" Name=\"a\" format=\"ascii\">1 2</DataArray>"
                            "</PointData></Piece></ImageData></VTKFile>");
  EXPECT_FALSE(open_volume_slabs((dir / "ascii.vti").string()));
  formats_test::write_bytes(dir / "n.nrrd", "NRRD0004\ntype: float\ndimension: 3\nsizes: 1 1 1\nencoding: raw\n\n" +
                                                std::string(4, '\0'));
  EXPECT_FALSE(open_volume_slabs((dir / "n.nrrd").string()));
  // ... and open_volume_slabs_or_load() loads them whole behind the same interface.
  std::unique_ptr<VolumeSlabReader> r = open_volume_slabs_or_load((dir / "ascii.vti").string());
  ASSERT_TRUE(r);
  EXPECT_FALSE(r->streams());
  float two[2];
  r->read_slices(0, 1, two);
  EXPECT_EQ(two[0], 1.0f);
  EXPECT_EQ(two[1], 2.0f);
}

TEST(VolumeSlabs, TruncatedFilesFailNamingTheFile) {
  TempDir dir;
  const Volume v = slab_test::test_field({8, 8, 8}, 3);
  const auto raw = slab_test::write_raw(dir.path(), "t", v);
  const auto vti = slab_test::write_vti_file(dir.path(), "t", v, false);
  std::filesystem::resize_file(raw, 8 * 8 * 8 * 4 - 100);
  expect_error([&] { open_volume_slabs(raw.string()); }, {raw.string(), "1948 bytes", "needs 2048"});
  // Shortened after it was opened: the read that misses bytes names the file.
  std::filesystem::resize_file(raw, 8 * 8 * 8 * 4);
  std::unique_ptr<VolumeSlabReader> r = open_volume_slabs(raw.string());
  std::filesystem::resize_file(raw, 8 * 8 * 4 * 4);
  std::vector<float> out(8 * 8 * 4);
  r->read_slices(0, 4, out.data());
  expect_error([&] { r->read_slices(4, 4, out.data()); }, {raw.string(), "read failed"});
  std::filesystem::resize_file(vti, std::filesystem::file_size(vti) - 200);
  expect_error([&] { open_volume_slabs(vti.string() + ":other"); }, {vti.string(), "truncated"});
  EXPECT_THROW(r->read_slices(8, 1, out.data()), std::invalid_argument);
}

}  // namespace
}  // namespace tfm
