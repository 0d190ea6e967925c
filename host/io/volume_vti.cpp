// VTK XML ImageData (.vti): reading ascii, inline base64 and appended (raw or base64) arrays,
// zlib-compressed or not, UInt32 or UInt64 headers, either byte order; writing Float32 arrays.
#include "tfmatch/io/volume_vti.h"

#include <algorithm>
#include <cctype>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>

#include <zlib.h>

#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/base64.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/io/xml_tree.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm {
namespace {

struct VtiArray {
  std::string name;
  std::string section;  // "point data", "cell data", "field data"
  ElementType type = ElementType::Float32;
  uint64_t components = 1;
  uint64_t tuples = 0;
  std::string format;   // ascii, binary, appended
  size_t content_begin = 0, content_end = 0;
  uint64_t offset = 0;
  int line = 0;
  std::string axis_name, units;  // field data written by tfmatch: an axis's coordinates (see write_vti)
};

struct VtiDocument {
  bool big_endian = false;
  bool header64 = false;
  bool compressed = false;
  std::array<uint64_t, 3> dims{0, 0, 0};
  std::array<double, 3> spacing{1, 1, 1};
  std::array<double, 3> origin{0, 0, 0};
  std::vector<VtiArray> arrays;
  std::string active_scalars;
  bool has_appended = false;
  bool appended_base64 = false;
  size_t appended_begin = 0;  // first byte after '_'
};

ElementType parse_vti_type(const std::string& t, const std::string& where) {
  if (t == "Int8" || t == "Char") return ElementType::Int8;
  if (t == "UInt8" || t == "UnsignedChar") return ElementType::UInt8;
  if (t == "Int16" || t == "Short") return ElementType::Int16;
  if (t == "UInt16" || t == "UnsignedShort") return ElementType::UInt16;
  if (t == "Int32" || t == "Int") return ElementType::Int32;
  if (t == "UInt32" || t == "UnsignedInt") return ElementType::UInt32;
  if (t == "Int64") return ElementType::Int64;
  if (t == "UInt64") return ElementType::UInt64;
  if (t == "Float32" || t == "Float") return ElementType::Float32;
  if (t == "Float64" || t == "Double") return ElementType::Float64;
  throw std::runtime_error(where + ": unsupported data type '" + t + "'");
}

template <size_t N>
std::array<double, N> parse_numbers(const std::string* text, std::array<double, N> fallback, const std::string& where) {
  if (!text) return fallback;
  std::istringstream in(*text);
  std::array<double, N> out{};
  for (auto& v : out) {
    std::string tok;
    in >> tok;
    auto n = parse_number(tok);
    if (!n) throw std::runtime_error(where + ": expected " + std::to_string(N) + " numbers, found '" + *text + "'");
    v = *n;
  }
  std::string extra;
  if (in >> extra) throw std::runtime_error(where + ": expected " + std::to_string(N) + " numbers, found '" + *text + "'");
  return out;
}

uint64_t parse_uint(const std::string* text, uint64_t fallback, const std::string& where) {
  if (!text) return fallback;
  auto v = parse_number(*text);
  if (!v || *v < 0 || *v != std::floor(*v) || *v > 9.0e15)
    throw std::runtime_error(where + ": expected a non-negative integer, found '" + *text + "'");
  return static_cast<uint64_t>(*v);
}

VtiDocument parse_document(std::string_view bytes, const std::string& file) {
  VtiDocument doc;
  // Raw appended data is not XML: parse the part before it, closed by hand.
  std::string xml_copy;
  std::string_view xml = bytes;
  const size_t app = bytes.find("<AppendedData");
  if (app != std::string_view::npos) {
    const size_t gt = bytes.find('>', app);
    if (gt == std::string_view::npos) throw std::runtime_error(file + ": unterminated <AppendedData> tag");
    const bool self_closing = gt > 0 && bytes[gt - 1] == '/';
    xml_copy.assign(bytes.substr(0, gt + 1));
    xml_copy += self_closing ? "</VTKFile>" : "</AppendedData></VTKFile>";
    xml = xml_copy;
    if (!self_closing) {
      size_t p = gt + 1;
      while (p < bytes.size() && std::isspace(static_cast<unsigned char>(bytes[p]))) ++p;
      if (p >= bytes.size() || bytes[p] != '_')
        throw std::runtime_error(file + ": appended data must start with '_'");
      doc.has_appended = true;
      doc.appended_begin = p + 1;
    }
  }
  auto root = parse_xml(xml, file);
  if (root->name != "VTKFile") throw std::runtime_error(file + ": the root element is <" + root->name + ">, not <VTKFile>");
  const std::string* type = root->attribute("type");
  if (!type || *type != "ImageData")
    throw std::runtime_error(file + ": VTK XML type '" + (type ? *type : std::string("?")) +
                             "' is not supported (only ImageData, .vti)");
  if (auto* bo = root->attribute("byte_order")) {
    if (*bo != "LittleEndian" && *bo != "BigEndian") throw std::runtime_error(file + ": unknown byte_order '" + *bo + "'");
    doc.big_endian = *bo == "BigEndian";
  }
  if (auto* ht = root->attribute("header_type")) {
    if (*ht != "UInt32" && *ht != "UInt64") throw std::runtime_error(file + ": unknown header_type '" + *ht + "'");
    doc.header64 = *ht == "UInt64";
  }
  if (auto* comp = root->attribute("compressor"); comp && !comp->empty()) {
    if (*comp != "vtkZLibDataCompressor")
      throw std::runtime_error(file + ": compressor '" + *comp + "' is not supported (only vtkZLibDataCompressor)");
    doc.compressed = true;
  }
  if (const XmlElement* ad = root->child("AppendedData"); ad && doc.has_appended) {
    const std::string* enc = ad->attribute("encoding");
    if (!enc || (*enc != "raw" && *enc != "base64"))
      throw std::runtime_error(file + ": AppendedData encoding must be raw or base64");
    doc.appended_base64 = *enc == "base64";
  }
  const XmlElement* image = root->child("ImageData");
  if (!image) throw std::runtime_error(file + ": no <ImageData> element");
  const std::string* we = image->attribute("WholeExtent");
  if (!we) throw std::runtime_error(file + ": <ImageData> has no WholeExtent");
  auto extent = parse_numbers<6>(we, {}, file + ": WholeExtent");
  for (int i = 0; i < 3; ++i) {
    const double lo = extent[2 * i], hi = extent[2 * i + 1];
    if (lo != std::floor(lo) || hi != std::floor(hi) || hi < lo || hi - lo >= double(kMaxVoxels))
      throw std::runtime_error(file + ": bad WholeExtent '" + *we + "'");
    doc.dims[i] = static_cast<uint64_t>(hi - lo) + 1;
  }
  const uint64_t points = checked_voxel_count(doc.dims, file);
  doc.spacing = parse_numbers<3>(image->attribute("Spacing"), {1.0, 1.0, 1.0}, file + ": Spacing");
  doc.origin = parse_numbers<3>(image->attribute("Origin"), {0.0, 0.0, 0.0}, file + ": Origin");
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(doc.origin[i])) throw std::runtime_error(file + ": Origin must be finite");
    doc.origin[i] += extent[2 * i] * doc.spacing[i];  // the position of the first point of the extent
  }
  for (double& s : doc.spacing) {
    if (!std::isfinite(s) || s == 0) throw std::runtime_error(file + ": Spacing must be finite and non-zero");
    s = std::abs(s);  // a negative spacing mirrors the axis; the voxel size is its magnitude
  }
  auto pieces = image->children_named("Piece");
  if (pieces.size() != 1)
    throw std::runtime_error(file + ": " + std::to_string(pieces.size()) + " <Piece> elements; only single-piece files are supported");
  if (auto* pe = pieces[0]->attribute("Extent"); pe && parse_numbers<6>(pe, {}, file + ": Piece Extent") != extent)
    throw std::runtime_error(file + ": the piece's Extent differs from WholeExtent (partial pieces are not supported)");
  uint64_t cells = 1;
  for (uint64_t d : doc.dims) cells *= std::max<uint64_t>(1, d - 1);

  auto collect = [&](const XmlElement* parent, const std::string& section, uint64_t tuples) {
    if (!parent) return;
    if (section == "point data")
      if (auto* s = parent->attribute("Scalars")) doc.active_scalars = *s;
    int index = 0;
    for (const XmlElement* da : parent->children_named("DataArray")) {
      VtiArray a;
      const std::string where = file + ": line " + std::to_string(da->line) + ": DataArray";
      a.section = section;
      a.line = da->line;
      const std::string* t = da->attribute("type");
      if (!t) throw std::runtime_error(where + " has no type");
      a.type = parse_vti_type(*t, where);
      a.name = da->attribute("Name") ? *da->attribute("Name") : "array" + std::to_string(index);
      a.components = parse_uint(da->attribute("NumberOfComponents"), 1, where + " NumberOfComponents");
      if (a.components == 0 || a.components > 1024) throw std::runtime_error(where + ": NumberOfComponents must be 1..1024");
      a.tuples = section == "field data" ? parse_uint(da->attribute("NumberOfTuples"), 1, where + " NumberOfTuples") : tuples;
      a.format = da->attribute("format") ? *da->attribute("format") : "ascii";
      if (a.format != "ascii" && a.format != "binary" && a.format != "appended")
        throw std::runtime_error(where + ": unknown format '" + a.format + "'");
      if (a.format == "appended") {
        if (!doc.has_appended) throw std::runtime_error(where + " '" + a.name + "' is appended, but the file has no AppendedData");
        a.offset = parse_uint(da->attribute("offset"), 0, where + " offset");
      }
      if (const std::string* n = da->attribute("axis_name")) a.axis_name = *n;
      if (const std::string* u = da->attribute("units")) a.units = *u;
      a.content_begin = da->content_begin;
      a.content_end = da->content_end;
      doc.arrays.push_back(a);
      ++index;
    }
  };
  collect(pieces[0]->child("PointData"), "point data", points);
  collect(pieces[0]->child("CellData"), "cell data", cells);
  collect(image->child("FieldData"), "field data", 0);
  return doc;
}

// Where an array's bytes come from: raw bytes in place, or base64 decoded on demand.
class ByteSource {
 public:
  ByteSource(std::string_view raw, bool base64) : raw_(raw) {
    if (base64) b64_.emplace(raw);
  }
  uint64_t upper_bound() const { return b64_ ? b64_->remaining_upper_bound() : raw_.size() - pos_; }
  // Exactly n bytes, or throws (the caller adds the file and array).
  std::string_view read(uint64_t n) {
    if (n > upper_bound()) throw std::runtime_error("data truncated: " + std::to_string(n) + " bytes needed, at most " +
                                                    std::to_string(upper_bound()) + " present");
    if (!b64_) {
      std::string_view v = raw_.substr(pos_, n);
      pos_ += n;
      return v;
    }
    buffer_.clear();
    if (b64_->read(n, buffer_) != n) throw std::runtime_error("base64 data truncated: " + std::to_string(n) + " bytes needed");
    return buffer_;
  }

 private:
  std::string_view raw_;
  size_t pos_ = 0;
  std::optional<Base64Decoder> b64_;
  std::string buffer_;
};

uint64_t read_header_uint(ByteSource& src, const VtiDocument& doc) {
  std::string_view b = src.read(doc.header64 ? 8 : 4);
  uint64_t v = 0;
  for (size_t i = 0; i < b.size(); ++i) {
    const size_t k = doc.big_endian ? i : b.size() - 1 - i;
    v = (v << 8) | static_cast<unsigned char>(b[k]);
  }
  return v;
}

// The array's decompressed bytes, exactly `expected` of them, handed to `sink` a block at a time
// (a zlib block, or a slice of uncompressed data): the whole array's bytes never exist at once.
void read_binary(ByteSource& src, const VtiDocument& doc, uint64_t expected, const std::string& where,
                 const std::function<void(std::string_view)>& sink) {
  if (!doc.compressed) {
    const uint64_t n = read_header_uint(src, doc);
    if (n != expected)
      throw std::runtime_error(where + ": its header says " + std::to_string(n) + " bytes, the array needs " +
                               std::to_string(expected));
    if (n > src.upper_bound()) src.read(n);  // throws "data truncated", before anything is decoded
    constexpr uint64_t kSlice = uint64_t(16) << 20;
    for (uint64_t done = 0; done < n; done += kSlice) sink(src.read(std::min(kSlice, n - done)));
    return;
  }
  const uint64_t hb = doc.header64 ? 8 : 4;
  const uint64_t blocks = read_header_uint(src, doc);
  const uint64_t block_size = read_header_uint(src, doc);
  const uint64_t last_size = read_header_uint(src, doc);
  if (blocks > src.upper_bound() / hb) throw std::runtime_error(where + ": compression header names more blocks than the file holds");
  if (blocks > 0 && (block_size == 0 || last_size > block_size))
    throw std::runtime_error(where + ": bad compression header (block size " + std::to_string(block_size) + ", last block " +
                             std::to_string(last_size) + ")");
  const uint64_t total =
      blocks == 0 ? 0 : checked_mul(blocks - 1, block_size, kMaxVoxels * 8, where, "compressed size") + (last_size ? last_size : block_size);
  if (total != expected)
    throw std::runtime_error(where + ": compressed blocks hold " + std::to_string(total) + " bytes, the array needs " +
                             std::to_string(expected));
  std::vector<uint64_t> sizes(blocks);
  uint64_t compressed = 0;
  for (auto& s : sizes) {
    s = read_header_uint(src, doc);
    if (s > src.upper_bound()) throw std::runtime_error(where + ": a compressed block is larger than the data present");
    compressed += s;
  }
  if (compressed > src.upper_bound()) throw std::runtime_error(where + ": compressed blocks are larger than the data present");
  if (expected > kMaxDeflateRatio * compressed + 1024)
    throw std::runtime_error(where + ": " + std::to_string(compressed) + " compressed bytes cannot hold " +
                             std::to_string(expected) + " bytes");
  // One block at a time; a block cannot expand past zlib's ratio either, which bounds the buffer.
  std::string block;
  for (uint64_t b = 0; b < blocks; ++b) {
    const uint64_t want = (b + 1 == blocks && last_size) ? last_size : block_size;
    std::string_view in = src.read(sizes[b]);
    if (want > kMaxDeflateRatio * in.size() + 1024)
      throw std::runtime_error(where + ": zlib block " + std::to_string(b) + " of " + std::to_string(in.size()) +
                               " bytes cannot hold " + std::to_string(want));
    block.resize(want);
    uLongf got = static_cast<uLongf>(want);
    const int rc = uncompress(reinterpret_cast<Bytef*>(block.data()), &got, reinterpret_cast<const Bytef*>(in.data()),
                              static_cast<uLong>(in.size()));
    if (rc != Z_OK || got != want)
      throw std::runtime_error(where + ": zlib block " + std::to_string(b) + " is corrupt (" +
                               (rc == Z_OK ? "wrong size" : zError(rc)) + ")");
    sink(block);
  }
}

std::vector<float> decode_array(std::string_view bytes, const VtiDocument& doc, const VtiArray& a, const std::string& file) {
  const std::string where = file + ": array '" + a.name + "'";
  const uint64_t count = checked_mul(a.tuples, a.components, kMaxVoxels, file, "array '" + a.name + "'");
  // The budget is checked where the values are allocated, after the data were found to hold them:
  // a 400-byte file claiming 10^12 values is short, not a matter of --max-memory.
  const auto allocate = [&](std::vector<float>& values) {
    check_memory(count * sizeof(float), where + ": " + std::to_string(count) + " values");
    values.resize(count);
  };
  std::vector<float> v;
  if (a.format == "ascii") {
    std::string_view text = bytes.substr(a.content_begin, a.content_end - a.content_begin);
    if (count > (text.size() + 1) / 2) throw std::runtime_error(where + ": needs " + std::to_string(count) + " values, the text is too short");
    allocate(v);
    size_t p = 0;
    auto space = [&](char c) { return std::isspace(static_cast<unsigned char>(c)) != 0; };
    for (uint64_t i = 0; i < count; ++i) {
      while (p < text.size() && space(text[p])) ++p;
      size_t b = p;
      while (p < text.size() && !space(text[p])) ++p;
      auto n = parse_number(text.substr(b, p - b));
      if (!n) throw std::runtime_error(where + ": value " + std::to_string(i) + " is '" + std::string(text.substr(b, p - b)) + "', not a number");
      if (!fits_element_type(*n, a.type))
        throw std::runtime_error(where + ": value " + std::to_string(i) + " is " + std::string(text.substr(b, p - b)) +
                                 ", no " + element_type_name(a.type) + " value (the array's declared type)");
      v[i] = static_cast<float>(*n);
    }
    while (p < text.size() && space(text[p])) ++p;
    if (p != text.size()) throw std::runtime_error(where + ": more values than " + std::to_string(count));
    return v;
  }
  if (a.format == "appended" && a.offset > bytes.size() - doc.appended_begin)
    throw std::runtime_error(where + ": offset " + std::to_string(a.offset) + " lies beyond the end of the file");
  std::string_view region = a.format == "binary" ? bytes.substr(a.content_begin, a.content_end - a.content_begin)
                                                 : bytes.substr(doc.appended_begin + a.offset);
  ByteSource src(region, a.format == "binary" || doc.appended_base64);
  // Bytes arrive in blocks that need not end on an element: a partial element waits in `carry`.
  const uint64_t elem = element_bytes(a.type);
  uint64_t filled = 0;
  std::string carry;
  auto decode = [&](std::string_view bytes) {
    // Allocated with the first bytes, once read_binary has checked the sizes its header claims.
    if (v.size() != count) allocate(v);
    if (!carry.empty()) {
      const size_t take = std::min<size_t>(elem - carry.size(), bytes.size());
      carry.append(bytes.substr(0, take));
      bytes.remove_prefix(take);
      if (carry.size() == elem) decode_elements(carry.data(), 1, a.type, doc.big_endian, v.data() + filled++), carry.clear();
    }
    const uint64_t whole = bytes.size() / elem;
    decode_elements(bytes.data(), whole, a.type, doc.big_endian, v.data() + filled);
    filled += whole;
    carry.assign(bytes.substr(whole * elem));
    checkpoint("load");
  };
  try {
    read_binary(src, doc, count * elem, where, decode);
  } catch (const std::runtime_error& e) {
    const std::string m = e.what();
    throw std::runtime_error(m.rfind(file, 0) == 0 ? m : where + ": " + m);
  }
  return v;
}

std::array<uint64_t, 3> grid_of(const VtiDocument& doc, const VtiArray& a) {
  std::array<uint64_t, 3> g = doc.dims;
  if (a.section == "cell data")
    for (auto& d : g) d = std::max<uint64_t>(1, d - 1);
  return g;
}

std::string format_double(double v) {
  std::ostringstream os;
  os.precision(17);
  os << v;
  return os.str();
}

}  // namespace

Volume parse_vti(std::string_view bytes, const std::string& file, const VolumeOptions& options) {
  VtiDocument doc = parse_document(bytes, file);
  const ArraySelector sel = parse_array_selector(options.variable, file);
  // Without a name: the active scalars, else the first point array, else the first cell array.
  auto rank = [&](const VtiArray& a) {
    return a.section == "point data" ? (a.name == doc.active_scalars ? 0 : 1) : 2;
  };
  const VtiArray& pick = pick_grid_array(doc.arrays, sel, rank, file);
  Volume v;
  v.dims = grid_of(doc, pick);
  v.spacing = doc.spacing;
  v.origin = origin_of(doc.origin, doc.spacing, pick.section);
  v.name = file + ":" + pick.name + (sel.component ? "[" + std::to_string(*sel.component) + "]" : "");
  v.units = pick.units;
  v.values = select_component(decode_array(bytes, doc, pick, file), pick.components, sel.component, v.name);
  // Axis coordinates tfmatch wrote as field data (x_coordinates, ...), when they fit the grid.
  static const char* kAxes[3] = {"x", "y", "z"};
  for (const VtiArray& a : doc.arrays) {
    for (int k = 0; k < 3; ++k) {
      if (a.section != "field data" || a.name != std::string(kAxes[k]) + "_coordinates" || a.components != 1 ||
          a.tuples != v.dims[size_t(k)])
        continue;
      const std::vector<float> c = decode_array(bytes, doc, a, file);
      v.axes[size_t(k)].coordinates.assign(c.begin(), c.end());
      v.axes[size_t(k)].name = a.axis_name;
      v.axes[size_t(k)].units = a.units;
    }
  }
  return v;
}

namespace {

// An uncompressed array in raw appended data, read slab by slab straight from the file.
class VtiSlabs final : public VolumeSlabReader {
 public:
  VtiSlabs(const std::filesystem::path& path, Volume grid, uint64_t data_begin, ElementType type, bool big_endian,
           uint64_t components, std::optional<uint64_t> component)
      : in_(path, std::ios::binary), name_(path.string()), data_begin_(data_begin), type_(type),
        big_endian_(big_endian), components_(components), component_(component) {
    if (!in_) throw std::runtime_error(name_ + ": cannot open");
    grid_ = std::move(grid);
  }
  void read_slices(uint64_t z0, uint64_t nz, float* out) override {
    check_slices(z0, nz);
    const uint64_t elem = element_bytes(type_), tuple_bytes = elem * components_;
    const uint64_t tuples = nz * slice_voxels();
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(data_begin_ + z0 * slice_voxels() * tuple_bytes));
    const uint64_t block = std::max<uint64_t>(1, (uint64_t(4) << 20) / components_);  // tuples per read
    bytes_.resize(std::min(tuples, block) * tuple_bytes);
    values_.resize(std::min(tuples, block) * components_);
    for (uint64_t done = 0; done < tuples; done += block) {
      checkpoint("load");
      const uint64_t n = std::min(block, tuples - done);
      in_.read(bytes_.data(), static_cast<std::streamsize>(n * tuple_bytes));
      if (!in_) throw std::runtime_error(name_ + ": read failed (the file is shorter than when it was opened?)");
      if (components_ == 1) {
        decode_elements(bytes_.data(), n, type_, big_endian_, out + done);
        continue;
      }
      decode_elements(bytes_.data(), n * components_, type_, big_endian_, values_.data());
      for (uint64_t i = 0; i < n; ++i) out[done + i] = reduce_tuple(values_.data() + i * components_, components_, component_);
    }
  }

 private:
  std::ifstream in_;
  std::string name_;
  uint64_t data_begin_;
  ElementType type_;
  bool big_endian_;
  uint64_t components_;
  std::optional<uint64_t> component_;
  std::vector<char> bytes_;
  std::vector<float> values_;
};

}  // namespace

std::unique_ptr<VolumeSlabReader> open_vti_slabs(const std::filesystem::path& path, const VolumeOptions& options) {
  const std::string file = path.string();
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(file + ": cannot open");
  // The XML before the appended data ('_'), read in pieces: only it is parsed.
  std::string head;
  constexpr size_t kPiece = size_t(1) << 20, kMaxHead = size_t(64) << 20;
  size_t underscore = std::string::npos;
  while (head.size() < kMaxHead) {
    const size_t old = head.size();
    head.resize(old + kPiece);
    in.read(head.data() + old, std::streamsize(kPiece));
    head.resize(old + size_t(in.gcount()));
    const size_t app = head.find("<AppendedData");
    const size_t gt = app == std::string::npos ? app : head.find('>', app);
    if (gt != std::string::npos) {
      size_t p = gt + 1;
      while (p < head.size() && std::isspace(static_cast<unsigned char>(head[p]))) ++p;
      if (p < head.size()) {
        underscore = p;
        break;
      }
    }
    if (head.size() == old) break;  // end of file
  }
  if (underscore == std::string::npos) return nullptr;  // inline or ASCII arrays: loaded whole
  head.resize(underscore + 1);
  const VtiDocument doc = parse_document(head, file);
  if (doc.compressed || doc.appended_base64) return nullptr;
  const ArraySelector sel = parse_array_selector(options.variable, file);
  auto rank = [&](const VtiArray& a) { return a.section == "point data" ? (a.name == doc.active_scalars ? 0 : 1) : 2; };
  const VtiArray& pick = pick_grid_array(doc.arrays, sel, rank, file);
  if (pick.format != "appended") return nullptr;
  const std::string where = file + ": array '" + pick.name + "'";
  const std::string name = file + ":" + pick.name + (sel.component ? "[" + std::to_string(*sel.component) + "]" : "");
  if (sel.component && *sel.component >= pick.components)
    throw std::runtime_error(name + ": component " + std::to_string(*sel.component) + " requested, the array has " +
                             std::to_string(pick.components));
  const uint64_t count = checked_mul(pick.tuples, pick.components, kMaxVoxels, file, "array '" + pick.name + "'");
  const uint64_t bytes = count * element_bytes(pick.type), header = doc.header64 ? 8 : 4;
  const uint64_t size = std::filesystem::file_size(path);
  const uint64_t header_at = doc.appended_begin + pick.offset;
  if (header_at > size || size - header_at < header + bytes)
    throw std::runtime_error(where + ": data truncated: " + std::to_string(header + bytes) + " bytes needed at offset " +
                             std::to_string(pick.offset) + ", the file ends before");
  std::string h(header, '\0');
  in.clear();
  in.seekg(std::streamoff(header_at));
  in.read(h.data(), std::streamsize(header));
  ByteSource src(h, false);
  const uint64_t n = read_header_uint(src, doc);
  if (n != bytes)
    throw std::runtime_error(where + ": its header says " + std::to_string(n) + " bytes, the array needs " +
                             std::to_string(bytes));
  Volume grid;
  grid.dims = grid_of(doc, pick);
  grid.spacing = doc.spacing;
  grid.origin = origin_of(doc.origin, doc.spacing, pick.section);
  grid.name = name;
  grid.units = pick.units;
  return std::make_unique<VtiSlabs>(path, std::move(grid), header_at + header, pick.type, doc.big_endian,
                                    pick.components, sel.component);
}

Volume read_vti_volume(const std::filesystem::path& path, const VolumeOptions& options) {
  return parse_vti(read_file_bytes(path), path.string(), options);
}

FileInfo describe_vti(const std::filesystem::path& path, const VolumeOptions&) {
  const std::string file = path.string();
  const std::string bytes = read_file_bytes(path);
  VtiDocument doc = parse_document(bytes, file);
  FileInfo info{file, "VTK XML ImageData", {}, {}};
  info.notes.push_back(std::string(doc.big_endian ? "big-endian" : "little-endian") + ", header " +
                       (doc.header64 ? "UInt64" : "UInt32") + (doc.compressed ? ", zlib-compressed" : ", uncompressed") +
                       (doc.has_appended ? (doc.appended_base64 ? ", appended base64" : ", appended raw") : ""));
  for (const auto& a : doc.arrays) {
    ArrayInfo ai;
    ai.name = a.name;
    ai.kind = a.section + (a.name == doc.active_scalars && a.section == "point data" ? " (active scalars)" : "");
    ai.type = element_type_name(a.type);
    ai.components = a.components;
    ai.shape = std::to_string(a.tuples) + " tuples x " + std::to_string(a.components) + " components, format " + a.format;
    if (a.section != "field data") {
      ai.grid = grid_of(doc, a);
      ai.spacing = doc.spacing;
      ai.origin = origin_of(doc.origin, doc.spacing, a.section);  // as load_volume() places it
    }
    if (a.components > 1) ai.notes.push_back("loads as the magnitude; NAME[k] picks component k");
    std::vector<float> v = select_component(decode_array(bytes, doc, a, file), a.components, std::nullopt, file);
    accumulate_stats(ai, v.data(), v.size());
    info.arrays.push_back(std::move(ai));
  }
  return info;
}

std::string vti_bytes(const std::vector<std::pair<std::string, const Volume*>>& arrays, const std::string& name,
                      const VtiWriteOptions& options) {
  const std::filesystem::path path = name;  // for messages
  if (arrays.empty()) throw std::invalid_argument("write_vti: no arrays");
  const Volume& first = *arrays.front().second;
  for (const auto& [name, v] : arrays) {
    if (v->dims != first.dims)
      throw std::runtime_error(path.string() + ": arrays to write are on different grids (" + arrays.front().first + ", " + name + ")");
    if (v->values.size() != v->voxel_count()) throw std::invalid_argument("write_vti: volume size does not match its dims");
  }
  const auto& d = first.dims;
  // Axis coordinates (latitudes, pressure levels, ...) as field data, so that what the regular
  // Origin/Spacing cannot say (Gaussian latitudes, uneven levels, units) travels with the grid:
  // Float64 ascii arrays "x_coordinates" ... with the axis name and units as extra attributes
  // (VTK readers keep the arrays and ignore the attributes; tfmatch restores both).
  std::ostringstream fd;
  bool any_coordinates = false;
  for (int k = 0; k < 3; ++k) any_coordinates |= first.axes[size_t(k)].coordinates.size() == d[size_t(k)];
  if (any_coordinates) {
    fd << "    <FieldData>\n";
    static const char* kAxes[3] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k) {
      const GridAxis& a = first.axes[size_t(k)];
      if (a.coordinates.size() != d[size_t(k)]) continue;
      fd << "      <DataArray type=\"Float64\" Name=\"" << kAxes[k] << "_coordinates\" NumberOfTuples=\""
          << a.coordinates.size() << "\" format=\"ascii\" axis_name=\"" << xml_escape(a.name) << "\" units=\""
          << xml_escape(a.units) << "\">";
      for (size_t i = 0; i < a.coordinates.size(); ++i) fd << (i ? " " : "") << format_double(a.coordinates[i]);
      fd << "</DataArray>\n";
    }
    fd << "    </FieldData>\n";
  }
  std::ostringstream xml;
  const auto& o = options.extent_offset;
  std::string extent;
  for (int k = 0; k < 3; ++k)
    extent += (k ? " " : "") + std::to_string(o[size_t(k)]) + " " + std::to_string(o[size_t(k)] + d[size_t(k)] - 1);
  xml << "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\" "
         "header_type=\"UInt64\""
      << (options.compress ? " compressor=\"vtkZLibDataCompressor\"" : "") << ">\n"
      << "  <ImageData WholeExtent=\"" << extent << "\" Origin=\"" << format_double(first.origin[0]) << " "
      << format_double(first.origin[1]) << " " << format_double(first.origin[2]) << "\" Spacing=\"" << format_double(first.spacing[0]) << " "
      << format_double(first.spacing[1]) << " " << format_double(first.spacing[2]) << "\">\n"
      << fd.str() << "    <Piece Extent=\"" << extent << "\">\n"
      << "      <PointData Scalars=\"" << xml_escape(arrays.front().first) << "\">\n";
  // Each array's payload: little-endian float32, as UInt64 size + bytes or as zlib blocks (header,
  // then the blocks). Compressed payloads are made first, since the XML names every offset; the
  // file is then built once, with uncompressed values copied straight from the volumes: about one
  // copy of the output beside the inputs (it was three or four, none checked).
  auto put64 = [](std::string& s, uint64_t x) {
    for (int b = 0; b < 8; ++b) s.push_back(static_cast<char>((x >> (8 * b)) & 0xff));
  };
  auto append_le = [](std::string& out, const float* values, size_t n) {
    const size_t at = out.size();
    out.resize(at + n * 4);
    if constexpr (std::endian::native == std::endian::little) {
      std::memcpy(out.data() + at, values, n * 4);
    } else {
      for (size_t i = 0; i < n; ++i) {
        const uint32_t bits = __builtin_bswap32(std::bit_cast<uint32_t>(values[i]));
        std::memcpy(out.data() + at + i * 4, &bits, 4);
      }
    }
  };
  uint64_t payload_bytes = 0;
  for (const auto& entry : arrays) payload_bytes += 8 + entry.second->values.size() * 4;
  check_memory(payload_bytes + (options.compress ? payload_bytes : 0),
               path.string() + ": the VTI file's " + std::to_string(arrays.size()) + " array(s) in memory");
  std::vector<std::string> compressed(arrays.size());
  uint64_t offset = 0;
  for (size_t k = 0; k < arrays.size(); ++k) {
    const auto& [name, v] = arrays[k];
    if (options.compress) {
      // 32 KiB blocks, each deflated on its own (VTK's vtkZLibDataCompressor layout).
      const uint64_t size = v->values.size() * 4, block = 32768, blocks = (size + block - 1) / block;
      std::string header, body, raw;
      put64(header, blocks);
      put64(header, block);
      put64(header, size % block);
      for (uint64_t b = 0; b < blocks; ++b) {
        const uint64_t n = std::min<uint64_t>(block, size - b * block);
        raw.clear();
        const size_t first = size_t(b * block / 4);
        append_le(raw, v->values.data() + first, size_t(n / 4));
        std::string out(compressBound(static_cast<uLong>(n)), '\0');
        uLongf got = static_cast<uLongf>(out.size());
        if (compress2(reinterpret_cast<Bytef*>(out.data()), &got, reinterpret_cast<const Bytef*>(raw.data()),
                      static_cast<uLong>(n), Z_DEFAULT_COMPRESSION) != Z_OK)
          throw std::runtime_error(path.string() + ": zlib compression failed");
        put64(header, got);
        body.append(out.data(), got);
      }
      header += body;
      compressed[k] = std::move(header);
    }
    float lo = std::numeric_limits<float>::infinity(), hi = -lo;
    for (float x : v->values)
      if (std::isfinite(x)) lo = std::min(lo, x), hi = std::max(hi, x);
    xml << "        <DataArray type=\"Float32\" Name=\"" << xml_escape(name) << "\" NumberOfComponents=\"1\" format=\"appended\"";
    if (lo <= hi) xml << " RangeMin=\"" << format_double(lo) << "\" RangeMax=\"" << format_double(hi) << "\"";
    // The values' units as an extra attribute (VTK ignores it; tfmatch reads it back).
    if (!v->units.empty()) xml << " units=\"" << xml_escape(v->units) << "\"";
    xml << " offset=\"" << offset << "\"/>\n";
    offset += options.compress ? compressed[k].size() : 8 + v->values.size() * 4;
  }
  xml << "      </PointData>\n      <CellData>\n      </CellData>\n    </Piece>\n  </ImageData>\n"
      << "  <AppendedData encoding=\"raw\">\n   _";
  const std::string tail = "\n  </AppendedData>\n</VTKFile>\n";
  std::string bytes = xml.str();
  bytes.reserve(bytes.size() + offset + tail.size());
  for (size_t k = 0; k < arrays.size(); ++k) {
    if (options.compress) {
      bytes += compressed[k];
      std::string().swap(compressed[k]);
    } else {
      put64(bytes, arrays[k].second->values.size() * 4);
      append_le(bytes, arrays[k].second->values.data(), arrays[k].second->values.size());
    }
  }
  bytes += tail;
  return bytes;
}

void write_vti(const std::filesystem::path& path, const std::vector<std::pair<std::string, const Volume*>>& arrays,
               const VtiWriteOptions& options) {
  write_file_atomically(path, vti_bytes(arrays, path.string(), options));
}

void write_vti(const std::filesystem::path& path, const Volume& volume, const std::string& array_name,
               const VtiWriteOptions& options) {
  write_vti(path, {{array_name, &volume}}, options);
}

void write_pvti(const std::filesystem::path& path, const Volume& whole, const std::string& array_name,
                const std::vector<PvtiPiece>& pieces) {
  const auto& d = whole.dims;
  auto extent = [&](uint64_t z0, uint64_t z1) {
    return "0 " + std::to_string(d[0] - 1) + " 0 " + std::to_string(d[1] - 1) + " " + std::to_string(z0) + " " +
           std::to_string(z1);
  };
  std::ostringstream xml;
  xml << "<?xml version=\"1.0\"?>\n<VTKFile type=\"PImageData\" version=\"1.0\" byte_order=\"LittleEndian\" "
         "header_type=\"UInt64\">\n"
      << "  <PImageData WholeExtent=\"" << extent(0, d[2] - 1) << "\" GhostLevel=\"0\" Origin=\""
      << format_double(whole.origin[0]) << " " << format_double(whole.origin[1]) << " " << format_double(whole.origin[2])
      << "\" Spacing=\"" << format_double(whole.spacing[0]) << " " << format_double(whole.spacing[1]) << " "
      << format_double(whole.spacing[2]) << "\">\n"
      << "    <PPointData Scalars=\"" << xml_escape(array_name) << "\">\n"
      << "      <PDataArray type=\"Float32\" Name=\"" << xml_escape(array_name) << "\" NumberOfComponents=\"1\"/>\n"
      << "    </PPointData>\n";
  for (const PvtiPiece& p : pieces) {
    if (p.z_last < p.z_first || p.z_last >= d[2])
      throw std::invalid_argument(path.string() + ": a piece's slices " + std::to_string(p.z_first) + ".." +
                                  std::to_string(p.z_last) + " are outside the grid's " + std::to_string(d[2]));
    xml << "    <Piece Extent=\"" << extent(p.z_first, p.z_last) << "\" Source=\"" << xml_escape(p.source) << "\"/>\n";
  }
  xml << "  </PImageData>\n</VTKFile>\n";
  write_file_atomically(path, xml.str());
}

}  // namespace tfm
