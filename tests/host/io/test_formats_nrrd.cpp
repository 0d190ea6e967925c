// NRRD reader: attached and detached data, raw/gzip/ASCII/hex encodings, both byte orders, the
// multi-file forms ("name.%03d min max step" and LIST), byte/line skips, components; malformed
// headers; the real headsq (quarter.nhdr + 93 slices).
#include <gtest/gtest.h>
#include <zlib.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <tuple>

#include "formats_test_util.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/volume.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using formats_test::expect_error;
using formats_test::put;

// 3x2x2 int16 values -5, 0, 5, ..., 50.
std::string shorts(bool big) {
  std::string s;
  for (int i = 0; i < 12; ++i) put(s, int16_t(i * 5 - 5), big);
  return s;
}

void expect_values(const Volume& v) {
  ASSERT_EQ(v.dims, (std::array<uint64_t, 3>{3, 2, 2}));
  for (int i = 0; i < 12; ++i) EXPECT_EQ(v.values[i], float(i * 5 - 5)) << i;
}

Volume parse(const std::string& bytes, const DataFileLoader& files = {}) {
  return parse_nrrd(bytes, "mem.nrrd", {}, files ? files : [](const std::string& n) -> std::string {
    throw std::runtime_error("no file " + n);
  });
}

std::string gzip(const std::string& data) {
  z_stream z{};
  deflateInit2(&z, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY);
  std::string out(deflateBound(&z, data.size()) + 32, '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  z.avail_in = data.size();
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = out.size();
  deflate(&z, Z_FINISH);
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}

const std::string kHead = "NRRD0004\n# comment\ntype: short\ndimension: 3\nsizes: 3 2 2\nspacings: 0.5 1 2\n";

TEST(Nrrd, AttachedEncodingsAndByteOrders) {
  Volume v = parse(kHead + "endian: little\nencoding: raw\nkey:=value\n\n" + shorts(false));
  expect_values(v);
  EXPECT_EQ(v.spacing, (std::array<double, 3>{0.5, 1, 2}));
  expect_values(parse(kHead + "endian: big\nencoding: raw\n\n" + shorts(true)));
  expect_values(parse(kHead + "endian: little\nencoding: gzip\n\n" + gzip(shorts(false))));
  // Two concatenated gzip members are one stream.
  const std::string s = shorts(true);
  expect_values(parse(kHead + "endian: big\nencoding: gz\n\n" + gzip(s.substr(0, 10)) + gzip(s.substr(10))));
  expect_values(parse(kHead + "encoding: ascii\n\n-5 0 5 10\n15 20 25 30 35 40 45 50\n"));
  std::string hex;
  for (unsigned char c : shorts(true)) {
    const char* d = "0123456789abcdef";
    hex += d[c >> 4];
    hex += d[c & 15];
    hex += ' ';
  }
  expect_values(parse(kHead + "endian: big\nencoding: hex\n\n" + hex));
}

TEST(Nrrd, DetachedFilesSkipsAndComponents) {
  // One file with a line skip and a byte skip.
  auto files = [](std::map<std::string, std::string> m) {
    return [m](const std::string& n) {
      auto it = m.find(n);
      if (it == m.end()) throw std::runtime_error("missing " + n);
      return it->second;
    };
  };
  expect_values(parse(kHead + "endian: little\nencoding: raw\ndata file: d.raw\nline skip: 2\nbyte skip: 3\n",
                      files({{"d.raw", "line1\nline2\nxyz" + shorts(false)}})));
  // byte skip -1: the data are the file's last bytes.
  expect_values(parse(kHead + "endian: little\nencoding: raw\ndata file: d.raw\nbyte skip: -1\n",
                      files({{"d.raw", "some header of another tool" + shorts(false)}})));
  // One slice per file, numbered with a printf-style format (as the headsq data set).
  const std::string all = shorts(false);
  expect_values(parse(kHead + "endian: little\nencoding: raw\ndata file: s.%03d 1 2 1\n",
                      files({{"s.001", all.substr(0, 12)}, {"s.002", all.substr(12)}})));
  // Descending numbering and a LIST of files.
  expect_values(parse(kHead + "endian: little\nencoding: raw\ndata file: s%d 9 8 -1\n",
                      files({{"s9", all.substr(0, 12)}, {"s8", all.substr(12)}})));
  expect_values(parse(kHead + "endian: little\nencoding: gzip\ndata file: LIST\nfirst.gz\nsecond.gz\n",
                      files({{"first.gz", gzip(all.substr(0, 12))}, {"second.gz", gzip(all.substr(12))}})));
  // 4D: the fastest axis holds components; space directions give the spacing.
  std::string vec = "NRRD0005\ntype: float\ndimension: 4\nsizes: 2 2 1 1\nendian: little\nencoding: raw\n"
                    "space directions: none (0,3,4) (1,0,0) (0,0,2)\n\n";
  for (float x : {3.f, 4.f, 6.f, 8.f}) put(vec, x, false);
  Volume m = parse(vec);
  EXPECT_EQ(m.dims, (std::array<uint64_t, 3>{2, 1, 1}));
  EXPECT_EQ(m.values, (std::vector<float>{5, 10}));
  EXPECT_EQ(m.spacing, (std::array<double, 3>{5, 1, 2}));
  EXPECT_EQ(parse_nrrd(vec, "v.nrrd", VolumeOptions{.variable = "[1]"}, {}).values, (std::vector<float>{4, 8}));
}

// More raw data than the sizes need is read from the start, as teem reads it, and `info` says so
// (it is how wrong sizes in a header show); data read from the end (byte skip -1) are not extra.
TEST(Nrrd, InfoNamesDataBeyondWhatTheSizesNeed) {
  formats_test::TempDir dir;
  auto notes_of = [&](const std::string& name, const std::string& bytes) {
    formats_test::write_bytes(dir / name, bytes);
    const FileInfo info = describe_file(dir / name);
    std::string all;
    for (const auto& n : info.arrays.at(0).notes) all += n + "\n";
    return all;
  };
  const std::string head = kHead + "endian: little\nencoding: raw\n";
  expect_values(parse(head + "\n" + shorts(false) + "1234"));
  EXPECT_NE(notes_of("extra.nrrd", head + "\n" + shorts(false) + "1234")
                .find("attached data holds 4 bytes more than sizes 3 2 2 of short need: the first are read"),
            std::string::npos);
  EXPECT_EQ(notes_of("exact.nrrd", head + "\n" + shorts(false)).find("more than"), std::string::npos);
  formats_test::write_bytes(dir / "d.raw", "header of another tool" + shorts(false));
  EXPECT_EQ(notes_of("end.nhdr", head + "data file: d.raw\nbyte skip: -1\n").find("more than"), std::string::npos);
  EXPECT_NE(notes_of("skip.nhdr", head + "data file: d.raw\nbyte skip: 2\n")
                .find("data file d.raw holds 20 bytes more"),
            std::string::npos);
}

// `info` reads raw data from disk a block at a time (attached or detached, any byte skip, either
// byte order), other encodings from the file's bytes: the same statistics as the loaded volume,
// the same errors for short data, and a raw file larger than the memory budget is described.
TEST(Nrrd, InfoStreamsRawDataFromDisk) {
  formats_test::TempDir dir;
  auto stats = [&](const std::string& name, const std::string& bytes) {
    formats_test::write_bytes(dir / name, bytes);
    const ArrayInfo a = describe_file(dir / name).arrays.at(0);
    return std::tuple{a.values, a.min.value_or(NAN), a.max.value_or(NAN)};
  };
  const auto expected = std::tuple{uint64_t(12), -5.0, 50.0};
  const std::string head = kHead + "endian: little\nencoding: raw\n";
  EXPECT_EQ(stats("a.nrrd", head + "\n" + shorts(false)), expected);
  EXPECT_EQ(stats("big.nrrd", kHead + "endian: big\nencoding: raw\n\n" + shorts(true)), expected);
  EXPECT_EQ(stats("skip.nrrd", head + "byte skip: 5\n\nabcde" + shorts(false)), expected);
  formats_test::write_bytes(dir / "d.raw", "another tool's header" + shorts(false));
  EXPECT_EQ(stats("end.nhdr", head + "data file: d.raw\nbyte skip: -1\n"), expected);
  EXPECT_EQ(stats("gz.nrrd", kHead + "endian: little\nencoding: gzip\n\n" + gzip(shorts(false))), expected);
  formats_test::write_bytes(dir / "l.raw", "a line to skip\n" + shorts(false));
  EXPECT_EQ(stats("lines.nhdr", head + "data file: l.raw\nline skip: 1\n"), expected);
  formats_test::write_bytes(dir / "short.nrrd", head + "\n" + shorts(false).substr(0, 20));
  expect_error([&] { describe_file(dir / "short.nrrd"); }, {"attached data has 20 bytes", "too few for 12"});
  // 4 Mi floats (16 MiB) under a budget with 8 MiB left: described; loading it is refused.
  std::string body = "NRRD0004\ntype: float\ndimension: 3\nsizes: 256 256 64\nendian: little\nencoding: raw\n\n";
  for (uint32_t i = 0; i < 256 * 256 * 64; ++i) put(body, float(i % 1000) - 1.5f, false);
  formats_test::write_bytes(dir / "large.nrrd", body);
  body = {};
  set_memory_budget(resident_memory() + (uint64_t(8) << 20), "--max-memory test");
  const ArrayInfo a = describe_file(dir / "large.nrrd").arrays.at(0);
  EXPECT_THROW(load_volume((dir / "large.nrrd").string()), MemoryBudgetExceeded);
  set_memory_budget(0, "");
  EXPECT_EQ(a.values, uint64_t(256 * 256 * 64));
  EXPECT_EQ(a.min, -1.5);
  EXPECT_EQ(a.max, 997.5);
}

TEST(Nrrd, MalformedInputGivesClearErrors) {
  const std::string raw = "endian: little\nencoding: raw\n\n";
  expect_error([&] { parse("NRRD0009\n"); }, {"mem.nrrd", "not a NRRD file"});
  expect_error([&] { parse("P6\n"); }, {"not a NRRD file"});
  expect_error([&] { parse(kHead + "encoding: raw\n\n" + shorts(false)); }, {"no endian field"});
  expect_error([&] { parse(kHead + raw + shorts(false).substr(0, 20)); }, {"attached data has 20 bytes", "too few for 12"});
  expect_error([&] { parse("NRRD0004\ntype: quad\n"); }, {"line 2", "type 'quad' is not supported"});
  expect_error([&] { parse("NRRD0004\ntype: short\ndimension: 3\nsizes: 3 2\n" + raw); }, {"sizes has 2 entries"});
  expect_error([&] { parse("NRRD0004\ntype: short\ndimension: 5\nsizes: 1 1 1 1 1\n" + raw); }, {"dimension 5 is not supported"});
  expect_error([&] { parse("NRRD0004\ntype: float\ndimension: 3\nsizes: 100000 100000 100000\n" + raw); },
               {"too large: more than 1099511627776 (2^40) values, the most tfmatch reads"});
  // A tiny gzip stream cannot hold what the header promises: refused before allocating.
  expect_error([&] { parse("NRRD0004\ntype: float\ndimension: 3\nsizes: 1000 1000 1000\nendian: little\nencoding: gzip\n\n" +
                           gzip("x")); },
               {"too few for 1000000000"});
  expect_error([&] { parse(kHead + "endian: little\nencoding: gzip\n\n" + gzip(shorts(false).substr(0, 8)) + "junk"); },
               {"gzip data", "after 8 bytes, 24 needed"});
  expect_error([&] { parse(kHead + "endian: little\nencoding: bzip2\n\n"); }, {"bzip2 encoding is not supported"});
  expect_error([&] { parse(kHead + "endian: little\nencoding: raw\ndata file: a%d%d 1 2 1\n"); }, {"exactly one %d"});
  expect_error([&] { parse(kHead + "endian: little\nencoding: raw\ndata file: a%d 1 3 1\n"); }, {"3 data files", "needing 2"});
  expect_error([&] { parse(kHead + "endian: little\nencoding: raw\ndata file: gone.raw\n"); }, {"no file gone.raw"});
  expect_error([&] { parse(kHead + "encoding: ascii\n\n1 2 x 4 5 6 7 8 9 10 11 12\n"); }, {"value 2 ('x') is not a number"});
  expect_error([&] { parse(kHead + "endian: big\nencoding: hex\n\n00 0g 00\n"); }, {"has 9 bytes, too few for 12 short values (hex"});
  expect_error([&] { parse("NRRD0004\nno colon here\n"); }, {"line 2", "expected 'field: description'"});
  expect_error([&] { parse(kHead + "endian: little\nencoding: gzip\nbyte skip: -1\n\n"); }, {"byte skip -1 needs raw"});
}

// What was dropped or misnamed: spacings that are no spacing (unit spacing was taken in silence),
// ASCII data that ends early ("value 11 is not a number"), a data file that is a directory (a
// filesystem exception's text).
TEST(Nrrd, SpacingsShortTextAndDataFilesThatAreNoFiles) {
  const std::string head = "NRRD0004\ntype: short\ndimension: 3\nsizes: 3 2 2\n";
  const std::string ascii = "encoding: ascii\n\n1 2 3 4 5 6 7 8 9 10 11 12\n";
  expect_error([&] { parse(head + "spacings: nan inf 1\n" + ascii); },
               {"line 5", "spacings: 'inf' is not a spacing", "nan for an axis without one"});
  expect_error([&] { parse(head + "spacings: 1 0 1\n" + ascii); }, {"spacings: '0' is not a spacing"});
  expect_error([&] { parse(head + "spacings: 1 x 1\n" + ascii); }, {"spacings: 'x' is not a spacing"});
  // nan is the format's own "no spacing", and a negative spacing runs the axis backwards.
  const Volume v = parse(head + "spacings: nan -2 0.5\n" + ascii);
  EXPECT_EQ(v.spacing, (std::array<double, 3>{1, 2, 0.5}));
  expect_error([&] { parse(head + "encoding: ascii\n\n1 2 3 4 5 6 7 8 9 10 11\n"); },
               {"attached data: 11 values, the sizes need 12"});
  expect_error([&] { parse(head + "encoding: ascii\n\n1 2 3 4 5 6 7 8 9 10 11 40000\n"); },
               {"value 11 (40000) is no short value"});
  expect_error([&] { parse(head + "encoding: ascii\n\n1 2 3\n"); },
               {"bytes of text hold at most 3 values, the sizes need 12"});
  formats_test::TempDir dir;
  std::filesystem::create_directory(dir.path() / "slices");
  const auto header = dir.path() / "h.nhdr";
  std::ofstream(header) << head << "endian: little\nencoding: raw\ndata file: slices\n";
  expect_error([&] { load_volume(header.string()); }, {"h.nhdr: data file", "slices is a directory"});
}

TEST(NrrdRealFiles, HeadsqQuarterSlices) {
  const std::string dir = test::shared_data_dir();
  if (dir.empty()) GTEST_SKIP() << "../shared/data not present";
  // quarter.nhdr: 64x64x93 little-endian int16 in quarter.1 .. quarter.93; python3
  // struct.unpack('<h') of the concatenated slices: range 0..3926, (20,30,50) = 1617.
  Volume v = load_volume(dir + "/nrrd_headsq/quarter.nhdr");
  ASSERT_EQ(v.dims, (std::array<uint64_t, 3>{64, 64, 93}));
  EXPECT_EQ(v.spacing, (std::array<double, 3>{3.2, 3.2, 1.5}));
  EXPECT_EQ(*std::min_element(v.values.begin(), v.values.end()), 0.0f);
  EXPECT_EQ(*std::max_element(v.values.begin(), v.values.end()), 3926.0f);
  EXPECT_EQ(v.at(20, 30, 50), 1617.0f);
  // Slice 51's bytes, read directly, hold that value at (20, 30).
  const std::string slice = formats_test::read_bytes(dir + "/nrrd_headsq/quarter.51");
  int16_t raw;
  std::memcpy(&raw, slice.data() + 2 * (30 * 64 + 20), 2);
  EXPECT_EQ(raw, 1617);
}

}  // namespace
}  // namespace tfm
