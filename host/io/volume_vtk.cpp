// Legacy VTK STRUCTURED_POINTS files (.vtk): ASCII or BINARY (always big-endian), scalars of any
// numeric type, VECTORS/NORMALS/TENSORS/FIELD arrays, POINT_DATA and CELL_DATA, version 1
// ASPECT_RATIO as well as SPACING. Multi-component arrays load as their magnitude, or NAME[k].
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm {
namespace {

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }

std::string lower(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return std::tolower(c); });
  return out;
}

// Reads the file line by line for headers and token by token for ASCII data.
class Cursor {
 public:
  Cursor(std::string_view s, const std::string& file) : s_(s), file_(file) {}
  bool at_end() const { return pos_ >= s_.size(); }
  size_t pos() const { return pos_; }
  void seek(size_t p) { pos_ = std::min(p, s_.size()); }
  size_t remaining() const { return s_.size() - pos_; }
  std::string_view bytes(size_t n) const { return s_.substr(pos_, n); }

  std::string_view line() {
    size_t end = s_.find('\n', pos_);
    if (end == std::string_view::npos) end = s_.size();
    std::string_view l = s_.substr(pos_, end - pos_);
    pos_ = std::min(end + 1, s_.size());
    if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
    return l;
  }
  // Next line with a non-blank character, split into tokens; empty at the end of the file.
  std::vector<std::string_view> tokens_of_next_line() {
    while (!at_end()) {
      std::vector<std::string_view> t = split(line());
      if (!t.empty()) return t;
    }
    return {};
  }
  std::string_view token() {
    while (pos_ < s_.size() && is_space(s_[pos_])) ++pos_;
    size_t b = pos_;
    while (pos_ < s_.size() && !is_space(s_[pos_])) ++pos_;
    return s_.substr(b, pos_ - b);
  }
  bool next_line_starts_with(std::string_view word) const {
    size_t p = pos_;
    while (p < s_.size() && is_space(s_[p])) ++p;
    return lower(s_.substr(p, word.size())) == lower(word);
  }
  int line_number() const { return 1 + static_cast<int>(std::count(s_.begin(), s_.begin() + long(pos_), '\n')); }
  [[noreturn]] void fail(const std::string& what) const {
    throw std::runtime_error(file_ + ": line " + std::to_string(line_number()) + ": " + what);
  }
  static std::vector<std::string_view> split(std::string_view l) {
    std::vector<std::string_view> out;
    size_t i = 0;
    while (i < l.size()) {
      while (i < l.size() && is_space(l[i])) ++i;
      size_t b = i;
      while (i < l.size() && !is_space(l[i])) ++i;
      if (i > b) out.push_back(l.substr(b, i - b));
    }
    return out;
  }

 private:
  std::string_view s_;
  size_t pos_ = 0;
  const std::string& file_;
};

struct VtkArray {
  std::string name;
  std::string section;   // "point data", "cell data", "field data"
  std::string keyword;   // SCALARS, VECTORS, FIELD, ...
  ElementType type = ElementType::Float32;
  bool color_uchar = false;  // binary COLOR_SCALARS: uchar scaled to [0,1]
  uint64_t components = 1;
  uint64_t tuples = 0;
  size_t data_begin = 0;     // byte offset of the data (binary) or its first token (ASCII)
};

struct VtkDocument {
  bool binary = false;
  std::array<uint64_t, 3> dims{0, 0, 0};
  std::array<double, 3> spacing{1, 1, 1};
  std::array<double, 3> origin{0, 0, 0};
  std::vector<VtkArray> arrays;
};

uint64_t parse_count(std::string_view tok, const Cursor& c, const std::string& what) {
  uint64_t v = 0;
  auto [p, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), v);
  if (tok.empty() || ec != std::errc() || p != tok.data() + tok.size())
    c.fail(what + ": expected a non-negative integer, found '" + std::string(tok) + "'");
  return v;
}

double parse_real(std::string_view tok, const Cursor& c, const std::string& what) {
  auto v = parse_number(tok);
  if (!v) c.fail(what + ": expected a number, found '" + std::string(tok) + "'");
  return *v;
}

ElementType parse_vtk_type(std::string_view tok, const Cursor& c) {
  const std::string t = lower(tok);
  if (t == "unsigned_char") return ElementType::UInt8;
  if (t == "char" || t == "signed_char") return ElementType::Int8;
  if (t == "unsigned_short") return ElementType::UInt16;
  if (t == "short") return ElementType::Int16;
  if (t == "unsigned_int") return ElementType::UInt32;
  if (t == "int") return ElementType::Int32;
  // VTK writes `long` with sizeof(long): 8 bytes on the LP64 systems this runs on.
  if (t == "unsigned_long" || t == "vtktypeuint64") return ElementType::UInt64;
  if (t == "long" || t == "vtktypeint64" || t == "vtkidtype") return ElementType::Int64;
  if (t == "float") return ElementType::Float32;
  if (t == "double") return ElementType::Float64;
  if (t == "bit") c.fail("data type 'bit' is not supported");
  c.fail("unknown data type '" + std::string(tok) + "'");
}

// Legacy names encode spaces and other characters as %XX (VTK 4 and later).
std::string decode_name(std::string_view n) {
  std::string out;
  for (size_t i = 0; i < n.size(); ++i) {
    unsigned v = 0;
    if (n[i] == '%' && i + 3 <= n.size() &&
        std::from_chars(n.data() + i + 1, n.data() + i + 3, v, 16).ptr == n.data() + i + 3) {
      out.push_back(static_cast<char>(v));
      i += 2;
    } else {
      out.push_back(n[i]);
    }
  }
  return out;
}

// Skips over an array's data, checking that it is all there.
void skip_data(Cursor& c, VtkArray& a, bool binary, const std::string& file) {
  a.data_begin = c.pos();
  const std::string what = a.keyword + " '" + a.name + "'";
  const uint64_t count = checked_mul(a.tuples, a.components, kMaxVoxels, file, what);
  if (binary) {
    const uint64_t bytes = count * (a.color_uchar ? 1 : element_bytes(a.type));
    if (bytes > c.remaining())
      c.fail(what + " needs " + std::to_string(bytes) + " bytes of data, only " + std::to_string(c.remaining()) +
             " remain (truncated file?)");
    c.seek(c.pos() + bytes);
  } else {
    // Every value takes at least two characters (digit and separator): a cheap bound first.
    if (count > (c.remaining() + 1) / 2)
      c.fail(what + " needs " + std::to_string(count) + " values; the file is too short");
    for (uint64_t i = 0; i < count; ++i)
      if (c.token().empty())
        c.fail(what + ": the file ends after " + std::to_string(i) + " of " + std::to_string(count) + " values");
  }
}

// Reads the attribute arrays of one POINT_DATA / CELL_DATA / FIELD section header line `t`.
void parse_attribute(Cursor& c, VtkDocument& doc, const std::vector<std::string_view>& t, const std::string& section,
                     uint64_t tuples, const std::string& file) {
  const std::string key = lower(t[0]);
  auto need = [&](size_t n, const char* form) {
    if (t.size() < n) c.fail(std::string("expected '") + form + "'");
  };
  VtkArray a;
  a.section = section;
  a.keyword = key;
  std::transform(a.keyword.begin(), a.keyword.end(), a.keyword.begin(), ::toupper);
  a.tuples = tuples;
  if (key == "scalars") {
    need(3, "SCALARS name type [components]");
    a.name = decode_name(t[1]);
    a.type = parse_vtk_type(t[2], c);
    a.components = t.size() > 3 ? parse_count(t[3], c, "SCALARS components") : 1;
    if (a.components < 1 || a.components > 4) c.fail("SCALARS components must be 1..4");
    // LOOKUP_TABLE is required by the format but some writers omit it; take it when present.
    if (c.next_line_starts_with("LOOKUP_TABLE")) c.line();
  } else if (key == "color_scalars") {
    need(3, "COLOR_SCALARS name components");
    a.name = decode_name(t[1]);
    a.components = parse_count(t[2], c, "COLOR_SCALARS components");
    if (a.components < 1 || a.components > 4) c.fail("COLOR_SCALARS components must be 1..4");
    a.color_uchar = doc.binary;  // binary: unsigned char 0..255 meaning 0..1; ASCII: floats
    a.type = doc.binary ? ElementType::UInt8 : ElementType::Float32;
  } else if (key == "vectors" || key == "normals") {
    need(3, "VECTORS name type");
    a.name = decode_name(t[1]);
    a.type = parse_vtk_type(t[2], c);
    a.components = 3;
  } else if (key == "tensors" || key == "tensors6") {
    need(3, "TENSORS name type");
    a.name = decode_name(t[1]);
    a.type = parse_vtk_type(t[2], c);
    a.components = key == "tensors" ? 9 : 6;
  } else if (key == "texture_coordinates") {
    need(4, "TEXTURE_COORDINATES name dimension type");
    a.name = decode_name(t[1]);
    a.components = parse_count(t[2], c, "TEXTURE_COORDINATES dimension");
    if (a.components < 1 || a.components > 3) c.fail("TEXTURE_COORDINATES dimension must be 1..3");
    a.type = parse_vtk_type(t[3], c);
  } else if (key == "lookup_table") {
    need(3, "LOOKUP_TABLE name size");
    a.name = decode_name(t[1]);
    a.tuples = parse_count(t[2], c, "LOOKUP_TABLE size");
    a.components = 4;
    a.color_uchar = doc.binary;
    a.type = doc.binary ? ElementType::UInt8 : ElementType::Float32;
    skip_data(c, a, doc.binary, file);
    return;  // a colour table, not data on the grid
  } else if (key == "field") {
    need(3, "FIELD name arrays");
    const uint64_t n = parse_count(t[2], c, "FIELD number of arrays");
    for (uint64_t i = 0; i < n; ++i) {
      auto h = c.tokens_of_next_line();
      if (h.size() < 4) c.fail("expected 'arrayName components tuples type' for FIELD array " + std::to_string(i));
      VtkArray f;
      f.section = section == "dataset" ? "field data" : section;
      f.keyword = "FIELD";
      f.name = decode_name(h[0]);
      f.components = parse_count(h[1], c, "FIELD array components");
      f.tuples = parse_count(h[2], c, "FIELD array tuples");
      if (f.components == 0) c.fail("FIELD array '" + f.name + "' has 0 components");
      f.type = parse_vtk_type(h[3], c);
      // Inside POINT_DATA / CELL_DATA only arrays with one tuple per point / cell lie on the grid.
      if (section != "dataset" && f.tuples != tuples) f.section = "field data";
      skip_data(c, f, doc.binary, file);
      doc.arrays.push_back(f);
      if (c.next_line_starts_with("METADATA")) {
        c.line();
        while (!c.at_end() && !Cursor::split(c.line()).empty()) {}
      }
    }
    return;
  } else {
    c.fail("unknown keyword '" + std::string(t[0]) + "'");
  }
  skip_data(c, a, doc.binary, file);
  doc.arrays.push_back(a);
}

VtkDocument parse_document(std::string_view bytes, const std::string& file) {
  Cursor c(bytes, file);
  VtkDocument doc;
  const std::string l1 = lower(c.line());
  if (l1.rfind("# vtk datafile version", 0) != 0)
    throw std::runtime_error(file + ": not a legacy VTK file (the first line must be '# vtk DataFile Version x.y')");
  c.line();  // title
  auto mode = c.tokens_of_next_line();
  if (mode.size() != 1 || (lower(mode[0]) != "ascii" && lower(mode[0]) != "binary"))
    c.fail("expected ASCII or BINARY");
  doc.binary = lower(mode[0]) == "binary";
  auto ds = c.tokens_of_next_line();
  if (ds.size() != 2 || lower(ds[0]) != "dataset") c.fail("expected 'DATASET STRUCTURED_POINTS'");
  if (lower(ds[1]) != "structured_points")
    c.fail("dataset type " + std::string(ds[1]) + " is not supported (only STRUCTURED_POINTS, a regular grid)");
  bool have_dims = false;
  std::string section = "dataset";
  uint64_t tuples = 0;
  for (auto t = c.tokens_of_next_line(); !t.empty(); t = c.tokens_of_next_line()) {
    const std::string key = lower(t[0]);
    if (key == "dimensions" || key == "spacing" || key == "aspect_ratio" || key == "origin") {
      if (section != "dataset") c.fail(std::string(t[0]) + " after the data sections");
      if (t.size() != 4) c.fail("expected '" + std::string(t[0]) + " x y z'");
      for (int i = 0; i < 3; ++i) {
        if (key == "dimensions") doc.dims[i] = parse_count(t[1 + i], c, "DIMENSIONS");
        else if (key != "origin") doc.spacing[i] = parse_real(t[1 + i], c, std::string(t[0]));
        else doc.origin[i] = parse_real(t[1 + i], c, "ORIGIN");
      }
      if (key == "dimensions") {
        checked_voxel_count(doc.dims, file);
        have_dims = true;
      }
      if (key == "spacing" || key == "aspect_ratio")
        for (double s : doc.spacing)
          if (!(s > 0) || !std::isfinite(s)) c.fail(std::string(t[0]) + " must be positive");
    } else if (key == "point_data" || key == "cell_data") {
      if (!have_dims) c.fail(std::string(t[0]) + " before DIMENSIONS");
      if (t.size() != 2) c.fail("expected '" + std::string(t[0]) + " n'");
      tuples = parse_count(t[1], c, std::string(t[0]));
      std::array<uint64_t, 3> grid = doc.dims;
      if (key == "cell_data")
        for (auto& d : grid) d = std::max<uint64_t>(1, d - 1);
      const uint64_t expected = grid[0] * grid[1] * grid[2];
      if (tuples != expected)
        c.fail(std::string(t[0]) + " " + std::to_string(tuples) + " does not match DIMENSIONS " +
               std::to_string(doc.dims[0]) + "x" + std::to_string(doc.dims[1]) + "x" + std::to_string(doc.dims[2]) +
               " (" + std::to_string(expected) + (key == "cell_data" ? " cells)" : " points)"));
      section = key == "point_data" ? "point data" : "cell data";
    } else if (key == "metadata") {
      while (!c.at_end() && !Cursor::split(c.line()).empty()) {}
    } else {
      if (section == "dataset" && key != "field") c.fail("'" + std::string(t[0]) + "' before POINT_DATA or CELL_DATA");
      parse_attribute(c, doc, t, section, tuples, file);
    }
  }
  if (!have_dims) throw std::runtime_error(file + ": no DIMENSIONS");
  return doc;
}

std::vector<float> decode_array(std::string_view bytes, const VtkDocument& doc, const VtkArray& a, const std::string& file) {
  const uint64_t count = a.tuples * a.components;  // checked in skip_data
  check_memory(count * sizeof(float), file + ": array '" + a.name + "': " + std::to_string(count) + " values");
  std::vector<float> v(count);
  if (doc.binary) {
    decode_elements(bytes.data() + a.data_begin, count, a.type, true, v.data());
    if (a.color_uchar)
      for (float& x : v) x /= 255.0f;
  } else {
    Cursor c(bytes, file);
    c.seek(a.data_begin);
    for (uint64_t i = 0; i < count; ++i) {
      std::string_view tok = c.token();
      const double x = parse_real(tok, c, a.keyword + " '" + a.name + "'");
      if (!fits_element_type(x, a.type))
        c.fail(a.keyword + " '" + a.name + "': value " + std::string(tok) + " is no " + element_type_name(a.type) +
               " value (the type the header declares)");
      v[i] = static_cast<float>(x);
    }
  }
  return v;
}

std::array<uint64_t, 3> grid_of(const VtkDocument& doc, const VtkArray& a) {
  std::array<uint64_t, 3> g = doc.dims;
  if (a.section == "cell data")
    for (auto& d : g) d = std::max<uint64_t>(1, d - 1);
  return g;
}

}  // namespace

Volume parse_vtk_legacy(std::string_view bytes, const std::string& file, const VolumeOptions& options) {
  VtkDocument doc = parse_document(bytes, file);
  const ArraySelector sel = parse_array_selector(options.variable, file);
  // Without a name: point SCALARS first, then any point array, then cell arrays (file order).
  auto rank = [](const VtkArray& a) { return (a.section == "point data" ? 0 : 2) + (a.keyword == "SCALARS" ? 0 : 1); };
  const VtkArray& pick = pick_grid_array(doc.arrays, sel, rank, file);
  Volume v;
  v.dims = grid_of(doc, pick);
  v.spacing = doc.spacing;
  v.origin = origin_of(doc.origin, doc.spacing, pick.section);
  v.name = file + ":" + pick.name + (sel.component ? "[" + std::to_string(*sel.component) + "]" : "");
  v.values = select_component(decode_array(bytes, doc, pick, file), pick.components, sel.component, v.name);
  return v;
}

Volume read_vtk_legacy_volume(const std::filesystem::path& path, const VolumeOptions& options) {
  return parse_vtk_legacy(read_file_bytes(path), path.string(), options);
}

FileInfo describe_vtk_legacy(const std::filesystem::path& path, const VolumeOptions&) {
  const std::string file = path.string();
  const std::string bytes = read_file_bytes(path);
  VtkDocument doc = parse_document(bytes, file);
  FileInfo info{file, std::string("legacy VTK STRUCTURED_POINTS (") + (doc.binary ? "BINARY, big-endian" : "ASCII") + ")", {}, {}};
  for (const auto& a : doc.arrays) {
    ArrayInfo ai;
    ai.name = a.name;
    ai.kind = a.section + " " + lower(a.keyword);
    ai.type = element_type_name(a.type);
    ai.components = a.components;
    ai.shape = std::to_string(a.tuples) + " tuples x " + std::to_string(a.components) + " components";
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

}  // namespace tfm
