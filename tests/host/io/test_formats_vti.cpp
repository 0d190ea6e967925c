// VTK XML ImageData: hand-built files in every encoding (ascii, inline base64 with the header
// encoded apart or together, zlib blocks, appended raw and base64, both byte orders and header
// types), the writer's round trip, malformed files, and the real hydrogen and Isabel files.
#include <gtest/gtest.h>
#include <zlib.h>

#include <cmath>
#include <numeric>

#include "formats_test_util.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/io/base64.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/io/volume_vti.h"
#include "tfmatch/model/volume.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using formats_test::expect_error;
using formats_test::put;

Volume parse(const std::string& bytes, const std::string& var = "") {
  VolumeOptions o;
  o.variable = var;
  return parse_vti(bytes, "mem.vti", o);
}

// A 3x2x1 ImageData with the given VTKFile attributes, point-data arrays and appended section.
std::string document(const std::string& file_attrs, const std::string& arrays, const std::string& appended = "",
                     const std::string& cells = "") {
  std::string s = "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" " + file_attrs + ">\n"
                  "<ImageData WholeExtent=\"0 2 0 1 0 0\" Origin=\"0 0 0\" Spacing=\"1 0.5 2\">\n"
                  "<Piece Extent=\"0 2 0 1 0 0\">\n<PointData Scalars=\"b\">\n" + arrays + "</PointData>\n"
                  "<CellData>" + cells + "</CellData>\n</Piece>\n</ImageData>\n";
  if (!appended.empty()) s += "<AppendedData encoding=\"raw\">\n  _" + appended + "\n</AppendedData>\n";
  return s + "</VTKFile>\n";
}

std::string floats_le(const std::vector<float>& v, bool big = false) {
  std::string s;
  for (float x : v) put(s, x, big);
  return s;
}

const std::vector<float> kValues{0.5f, -1.0f, 2.0f, 3.25f, 1e6f, -7.0f};

TEST(Vti, AsciiArraysComponentsAndCellData) {
  std::string arrays =
      "<DataArray type=\"Float32\" Name=\"a\" NumberOfComponents=\"2\" format=\"ascii\">3 4 0 1 1 0\n 6 8 0 0 5 12</DataArray>\n"
      "<DataArray type=\"Int64\" Name=\"b\" format=\"ascii\">-9000000000 1 2 3 4 5</DataArray>\n";
  std::string doc = document("byte_order=\"LittleEndian\"", arrays, "",
                             "<DataArray type=\"UInt8\" Name=\"c\" format=\"ascii\">200 201</DataArray>");
  Volume b = parse(doc);  // the active scalars
  EXPECT_EQ(b.dims, (std::array<uint64_t, 3>{3, 2, 1}));
  EXPECT_EQ(b.spacing, (std::array<double, 3>{1, 0.5, 2}));
  EXPECT_EQ(b.values[0], -9.0e9f);
  Volume a = parse(doc, "a");
  EXPECT_EQ(a.values, (std::vector<float>{5, 1, 1, 10, 0, 13}));
  EXPECT_EQ(parse(doc, "a[1]").values, (std::vector<float>{4, 1, 0, 8, 0, 12}));
  Volume c = parse(doc, "c");
  EXPECT_EQ(c.dims, (std::array<uint64_t, 3>{2, 1, 1}));
  EXPECT_EQ(c.values, (std::vector<float>{200, 201}));
  // Text that is no value of the declared type is an error, not a uint8 field of range [200, 300].
  for (const std::string bad : {"200 300", "200 -1", "200 1.5", "200 nan"}) {
    const std::string d = document("byte_order=\"LittleEndian\"", arrays, "",
                                   "<DataArray type=\"UInt8\" Name=\"c\" format=\"ascii\">" + bad + "</DataArray>");
    expect_error([&] { parse(d, "c"); }, {"mem.vti", "array 'c'", "value 1 is " + bad.substr(4), "no uint8 value"});
  }
}

TEST(Vti, InlineBase64HeaderApartOrTogether) {
  const std::string data = floats_le(kValues);
  std::string header;
  put(header, uint32_t(data.size()), false);
  // VTK encodes the header and the data separately; other writers encode them together.
  for (const std::string& b64 : {base64_encode(header) + base64_encode(data), base64_encode(header + data)}) {
    std::string doc = document("byte_order=\"LittleEndian\" header_type=\"UInt32\"",
                               "<DataArray type=\"Float32\" Name=\"b\" format=\"binary\">\n  " + b64 + "\n</DataArray>\n");
    EXPECT_EQ(parse(doc).values, kValues);
  }
}

// zlib blocks of `block` bytes (the last one partial) behind a VTK compression header.
std::string compressed(const std::string& data, size_t block, bool header64, bool big) {
  std::string head, body;
  const size_t blocks = (data.size() + block - 1) / block;
  auto h = [&](uint64_t v) { header64 ? put(head, v, big) : put(head, uint32_t(v), big); };
  h(blocks);
  h(block);
  h(data.size() % block);
  for (size_t b = 0; b < blocks; ++b) {
    const size_t n = std::min(block, data.size() - b * block);
    std::string out(compressBound(n), '\0');
    uLongf got = out.size();
    compress(reinterpret_cast<Bytef*>(out.data()), &got, reinterpret_cast<const Bytef*>(data.data() + b * block), n);
    h(got);
    body.append(out.data(), got);
  }
  return head + body;
}

TEST(Vti, ZlibBlocksInlineAndAppendedBothByteOrders) {
  for (bool big : {false, true})
    for (bool h64 : {false, true}) {
      const std::string data = floats_le(kValues, big);
      const std::string attrs = std::string("byte_order=\"") + (big ? "BigEndian" : "LittleEndian") + "\" header_type=\"" +
                                (h64 ? "UInt64" : "UInt32") + "\" compressor=\"vtkZLibDataCompressor\"";
      const std::string blob = compressed(data, 8, h64, big);  // 3 blocks, the last one full
      std::string inline_doc = document(attrs, "<DataArray type=\"Float32\" Name=\"b\" format=\"binary\">" +
                                                   base64_encode(blob) + "</DataArray>\n");
      EXPECT_EQ(parse(inline_doc).values, kValues) << big << h64;
      const std::string blob2 = compressed(data, 10, h64, big);  // a partial last block
      std::string appended_doc =
          document(attrs,
                   "<DataArray type=\"Float32\" Name=\"x\" format=\"appended\" offset=\"0\"/>\n"
                   "<DataArray type=\"Float32\" Name=\"b\" format=\"appended\" offset=\"" + std::to_string(blob.size()) + "\"/>\n",
                   blob + blob2);
      EXPECT_EQ(parse(appended_doc).values, kValues);
      EXPECT_EQ(parse(appended_doc, "x").values, kValues);
    }
}

TEST(Vti, AppendedBase64) {
  std::string header;
  const std::string data = floats_le(kValues);
  put(header, uint64_t(data.size()), false);
  const std::string b64 = base64_encode(header) + base64_encode(data);
  std::string doc = document("byte_order=\"LittleEndian\" header_type=\"UInt64\"",
                             "<DataArray type=\"Float32\" Name=\"b\" format=\"appended\" offset=\"0\"/>\n", b64);
  doc.replace(doc.find("encoding=\"raw\""), 14, "encoding=\"base64\"");
  EXPECT_EQ(parse(doc).values, kValues);
}

TEST(Vti, WriterRoundTripsThroughTheReader) {
  formats_test::TempDir dir;
  Volume a;
  a.dims = {5, 4, 3};
  a.spacing = {0.25, 1.5, 3};
  a.values.resize(60);
  std::iota(a.values.begin(), a.values.end(), -10.0f);
  a.values[7] = NAN;
  Volume b = a;
  for (float& x : b.values) x *= 2;
  a.units = "kg m-3 <dry>";  // written as the array's units attribute, read back
  for (bool compress : {true, false}) {
    const auto path = dir / (compress ? "z.vti" : "raw.vti");
    write_vti(path, {{"first & <one>", &a}, {"second", &b}}, VtiWriteOptions{compress});
    Volume ra = load_volume(path.string());  // active scalars: the first
    EXPECT_EQ(ra.dims, a.dims);
    EXPECT_EQ(ra.spacing, a.spacing);
    EXPECT_EQ(ra.units, a.units);
    EXPECT_EQ(load_volume(path.string() + ":second").units, "");
    ASSERT_EQ(ra.values.size(), a.values.size());
    for (size_t i = 0; i < a.values.size(); ++i)
      if (i == 7) EXPECT_TRUE(std::isnan(ra.values[i]));
      else EXPECT_EQ(ra.values[i], a.values[i]);
    EXPECT_EQ(load_volume(path.string() + ":second").values[3], b.values[3]);
    EXPECT_EQ(load_volume(path.string() + ":first & <one>").values[0], a.values[0]);
  }
  Volume c = a;
  c.dims = {5, 4, 2};
  c.values.resize(40);
  expect_error([&] { write_vti(dir / "bad.vti", {{"a", &a}, {"c", &c}}); }, {"bad.vti", "different grids"});
  // The file is built in memory once, after a check against the budget that names it (payload
  // and its compressed blocks: 2 x 16 MiB).
  Volume big;
  big.dims = {256, 256, 64};
  big.values.assign(big.voxel_count(), 0.5f);
  set_memory_budget(resident_memory() + (uint64_t(8) << 20), "--max-memory test");
  expect_error([&] { write_vti(dir / "big.vti", {{"v", &big}}); }, {"big.vti", "needs 32.0 MiB", "--max-memory test"});
  set_memory_budget(0, "");
  EXPECT_FALSE(std::filesystem::exists(dir / "big.vti"));
}

TEST(Vti, MalformedInputGivesClearErrors) {
  const std::string le = "byte_order=\"LittleEndian\" header_type=\"UInt32\"";
  const std::string data = floats_le(kValues);
  auto appended = [&](const std::string& attrs, const std::string& blob, const std::string& type = "Float32",
                      const std::string& offset = "0") {
    return document(attrs, "<DataArray type=\"" + type + "\" Name=\"b\" format=\"appended\" offset=\"" + offset + "\"/>\n", blob);
  };
  std::string h;
  put(h, uint32_t(data.size() + 4), false);
  expect_error([&] { parse(appended(le, h + data)); }, {"mem.vti", "array 'b'", "header says 28 bytes", "needs 24"});
  put(h = "", uint32_t(data.size()), false);
  // Raw appended data runs to the end of the file: cut the file inside it.
  const std::string cut = appended(le, h + data);
  expect_error([&] { parse(cut.substr(0, cut.find("\n  _") + 4 + 4 + 10)); }, {"mem.vti", "array 'b'", "truncated"});
  expect_error([&] { parse(appended(le, h + data, "Float32", "999")); }, {"offset 999", "beyond the end"});
  expect_error([&] { parse(appended(le, h + data, "Quad")); }, {"unsupported data type 'Quad'"});
  // A compression header that promises far more than its compressed bytes can hold.
  const std::string z = le + " compressor=\"vtkZLibDataCompressor\"";
  std::string lie;
  for (uint32_t v : {1u, 400000000u, 0u, 3u}) put(lie, v, false);
  std::string big_doc = appended(z, lie + "abc");
  big_doc.replace(big_doc.find("0 2 0 1 0 0"), 11, "0 999 0 999 0 99");
  big_doc.replace(big_doc.find("0 2 0 1 0 0"), 11, "0 999 0 999 0 99");
  expect_error([&] { parse(big_doc); }, {"3 compressed bytes cannot hold 400000000 bytes"});
  std::string corrupt = compressed(data, 64, false, false);
  corrupt[corrupt.size() - 3] ^= 0x55;
  expect_error([&] { parse(appended(z, corrupt)); }, {"zlib block 0 is corrupt"});
  std::string many;
  for (uint32_t v : {4000000000u, 8u, 0u}) put(many, v, false);
  expect_error([&] { parse(appended(z, many)); }, {"more blocks than the file holds"});
  expect_error([&] { parse(appended(le + " compressor=\"vtkLZ4DataCompressor\"", h + data)); }, {"vtkLZ4DataCompressor", "not supported"});
  expect_error([&] { parse(document(le, "<DataArray type=\"Float32\" Name=\"b\" format=\"binary\">AAA*AAAA</DataArray>")); },
               {"invalid base64 character"});
  expect_error([&] { parse(document(le, "<DataArray type=\"Float32\" Name=\"b\" format=\"ascii\">1 2 3</DataArray>")); },
               {"needs 6 values"});
  expect_error([&] { parse(document(le, "<DataArray type=\"Float32\" Name=\"b\" format=\"ascii\">1 2 3 4 5 z</DataArray>")); },
               {"value 5 is 'z'"});
  expect_error([&] { parse("<VTKFile type=\"PolyData\"></VTKFile>"); }, {"PolyData", "only ImageData"});
  expect_error([&] { parse("<VTKFile type=\"ImageData\"><ImageData/></VTKFile>"); }, {"no WholeExtent"});
  expect_error([&] { parse("<VTKFile type=\"ImageData\"><ImageData WholeExtent=\"0 1 0 1\"/></VTKFile>"); }, {"expected 6 numbers"});
  expect_error([&] { parse("<VTKFile type=\"ImageData\"><ImageData WholeExtent=\"0 9999999 0 9999999 0 9999999\"/></VTKFile>"); },
               {"too large"});
  expect_error([&] { parse("<VTKFile type=\"ImageData\"><ImageData WholeExtent=\"0 1 0 1 0 1\"><Piece/><Piece/></ImageData></VTKFile>"); },
               {"2 <Piece> elements"});
  expect_error([&] { parse("<VTKFile type=\"ImageData\"><ImageData"); }, {"mem.vti", "not well-formed XML"});
  expect_error([&] { parse("<VTKFile type=\"ImageData\"><AppendedData encoding=\"raw\">x"); }, {"must start with '_'"});
}

std::string data(const std::string& rel) {
  const std::string d = test::shared_data_dir();
  return d.empty() ? "" : d + "/" + rel;
}

TEST(VtiRealFiles, HydrogenAndIsabel) {
  if (data("").empty()) GTEST_SKIP() << "../shared/data not present";
  // hydrogen.vti decoded with python3 base64 + zlib + struct: 262144 floats in 0..1, value
  // 200000 = 1.8000000636675395e-05, sum (double, in order) 4856.008970333924.
  Volume h = load_volume(data("vti_hydrogen/hydrogen.vti"));
  ASSERT_EQ(h.dims, (std::array<uint64_t, 3>{64, 64, 64}));
  EXPECT_EQ(h.values[200000], 1.8000000636675395e-05f);
  double sum = 0;
  for (float x : h.values) sum += x;
  EXPECT_DOUBLE_EQ(sum, 4856.008970333924);
  // Isabel: struct.unpack('<d') after the UInt64 count at appended offset 32; ranges as in
  // SOURCES.md; value at (61,60,12).
  struct Case {
    const char* file;
    double max, value;
  } cases[] = {{"isabel_vti/isabel_02.vti", 68.2454776917825, 9.583816671133615},
               {"isabel_vti/isabel_30.vti", 78.65940926169091, 18.411757742486277},
               {"isabel_vti/isabel_31.vti", 76.56533407845446, 21.22508408442738}};
  std::vector<Volume> isabel;
  for (const auto& c : cases) {
    Volume v = load_volume(data(c.file));
    ASSERT_EQ(v.dims, (std::array<uint64_t, 3>{125, 125, 25}));
    EXPECT_NEAR(v.spacing[0], 4.0080321286, 1e-12);
    EXPECT_NEAR(v.spacing[2], 4.0408163266, 1e-12);
    EXPECT_EQ(*std::min_element(v.values.begin(), v.values.end()), 0.0f);
    EXPECT_EQ(*std::max_element(v.values.begin(), v.values.end()), float(c.max));
    EXPECT_EQ(v.at(61, 60, 12), float(c.value));
    isabel.push_back(std::move(v));
  }
  EXPECT_NO_THROW(require_same_grid(isabel[1], isabel[2]));
  expect_error([&] { load_volume(data("isabel_vti/isabel_30.vti:TimeStep")); }, {"field data", "not on the grid"});
}

}  // namespace
}  // namespace tfm
