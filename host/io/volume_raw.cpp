// Raw volumes (dimensions and type from the Open SciVis file-name convention
// `name_256x256x128_float32.raw`, or from options) and `.dat` descriptor files: reading and what
// `tfmatch info` says about them.
#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <regex>
#include <sstream>
#include <stdexcept>

#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/model/volume.h"

namespace tfm {
namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// The raw reader's element types are a subset of the format readers' (volume_formats.h), whose
// decoder does the work.
void decode(const char* src, uint64_t count, ScalarType type, bool big_endian, float* dst) {
  ElementType e;
  switch (type) {
    case ScalarType::UInt8: e = ElementType::UInt8; break;
    case ScalarType::Int8: e = ElementType::Int8; break;
    case ScalarType::UInt16: e = ElementType::UInt16; break;
    case ScalarType::Int16: e = ElementType::Int16; break;
    case ScalarType::UInt32: e = ElementType::UInt32; break;
    case ScalarType::Int32: e = ElementType::Int32; break;
    case ScalarType::Float32: e = ElementType::Float32; break;
    case ScalarType::Float64: e = ElementType::Float64; break;
    default: throw std::logic_error("decode: unknown scalar type");
  }
  decode_elements(src, count, e, big_endian, dst);
}

// Decodes `count` four-byte elements stored at `bytes` into floats at the same address.
void decode_in_place(char* bytes, uint64_t count, ScalarType type, bool big_endian) {
  if (type == ScalarType::Float32 && big_endian == (std::endian::native == std::endian::big)) return;
  decode(bytes, count, type, big_endian, reinterpret_cast<float*>(bytes));
}

// Throws "<file>: file has B bytes, but a XxYxZ type volume needs ..." unless the file holds
// exactly offset + voxels * size bytes (at least that many when `allow_trailing`).
void check_file_size(const std::filesystem::path& path, std::array<uint64_t, 3> dims, ScalarType type, uint64_t offset,
                     bool allow_trailing) {
  const std::string name = path.string();
  const uint64_t bytes = checked_voxel_count(dims, name) * scalar_bytes(type);
  std::error_code ec;
  uint64_t file_size = std::filesystem::file_size(path, ec);
  if (ec) throw std::runtime_error(name + ": cannot open (" + ec.message() + ")");
  if (file_size < offset + bytes || (!allow_trailing && file_size != offset + bytes)) {
    std::ostringstream os;
    os << name << ": file has " << file_size << " bytes, but a " << dims[0] << "x" << dims[1] << "x"
       << dims[2] << " " << scalar_type_name(type) << " volume needs " << offset + bytes;
    throw std::runtime_error(os.str());
  }
}

// Checks that the file holds exactly offset + count * size bytes (or at least that many when
// `allow_trailing`) for `count` elements of `type` at `offset`, then decodes them block by block
// into `sink`, with a cancellation checkpoint per block.
template <class Sink>
void stream_elements(const std::filesystem::path& path, std::array<uint64_t, 3> dims, ScalarType type, bool big_endian,
                     uint64_t offset, bool allow_trailing, Sink sink) {
  const std::string name = path.string();
  const uint64_t count = checked_voxel_count(dims, name);
  check_file_size(path, dims, type, offset, allow_trailing);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(name + ": cannot open");
  in.seekg(static_cast<std::streamoff>(offset));
  // Decode in blocks so the file is never held in memory beside the values.
  const uint64_t block = uint64_t(1) << 22;
  std::vector<char> buffer(std::min(count, block) * scalar_bytes(type));
  std::vector<float> values(std::min(count, block));
  for (uint64_t done = 0; done < count; done += block) {
    checkpoint("load");
    uint64_t n = std::min(block, count - done);
    in.read(buffer.data(), static_cast<std::streamsize>(n * scalar_bytes(type)));
    if (!in) throw std::runtime_error(name + ": read failed");
    decode(buffer.data(), n, type, big_endian, values.data());
    sink(values.data(), n);
  }
}

Volume read_elements(const std::filesystem::path& path, std::array<uint64_t, 3> dims, ScalarType type,
                     bool big_endian, uint64_t offset, bool allow_trailing) {
  Volume v;
  v.dims = dims;
  v.name = path.string();
  const uint64_t count = checked_voxel_count(dims, v.name);
  // The file first: a small file that claims a huge grid is short, not a matter of --max-memory.
  check_file_size(path, dims, type, offset, allow_trailing);
  check_memory(count * sizeof(float), v.name + ": " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                                          std::to_string(dims[2]) + " volume (decoded as float32)");
  const size_t size = scalar_bytes(type);
  if (size != sizeof(float)) {
    v.values.reserve(count);
    stream_elements(path, dims, type, big_endian, offset, allow_trailing,
                    [&](const float* values, uint64_t n) { v.values.insert(v.values.end(), values, values + n); });
    return v;
  }
  // Four-byte elements are read straight into the values and decoded in place (a no-op for
  // native float32): two fewer copies of the volume than through a block buffer.
  check_file_size(path, dims, type, offset, allow_trailing);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(v.name + ": cannot open");
  in.seekg(static_cast<std::streamoff>(offset));
  v.values.resize(count);
  const uint64_t block = uint64_t(1) << 22;
  for (uint64_t done = 0; done < count; done += block) {
    checkpoint("load");
    const uint64_t n = std::min(block, count - done);
    char* bytes = reinterpret_cast<char*>(v.values.data() + done);
    in.read(bytes, static_cast<std::streamsize>(n * size));
    if (!in) throw std::runtime_error(v.name + ": read failed");
    decode_in_place(bytes, n, type, big_endian);
  }
  return v;
}

// A raw file (or a .dat file's data) read slab by slab: a seek and one read per block of a slab.
class RawSlabs final : public VolumeSlabReader {
 public:
  RawSlabs(const std::filesystem::path& data, std::array<uint64_t, 3> dims, ScalarType type, bool big_endian)
      : data_(data), type_(type), big_endian_(big_endian) {
    check_file_size(data, dims, type, 0, false);
    in_.open(data, std::ios::binary);
    if (!in_) throw std::runtime_error(data.string() + ": cannot open");
    grid_.dims = dims;
    grid_.name = data.string();
  }
  // A .dat descriptor's spacing and name.
  void set_grid(std::array<double, 3> spacing, std::string name) {
    grid_.spacing = spacing;
    grid_.name = std::move(name);
  }
  void read_slices(uint64_t z0, uint64_t nz, float* out) override {
    check_slices(z0, nz);
    const uint64_t size = scalar_bytes(type_), count = nz * slice_voxels();
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(z0 * slice_voxels() * size));
    const uint64_t block = uint64_t(1) << 22;
    // Four-byte elements straight into `out`, decoded in place (as read_elements); others
    // through a block buffer.
    const bool in_place = size == sizeof(float);
    if (!in_place) buffer_.resize(std::min(count, block) * size);
    for (uint64_t done = 0; done < count; done += block) {
      checkpoint("load");
      const uint64_t n = std::min(block, count - done);
      char* bytes = in_place ? reinterpret_cast<char*>(out + done) : buffer_.data();
      in_.read(bytes, static_cast<std::streamsize>(n * size));
      if (!in_)
        throw std::runtime_error(data_.string() + ": read failed at byte " +
                                 std::to_string((z0 * slice_voxels() + done) * size) +
                                 " (the file is shorter than when it was opened?)");
      if (in_place) decode_in_place(bytes, n, type_, big_endian_);
      else decode(buffer_.data(), n, type_, big_endian_, out + done);
    }
  }

 private:
  std::filesystem::path data_;
  ScalarType type_;
  bool big_endian_;
  std::ifstream in_;
  std::vector<char> buffer_;
};

// The one array of a raw or .dat file, for `tfmatch info`: statistics as the values stream by,
// so `info` never holds the decoded volume.
FileInfo describe_one_array(const std::filesystem::path& path, const std::string& format, const std::filesystem::path& data,
                            std::array<uint64_t, 3> dims, ScalarType type, bool big_endian,
                            std::array<double, 3> spacing) {
  FileInfo info{path.string(), format, {}, {}};
  ArrayInfo a;
  a.name = "(the only array)";
  a.kind = "volume";
  a.type = scalar_type_name(type);  // as resolved from --type, the file name or the descriptor
  a.grid = dims;
  a.spacing = spacing;
  a.shape = std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]);
  stream_elements(data, dims, type, big_endian, 0, false, [&](const float* v, uint64_t n) { accumulate_stats(a, v, n); });
  info.arrays.push_back(std::move(a));
  return info;
}

// A raw file without dimensions: say what is known (its size) and which cubes would fit.
FileInfo describe_headerless(const std::filesystem::path& path, const std::string& why) {
  FileInfo info{path.string(), "raw (no header)", {why}, {}};
  const uint64_t bytes = std::filesystem::file_size(path);
  std::string fits;
  const std::pair<uint64_t, const char*> types[] = {{1, "uint8"}, {2, "uint16/int16"}, {4, "float32"}, {8, "float64"}};
  for (auto [size, name] : types) {
    if (bytes == 0 || bytes % size) continue;  // an empty file fits no cube
    const uint64_t n = bytes / size, edge = static_cast<uint64_t>(std::llround(std::cbrt(double(n))));
    if (edge * edge * edge == n) fits += (fits.empty() ? "" : ", ") + std::to_string(edge) + "^3 " + name;
  }
  info.notes.push_back(std::to_string(bytes) + " bytes" + (bytes == 0 ? " (an empty file)" : "") +
                       (fits.empty() ? "" : "; cubes that fit: " + fits) +
                       " (pass " + parameter("dims") + " X,Y,Z " + parameter("type") + " T, or name it name_XxYxZ_type.raw)");
  return info;
}

}  // namespace

ScalarType parse_scalar_type(std::string s) {
  s = lower(s);
  if (s == "uint8" || s == "uchar" || s == "unsigned_char" || s == "unsigned char") return ScalarType::UInt8;
  if (s == "int8" || s == "char" || s == "signed char") return ScalarType::Int8;
  if (s == "uint16" || s == "ushort" || s == "unsigned_short" || s == "unsigned short") return ScalarType::UInt16;
  if (s == "int16" || s == "short") return ScalarType::Int16;
  if (s == "uint32" || s == "uint" || s == "unsigned_int" || s == "unsigned int") return ScalarType::UInt32;
  if (s == "int32" || s == "int") return ScalarType::Int32;
  if (s == "float32" || s == "float") return ScalarType::Float32;
  if (s == "float64" || s == "double") return ScalarType::Float64;
  return ScalarType::Unknown;
}

size_t scalar_bytes(ScalarType t) {
  switch (t) {
    case ScalarType::UInt8: case ScalarType::Int8: return 1;
    case ScalarType::UInt16: case ScalarType::Int16: return 2;
    case ScalarType::UInt32: case ScalarType::Int32: case ScalarType::Float32: return 4;
    case ScalarType::Float64: return 8;
    default: return 0;
  }
}

const char* scalar_type_name(ScalarType t) {
  switch (t) {
    case ScalarType::UInt8: return "uint8";
    case ScalarType::Int8: return "int8";
    case ScalarType::UInt16: return "uint16";
    case ScalarType::Int16: return "int16";
    case ScalarType::UInt32: return "uint32";
    case ScalarType::Int32: return "int32";
    case ScalarType::Float32: return "float32";
    case ScalarType::Float64: return "float64";
    default: return "unknown";
  }
}

// The grid and element type of a raw file: from the options, else from its name.
static std::pair<std::array<uint64_t, 3>, ScalarType> raw_layout(const std::filesystem::path& path, const VolumeOptions& options) {
  std::optional<std::array<uint64_t, 3>> dims = options.dims;
  ScalarType type = options.type;
  // Open SciVis convention: <name>_<X>x<Y>x<Z>_<type>.raw
  static const std::regex pattern(R"(_(\d+)x(\d+)x(\d+)_([a-z0-9]+)\.raw$)", std::regex::icase);
  std::smatch m;
  const std::string file = path.filename().string();
  if (std::regex_search(file, m, pattern)) {
    std::array<uint64_t, 3> named{};
    try {
      named = {std::stoull(m[1]), std::stoull(m[2]), std::stoull(m[3])};
    } catch (const std::exception&) {
      throw std::runtime_error(path.string() + ": dimensions in the file name are out of range");
    }
    const ScalarType named_type = parse_scalar_type(m[4]);
    if (named_type == ScalarType::Unknown && type == ScalarType::Unknown)
      throw std::runtime_error(path.string() + ": unknown element type '" + m[4].str() + "' in the file name");
    // A name and an option that disagree leave no way to tell which is right: reading with either
    // could give a plausible-looking but wrong field.
    auto dims_text = [](const std::array<uint64_t, 3>& d) {
      return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
    };
    auto disagree = [&](const std::string& option, const std::string& by_name, const std::string& by_option) {
      return std::runtime_error(path.string() + ": the file name says " + by_name + " but " + parameter(option) +
                                " says " + by_option + ": rename the file or leave out " + parameter(option));
    };
    if (dims && *dims != named) throw disagree("dims", dims_text(named), dims_text(*dims));
    if (type != ScalarType::Unknown && named_type != ScalarType::Unknown && type != named_type)
      throw disagree("type", scalar_type_name(named_type), scalar_type_name(type));
    dims = named;
    if (type == ScalarType::Unknown) type = named_type;
  }
  if (!dims)
    throw std::runtime_error(path.string() + ": raw file without dimensions: name it name_XxYxZ_type.raw "
                             "or pass " + parameter("dims") + " X,Y,Z (and " + parameter("type") + ")");
  if (type == ScalarType::Unknown)
    throw std::runtime_error(path.string() + ": raw file without element type: pass " + parameter("type") + " "
                             "(uint8, uint16, int16, float32, float64, ...)");
  return {*dims, type};
}

Volume read_raw_volume(const std::filesystem::path& path, const VolumeOptions& options) {
  const auto [dims, type] = raw_layout(path, options);
  return read_elements(path, dims, type, options.big_endian, 0, false);
}

// .dat descriptor: lines "Key: value" with ObjectFileName, Resolution (X Y Z), Format
// (UCHAR, USHORT, FLOAT, DOUBLE, ...), optional SliceThickness (spacing) and Endianness.
DatDescriptor parse_dat_descriptor(std::string_view text, const std::string& name, bool big_endian_default) {
  DatDescriptor d;
  d.big_endian = big_endian_default;
  bool have_dims = false;
  std::istringstream in{std::string(text)};
  std::string line;
  int line_no = 0;
  auto fail = [&](const std::string& what) {
    return std::runtime_error(name + ": line " + std::to_string(line_no) + ": " + what);
  };
  while (std::getline(in, line)) {
    ++line_no;
    if (line.size() > 4096) throw fail("line too long");
    auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    std::string key = lower(line.substr(0, colon));
    key.erase(std::remove_if(key.begin(), key.end(), [](unsigned char c) { return std::isspace(c); }), key.end());
    std::istringstream value(line.substr(colon + 1));
    if (key == "objectfilename") {
      value >> std::ws;
      std::getline(value, d.object_file);
      while (!d.object_file.empty() && std::isspace(static_cast<unsigned char>(d.object_file.back()))) d.object_file.pop_back();
    } else if (key == "resolution") {
      std::array<long long, 3> r{};
      if (!(value >> r[0] >> r[1] >> r[2]) || r[0] <= 0 || r[1] <= 0 || r[2] <= 0)
        throw fail("Resolution needs three positive integers");
      d.dims = std::array<uint64_t, 3>{uint64_t(r[0]), uint64_t(r[1]), uint64_t(r[2])};
      have_dims = true;
    } else if (key == "format") {
      value >> d.format;
    } else if (key == "slicethickness") {
      auto& sp = d.spacing;
      if (!(value >> sp[0] >> sp[1] >> sp[2]) || !(sp[0] > 0) || !(sp[1] > 0) || !(sp[2] > 0) || !std::isfinite(sp[0]) ||
          !std::isfinite(sp[1]) || !std::isfinite(sp[2]))
        throw fail("SliceThickness needs three positive numbers");
    } else if (key == "endianness" || key == "byteorder") {
      std::string e;
      value >> e;
      d.big_endian = lower(e).find("big") != std::string::npos;
    }
  }
  if (d.object_file.empty()) throw std::runtime_error(name + ": no ObjectFileName");
  if (!have_dims) throw std::runtime_error(name + ": no Resolution");
  if (d.format.empty()) throw std::runtime_error(name + ": no Format");
  d.type = parse_scalar_type(d.format);
  if (d.type == ScalarType::Unknown) throw std::runtime_error(name + ": unknown Format '" + d.format + "'");
  return d;
}

// The descriptor of a .dat file (a few lines, read whole).
static DatDescriptor read_dat_descriptor(const std::filesystem::path& path, const VolumeOptions& options) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path.string() + ": cannot open");
  // A descriptor is a few lines; refuse to read a large binary file given as .dat by mistake.
  std::string text(64 * 1024, '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<size_t>(in.gcount()));
  if (in.gcount() == 64 * 1024 && in.peek() != EOF)
    throw std::runtime_error(path.string() + ": too large for a .dat descriptor (over 64 KiB)");
  return parse_dat_descriptor(text, path.string(), options.big_endian);
}

Volume read_dat_volume(const std::filesystem::path& path, const VolumeOptions& options) {
  const DatDescriptor d = read_dat_descriptor(path, options);
  const std::filesystem::path data = path.parent_path() / d.object_file;
  Volume v = read_elements(data, d.dims, d.type, d.big_endian, 0, false);
  v.spacing = d.spacing;
  v.name = path.string();
  return v;
}

std::unique_ptr<VolumeSlabReader> open_raw_slabs(const std::filesystem::path& path, const VolumeOptions& options) {
  const auto [dims, type] = raw_layout(path, options);
  return std::make_unique<RawSlabs>(path, dims, type, options.big_endian);
}

std::unique_ptr<VolumeSlabReader> open_dat_slabs(const std::filesystem::path& path, const VolumeOptions& options) {
  const DatDescriptor d = read_dat_descriptor(path, options);
  auto r = std::make_unique<RawSlabs>(path.parent_path() / d.object_file, d.dims, d.type, d.big_endian);
  r->set_grid(d.spacing, path.string());
  return r;
}

FileInfo describe_raw(const std::filesystem::path& path, const VolumeOptions& options) {
  std::pair<std::array<uint64_t, 3>, ScalarType> layout;
  try {
    layout = raw_layout(path, options);
  } catch (const std::runtime_error& e) {
    // A raw file that says nothing about itself is described rather than refused.
    const std::string m = e.what();
    if (m.find("without dimensions") != std::string::npos || m.find("without element type") != std::string::npos)
      return describe_headerless(path, "dimensions or element type unknown");
    throw;
  }
  return describe_one_array(path, "raw", path, layout.first, layout.second, options.big_endian, {1, 1, 1});
}

FileInfo describe_dat(const std::filesystem::path& path, const VolumeOptions& options) {
  const DatDescriptor d = read_dat_descriptor(path, options);
  return describe_one_array(path, ".dat descriptor + raw data", path.parent_path() / d.object_file, d.dims, d.type,
                            d.big_endian, d.spacing);
}

void write_raw_float32(const std::filesystem::path& path, const Volume& v) {
  if constexpr (std::endian::native == std::endian::little) {
    // The values' bytes are the file's: written as they are, without a copy.
    return write_file_atomically(path, std::string_view(reinterpret_cast<const char*>(v.values.data()),
                                                        v.values.size() * sizeof(float)));
  }
  check_memory(v.values.size() * sizeof(float), path.string() + ": writing " + std::to_string(v.values.size()) + " values");
  std::string bytes(v.values.size() * sizeof(float), '\0');
  for (size_t i = 0; i < v.values.size(); ++i) {
    uint32_t bits = std::bit_cast<uint32_t>(v.values[i]);
    if constexpr (std::endian::native == std::endian::big) bits = __builtin_bswap32(bits);
    std::memcpy(bytes.data() + i * 4, &bits, 4);
  }
  write_file_atomically(path, bytes);
}

}  // namespace tfm
