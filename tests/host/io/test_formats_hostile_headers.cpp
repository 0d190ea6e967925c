// Hostile headers that the libraries would trust (what the NetCDF and GRIB fuzz targets found):
// a classic NetCDF header whose name length or counts claim gigabytes (netCDF-C allocates them
// before reading), GRIB 2 messages whose length or sections run past their end (ecCodes then
// returns fields without end) or come out of order (ecCodes then allocates without end), and a GRIB 1 bitmap section shorter than its header (ecCodes
// aborts). tfmatch's own checks refuse them first, naming the file and what
// is wrong, from a file and from memory alike.
#include <gtest/gtest.h>

#include <fstream>
#include <string>
#include <vector>

#include "cli_runner.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm {
namespace {

void put(std::string& s, uint64_t v, int bytes) {
  for (int k = bytes - 1; k >= 0; --k) s.push_back(char((v >> (8 * k)) & 0xff));
}

// Expects f() to throw std::runtime_error holding every needle, and that it allocated nothing
// large on the way (resident memory grows by less than 64 MiB).
template <class F>
void expect_refused(F f, std::initializer_list<std::string> needles) {
  const uint64_t before = resident_memory();
  try {
    f();
    ADD_FAILURE() << "accepted";
  } catch (const std::runtime_error& e) {
    for (const std::string& n : needles) EXPECT_NE(std::string(e.what()).find(n), std::string::npos) << e.what();
  }
  EXPECT_LT(resident_memory(), before + (uint64_t(64) << 20));
}

// CDF-1: magic, numrecs, then a dimension list whose first name claims `name_length` bytes.
std::string netcdf_claiming_name(uint32_t name_length) {
  std::string s = std::string("CDF\x01", 4);
  put(s, 0, 4);           // numrecs
  put(s, 0x0A, 4);        // NC_DIMENSION
  put(s, 1, 4);           // one dimension
  put(s, name_length, 4);  // its name's length
  s += "x";
  s.resize(64, '\0');
  return s;
}

// A tiny file that claims a huge grid is short; that is the error, whatever the memory budget
// (it read "needs 3.64 TiB ... raise it with --max-memory"), for raw files and VTI arrays alike.
// `info` names a raw file's element type as resolved ("float32", not "from the file name").
TEST(FormatsHostileHeaders, ATinyFileClaimingAHugeGridIsShortNotTooLarge) {
  test::TempDir dir;
  std::ofstream(dir / "s_10000x10000x10000_float32.raw", std::ios::binary) << "abcdefgh";
  try {
    load_volume(dir / "s_10000x10000x10000_float32.raw");
    ADD_FAILURE() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("file has 8 bytes"), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find("--max-memory"), std::string::npos) << e.what();
  }
  std::ofstream(dir / "huge.vti") << "<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\">"
                                     "<ImageData WholeExtent=\"0 9999 0 9999 0 9999\" Origin=\"0 0 0\" Spacing=\"1 1 1\">"
                                     "<Piece Extent=\"0 9999 0 9999 0 9999\"><PointData Scalars=\"a\">"
                                     "<DataArray type=\"Float32\" Name=\"a\" format=\"ascii\">1 2 3</DataArray>"
                                     "</PointData></Piece></ImageData></VTKFile>";
  try {
    load_volume(dir / "huge.vti");
    ADD_FAILURE() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("the text is too short"), std::string::npos) << e.what();
  }
  std::vector<char> bytes(4 * 8, 0);
  std::ofstream(dir / "t_2x2x2_float32.raw", std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
  EXPECT_EQ(describe_file(dir / "t_2x2x2_float32.raw").arrays.at(0).type, "float32");
}

TEST(FormatsHostileHeaders, NetcdfClassicHeaderClaimingGigabytesIsRefused) {
  const std::string huge_name = netcdf_claiming_name(0xB8B8B8B8u);  // 3 GB, as the fuzzer found
  expect_refused([&] { parse_netcdf(huge_name, "name.nc", {}); }, {"name.nc: NetCDF header", "the name of a dimension"});
  expect_refused([&] { describe_netcdf_bytes(huge_name, "name.nc"); }, {"name.nc: NetCDF header"});
  // A dimension count no file of this size can hold.
  std::string many = std::string("CDF\x02", 4);
  put(many, 0, 4);
  put(many, 0x0A, 4);
  put(many, 0x10000000, 4);
  many.resize(64, '\0');
  expect_refused([&] { parse_netcdf(many, "many.nc", {}); }, {"many.nc: NetCDF header", "claims 268435456 entries"});
  // The same from a file on disk.
  test::TempDir dir;
  std::ofstream(dir / "name.nc", std::ios::binary) << huge_name;
  expect_refused([&] { load_volume(dir / "name.nc"); }, {"name.nc: NetCDF header"});
}

// A CDF-1 file with dimensions (name, length) and one float variable "v" over `var_dims`.
std::string netcdf_with(const std::vector<std::pair<std::string, uint32_t>>& dims, const std::vector<uint32_t>& var_dims,
                        uint32_t var_type = 5) {
  auto name = [](std::string& s, const std::string& n) {
    put(s, n.size(), 4);
    s += n;
    s.resize((s.size() + 3) / 4 * 4, '\0');
  };
  std::string s = std::string("CDF\x01", 4);
  put(s, 0, 4);
  put(s, 0x0A, 4);
  put(s, dims.size(), 4);
  for (const auto& [n, len] : dims) name(s, n), put(s, len, 4);
  put(s, 0, 8);  // no global attributes
  put(s, 0x0B, 4);
  put(s, 1, 4);
  name(s, "v");
  put(s, var_dims.size(), 4);
  for (uint32_t d : var_dims) put(s, d, 4);
  put(s, 0, 8);  // no attributes
  put(s, var_type, 4);
  put(s, 4, 4);  // vsize
  put(s, uint32_t(s.size() + 4), 4);  // begin: right after the header
  s.resize(s.size() + 256, '\0');
  return s;
}

// Shapes of header that crash netCDF-C itself (what the fuzzer found next): a name longer than
// the NC_MAX_NAME buffers it copies into, the unlimited dimension after the first (a division by
// zero while sizing the variable), a type that is no classic type.
TEST(FormatsHostileHeaders, NetcdfHeadersThatCrashNetcdfCAreRefused) {
  expect_refused([&] { parse_netcdf(netcdf_with({{std::string(300, 'x'), 4}}, {0}), "long.nc", {}); },
                 {"long.nc: NetCDF header", "300 bytes, more than netCDF's 256"});
  expect_refused([&] { parse_netcdf(netcdf_with({{"x", 4}, {"t", 0}}, {0, 1}), "rec.nc", {}); },
                 {"rec.nc: NetCDF header", "unlimited dimension in position 1"});
  expect_refused([&] { parse_netcdf(netcdf_with({{"x", 4}}, {0}, 9), "type.nc", {}); }, {"type.nc", "9 is not a classic type"});
  expect_refused([&] { parse_netcdf(netcdf_with({{"x", 4}}, {3}), "dim.nc", {}); }, {"names dimension 3 of 1"});
  // A wrong value inside the file is not said to lie beyond its end; a header cut short is.
  try {
    parse_netcdf(netcdf_with({{"x", 4}}, {0}, 9), "type.nc", {});
    ADD_FAILURE() << "type 9 accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()).find("file's"), std::string::npos) << e.what();
  }
  const std::string cut = netcdf_with({{"x", 4}}, {0}).substr(0, 30);
  expect_refused([&] { parse_netcdf(cut, "cut.nc", {}); }, {"cut.nc: NetCDF header", "of the file's 30 bytes"});
  // The same layout with sound values opens (the checks do not refuse real files).
  VolumeOptions v;
  v.variable = "v";
  EXPECT_EQ(parse_netcdf(netcdf_with({{"t", 0}, {"y", 2}, {"x", 4}}, {1, 2}), "ok.nc", v).voxel_count(), 8u);
}

// A GRIB 2 message: indicator (16 bytes) with `length`, then the given sections, then 7777.
std::string grib2(const std::vector<std::pair<uint32_t, int>>& sections, int64_t length = -1) {
  std::string body;
  for (auto [bytes, number] : sections) {
    put(body, bytes, 4);
    body.push_back(char(number));
    body.resize(body.size() + (bytes >= 5 ? std::min<uint32_t>(bytes, 64) - 5 : 0), '\0');
  }
  std::string m = "GRIB";
  m += std::string("\xff\xff\x00\x02", 4);
  put(m, length >= 0 ? uint64_t(length) : 16 + body.size() + 4, 8);
  return m + body + "7777";
}

TEST(FormatsHostileHeaders, GribSectionsPastTheirMessageAreRefused) {
  // Section 3 claims 796226418 bytes inside a 64-byte message (what the fuzzer found).
  const std::string bad_section = grib2({{21, 1}, {796226418, 47}});
  expect_refused([&] { parse_grib(bad_section, "sec.grib2", {}); },
                 {"sec.grib2: GRIB message 1", "section 47", "past the message's end"});
  // A total length past the end of the file.
  const std::string long_message = grib2({{21, 1}}, 1 << 30);
  expect_refused([&] { describe_grib_bytes(long_message, "len.grib2"); }, {"len.grib2: GRIB message 1", "claims 1073741824 bytes"});
  // The second message of a file is checked too, after a well-framed first one.
  const std::vector<std::pair<uint32_t, int>> whole = {{21, 1}, {14, 3}, {9, 4}, {11, 5}, {6, 6}, {5, 7}};
  const std::string two = grib2(whole) + grib2({{21, 1}, {4, 3}});
  expect_refused([&] { parse_grib(two, "two.grib2", {}); }, {"GRIB message 2"});
  // Sections out of GRIB 2's order (ecCodes then built accessors without end: gigabytes in
  // seconds, what the fuzzer found): a repeated section 6, a message ending before section 7.
  expect_refused([&] { describe_grib_bytes(grib2({{21, 1}, {14, 3}, {9, 4}, {11, 5}, {6, 6}, {6, 6}}), "order.grib2"); },
                 {"order.grib2: GRIB message 1", "section 6 at byte 77 follows section 6"});
  expect_refused([&] { parse_grib(grib2({{21, 1}, {14, 3}, {9, 4}, {11, 5}, {6, 6}}), "short.grib2", {}); },
                 {"ends after section 6, not after section 7"});
  // Several fields in one message (the runs 4-7 and 3-7 repeated) are in order.
  try {
    describe_grib_bytes(grib2({{21, 1}, {14, 3}, {9, 4}, {11, 5}, {6, 6}, {5, 7}, {9, 4}, {11, 5}, {6, 6}, {5, 7},
                               {14, 3}, {9, 4}, {11, 5}, {6, 6}, {5, 7}}),
                        "multi.grib2");
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()).find("order"), std::string::npos) << e.what();
  }
  test::TempDir dir;
  std::ofstream(dir / "sec.grib2", std::ios::binary) << bad_section;
  expect_refused([&] { load_volume(dir / "sec.grib2"); }, {"sec.grib2: GRIB message 1", "past the message's end"});
}

// A GRIB 1 message with product, grid and bitmap sections (flags 0xC0) whose bitmap section
// claims `bitmap_bytes`; the sections' contents are zero.
std::string grib1_with_bitmap(uint32_t bitmap_bytes) {
  std::string body;
  auto section = [&](uint32_t bytes, uint32_t stored, int flag_at = -1) {
    const size_t at = body.size();
    put(body, stored, 3);
    body.resize(at + bytes, '\0');
    if (flag_at >= 0) body[at + size_t(flag_at)] = char(0xC0);
  };
  section(28, 28, 7);              // product definition, flag octet 8: grid and bitmap present
  section(32, 32);                 // grid description
  section(8, bitmap_bytes);        // bitmap: 8 bytes, claiming bitmap_bytes
  section(12, 12);                 // binary data
  std::string m = "GRIB";
  put(m, 8 + body.size() + 4, 3);
  m.push_back(char(1));
  return m + body + "7777";
}

TEST(FormatsHostileHeaders, Grib1SectionsShorterThanTheirHeaderAreRefused) {
  // A bitmap section claiming 0 bytes makes ecCodes abort the process (an assertion in its bitmap
  // accessor; what the GRIB fuzz target found); a grid section claiming past the message's end.
  expect_refused([&] { parse_grib(grib1_with_bitmap(0), "bms.grib", {}); },
                 {"bms.grib: GRIB message 1", "bitmap section at byte 68 claims 0 bytes"});
  expect_refused([&] { describe_grib_bytes(grib1_with_bitmap(3), "bms.grib"); }, {"bitmap section", "claims 3 bytes"});
  const std::string two = grib1_with_bitmap(8) + grib1_with_bitmap(70000);
  expect_refused([&] { describe_grib_bytes(two, "two.grib"); }, {"GRIB message 2", "claims 70000 bytes"});
  // The well-framed message passes the framing check (ecCodes then reads or refuses its contents).
  try {
    describe_grib_bytes(grib1_with_bitmap(8), "ok.grib");
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()).find("section at byte"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tfm
