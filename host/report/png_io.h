// PNG files of 8-bit RGB images (libpng's simplified API), written atomically.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <future>
#include <string>
#include <string_view>
#include <utility>

#include "tfmatch/model/image.h"

namespace tfm {

// The PNG byte stream of an image. Throws std::runtime_error when libpng fails.
std::string encode_png(const Image& image);
// The same pixels as encode_png, encoded for speed rather than size (the viewer's interactive
// frames): each row filtered by the one above it ("Up"), deflated at zlib level 1 with run-length
// matches only. About 30 % larger; several times faster. Throws std::runtime_error when zlib
// fails.
std::string encode_png_fast(const Image& image);
// Writes atomically (host/io/atomic_file.h). Throws std::runtime_error naming the path.
void write_png(const std::filesystem::path& path, const Image& image);
// PNG files encoded on threads of their own while the caller goes on (reports: zlib on one core
// had been most of their time between renders), written atomically in the order added, from the
// calling thread (an OutputBatch is single-threaded). At most `max_pending` encodings are in
// flight (0: the machine's cores); add() writes the oldest first when that many are. The caller's
// wait counts as the write phase, the encoding threads' time not again. Destroying the writer
// waits for its encodings and drops what finish() did not write.
class BackgroundPngWriter {
 public:
  explicit BackgroundPngWriter(std::size_t max_pending = 0);
  void add(std::filesystem::path path, const Image& image);
  // Writes every picture still pending; rethrows an encoding or writing failure.
  void finish();

 private:
  void write_oldest();
  std::size_t max_pending_;
  std::deque<std::pair<std::filesystem::path, std::future<std::string>>> pending_;
};
// Reads any PNG as 8-bit RGB, the values as stored: grey and palette images are expanded, 16-bit
// values reduced to their high byte, no gamma conversion (a gAMA chunk is not applied), and an
// alpha channel is composited over white on those values (c a + 255 (1 - a)), as viewers show it. Throws std::runtime_error naming the path when the
// file is missing or not a PNG, and before allocating the image when its header claims more
// pixels than its bytes can hold (zlib expands at most 1032:1) or than the memory budget allows
// (host/model/memory_budget.h).
Image read_png(const std::filesystem::path& path);
// The width and height a PNG's header gives, read without decoding the image (to compare sizes
// before paying for two decodings). Throws as read_png does for a missing file or one that is
// not a PNG.
std::pair<uint32_t, uint32_t> read_png_size(const std::filesystem::path& path);
// The same for a PNG in memory; `name` starts every message.
Image decode_png(std::string_view bytes, const std::string& name);

}  // namespace tfm
