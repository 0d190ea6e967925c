// Hostile headers that the libraries would trust (what the NetCDF and GRIB fuzz targets found):
// a classic NetCDF header whose name length or counts claim gigabytes (netCDF-C allocates them
// before reading), and GRIB 2 messages whose length or sections run past their end (ecCodes then
// returns fields without end). tfmatch's own checks refuse them first, naming the file and what
// is wrong, from a file and from memory alike.
#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "cli_runner.h"
#include "memory_budget.h"
#include "volume_formats.h"
#include "volume_io.h"

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
  const std::string two = grib2({{21, 1}}) + grib2({{21, 1}, {4, 3}});
  expect_refused([&] { parse_grib(two, "two.grib2", {}); }, {"GRIB message 2"});
  test::TempDir dir;
  std::ofstream(dir / "sec.grib2", std::ios::binary) << bad_section;
  expect_refused([&] { load_volume(dir / "sec.grib2"); }, {"sec.grib2: GRIB message 1", "past the message's end"});
}

}  // namespace
}  // namespace tfm
