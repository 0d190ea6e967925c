// Helpers shared by the volume-format readers: element decoding, checked sizes, component
// selection, number parsing.
#include "tfmatch/io/volume_formats.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm {
namespace {

// Each element is copied out before its float is stored, so `dst` may be `src` for four-byte
// types (decoding in place).
template <class T>
void convert(const char* src, uint64_t count, bool big_endian, float* dst) {
  const bool swap = big_endian != (std::endian::native == std::endian::big);
  for (uint64_t i = 0; i < count; ++i) {
    unsigned char bytes[sizeof(T)];
    std::memcpy(bytes, src + i * sizeof(T), sizeof(T));
    if (swap) std::reverse(bytes, bytes + sizeof(T));
    T v;
    std::memcpy(&v, bytes, sizeof(T));
    dst[i] = static_cast<float>(v);
  }
}

}  // namespace

size_t element_bytes(ElementType t) {
  switch (t) {
    case ElementType::UInt8: case ElementType::Int8: return 1;
    case ElementType::UInt16: case ElementType::Int16: return 2;
    case ElementType::UInt32: case ElementType::Int32: case ElementType::Float32: return 4;
    case ElementType::UInt64: case ElementType::Int64: case ElementType::Float64: return 8;
  }
  return 0;
}

const char* element_type_name(ElementType t) {
  switch (t) {
    case ElementType::UInt8: return "uint8";
    case ElementType::Int8: return "int8";
    case ElementType::UInt16: return "uint16";
    case ElementType::Int16: return "int16";
    case ElementType::UInt32: return "uint32";
    case ElementType::Int32: return "int32";
    case ElementType::UInt64: return "uint64";
    case ElementType::Int64: return "int64";
    case ElementType::Float32: return "float32";
    case ElementType::Float64: return "float64";
  }
  return "unknown";
}

bool fits_element_type(double v, ElementType t) {
  double lo = 0, hi = 0;
  switch (t) {
    case ElementType::Float32:
    case ElementType::Float64: return true;
    case ElementType::UInt8: hi = 255; break;
    case ElementType::Int8: lo = -128, hi = 127; break;
    case ElementType::UInt16: hi = 65535; break;
    case ElementType::Int16: lo = -32768, hi = 32767; break;
    case ElementType::UInt32: hi = 4294967295.0; break;
    case ElementType::Int32: lo = -2147483648.0, hi = 2147483647.0; break;
    case ElementType::UInt64: hi = 18446744073709551615.0; break;
    case ElementType::Int64: lo = -9223372036854775808.0, hi = 9223372036854775807.0; break;
  }
  return v == std::floor(v) && v >= lo && v <= hi;  // false for NaN and the infinities
}

void decode_elements(const char* src, uint64_t count, ElementType type, bool big_endian, float* dst) {
  switch (type) {
    case ElementType::UInt8: convert<uint8_t>(src, count, big_endian, dst); break;
    case ElementType::Int8: convert<int8_t>(src, count, big_endian, dst); break;
    case ElementType::UInt16: convert<uint16_t>(src, count, big_endian, dst); break;
    case ElementType::Int16: convert<int16_t>(src, count, big_endian, dst); break;
    case ElementType::UInt32: convert<uint32_t>(src, count, big_endian, dst); break;
    case ElementType::Int32: convert<int32_t>(src, count, big_endian, dst); break;
    case ElementType::UInt64: convert<uint64_t>(src, count, big_endian, dst); break;
    case ElementType::Int64: convert<int64_t>(src, count, big_endian, dst); break;
    case ElementType::Float32: convert<float>(src, count, big_endian, dst); break;
    case ElementType::Float64: convert<double>(src, count, big_endian, dst); break;
  }
}

uint64_t checked_mul(uint64_t a, uint64_t b, uint64_t limit, const std::string& file, const std::string& what) {
  if (a != 0 && b > limit / a) {
    // A cap (kMaxVoxels and the like), not an overflow: say which.
    std::ostringstream cap;
    cap << file << ": " << what << " is too large: more than " << limit;
    if (limit == kMaxVoxels) cap << " (2^40) values, the most tfmatch reads";
    throw std::runtime_error(cap.str());
  }
  return a * b;
}

uint64_t checked_voxel_count(const std::array<uint64_t, 3>& dims, const std::string& file) {
  for (uint64_t d : dims)
    if (d == 0) throw std::runtime_error(file + ": a grid dimension is 0");
  std::ostringstream what;
  what << "grid " << dims[0] << "x" << dims[1] << "x" << dims[2];
  uint64_t xy = checked_mul(dims[0], dims[1], kMaxVoxels, file, what.str());
  return checked_mul(xy, dims[2], kMaxVoxels, file, what.str());
}

std::string read_file_bytes(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw std::runtime_error(path.string() + ": no such file");
  if (std::filesystem::is_directory(path, ec)) throw std::runtime_error(path.string() + ": is a directory");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path.string() + ": cannot open");
  const uint64_t size = std::filesystem::file_size(path, ec);
  if (ec) throw std::runtime_error(path.string() + ": cannot read its size (" + ec.message() + ")");
  check_memory(size, path.string() + ": reading the file");
  std::string bytes(size, '\0');
  // In blocks, so that an interrupt stops a large read within a fraction of a second.
  constexpr uint64_t kBlock = uint64_t(16) << 20;
  for (uint64_t done = 0; done < size; done += kBlock) {
    checkpoint("load");
    in.read(bytes.data() + done, std::streamsize(std::min(kBlock, size - done)));
    if (!in) throw std::runtime_error(path.string() + ": read failed (" + std::to_string(done + uint64_t(in.gcount())) +
                                      " of " + std::to_string(size) + " bytes)");
  }
  return bytes;
}

ArraySelector parse_array_selector(const std::string& text, const std::string& file) {
  ArraySelector sel{text, std::nullopt};
  if (!text.empty() && text.back() == ']') {
    auto open = text.rfind('[');
    if (open == std::string::npos)
      throw std::runtime_error(file + ": bad array selection '" + text + "' (expected NAME or NAME[k])");
    std::string digits = text.substr(open + 1, text.size() - open - 2);
    uint64_t k = 0;
    auto [p, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), k);
    if (digits.empty() || ec != std::errc() || p != digits.data() + digits.size())
      throw std::runtime_error(file + ": bad component index in '" + text + "' (expected NAME[k], k >= 0)");
    sel.name = text.substr(0, open);
    sel.component = k;
  }
  return sel;
}

std::array<double, 3> origin_of(const std::array<double, 3>& origin, const std::array<double, 3>& spacing,
                                const std::string& section) {
  std::array<double, 3> o = origin;
  if (section == "cell data")
    for (int i = 0; i < 3; ++i) o[i] += 0.5 * spacing[i];
  return o;
}

std::vector<float> select_component(std::vector<float> values, uint64_t components,
                                    std::optional<uint64_t> component, const std::string& what) {
  if (components == 0) throw std::runtime_error(what + ": array has 0 components");
  if (component && *component >= components)
    throw std::runtime_error(what + ": component " + std::to_string(*component) + " requested, the array has " +
                             std::to_string(components));
  if (components == 1) return values;
  const uint64_t tuples = values.size() / components;
  std::vector<float> out(tuples);
  for (uint64_t i = 0; i < tuples; ++i) out[i] = reduce_tuple(values.data() + i * components, components, component);
  return out;
}

float reduce_tuple(const float* tuple, uint64_t components, std::optional<uint64_t> component) {
  if (component) return tuple[*component];
  // Magnitude in double: NaN in any component gives NaN (no data), as it should.
  double s = 0.0;
  for (uint64_t c = 0; c < components; ++c) s += double(tuple[c]) * double(tuple[c]);
  return static_cast<float>(std::sqrt(s));
}

std::optional<double> parse_number(std::string_view token) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty()) return std::nullopt;
  double v = 0.0;
  auto [p, ec] = std::from_chars(token.data(), token.data() + token.size(), v);
  // Out-of-range magnitudes are reported as errc::result_out_of_range; treat them as errors too.
  if (ec != std::errc() || p != token.data() + token.size()) return std::nullopt;
  return v;
}

}  // namespace tfm
