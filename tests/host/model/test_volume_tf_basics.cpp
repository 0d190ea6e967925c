// Raw and .dat volumes, the TF JSON format and resampling, and the field-to-TF mapping.
#include <bit>
#include <cmath>
#include <algorithm>
#include <cstring>
#include <fstream>

#include <gtest/gtest.h>

#include "cli_runner.h"
#include "tfmatch/io/tf_json.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm {
namespace {

using test::TempDir;

template <class T>
void write_values(const std::string& path, const std::vector<T>& v, bool big_endian = false) {
  std::ofstream out(path, std::ios::binary);
  for (T x : v) {
    unsigned char b[sizeof(T)];
    std::memcpy(b, &x, sizeof(T));
    if (big_endian != (std::endian::native == std::endian::big)) std::reverse(b, b + sizeof(T));
    out.write(reinterpret_cast<const char*>(b), sizeof(T));
  }
}

TEST(RawVolume, DimensionsAndTypeFromTheName) {
  TempDir dir;
  std::vector<uint16_t> v(3 * 4 * 5);
  for (size_t i = 0; i < v.size(); ++i) v[i] = uint16_t(1000 + 7 * i);
  write_values(dir / "head_3x4x5_uint16.raw", v);
  Volume vol = load_volume(dir / "head_3x4x5_uint16.raw");
  EXPECT_EQ(vol.dims, (std::array<uint64_t, 3>{3, 4, 5}));
  EXPECT_EQ(vol.at(2, 3, 4), float(1000 + 7 * 59));  // x fastest
  EXPECT_EQ(vol.at(1, 0, 0), 1007.0f);
}

TEST(RawVolume, FlagsForTypeDimsAndByteOrder) {
  TempDir dir;
  std::vector<int16_t> v = {-300, 5, 32767, -32768, 0, 1, 2, 3};
  write_values(dir / "plain.raw", v, /*big_endian=*/true);
  VolumeOptions o;
  o.dims = std::array<uint64_t, 3>{2, 2, 2};
  o.type = ScalarType::Int16;
  o.big_endian = true;
  Volume vol = load_volume(dir / "plain.raw", o);
  EXPECT_EQ(vol.values[0], -300.0f);
  EXPECT_EQ(vol.values[3], -32768.0f);
  std::vector<double> d = {1.5, -2.25, NAN, 1e300};
  write_values(dir / "d_4x1x1_float64.raw", d);
  Volume dv = load_volume(dir / "d_4x1x1_float64.raw");
  EXPECT_EQ(dv.values[1], -2.25f);
  EXPECT_TRUE(std::isnan(dv.values[2]));
  EXPECT_TRUE(std::isinf(dv.values[3]));  // out of float range: no data for the range
  EXPECT_EQ(finite_stats(dv.values).nan, 2u);
}

// Four-byte elements are read into the values and decoded in place, block by block (4 Mi
// elements): both byte orders, integer and float types, and a volume one block and a bit long.
TEST(RawVolume, FourByteTypesDecodeInPlaceAcrossBlocks) {
  TempDir dir;
  const uint64_t n = (uint64_t(1) << 22) + 5;
  std::vector<uint32_t> u(n);
  for (uint64_t i = 0; i < n; ++i) u[i] = uint32_t(i * 2654435761u) >> 9;  // exact in float
  write_values(dir / "u_4194309x1x1_uint32.raw", u, /*big_endian=*/true);
  VolumeOptions big;
  big.big_endian = true;
  const Volume vu = load_volume(dir / "u_4194309x1x1_uint32.raw", big);
  ASSERT_EQ(vu.values.size(), n);
  for (uint64_t i : {uint64_t(0), uint64_t(1), (uint64_t(1) << 22) - 1, uint64_t(1) << 22, n - 1})
    EXPECT_EQ(vu.values[i], float(u[i])) << i;
  std::vector<int32_t> s = {-7, 2147483647, -2147483647 - 1, 12345};
  write_values(dir / "s_4x1x1_int32.raw", s);
  const Volume vs = load_volume(dir / "s_4x1x1_int32.raw");
  EXPECT_EQ(vs.values, (std::vector<float>{-7.0f, 2147483648.0f, -2147483648.0f, 12345.0f}));
  std::vector<float> f = {1.5f, -0.0f, NAN, 3e38f, -1e-40f, 2.0f};
  for (bool be : {false, true}) {
    write_values(dir / "f_3x2x1_float32.raw", f, be);
    VolumeOptions o;
    o.big_endian = be;
    const Volume vf = load_volume(dir / "f_3x2x1_float32.raw", o);
    for (size_t i = 0; i < f.size(); ++i)
      EXPECT_EQ(std::bit_cast<uint32_t>(vf.values[i]), std::bit_cast<uint32_t>(f[i])) << i << (be ? " big" : " little");
  }
}

// The vectorized finite min/max against a plain loop, on sizes around its 16 lanes and past the
// 2^24 values after which it empties its per-lane counts, with NaN and infinities in the lanes,
// on both sides of that point and in the tail.
TEST(FiniteStats, MatchesAPlainLoopOnAwkwardSizes) {
  for (size_t n : {size_t(0), size_t(1), size_t(15), size_t(16), size_t(17), size_t(33), size_t(1000003),
                   (size_t(16) << 20) + 35}) {
    std::vector<float> v(n);
    for (size_t i = 0; i < n; ++i) v[i] = std::sin(0.37f * float(i)) * 100.0f + float(i % 7);
    if (n > 2) v[n - 1] = NAN, v[n / 2] = INFINITY, v[1] = -INFINITY;
    for (size_t i = 3; i < n; i += 1000003) v[i] = NAN;  // in every block of counts
    if (n > 100) v[5] = -250.5f, v[n - 2] = 1e30f;
    double lo = INFINITY, hi = -INFINITY;
    uint64_t finite = 0;
    for (float x : v)
      if (std::isfinite(x)) lo = std::min<double>(lo, x), hi = std::max<double>(hi, x), ++finite;
    const FiniteStats s = finite_stats(v);
    EXPECT_EQ(s.finite, finite) << n;
    EXPECT_EQ(s.nan, n - finite) << n;
    if (finite) {
      EXPECT_EQ(s.lo, lo) << n;
      EXPECT_EQ(s.hi, hi) << n;
    }
  }
  const std::vector<float> none = {NAN, INFINITY, -INFINITY};
  EXPECT_EQ(finite_stats(none).finite, 0u);
  EXPECT_EQ(finite_stats(none).nan, 3u);
}

// The vectorized, threaded coverage counts against a plain loop comparing in double, on sizes
// around its lanes and parts, with values at the float neighbours of ends that float cannot hold
// (0.1, 0.7) or reach (beyond float32), and non-finite values that never count.
TEST(RangeCoverage, MatchesAPlainDoubleLoopOnAwkwardSizesAndEnds) {
  const FieldRange ranges[] = {{0.1, 0.7}, {0.7, 0.95}, {-0.5, 0.1}, {-0.3, 0.30000001192092896}, {-1e39, 0.5},
                               {0.25, 1e39}, {0.0, 1.0}};
  for (size_t n : {size_t(0), size_t(1), size_t(17), size_t(1000003), (size_t(16) << 20) + 35}) {
    std::vector<float> v(n);
    for (size_t i = 0; i < n; ++i) v[i] = std::sin(0.37f * float(i)) * 0.8f + 0.2f;
    for (size_t i = 7; i < n; i += 999983) {  // the ends' float neighbours, in every part
      const float ends[] = {0.1f, 0.7f, 0.3f, -0.3f, 0.5f, 0.25f, 0.95f, -0.5f};
      const float e = ends[(i / 999983) % 8];
      v[i] = e;
      if (i + 1 < n) v[i + 1] = std::nextafter(e, -1.0f);
      if (i + 2 < n) v[i + 2] = std::nextafter(e, 2.0f);
      if (i + 3 < n) v[i + 3] = (i % 2) ? NAN : -INFINITY;
    }
    if (n > 2) v[n - 1] = INFINITY, v[0] = NAN;
    for (const FieldRange& r : ranges) {
      RangeCoverage plain;
      for (float x : v) {
        if (!std::isfinite(x)) continue;
        ++plain.finite;
        plain.below += double(x) < r.lo;
        plain.above += double(x) > r.hi;
      }
      const RangeCoverage c = range_coverage(v, r);
      EXPECT_EQ(c.finite, plain.finite) << n << " [" << r.lo << ", " << r.hi << "]";
      EXPECT_EQ(c.below, plain.below) << n << " [" << r.lo << ", " << r.hi << "]";
      EXPECT_EQ(c.above, plain.above) << n << " [" << r.lo << ", " << r.hi << "]";
    }
  }
}

// Same dims, other spacing or origin: compared index by index, with a warning naming both files
// and the difference; rounding in the files' numbers (1e-9 of the spacing or extent) is no difference.
TEST(GridGeometry, SameDimsOtherSpacingOrOriginIsSaid) {
  Volume a, b;
  a.dims = b.dims = {100, 100, 90};
  a.name = "isabel_30.vti", b.name = "copy.vti";
  a.spacing = {4.008, 4.008, 0.2};
  b.spacing = {4.008 * (1 + 1e-9), 4.008, 0.2};
  a.origin = b.origin = {-200.0, -200.0, 0.0};
  EXPECT_EQ(grid_geometry_warning(a, b), "");
  b.origin[2] = 1e-7;  // 1e-7 against an extent of 18
  EXPECT_EQ(grid_geometry_warning(a, b), "");
  b.spacing = {1, 1, 1};
  EXPECT_EQ(grid_geometry_warning(a, b),
            "isabel_30.vti and copy.vti have the same 100x100x90 voxels but not the same geometry (spacing 4.008 4.008 "
            "0.2 against 1 1 1): voxels are compared index by index, and what is written takes isabel_30.vti's");
  b.spacing = a.spacing;
  b.origin = {0, 0, 0};
  const std::string w = grid_geometry_warning(a, b);
  EXPECT_NE(w.find("(origin -200 -200 0 against 0 0 0)"), std::string::npos) << w;
}

TEST(RawVolume, ErrorsNameTheFileAndTheProblem) {
  TempDir dir;
  write_values(dir / "x_2x2x2_complex64.raw", std::vector<float>(8));
  try {
    load_volume(dir / "x_2x2x2_complex64.raw");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("complex64"), std::string::npos) << e.what();
  }
  write_values(dir / "huge_100000x100000x100000_uint8.raw", std::vector<uint8_t>(8));
  EXPECT_THROW(load_volume(dir / "huge_100000x100000x100000_uint8.raw"), std::runtime_error);
  write_values(dir / "zero_0x2x2_uint8.raw", std::vector<uint8_t>(0));
  EXPECT_THROW(load_volume(dir / "zero_0x2x2_uint8.raw"), std::runtime_error);
  EXPECT_THROW(load_volume(dir.path.string()), std::runtime_error);  // a directory
}

TEST(DatVolume, DescriptorWithSpacing) {
  TempDir dir;
  write_values(dir / "data.bin", std::vector<uint8_t>{1, 2, 3, 4, 5, 6});
  std::ofstream(dir / "vol.dat") << "ObjectFileName: data.bin\nTaggedFileName: ---\nResolution: 3 2 1\n"
                                    "SliceThickness: 0.5 0.5 2\nFormat: UCHAR\n";
  Volume v = load_volume(dir / "vol.dat");
  EXPECT_EQ(v.dims, (std::array<uint64_t, 3>{3, 2, 1}));
  EXPECT_EQ(v.spacing[2], 2.0);
  EXPECT_EQ(v.at(2, 1, 0), 6.0f);
  std::ofstream(dir / "bad.dat") << "ObjectFileName: data.bin\nResolution: 3 2\nFormat: UCHAR\n";
  EXPECT_THROW(load_volume(dir / "bad.dat"), std::runtime_error);
  std::ofstream(dir / "fmt.dat") << "ObjectFileName: data.bin\nResolution: 3 2 1\nFormat: QUATERNION\n";
  EXPECT_THROW(load_volume(dir / "fmt.dat"), std::runtime_error);
  std::ofstream(dir / "size.dat") << "ObjectFileName: data.bin\nResolution: 3 2 2\nFormat: UCHAR\n";
  EXPECT_THROW(load_volume(dir / "size.dat"), std::runtime_error);
}

TEST(TransferFunction, JsonRoundTripAndResampling) {
  TransferFunction tf;
  tf.rgba = {{0, 0, 0, 0}, {1, 0.5, 0.25, 1}};
  tf.range = FieldRange{-3, 7};
  TransferFunction back = parse_tf_json(tf_to_json(tf), "memory");
  EXPECT_EQ(back.rgba, tf.rgba);
  ASSERT_TRUE(back.range);
  EXPECT_EQ(back.range->lo, -3);
  // A linear TF stays exactly linear under resampling; entry j sits at t = j/(N-1).
  TransferFunction r = tf.resampled(5);
  ASSERT_EQ(r.size(), 5u);
  for (size_t j = 0; j < 5; ++j) EXPECT_NEAR(r.rgba[j][1], 0.5 * double(j) / 4.0, 1e-15);
  EXPECT_EQ(tf.resampled(2).rgba, tf.rgba);
  EXPECT_THROW(parse_tf_json(R"({"rgba": [[0,0,0,0],[1,1,1,1]], "range": [2, 1]})", "m"), std::runtime_error);
  EXPECT_THROW(parse_tf_json(R"({"rgba": [[0,0,0,0],[1,1,1,-0.1]]})", "m"), std::runtime_error);
}

TEST(FieldMapping, CoordinatesAtTheEdgesAndOutside) {
  FieldMapping m = make_mapping({2.0, 6.0}, 5);  // one entry per unit
  uint32_t j;
  float w;
  ASSERT_TRUE(tf_coordinate(2.0f, m, j, w));
  EXPECT_EQ(j, 0u);
  EXPECT_EQ(w, 0.0f);
  ASSERT_TRUE(tf_coordinate(6.0f, m, j, w));  // the top value lands on the last entry, w = 1
  EXPECT_EQ(j, 3u);
  EXPECT_EQ(w, 1.0f);
  ASSERT_TRUE(tf_coordinate(4.5f, m, j, w));
  EXPECT_EQ(j, 2u);
  EXPECT_EQ(w, 0.5f);
  ASSERT_TRUE(tf_coordinate(-100.0f, m, j, w));
  EXPECT_EQ(j, 0u);
  EXPECT_EQ(w, 0.0f);
  ASSERT_TRUE(tf_coordinate(1e30f, m, j, w));
  EXPECT_EQ(j, 3u);
  EXPECT_EQ(w, 1.0f);
  EXPECT_FALSE(tf_coordinate(NAN, m, j, w));
  std::vector<float> constant(10, 3.0f);
  try {
    resolve_range(constant, nullptr, "c");
    ADD_FAILURE() << "a constant field has no range";
  } catch (const std::runtime_error& e) {
    // (The parameters in the style the process installed: "--range" in the test program.)
    EXPECT_EQ(std::string(e.what()).rfind("c: the field is constant (every finite value is 3), so it has no range of its "
                                          "own to map the TF over; give it one (" + parameter("ref-range") + ", ", 0),
              0u) << e.what();
  }
  FieldRange user{0, 1};
  EXPECT_NO_THROW(resolve_range(constant, &user, "c"));
  EXPECT_THROW(make_mapping({0, 1}, 1), std::invalid_argument);
  // Past kMaxTableSize the kernels' slot counts (6N + 8, 32-bit) would wrap: N = 715827882 gave
  // 4 slots, and the assembly wrote far past them.
  EXPECT_NO_THROW(make_mapping({0, 1}, uint32_t(kMaxTableSize)));
  for (uint32_t n : {uint32_t(kMaxTableSize) + 1, 2796202u, 715827882u, 0x80000000u})
    EXPECT_THROW(make_mapping({0, 1}, n), std::invalid_argument) << n;
}

// Ranges the float32 mapping cannot take are refused with the field's name, given or from the
// data: a span wider than FLT_MAX (v - lo would overflow to +Inf in the kernels) and one too
// narrow for 1 / (hi - lo); the widest span that still fits maps its ends to the TF's ends.
TEST(FieldMapping, RangesFloat32CannotMapAreRefusedWithTheFieldsName) {
  const auto message = [](auto f) {
    try {
      f();
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::vector<float> wide = {-3e38f, 0.0f, 3e38f}, tiny = {0.0f, 1e-40f, 5e-41f};
  std::string m = message([&] { resolve_range(wide, nullptr, "s3e38.raw"); });
  EXPECT_NE(m.find("s3e38.raw (its finite min/max"), std::string::npos) << m;
  EXPECT_NE(m.find("too wide: hi - lo leaves float32"), std::string::npos) << m;
  const FieldRange given{-3e38, 3e38};
  m = message([&] { resolve_range(tiny, &given, "--range"); });
  EXPECT_NE(m.find("--range: range -3e+38,3e+38 is too wide"), std::string::npos) << m;
  m = message([&] { resolve_range(tiny, nullptr, "tiny.raw"); });
  EXPECT_NE(m.find("tiny.raw (its finite min/max"), std::string::npos) << m;
  EXPECT_NE(m.find("too narrow"), std::string::npos) << m;
  const FieldRange widest{-1.7e38, 1.7e38};
  EXPECT_NO_THROW(check_range(widest, "w"));
  const FieldMapping map = make_mapping(widest, 64);
  uint32_t j;
  float w;
  ASSERT_TRUE(tf_coordinate(1.7e38f, map, j, w));
  EXPECT_EQ(float(j) + w, 63.0f);
  ASSERT_TRUE(tf_coordinate(0.0f, map, j, w));
  EXPECT_NEAR(float(j) + w, 31.5f, 1e-4f);
}

TEST(FieldMapping, RangeCoverageWarnsAbove5AndFailsAbove95Percent) {
  // 0..99 and two NaNs (not counted): a value is outside when below lo or above hi.
  std::vector<float> v(100);
  for (int i = 0; i < 100; ++i) v[i] = float(i);
  v.push_back(NAN);
  v.push_back(INFINITY);
  const RangeCoverage c = range_coverage(v, {10, 89.5});
  EXPECT_EQ(c.finite, 100u);
  EXPECT_EQ(c.below, 10u);
  EXPECT_EQ(c.above, 10u);
  EXPECT_DOUBLE_EQ(c.outside_fraction(), 0.2);
  // Exactly 5 % outside: quiet; 6 %: a warning with the counts.
  EXPECT_EQ(check_range_coverage(v, {0, 94}, "f", "the TF file's range", false), "");
  const std::string w = check_range_coverage(v, {0, 93.5}, "f", "the TF file's range", false);
  EXPECT_NE(w.find("6.0 % of its finite values lie outside the TF file's range [0, 93.5] (0 below, 6 above, of 100"),
            std::string::npos) << w;
  EXPECT_NE(w.find("spans [0, 99]"), std::string::npos) << w;
  // 95 % outside: still a warning; 96 %: an error naming the way out, unless allowed.
  EXPECT_NE(check_range_coverage(v, {-10, 4.5}, "f", "r", false), "");
  try {
    check_range_coverage(v, {-10, 3.5}, "f", "the TF file's range", false);
    ADD_FAILURE() << "no error at 96 %";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("96.0 %"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--allow-out-of-range"), std::string::npos) << e.what();
  }
  const std::string allowed = check_range_coverage(v, {-10, 3.5}, "f", "r", true);
  EXPECT_NE(allowed.find("(--allow-out-of-range)"), std::string::npos) << allowed;
}

}  // namespace
}  // namespace tfm

namespace tfm {
namespace {

// A field kept in other units (a unorm16 volume of kelvin: value = 60 stored + 240) maps onto the
// TF as its values do: the same entry and weight, up to float rounding, across the range.
TEST(ValueMapping, StoredNumbersMapOntoTheTfAsTheirValues) {
  const FieldRange kelvin{250.0, 290.0};
  const ValueMapping stored{60.0, 240.0};
  const FieldMapping by_value = make_mapping(kelvin, 64), by_stored = make_mapping(kelvin, 64, stored);
  for (uint32_t c = 0; c <= 65535; c += 97) {
    const float n = float(c) / 65535.0f;
    const float value = float(60.0 * n + 240.0);
    uint32_t j1 = 0, j2 = 0;
    float w1 = 0, w2 = 0;
    ASSERT_TRUE(tf_coordinate(value, by_value, j1, w1));
    ASSERT_TRUE(tf_coordinate(n, by_stored, j2, w2));
    EXPECT_NEAR(double(j1) + w1, double(j2) + w2, 2e-4) << "code " << c;
  }
  EXPECT_THROW(make_mapping(kelvin, 64, ValueMapping{0.0, 1.0}), std::invalid_argument);
  EXPECT_THROW(make_mapping(kelvin, 64, ValueMapping{-1.0, 1.0}), std::invalid_argument);
}

}  // namespace
}  // namespace tfm
