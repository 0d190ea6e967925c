// Base64 decoding (segment-tolerant, see base64.h) and encoding.
#include "tfmatch/io/base64.h"

#include <array>
#include <stdexcept>

namespace tfm {
namespace {

constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

constexpr std::array<int8_t, 256> make_table() {
  std::array<int8_t, 256> t{};
  for (auto& v : t) v = -1;
  for (int i = 0; i < 64; ++i) t[static_cast<unsigned char>(kAlphabet[i])] = static_cast<int8_t>(i);
  return t;
}
constexpr std::array<int8_t, 256> kTable = make_table();

bool is_space(char c) { return c == ' ' || c == '\n' || c == '\r' || c == '\t' || c == '\f' || c == '\v'; }

}  // namespace

bool Base64Decoder::next_group() {
  char group[4];
  int have = 0;
  size_t group_start = pos_;
  while (have < 4 && pos_ < text_.size()) {
    char c = text_[pos_++];
    if (is_space(c)) continue;
    if (have == 0) group_start = pos_ - 1;
    group[have++] = c;
  }
  if (have == 0) return false;
  if (have < 4)
    throw std::runtime_error("base64 data ends in the middle of a group (at character " + std::to_string(group_start) + ")");
  int v[4];
  for (int i = 0; i < 4; ++i) {
    if (group[i] == '=') {
      // Padding is allowed only as "xx==" or "xxx=".
      if (i < 2 || (i == 2 && group[3] != '='))
        throw std::runtime_error("misplaced base64 padding at character " + std::to_string(group_start));
      v[i] = -2;
      continue;
    }
    v[i] = kTable[static_cast<unsigned char>(group[i])];
    if (v[i] < 0 || (i == 3 && v[2] == -2))
      throw std::runtime_error("invalid base64 character at character " + std::to_string(group_start + i));
  }
  const uint32_t bits = (uint32_t(v[0]) << 18) | (uint32_t(v[1]) << 12) | (uint32_t(v[2] < 0 ? 0 : v[2]) << 6) |
                        uint32_t(v[3] < 0 ? 0 : v[3]);
  pending_[0] = static_cast<unsigned char>(bits >> 16);
  pending_[1] = static_cast<unsigned char>(bits >> 8);
  pending_[2] = static_cast<unsigned char>(bits);
  pending_begin_ = 0;
  pending_end_ = v[2] == -2 ? 1 : v[3] == -2 ? 2 : 3;
  return true;
}

size_t Base64Decoder::read(size_t n, std::string& out) {
  size_t done = 0;
  while (done < n) {
    if (pending_begin_ == pending_end_ && !next_group()) break;
    while (done < n && pending_begin_ < pending_end_) {
      out.push_back(static_cast<char>(pending_[pending_begin_++]));
      ++done;
    }
  }
  return done;
}

std::string base64_decode(std::string_view text) {
  Base64Decoder d(text);
  std::string out;
  out.reserve(text.size() / 4 * 3);
  d.read(text.size(), out);
  return out;
}

std::string base64_encode(std::string_view bytes) {
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 3 <= bytes.size(); i += 3) {
    uint32_t b = (uint32_t(uint8_t(bytes[i])) << 16) | (uint32_t(uint8_t(bytes[i + 1])) << 8) | uint8_t(bytes[i + 2]);
    for (int s = 18; s >= 0; s -= 6) out.push_back(kAlphabet[(b >> s) & 63]);
  }
  if (size_t rest = bytes.size() - i) {
    uint32_t b = uint32_t(uint8_t(bytes[i])) << 16;
    if (rest == 2) b |= uint32_t(uint8_t(bytes[i + 1])) << 8;
    out.push_back(kAlphabet[(b >> 18) & 63]);
    out.push_back(kAlphabet[(b >> 12) & 63]);
    out.push_back(rest == 2 ? kAlphabet[(b >> 6) & 63] : '=');
    out.push_back('=');
  }
  return out;
}

}  // namespace tfm
