// Legacy VTK reader: hand-built ASCII and BINARY (big-endian) files of every numeric type, version
// 1 ASPECT_RATIO, CELL_DATA, FIELD arrays, components; malformed headers and data; the real
// ironProt and carotid files.
#include <gtest/gtest.h>

#include <cmath>

#include "formats_test_util.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/volume.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using formats_test::expect_error;
using formats_test::put;

Volume parse(const std::string& bytes, const std::string& var = "") {
  VolumeOptions o;
  o.variable = var;
  return parse_vtk_legacy(bytes, "mem.vtk", o);
}

const std::string kHeader3 = "# vtk DataFile Version 3.0\ntest\n";

TEST(VtkLegacy, AsciiScalarsVectorsAndCellData) {
  std::string f = kHeader3 + "ASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 3 2 2\nSPACING 0.5 1 2\nORIGIN 0 0 0\n"
                             "POINT_DATA 12\nSCALARS temp%20K float\nLOOKUP_TABLE default\n";
  for (int i = 0; i < 12; ++i) f += std::to_string(i * 1.5) + (i % 5 == 4 ? "\n" : " ");
  f += "\nVECTORS wind double\n";
  for (int i = 0; i < 12; ++i) f += "3 4 " + std::to_string(i) + "\n";
  f += "CELL_DATA 2\nSCALARS id int 1\nLOOKUP_TABLE default\n7 -8\n";
  Volume s = parse(f);  // default: the point scalars
  EXPECT_EQ(s.dims, (std::array<uint64_t, 3>{3, 2, 2}));
  EXPECT_EQ(s.spacing, (std::array<double, 3>{0.5, 1, 2}));
  EXPECT_EQ(s.at(2, 1, 1), 11 * 1.5f);
  EXPECT_NE(s.name.find("temp K"), std::string::npos);  // %20 decoded
  Volume w = parse(f, "wind");
  EXPECT_FLOAT_EQ(w.at(0, 0, 0), 5.0f);  // |(3,4,0)|
  EXPECT_FLOAT_EQ(w.at(1, 1, 1), float(std::sqrt(25.0 + 100.0)));
  EXPECT_EQ(parse(f, "wind[2]").at(1, 1, 1), 10.0f);
  Volume c = parse(f, "id");
  EXPECT_EQ(c.dims, (std::array<uint64_t, 3>{2, 1, 1}));
  EXPECT_EQ(c.at(1, 0, 0), -8.0f);
  expect_error([&] { parse(f, "wind[3]"); }, {"component 3", "has 3"});
  expect_error([&] { parse(f, "nope"); }, {"mem.vtk", "no array 'nope'", "wind"});
}

template <class T>
void check_binary_type(const char* vtk_type, T a, T b) {
  std::string f = kHeader3 + "BINARY\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 1 1\nORIGIN 0 0 0\nSPACING 1 1 1\n"
                             "POINT_DATA 2\nSCALARS s " + std::string(vtk_type) + "\nLOOKUP_TABLE default\n";
  put(f, a, true);
  put(f, b, true);
  f += "\n";
  Volume v = parse(f);
  EXPECT_EQ(v.values[0], static_cast<float>(a)) << vtk_type;
  EXPECT_EQ(v.values[1], static_cast<float>(b)) << vtk_type;
}

TEST(VtkLegacy, BinaryBigEndianEveryType) {
  check_binary_type<uint8_t>("unsigned_char", 0, 255);
  check_binary_type<int8_t>("char", -128, 127);
  check_binary_type<uint16_t>("unsigned_short", 1, 65535);
  check_binary_type<int16_t>("short", -32768, 3926);
  check_binary_type<uint32_t>("unsigned_int", 7, 4000000000u);
  check_binary_type<int32_t>("int", -5, 123456);
  check_binary_type<int64_t>("vtktypeint64", -(int64_t(1) << 40), 3);
  check_binary_type<uint64_t>("unsigned_long", uint64_t(1) << 50, 9);
  check_binary_type<float>("float", -1.25f, 580.0f);
  check_binary_type<double>("double", 1e-300, -2.5);
}

TEST(VtkLegacy, Version1AspectRatioAndFieldArrays) {
  std::string f = "# vtk DataFile Version 1.0\nold\nBINARY\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 2 1\n"
                  "ASPECT_RATIO 2 3 4\nORIGIN 0 0 0\nPOINT_DATA 4\nSCALARS s unsigned_char\nLOOKUP_TABLE default\n";
  f += std::string("\x01\x02\x03\x04", 4);
  f += "\nFIELD fd 2\nrho 1 4 float\n";
  for (float x : {1.f, 2.f, 3.f, 4.f}) put(f, x, true);
  f += "\ntime 1 1 double\n";
  put(f, 7.0, true);
  f += "\n";
  Volume v = parse(f);
  EXPECT_EQ(v.spacing, (std::array<double, 3>{2, 3, 4}));
  EXPECT_EQ(v.values, (std::vector<float>{1, 2, 3, 4}));
  EXPECT_EQ(parse(f, "rho").values, (std::vector<float>{1, 2, 3, 4}));
  expect_error([&] { parse(f, "time"); }, {"no array 'time'"});  // one tuple: not on the grid
}

TEST(VtkLegacy, MalformedInputGivesClearErrors) {
  const std::string head = kHeader3 + "BINARY\nDATASET STRUCTURED_POINTS\n";
  std::string body = "DIMENSIONS 4 4 4\nSPACING 1 1 1\nPOINT_DATA 64\nSCALARS s float\nLOOKUP_TABLE default\n";
  std::string full = head + body + std::string(64 * 4, '\0');
  EXPECT_NO_THROW(parse(full));
  expect_error([&] { parse(full.substr(0, full.size() - 10)); }, {"mem.vtk", "needs 256 bytes", "truncated"});
  expect_error([&] { parse("hello\n"); }, {"mem.vtk", "not a legacy VTK file"});
  expect_error([&] { parse(kHeader3 + "TEXT\n"); }, {"expected ASCII or BINARY"});
  expect_error([&] { parse(kHeader3 + "ASCII\nDATASET POLYDATA\n"); }, {"POLYDATA", "not supported"});
  expect_error([&] { parse(head + "DIMENSIONS 4 4 4\nPOINT_DATA 63\n"); }, {"POINT_DATA 63 does not match", "64 points"});
  expect_error([&] { parse(head + "DIMENSIONS 4 4 4\nPOINT_DATA 64\nSCALARS s quad\n"); }, {"unknown data type 'quad'"});
  expect_error([&] { parse(head + "DIMENSIONS 4 4 4\nPOINT_DATA 64\nSCALARS s bit\n"); }, {"'bit' is not supported"});
  expect_error([&] { parse(head + "DIMENSIONS 4000000 4000000 4000000\n"); }, {"too large"});
  expect_error([&] { parse(head + "DIMENSIONS -4 4 4\n"); }, {"non-negative integer", "-4"});
  expect_error([&] { parse(head + "DIMENSIONS 0 4 4\n"); }, {"dimension is 0"});
  expect_error([&] { parse(head + "SPACING 1 0 1\nDIMENSIONS 2 2 2\n"); }, {"SPACING must be positive"});
  expect_error([&] { parse(head + "POINT_DATA 8\n"); }, {"before DIMENSIONS"});
  expect_error([&] { parse(head + "DIMENSIONS 2 2 2\nPOINT_DATA 8\nSCALARS s float 9\n"); }, {"components must be 1..4"});
  // ASCII values must be values of the declared type (999 was read into a uint8 field).
  const std::string text = kHeader3 + "ASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 2 2\nPOINT_DATA 8\n";
  EXPECT_NO_THROW(parse(text + "SCALARS s unsigned_char\n1 2 3 4 5 6 7 255\n"));
  expect_error([&] { parse(text + "SCALARS s unsigned_char\n1 2 3 4 5 6 7 999\n"); },
               {"mem.vtk", "SCALARS 's': value 999 is no uint8 value"});
  expect_error([&] { parse(text + "SCALARS s short\n1 2 3 4 5 6 7 2.5\n"); }, {"value 2.5 is no int16 value"});
  expect_error([&] { parse(head + "DIMENSIONS 2 2 2\nPOINT_DATA 8\nFROBNICATE x\n"); }, {"unknown keyword"});
  // A huge array claimed by a header must not be allocated: it fails the size check first.
  expect_error([&] { parse(head + "DIMENSIONS 10000 10000 1000\nPOINT_DATA 100000000000\nSCALARS s double\n"); },
               {"needs 800000000000 bytes"});
  std::string ascii = kHeader3 + "ASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 1 1\nPOINT_DATA 2\nSCALARS s float\n"
                                 "LOOKUP_TABLE default\n1.5 x7\n";
  expect_error([&] { parse(ascii); }, {"expected a number", "x7"});
  expect_error([&] { parse(ascii.substr(0, ascii.size() - 4)); }, {"ends after 1 of 2 values"});
  expect_error([&] { parse(kHeader3 + "ASCII\nDATASET STRUCTURED_POINTS\n"); }, {"no DIMENSIONS"});
}

std::string data(const std::string& rel) {
  const std::string d = test::shared_data_dir();
  return d.empty() ? "" : d + "/" + rel;
}

TEST(VtkLegacyRealFiles, IronProteinAndCarotid) {
  if (data("").empty()) GTEST_SKIP() << "../shared/data not present";
  // ironProt.vtk: 68^3 unsigned char from byte 209 (SOURCES.md, `head -c`): compare with the bytes.
  const std::string iron_bytes = formats_test::read_bytes(data("vtk_ironprot/ironProt.vtk"));
  Volume iron = load_volume(data("vtk_ironprot/ironProt.vtk"));
  ASSERT_EQ(iron.dims, (std::array<uint64_t, 3>{68, 68, 68}));
  float lo = 255, hi = 0;
  for (size_t i = 0; i < iron.values.size(); ++i) {
    ASSERT_EQ(iron.values[i], float(static_cast<unsigned char>(iron_bytes[209 + i]))) << i;
    lo = std::min(lo, iron.values[i]);
    hi = std::max(hi, iron.values[i]);
  }
  EXPECT_EQ(lo, 0.0f);
  EXPECT_EQ(hi, 255.0f);
  // carotid.vtk: python3 struct.unpack('>f') of the SCALARS block (from byte 182): range 0..580,
  // point (40,25,20) = 51.0; |VECTORS| max 22.694928, vector at that point
  // (0.015543, -0.000251, -0.019555).
  Volume s = load_volume(data("vtk_carotid/carotid.vtk:scalars"));
  Volume v = load_volume(data("vtk_carotid/carotid.vtk:vectors"));
  ASSERT_EQ(s.dims, (std::array<uint64_t, 3>{76, 49, 45}));
  EXPECT_NO_THROW(require_same_grid(s, v));
  // ORIGIN 100 80 1, in the volume and in what `info` says of each array.
  EXPECT_EQ(s.origin, (std::array<double, 3>{100, 80, 1}));
  for (const ArrayInfo& a : describe_file(data("vtk_carotid/carotid.vtk")).arrays) EXPECT_EQ(a.origin, s.origin) << a.name;
  EXPECT_EQ(s.at(40, 25, 20), 51.0f);
  EXPECT_EQ(*std::max_element(s.values.begin(), s.values.end()), 580.0f);
  EXPECT_NEAR(*std::max_element(v.values.begin(), v.values.end()), 22.694928, 1e-5);
  EXPECT_NEAR(v.at(40, 25, 20), std::sqrt(0.015543 * 0.015543 + 0.000251 * 0.000251 + 0.019555 * 0.019555), 1e-6);
  EXPECT_FLOAT_EQ(load_volume(data("vtk_carotid/carotid.vtk:vectors[2]")).at(40, 25, 20), -0.019555000588297844f);
}

}  // namespace
}  // namespace tfm
