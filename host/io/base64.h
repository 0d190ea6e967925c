// Base64 as VTK XML files use it: decoding tolerates several independently padded segments one
// after another (VTK encodes a block header and the data separately) and ignores whitespace.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace tfm {

// Decodes on demand, so a caller can read a header, check the sizes it promises, then read on.
class Base64Decoder {
 public:
  explicit Base64Decoder(std::string_view text) : text_(text) {}
  // Appends up to `n` decoded bytes to `out`; returns how many were appended (fewer only at the
  // end of the text). Throws std::runtime_error (message without a file name) on a character
  // outside the alphabet, misplaced padding or a truncated final group.
  size_t read(size_t n, std::string& out);
  // Decoded bytes still available at most (for size checks before allocating).
  size_t remaining_upper_bound() const { return (text_.size() - pos_) / 4 * 3 + 3; }

 private:
  bool next_group();  // decodes the next 4-character group into pending_; false at the end
  std::string_view text_;
  size_t pos_ = 0;
  unsigned char pending_[3]{};
  size_t pending_begin_ = 0, pending_end_ = 0;
};

// The whole text decoded (same rules).
std::string base64_decode(std::string_view text);
// Standard base64 with padding, no line breaks.
std::string base64_encode(std::string_view bytes);

}  // namespace tfm
