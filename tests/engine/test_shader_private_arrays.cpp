// The private (per-invocation) arrays of every embedded shader stay small one by one: lavapipe
// compiles a private array in a time that grows faster than linearly with its size (measured:
// one array of 11 N 64-bit sums took 2.6 s at N = 64 and 14.8 s at N = 256 with a cold shader
// cache, eleven arrays of N took 0.4 s and 2.0 s), so the kernels keep one array per term or
// channel, each indexed by the TF entry. This reads each module's SPIR-V, sizes its arrays of the
// Function and Private storage classes with the TF-size constants set to a large N, and requires
// each to hold at most N + 3 elements of at most 8 bytes.
#include <gtest/gtest.h>

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "tfmatch/shaders/shader_registry.h"

namespace tfm {
namespace {

// SPIR-V opcodes, storage classes and decorations this reader needs (numbers from the SPIR-V
// specification, unified1).
enum Op : uint32_t {
  OpName = 5,
  OpTypeBool = 20,
  OpTypeInt = 21,
  OpTypeFloat = 22,
  OpTypeVector = 23,
  OpTypeArray = 28,
  OpTypeStruct = 30,
  OpTypePointer = 32,
  OpConstantTrue = 41,
  OpConstantFalse = 42,
  OpConstant = 43,
  OpSpecConstantTrue = 48,
  OpSpecConstantFalse = 49,
  OpSpecConstant = 50,
  OpSpecConstantOp = 52,
  OpVariable = 59,
  OpIAdd = 128,
  OpISub = 130,
  OpIMul = 132,
  OpUDiv = 134,
  OpUMod = 137,
  OpLogicalOr = 166,
  OpLogicalAnd = 167,
  OpLogicalNot = 168,
  OpSelect = 169,
  OpIEqual = 170,
  OpINotEqual = 171,
  OpUGreaterThan = 172,
  OpUGreaterThanEqual = 174,
  OpULessThan = 176,
  OpULessThanEqual = 178,
};
constexpr uint32_t kStoragePrivate = 6, kStorageFunction = 7;

std::string literal_string(std::span<const uint32_t> words) {
  std::string s;
  for (uint32_t w : words)
    for (int b = 0; b < 4; ++b) {
      const char c = char((w >> (8 * b)) & 0xFF);
      if (c == '\0') return s;
      s += c;
    }
  return s;
}

struct PrivateArray {
  std::string shader, variable;
  uint64_t elements = 0, element_bytes = 0;
};

// The module's Function/Private arrays, with the specialization constants named in `overrides`
// set to their values and every other one at its default.
std::vector<PrivateArray> private_arrays(const std::string& shader, std::span<const uint32_t> spirv,
                                         const std::map<std::string, uint64_t>& overrides) {
  if (spirv.size() < 5 || spirv[0] != 0x07230203u) throw std::runtime_error(shader + ": not SPIR-V");
  std::map<uint32_t, std::string> names;
  std::map<uint32_t, std::vector<uint32_t>> defs;  // result id -> the whole instruction
  std::vector<std::vector<uint32_t>> variables;
  for (size_t i = 5; i < spirv.size();) {
    const uint32_t count = spirv[i] >> 16, op = spirv[i] & 0xFFFF;
    if (count == 0 || i + count > spirv.size()) throw std::runtime_error(shader + ": truncated instruction");
    const std::vector<uint32_t> ins(spirv.begin() + long(i), spirv.begin() + long(i + count));
    switch (op) {
      case OpName: names[ins[1]] = literal_string(std::span(ins).subspan(2)); break;
      case OpTypeBool: case OpTypeInt: case OpTypeFloat: case OpTypeVector: case OpTypeArray:
      case OpTypeStruct: case OpTypePointer: defs[ins[1]] = ins; break;
      case OpConstantTrue: case OpConstantFalse: case OpConstant: case OpSpecConstantTrue:
      case OpSpecConstantFalse: case OpSpecConstant: case OpSpecConstantOp: defs[ins[2]] = ins; break;
      case OpVariable: variables.push_back(ins); break;
      default: break;
    }
    i += count;
  }
  auto def = [&](uint32_t id) -> const std::vector<uint32_t>& {
    const auto it = defs.find(id);
    if (it == defs.end()) throw std::runtime_error(shader + ": undefined id " + std::to_string(id));
    return it->second;
  };
  // Constants as unsigned integers (booleans 0/1); specialization constants from `overrides`.
  std::function<uint64_t(uint32_t)> value = [&](uint32_t id) -> uint64_t {
    const std::vector<uint32_t>& c = def(id);
    const uint32_t op = c[0] & 0xFFFF;
    if (op == OpSpecConstant || op == OpSpecConstantTrue || op == OpSpecConstantFalse) {
      const auto name = names.find(id);
      if (name != names.end())
        if (const auto o = overrides.find(name->second); o != overrides.end()) return o->second;
    }
    switch (op) {
      case OpConstantTrue: case OpSpecConstantTrue: return 1;
      case OpConstantFalse: case OpSpecConstantFalse: return 0;
      case OpConstant: case OpSpecConstant: return c[3];
      case OpSpecConstantOp: {
        auto a = [&](int k) { return value(c[4 + k]); };
        switch (c[3]) {
          case OpIAdd: return uint32_t(a(0) + a(1));
          case OpISub: return uint32_t(a(0) - a(1));
          case OpIMul: return uint32_t(a(0) * a(1));
          case OpUDiv: return a(1) ? a(0) / a(1) : 0;
          case OpUMod: return a(1) ? a(0) % a(1) : 0;
          case OpLogicalOr: return a(0) || a(1);
          case OpLogicalAnd: return a(0) && a(1);
          case OpLogicalNot: return !a(0);
          case OpSelect: return a(0) ? a(1) : a(2);
          case OpIEqual: return a(0) == a(1);
          case OpINotEqual: return a(0) != a(1);
          case OpUGreaterThan: return a(0) > a(1);
          case OpUGreaterThanEqual: return a(0) >= a(1);
          case OpULessThan: return a(0) < a(1);
          case OpULessThanEqual: return a(0) <= a(1);
          default:
            throw std::runtime_error(shader + ": specialization constant operation " + std::to_string(c[3]) +
                                     " not handled by this test");
        }
      }
      default: throw std::runtime_error(shader + ": id " + std::to_string(id) + " is not a constant");
    }
  };
  std::function<uint64_t(uint32_t)> bytes = [&](uint32_t type) -> uint64_t {
    const std::vector<uint32_t>& t = def(type);
    switch (t[0] & 0xFFFF) {
      case OpTypeBool: return 4;
      case OpTypeInt: case OpTypeFloat: return t[2] / 8;
      case OpTypeVector: return t[3] * bytes(t[2]);
      case OpTypeArray: return value(t[3]) * bytes(t[2]);
      case OpTypeStruct: {
        uint64_t sum = 0;
        for (size_t k = 2; k < t.size(); ++k) sum += bytes(t[k]);
        return sum;
      }
      default: return 8;
    }
  };
  std::vector<PrivateArray> out;
  for (const std::vector<uint32_t>& v : variables) {
    const std::vector<uint32_t>& pointer = def(v[1]);
    if (v[3] != kStoragePrivate && v[3] != kStorageFunction) continue;
    const std::vector<uint32_t>& pointee = def(pointer[3]);
    if ((pointee[0] & 0xFFFF) != OpTypeArray) continue;
    const auto name = names.find(v[2]);
    out.push_back({shader, name != names.end() ? name->second : "%" + std::to_string(v[2]), value(pointee[3]),
                   bytes(pointee[2])});
  }
  return out;
}

// The specialization constants that scale the shaders' private arrays with the TF size (entries,
// histogram bins, the reference TF's cached entries).
std::map<std::string, uint64_t> tf_sized(uint64_t n) {
  return {{"PRIVATE_BINS", n}, {"TF_CACHE_ENTRIES", n}, {"kPrivateCounters", n}};
}

TEST(ShaderPrivateArrays, EachHoldsAtMostOneEntryPerTfEntryOfAtMostEightBytes) {
  constexpr uint64_t kN = 1000;
  size_t scaled = 0;
  for (const std::string& shader : shader_names()) {
    SCOPED_TRACE(shader);
    const std::vector<PrivateArray> large = private_arrays(shader, shader_spirv(shader), tf_sized(kN));
    const std::vector<PrivateArray> small = private_arrays(shader, shader_spirv(shader), tf_sized(10));
    ASSERT_EQ(large.size(), small.size());
    for (size_t i = 0; i < large.size(); ++i) {
      const PrivateArray& a = large[i];
      EXPECT_LE(a.elements, kN + 3) << a.variable << ": one private array of " << a.elements
                                    << " elements at N = " << kN << "; split it (one array per term or channel)";
      EXPECT_LE(a.element_bytes, 8u) << a.variable << ": elements of " << a.element_bytes
                                     << " bytes; one array per component keeps each array small";
      if (a.elements > small[i].elements) ++scaled;
    }
  }
  // The reader found the TF-sized arrays (the assembly alone has eleven): the check is not empty.
  EXPECT_GE(scaled, 20u);
}

// The reader itself, on a shader whose arrays are known: the assembly's histograms are eleven
// arrays of N + 1 sums, and a term outside the pass gets one element.
TEST(ShaderPrivateArrays, ReaderSizesTheAssemblysHistograms) {
  const std::vector<PrivateArray> arrays =
      private_arrays("assemble_normal_equations", shader_spirv("assemble_normal_equations_int64"),
                     {{"PRIVATE_BINS", 64}, {"TERM_FIRST", 0}, {"TERM_COUNT", 11}});
  size_t hist = 0;
  for (const PrivateArray& a : arrays)
    if (a.variable.rfind("hist", 0) == 0) {
      ++hist;
      EXPECT_EQ(a.elements, 65u) << a.variable;
      EXPECT_EQ(a.element_bytes, 8u) << a.variable;
    }
  EXPECT_EQ(hist, 11u);
  // A pass of terms 3..5 keeps full arrays for those three only.
  size_t full = 0;
  for (const PrivateArray& a : private_arrays("assemble_normal_equations", shader_spirv("assemble_normal_equations_int64"),
                                              {{"PRIVATE_BINS", 64}, {"TERM_FIRST", 3}, {"TERM_COUNT", 3}}))
    if (a.variable.rfind("hist", 0) == 0 && a.elements == 65u) ++full;
  EXPECT_EQ(full, 3u);
}

}  // namespace
}  // namespace tfm
