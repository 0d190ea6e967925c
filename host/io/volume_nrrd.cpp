// NRRD volumes: attached (.nrrd) or detached (.nhdr + data files, including the multi-file
// forms "data file: name.%d min max step [subdim]" and "data file: LIST"); raw, gzip, ASCII and
// hex encodings; either byte order; dimension 1-3, or 4 with the fastest axis as components.
#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <stdexcept>

#include <zlib.h>

#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm {
namespace {

std::string trim(std::string_view s) {
  size_t b = 0, e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return std::string(s.substr(b, e - b));
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

std::vector<std::string> words(const std::string& s) {
  std::istringstream in(s);
  std::vector<std::string> out;
  for (std::string w; in >> w;) out.push_back(w);
  return out;
}

std::optional<ElementType> parse_nrrd_type(std::string t) {
  t = lower(trim(t));
  // Collapse runs of spaces: "unsigned  short" is still "unsigned short".
  std::string c;
  for (char ch : t)
    if (!(ch == ' ' && !c.empty() && c.back() == ' ')) c.push_back(ch);
  if (c == "signed char" || c == "int8" || c == "int8_t") return ElementType::Int8;
  if (c == "uchar" || c == "unsigned char" || c == "uint8" || c == "uint8_t") return ElementType::UInt8;
  if (c == "short" || c == "short int" || c == "signed short" || c == "signed short int" || c == "int16" || c == "int16_t")
    return ElementType::Int16;
  if (c == "ushort" || c == "unsigned short" || c == "unsigned short int" || c == "uint16" || c == "uint16_t")
    return ElementType::UInt16;
  if (c == "int" || c == "signed int" || c == "int32" || c == "int32_t") return ElementType::Int32;
  if (c == "uint" || c == "unsigned int" || c == "uint32" || c == "uint32_t") return ElementType::UInt32;
  if (c == "longlong" || c == "long long" || c == "long long int" || c == "signed long long" ||
      c == "signed long long int" || c == "int64" || c == "int64_t")
    return ElementType::Int64;
  if (c == "ulonglong" || c == "unsigned long long" || c == "unsigned long long int" || c == "uint64" || c == "uint64_t")
    return ElementType::UInt64;
  if (c == "float") return ElementType::Float32;
  if (c == "double") return ElementType::Float64;
  return std::nullopt;
}

struct NrrdHeader {
  int dimension = 0;
  std::vector<uint64_t> sizes;
  std::optional<ElementType> type;
  std::string type_text;
  std::string encoding;                 // raw, gzip, ascii, hex
  std::optional<bool> big_endian;
  std::vector<double> spacings;         // per axis, NaN when not given
  std::vector<std::string> data_files;  // empty: data attached after the header
  uint64_t subdim = 0;                  // axes per data file (0: all)
  int64_t byte_skip = 0;
  uint64_t line_skip = 0;
  size_t data_begin = 0;                // attached data offset
};

uint64_t parse_uint_field(const std::string& v, const std::string& where) {
  uint64_t x = 0;
  auto [p, ec] = std::from_chars(v.data(), v.data() + v.size(), x);
  if (v.empty() || ec != std::errc() || p != v.data() + v.size())
    throw std::runtime_error(where + ": expected a non-negative integer, found '" + v + "'");
  return x;
}

// Expands "name.%03d" with one integer: only %d/%i/%u with optional 0 flag and width (never
// handed to printf, since the header is untrusted).
std::string format_name(const std::string& fmt, int64_t value, const std::string& where) {
  std::string out;
  bool used = false;
  for (size_t i = 0; i < fmt.size(); ++i) {
    if (fmt[i] != '%') {
      out.push_back(fmt[i]);
      continue;
    }
    if (i + 1 < fmt.size() && fmt[i + 1] == '%') {
      out.push_back('%');
      ++i;
      continue;
    }
    size_t j = i + 1;
    bool zero = j < fmt.size() && fmt[j] == '0';
    if (zero) ++j;
    size_t width = 0;
    while (j < fmt.size() && std::isdigit(static_cast<unsigned char>(fmt[j])) && width < 64) width = width * 10 + (fmt[j++] - '0');
    if (j >= fmt.size() || (fmt[j] != 'd' && fmt[j] != 'i' && fmt[j] != 'u') || used)
      throw std::runtime_error(where + ": data file format '" + fmt + "' must contain exactly one %d");
    used = true;
    std::string digits = std::to_string(value < 0 ? -value : value);
    std::string sign = value < 0 ? "-" : "";
    const size_t len = sign.size() + digits.size();
    if (len < width) {
      if (zero) digits.insert(0, width - len, '0');
      else sign.insert(0, width - len, ' ');
    }
    out += sign + digits;
    i = j;
  }
  if (!used) throw std::runtime_error(where + ": data file format '" + fmt + "' must contain one %d");
  return out;
}

NrrdHeader parse_header(std::string_view bytes, const std::string& file) {
  NrrdHeader h;
  size_t pos = 0;
  int line_no = 0;
  auto next_line = [&](std::string& out) {
    if (pos >= bytes.size()) return false;
    size_t e = bytes.find('\n', pos);
    if (e == std::string_view::npos) e = bytes.size();
    out.assign(bytes.substr(pos, e - pos));
    if (!out.empty() && out.back() == '\r') out.pop_back();
    pos = std::min(e + 1, bytes.size());
    ++line_no;
    return true;
  };
  std::string line;
  if (!next_line(line) || line.size() != 8 || line.rfind("NRRD000", 0) != 0 || line[7] < '1' || line[7] > '5')
    throw std::runtime_error(file + ": not a NRRD file (the first line must be NRRD0001..NRRD0005)");
  auto fail = [&](const std::string& what) -> std::runtime_error {
    return std::runtime_error(file + ": line " + std::to_string(line_no) + ": " + what);
  };
  bool list_follows = false;
  while (next_line(line)) {
    if (list_follows) {
      if (!trim(line).empty()) h.data_files.push_back(trim(line));
      continue;
    }
    if (line.empty()) break;  // end of header; attached data follows
    if (line[0] == '#') continue;
    const size_t kv = line.find(":=");
    const size_t colon = line.find(": ");
    if (kv != std::string::npos && (colon == std::string::npos || kv < colon)) continue;  // key/value pair
    if (colon == std::string::npos) throw fail("expected 'field: description', found '" + line + "'");
    const std::string field = lower(trim(line.substr(0, colon)));
    const std::string value = trim(line.substr(colon + 2));
    if (field == "dimension") {
      const uint64_t d = parse_uint_field(value, file + ": dimension");
      if (d < 1 || d > 16) throw fail("dimension must be 1..16");
      h.dimension = static_cast<int>(d);
    } else if (field == "type") {
      h.type = parse_nrrd_type(value);
      h.type_text = value;
      if (!h.type) throw fail("type '" + value + "' is not supported");
    } else if (field == "sizes") {
      for (const auto& w : words(value)) h.sizes.push_back(parse_uint_field(w, file + ": sizes"));
    } else if (field == "endian") {
      if (value != "little" && value != "big") throw fail("endian must be little or big");
      h.big_endian = value == "big";
    } else if (field == "encoding") {
      const std::string e = lower(value);
      if (e == "raw") h.encoding = "raw";
      else if (e == "gz" || e == "gzip") h.encoding = "gzip";
      else if (e == "txt" || e == "text" || e == "ascii") h.encoding = "ascii";
      else if (e == "hex") h.encoding = "hex";
      else if (e == "bz2" || e == "bzip2") throw fail("bzip2 encoding is not supported (use raw or gzip)");
      else throw fail("unknown encoding '" + value + "'");
    } else if (field == "spacings") {
      // NaN is the format's "no spacing along this axis"; a negative one runs the axis backwards
      // (its size is what matters here). Anything else would be dropped for unit spacing.
      for (const auto& w : words(value)) {
        auto n = parse_number(w);
        const bool nan = n ? std::isnan(*n) : (w == "nan" || w == "NaN" || w == "NAN");
        if (!nan && (!n || !std::isfinite(*n) || *n == 0))
          throw fail("spacings: '" + w + "' is not a spacing (a finite non-zero number, or nan for an axis without one)");
        h.spacings.push_back(nan ? std::nan("") : std::abs(*n));
      }
    } else if (field == "space directions") {
      // "(x,y,z) (x,y,z) none ...": the voxel size along an axis is its direction's length.
      std::vector<double> norms;
      for (const auto& w : words(value)) {
        if (w == "none") {
          norms.push_back(std::nan(""));
          continue;
        }
        if (w.size() < 2 || w.front() != '(' || w.back() != ')') throw fail("bad space direction '" + w + "'");
        std::string inner = w.substr(1, w.size() - 2);
        std::replace(inner.begin(), inner.end(), ',', ' ');
        double s = 0;
        for (const auto& c : words(inner)) {
          auto n = parse_number(c);
          if (!n) throw fail("bad space direction '" + w + "'");
          s += *n * *n;
        }
        norms.push_back(std::sqrt(s));
      }
      if (h.spacings.empty()) h.spacings = norms;
    } else if (field == "byte skip" || field == "byteskip") {
      if (value == "-1") h.byte_skip = -1;
      else h.byte_skip = static_cast<int64_t>(std::min<uint64_t>(parse_uint_field(value, file + ": byte skip"), uint64_t(1) << 62));
    } else if (field == "line skip" || field == "lineskip") {
      h.line_skip = parse_uint_field(value, file + ": line skip");
    } else if (field == "data file" || field == "datafile") {
      std::vector<std::string> w = words(value);
      if (w.empty()) throw fail("empty data file");
      if (w[0] == "LIST") {
        if (w.size() > 1) h.subdim = parse_uint_field(w[1], file + ": data file LIST subdim");
        list_follows = true;
      } else if (w.size() >= 4 && w[0].find('%') != std::string::npos) {
        auto num = [&](const std::string& s) {
          int64_t v = 0;
          auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
          if (ec != std::errc() || p != s.data() + s.size()) throw fail("bad number '" + s + "' in data file");
          return v;
        };
        const int64_t lo = num(w[1]), hi = num(w[2]), step = num(w[3]);
        if (w.size() > 4) h.subdim = parse_uint_field(w[4], file + ": data file subdim");
        if (step == 0 || (hi - lo) / step < 0 || (hi - lo) / step >= 1000000)
          throw fail("data file range " + w[1] + ".." + w[2] + " step " + w[3] + " is empty or too long");
        for (int64_t i = lo; step > 0 ? i <= hi : i >= hi; i += step) h.data_files.push_back(format_name(w[0], i, file));
      } else {
        h.data_files.push_back(value);
      }
    }
    // Other fields (content, kinds, space, space origin, units, ...) do not affect the values.
  }
  h.data_begin = pos;
  if (h.dimension == 0) throw std::runtime_error(file + ": no dimension field");
  if (h.sizes.size() != size_t(h.dimension))
    throw std::runtime_error(file + ": sizes has " + std::to_string(h.sizes.size()) + " entries for dimension " +
                             std::to_string(h.dimension));
  if (!h.type) throw std::runtime_error(file + ": no type field");
  if (h.encoding.empty()) throw std::runtime_error(file + ": no encoding field");
  if (!h.big_endian && element_bytes(*h.type) > 1 && h.encoding != "ascii")
    throw std::runtime_error(file + ": no endian field (needed for " + h.type_text + " data)");
  if (h.byte_skip < 0 && h.encoding != "raw") throw std::runtime_error(file + ": byte skip -1 needs raw encoding");
  if (list_follows && h.data_files.empty()) throw std::runtime_error(file + ": data file LIST names no files");
  return h;
}

// Where decoded values go, in order, a block at a time.
using ValueSink = std::function<void(const float* values, uint64_t n)>;

// Values decoded per block: 1 Mi floats keep the buffers at a few MiB for any file size.
constexpr uint64_t kBlock = uint64_t(1) << 20;

// Decodes `count` elements from one data file's bytes (after line skip) into `sink`, a block at
// a time: compressed, hex and text data never exist in full beside the decoded values.
void decode_chunk(std::string_view data, const NrrdHeader& h, uint64_t count, const ValueSink& sink,
                  const std::string& where) {
  for (uint64_t i = 0; i < h.line_skip; ++i) {
    const size_t e = data.find('\n');
    if (e == std::string_view::npos) throw std::runtime_error(where + ": fewer lines than line skip " + std::to_string(h.line_skip));
    data.remove_prefix(e + 1);
  }
  const uint64_t elem = element_bytes(*h.type);
  const uint64_t need = count * elem;  // count * elem <= kMaxVoxels * 8 by the caller's checks
  const bool big = h.big_endian.value_or(false);
  std::vector<float> values(std::min(count, kBlock));
  // Decodes whole elements of `bytes` (a multiple of elem) block by block.
  auto emit = [&](const char* bytes, uint64_t n) {
    for (uint64_t done = 0; done < n; done += kBlock) {
      const uint64_t k = std::min(kBlock, n - done);
      decode_elements(bytes + done * elem, k, *h.type, big, values.data());
      sink(values.data(), k);
      checkpoint("load");
    }
  };
  if (h.encoding == "raw") {
    uint64_t skip = h.byte_skip < 0 ? (data.size() >= need ? data.size() - need : 0) : uint64_t(h.byte_skip);
    if (skip > data.size() || data.size() - skip < need)
      throw std::runtime_error(where + ": has " + std::to_string(data.size()) + " bytes, " + std::to_string(skip + need) +
                               " needed (truncated, or wrong sizes/type in the header)");
    emit(data.data() + skip, count);
  } else if (h.encoding == "gzip") {
    uint64_t skip = uint64_t(h.byte_skip);
    if (need + skip > kMaxDeflateRatio * data.size() + 1024)
      throw std::runtime_error(where + ": " + std::to_string(data.size()) + " compressed bytes cannot hold " +
                               std::to_string(need) + " bytes");
    if (data.size() > 0xffffffffu) throw std::runtime_error(where + ": gzip data over 4 GiB per file is not supported");
    z_stream z{};
    if (inflateInit2(&z, 15 + 32) != Z_OK) throw std::runtime_error(where + ": zlib initialization failed");
    struct End {
      z_stream* z;
      ~End() { inflateEnd(z); }
    } end{&z};
    z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
    z.avail_in = static_cast<uInt>(data.size());
    // Inflated bytes wait in `buf` until they make whole elements; the byte skip is inflated and
    // dropped.
    std::vector<char> buf(std::min(need, kBlock * elem) + elem);
    uint64_t held = 0, decoded = 0;
    int rc = Z_OK;
    while (decoded < count) {
      const uint64_t want = skip > 0 ? std::min<uint64_t>(skip, buf.size()) : std::min(buf.size() - held, (count - decoded) * elem - held);
      z.next_out = reinterpret_cast<Bytef*>(buf.data() + (skip > 0 ? 0 : held));
      z.avail_out = static_cast<uInt>(want);
      rc = inflate(&z, Z_NO_FLUSH);
      const uint64_t got = want - z.avail_out;
      if (skip > 0) {
        skip -= got;
      } else {
        held += got;
        const uint64_t whole = held / elem;
        if (whole > 0) {
          emit(buf.data(), whole);
          decoded += whole;
          std::memmove(buf.data(), buf.data() + whole * elem, held - whole * elem);
          held -= whole * elem;
        }
      }
      if (rc == Z_STREAM_END) {
        if (z.avail_in == 0 || inflateReset(&z) != Z_OK) break;  // more input: concatenated gzip members
      } else if (rc != Z_OK) {
        break;  // Z_BUF_ERROR: input exhausted; anything else: corrupt
      }
    }
    if (decoded < count)
      throw std::runtime_error(where + ": gzip data " + (rc == Z_OK || rc == Z_STREAM_END || rc == Z_BUF_ERROR ? "ends" : "is corrupt") +
                               " after " + std::to_string(decoded * elem + held) + " bytes, " + std::to_string(need) + " needed");
  } else if (h.encoding == "hex") {
    const uint64_t skip = std::min<uint64_t>(uint64_t(h.byte_skip), data.size());
    data.remove_prefix(skip);
    if (need > data.size() / 2) throw std::runtime_error(where + ": too little hex data for " + std::to_string(need) + " bytes");
    std::vector<char> buf;
    buf.reserve(std::min(need, kBlock * elem));
    uint64_t decoded = 0;
    int nibble = -1;
    for (char c : data) {
      if (decoded == count) break;
      if (std::isspace(static_cast<unsigned char>(c))) continue;
      int v = std::isdigit(static_cast<unsigned char>(c)) ? c - '0'
              : (c >= 'a' && c <= 'f') ? c - 'a' + 10 : (c >= 'A' && c <= 'F') ? c - 'A' + 10 : -1;
      if (v < 0) throw std::runtime_error(where + ": bad hex digit");
      if (nibble < 0) {
        nibble = v;
        continue;
      }
      buf.push_back(static_cast<char>(nibble * 16 + v));
      nibble = -1;
      if (buf.size() == buf.capacity() || decoded + buf.size() / elem == count) {
        const uint64_t whole = buf.size() / elem;
        emit(buf.data(), whole);
        decoded += whole;
        buf.erase(buf.begin(), buf.begin() + ptrdiff_t(whole * elem));
      }
    }
    if (decoded != count) throw std::runtime_error(where + ": hex data ends early");
  } else {  // ascii
    data.remove_prefix(std::min<uint64_t>(uint64_t(h.byte_skip), data.size()));
    if (count > (data.size() + 1) / 2) throw std::runtime_error(where + ": too little text for " + std::to_string(count) + " values");
    size_t p = 0;
    auto sep = [](char c) { return std::isspace(static_cast<unsigned char>(c)) || c == ','; };
    uint64_t filled = 0;
    for (uint64_t i = 0; i < count; ++i) {
      while (p < data.size() && sep(data[p])) ++p;
      size_t b = p;
      while (p < data.size() && !sep(data[p])) ++p;
      if (b == data.size())
        throw std::runtime_error(where + ": " + std::to_string(i) + " values, the sizes need " + std::to_string(count));
      auto n = parse_number(data.substr(b, p - b));
      if (!n) throw std::runtime_error(where + ": value " + std::to_string(i) + " ('" + std::string(data.substr(b, std::min<size_t>(p - b, 20))) + "') is not a number");
      if (!fits_element_type(*n, *h.type))
        throw std::runtime_error(where + ": value " + std::to_string(i) + " (" + std::string(data.substr(b, std::min<size_t>(p - b, 20))) +
                                 ") is no " + h.type_text + " value (the type the header declares)");
      values[filled++] = static_cast<float>(*n);
      if (filled == values.size() || i + 1 == count) {
        sink(values.data(), filled);
        filled = 0;
        checkpoint("load");
      }
    }
  }
}

// Reduces interleaved tuples of `components` values to one value each, as select_component()
// does (component k, or the magnitude), across block boundaries.
class TupleReducer {
 public:
  TupleReducer(uint64_t components, std::optional<uint64_t> component, ValueSink sink)
      : components_(components), component_(component), sink_(std::move(sink)) {
    tuple_.reserve(components);
  }
  void add(const float* v, uint64_t n) {
    if (components_ == 1) return sink_(v, n);
    for (uint64_t i = 0; i < n; ++i) {
      tuple_.push_back(v[i]);
      if (tuple_.size() < components_) continue;
      out_.push_back(reduce_tuple(tuple_.data(), components_, component_));
      tuple_.clear();
      if (out_.size() == kBlock) flush();
    }
  }
  void flush() {
    if (!out_.empty()) sink_(out_.data(), out_.size());
    out_.clear();
  }

 private:
  uint64_t components_;
  std::optional<uint64_t> component_;
  ValueSink sink_;
  std::vector<float> tuple_, out_;
};

// One data file's bytes: in memory (a view of the header file's bytes, or of a data file read
// whole), or, for raw data read in blocks (`info`), a range of a file on disk.
struct NrrdChunk {
  std::string_view bytes;
  std::filesystem::path file;  // set when the bytes stay on disk
  uint64_t offset = 0, size = 0;
  bool on_disk() const { return !file.empty(); }
  uint64_t byte_count() const { return on_disk() ? size : bytes.size(); }
};

// Raw data of a range of a file, `skip` bytes in (-1: the last count elements), decoded a block at
// a time into `sink`: the bytes are never held whole.
void stream_raw_chunk(const NrrdChunk& c, const NrrdHeader& h, uint64_t count, const ValueSink& sink,
                      const std::string& where) {
  const uint64_t elem = element_bytes(*h.type), need = count * elem;
  const uint64_t skip = h.byte_skip < 0 ? (c.size >= need ? c.size - need : 0) : uint64_t(h.byte_skip);
  if (skip > c.size || c.size - skip < need)
    throw std::runtime_error(where + ": has " + std::to_string(c.size) + " bytes, " + std::to_string(skip + need) +
                             " needed (truncated, or wrong sizes/type in the header)");
  std::ifstream in(c.file, std::ios::binary);
  if (!in) throw std::runtime_error(where + ": cannot open " + c.file.string());
  in.seekg(std::streamoff(c.offset + skip));
  std::vector<char> bytes(std::min(count, kBlock) * elem);
  std::vector<float> values(std::min(count, kBlock));
  for (uint64_t done = 0; done < count; done += kBlock) {
    checkpoint("load");
    const uint64_t n = std::min(kBlock, count - done);
    if (!in.read(bytes.data(), std::streamsize(n * elem))) throw std::runtime_error(where + ": read failed");
    decode_elements(bytes.data(), n, *h.type, h.big_endian.value_or(false), values.data());
    sink(values.data(), n);
  }
}

// A NRRD file resolved: its header, grid, and the bytes of each data file (checked against what
// the header promises before anything proportional to the grid is allocated).
struct NrrdData {
  NrrdHeader h;
  std::array<uint64_t, 3> dims{1, 1, 1};
  std::array<double, 3> spacing{1, 1, 1};
  uint64_t components = 1;
  uint64_t per_chunk = 0;
  std::vector<std::string> owned;  // data files read whole (reserved before: the views stay valid)
  std::vector<NrrdChunk> chunks;
  std::vector<std::string> where;
  // Raw data past what the sizes need (byte skip >= 0, no line skip), per data file: read from the
  // start and the rest left, as teem reads it; `info` names it, since it is how a header with
  // wrong sizes shows.
  std::vector<uint64_t> excess;

  // Decodes every data file into `reducer`, in order.
  void decode(TupleReducer& reducer) const {
    const ValueSink add = [&](const float* v, uint64_t n) { reducer.add(v, n); };
    for (size_t i = 0; i < chunks.size(); ++i)
      if (chunks[i].on_disk()) stream_raw_chunk(chunks[i], h, per_chunk, add, where[i]);
      else decode_chunk(chunks[i].bytes, h, per_chunk, add, where[i]);
    reducer.flush();
  }
};

// Where data file `name` of `header` is: relative names are beside the header.
std::filesystem::path data_file_path(const std::filesystem::path& header, const std::string& name) {
  std::filesystem::path p = name;
  if (p.is_relative()) p = header.parent_path() / p;
  std::error_code ec;
  const auto status = std::filesystem::status(p, ec);
  if (!std::filesystem::exists(status))
    throw std::runtime_error(header.string() + ": data file " + p.string() + " does not exist");
  // A directory, a device or a pipe has no size to check against the header's (and a pipe would
  // block the read): the data must be a file.
  if (!std::filesystem::is_regular_file(status))
    throw std::runtime_error(header.string() + ": data file " + p.string() + " is " +
                             (std::filesystem::is_directory(status) ? "a directory" : "not a regular file"));
  return p;
}

// Whether raw data can be read from disk a block at a time (no lines to skip first).
bool streams_from_disk(const NrrdHeader& h) { return h.encoding == "raw" && h.line_skip == 0; }

// `bytes`: the header file's bytes, whole, or (with `on_disk`) at least its header; with
// `on_disk`, the header file's path, and raw data is left on disk (streams_from_disk).
NrrdData resolve_nrrd(std::string_view bytes, const std::string& file, const DataFileLoader& open_data_file,
                      const std::filesystem::path* on_disk = nullptr) {
  NrrdData d;
  d.h = parse_header(bytes, file);
  const NrrdHeader& h = d.h;
  std::vector<uint64_t> s = h.sizes;
  if (h.dimension == 4) {
    d.components = s[0];
    if (d.components == 0 || d.components > 1024)
      throw std::runtime_error(file + ": 4D NRRD: the fastest axis (size " + std::to_string(d.components) +
                               ") must hold 1..1024 components");
    s.erase(s.begin());
  } else if (h.dimension > 4) {
    throw std::runtime_error(file + ": dimension " + std::to_string(h.dimension) + " is not supported (1 to 4)");
  }
  const size_t axis0 = h.dimension == 4 ? 1 : 0;
  for (size_t i = 0; i < s.size(); ++i) {
    d.dims[i] = s[i];
    const size_t a = axis0 + i;
    if (a < h.spacings.size() && std::isfinite(h.spacings[a]) && h.spacings[a] > 0) d.spacing[i] = h.spacings[a];
  }
  const uint64_t voxels = checked_voxel_count(d.dims, file);
  const uint64_t count = checked_mul(voxels, d.components, kMaxVoxels, file, "number of values");
  // Which files hold which part: each file holds the axes below `subdim`.
  const bool stream = on_disk && streams_from_disk(h);
  if (h.data_files.empty()) {
    if (stream) {
      const uint64_t size = std::filesystem::file_size(*on_disk);
      d.chunks.push_back({{}, *on_disk, h.data_begin, size > h.data_begin ? size - h.data_begin : 0});
    } else {
      d.chunks.push_back({bytes.substr(h.data_begin)});
    }
    d.where.push_back(file + ": attached data");
  } else {
    const uint64_t subdim = h.subdim ? h.subdim : (h.data_files.size() == 1 ? uint64_t(h.dimension) : uint64_t(h.dimension - 1));
    if (subdim < 1 || subdim > uint64_t(h.dimension)) throw std::runtime_error(file + ": data file subdim out of range");
    uint64_t files_needed = 1;
    for (size_t a = subdim; a < h.sizes.size(); ++a) files_needed *= h.sizes[a];
    if (files_needed != h.data_files.size())
      throw std::runtime_error(file + ": " + std::to_string(h.data_files.size()) + " data files for sizes needing " +
                               std::to_string(files_needed));
    d.owned.reserve(h.data_files.size());
    for (const auto& f : h.data_files) {
      if (stream) {
        const std::filesystem::path p = data_file_path(*on_disk, f);
        d.chunks.push_back({{}, p, 0, std::filesystem::file_size(p)});
      } else {
        d.chunks.push_back({d.owned.emplace_back(open_data_file(f))});
      }
      d.where.push_back(file + ": data file " + f);
    }
  }
  d.per_chunk = count / d.chunks.size();
  // A header can promise any size: check what each data file can hold at most before
  // allocating the volume (raw/hex/ASCII are bounded by their bytes, gzip by zlib's ratio).
  const uint64_t elem = element_bytes(*h.type);
  for (size_t i = 0; i < d.chunks.size(); ++i) {
    const uint64_t n = d.chunks[i].byte_count();
    const uint64_t bound = h.encoding == "raw"    ? n / elem
                           : h.encoding == "gzip" ? (kMaxDeflateRatio * n + 1024) / elem
                           : h.encoding == "hex"  ? n / 2 / elem
                                                  : (n + 1) / 2;
    if (d.per_chunk > bound && h.encoding == "ascii")
      throw std::runtime_error(d.where[i] + ": " + std::to_string(n) + " bytes of text hold at most " +
                               std::to_string(bound) + " values, the sizes need " + std::to_string(d.per_chunk) +
                               " (truncated, or wrong sizes in the header)");
    if (d.per_chunk > bound)
      throw std::runtime_error(d.where[i] + " has " + std::to_string(n) + " bytes, too few for " +
                               std::to_string(d.per_chunk) + " " + h.type_text + " values (" + h.encoding +
                               "; truncated, or wrong sizes in the header)");
    const uint64_t used = uint64_t(std::max<int64_t>(h.byte_skip, 0)) + d.per_chunk * elem;
    d.excess.push_back(h.encoding == "raw" && h.byte_skip >= 0 && h.line_skip == 0 && n > used ? n - used : 0);
  }
  return d;
}

// The start of a NRRD file through its header: up to the first empty line of an attached file,
// the whole file when there is none (a detached header, whose data file LIST may hold empty lines).
std::string read_nrrd_head(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return read_file_bytes(path);  // which says why
  std::string head;
  std::array<char, 1 << 16> block;
  while (in) {
    in.read(block.data(), std::streamsize(block.size()));
    head.append(block.data(), size_t(in.gcount()));
    if (head.find("\n\n") != std::string::npos || head.find("\n\r\n") != std::string::npos) {
      // A data file LIST reads to the end of the file, past empty lines.
      if (head.find("data file: LIST") != std::string::npos || head.find("datafile: LIST") != std::string::npos)
        return read_file_bytes(path);
      return head;
    }
    if (head.size() > (uint64_t(64) << 20)) break;  // no header is this long: the whole file says what is wrong
  }
  return read_file_bytes(path);
}

// Detached data files, relative to the header's directory.
DataFileLoader data_file_loader(const std::filesystem::path& header) {
  return [header](const std::string& name) { return read_file_bytes(data_file_path(header, name)); };
}

}  // namespace

Volume parse_nrrd(std::string_view bytes, const std::string& file, const VolumeOptions& options,
                  const DataFileLoader& open_data_file) {
  const NrrdData d = resolve_nrrd(bytes, file, open_data_file);
  if (!options.variable.empty() && parse_array_selector(options.variable, file).name != "")
    throw std::runtime_error(file + ": NRRD holds one array; use NAME[k] only to pick a component");
  const ArraySelector sel = parse_array_selector(options.variable, file);
  select_component({}, d.components, sel.component, file);  // a component past the last is an error now
  Volume v;
  v.dims = d.dims;
  v.spacing = d.spacing;
  v.name = file;
  const uint64_t voxels = v.voxel_count();
  check_memory(voxels * sizeof(float), file + ": " + std::to_string(d.dims[0]) + "x" + std::to_string(d.dims[1]) + "x" +
                                           std::to_string(d.dims[2]) + " volume (decoded as float32)");
  v.values.reserve(voxels);
  TupleReducer reducer(d.components, sel.component,
                       [&](const float* values, uint64_t n) { v.values.insert(v.values.end(), values, values + n); });
  d.decode(reducer);
  return v;
}

Volume read_nrrd_volume(const std::filesystem::path& path, const VolumeOptions& options) {
  return parse_nrrd(read_file_bytes(path), path.string(), options, data_file_loader(path));
}

FileInfo describe_nrrd(const std::filesystem::path& path, const VolumeOptions&) {
  const std::string file = path.string();
  // Raw data stays on disk and streams through the statistics (a 64 MiB file was read whole, and
  // its attached data copied once more); other encodings are decoded a block at a time from the
  // file's bytes in memory.
  std::string bytes = read_nrrd_head(path);
  const bool stream = streams_from_disk(parse_header(bytes, file));
  if (!stream) bytes = read_file_bytes(path);
  const NrrdData d = resolve_nrrd(bytes, file, data_file_loader(path), stream ? &path : nullptr);
  const NrrdHeader& h = d.h;
  FileInfo info{file, "NRRD", {}, {}};
  ArrayInfo a;
  a.name = "(the only array)";
  a.kind = "volume";
  a.type = element_type_name(*h.type);
  std::string sizes;
  for (uint64_t s : h.sizes) sizes += (sizes.empty() ? "" : " ") + std::to_string(s);
  a.shape = "sizes " + sizes + ", encoding " + h.encoding +
            (element_bytes(*h.type) > 1 && h.encoding != "ascii" ? (*h.big_endian ? ", big-endian" : ", little-endian") : "");
  if (!h.data_files.empty())
    a.notes.push_back(std::to_string(h.data_files.size()) + " data file(s): " + h.data_files.front() +
                      (h.data_files.size() > 1 ? " ... " + h.data_files.back() : ""));
  for (size_t i = 0; i < d.chunks.size(); ++i)
    if (d.excess[i])
      a.notes.push_back(d.where[i].substr(file.size() + 2) + " holds " + std::to_string(d.excess[i]) +
                        " bytes more than sizes " + sizes + " of " + h.type_text +
                        " need: the first are read, the rest left (as teem does); wrong sizes in the header would "
                        "show this way");
  a.grid = d.dims;
  a.spacing = d.spacing;
  if (h.dimension == 4) {
    a.components = h.sizes[0];
    a.notes.push_back("loads as the magnitude; [k] picks component k");
  }
  // Statistics as the values stream by: `info` never holds the decoded volume.
  TupleReducer reducer(d.components, std::nullopt, [&](const float* v, uint64_t n) { accumulate_stats(a, v, n); });
  d.decode(reducer);
  info.arrays.push_back(std::move(a));
  return info;
}

}  // namespace tfm
