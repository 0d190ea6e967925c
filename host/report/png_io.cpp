// PNG encoding through libpng's simplified (png_image) API, decoding through its full API.
#include "tfmatch/report/png_io.h"

#include <algorithm>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <new>
#include <stdexcept>
#include <thread>
#include <vector>

#include <png.h>
#include <zlib.h>

#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/volume_formats.h"  // read_file_bytes, kMaxDeflateRatio
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/phase_timer.h"

namespace tfm {
namespace {

png_image describe(const Image& image) {
  png_image p;
  std::memset(&p, 0, sizeof p);
  p.version = PNG_IMAGE_VERSION;
  p.width = image.width;
  p.height = image.height;
  p.format = PNG_FORMAT_RGB;
  return p;
}

}  // namespace

std::string encode_png(const Image& image) {
  PhaseScope timing(Phase::Write);  // encoding is part of writing an image
  if (image.width == 0 || image.height == 0 || image.rgb.size() != size_t(image.width) * image.height * 3)
    throw std::invalid_argument("encode_png: empty or inconsistent image");
  png_image p = describe(image);
  png_alloc_size_t bytes = 0;
  const png_int_32 stride = png_int_32(image.width * 3);
  if (!png_image_write_get_memory_size(p, bytes, 0, image.rgb.data(), stride, nullptr))
    throw std::runtime_error(std::string("PNG encoding failed: ") + p.message);
  std::string out(bytes, '\0');
  p = describe(image);
  if (!png_image_write_to_memory(&p, out.data(), &bytes, 0, image.rgb.data(), stride, nullptr))
    throw std::runtime_error(std::string("PNG encoding failed: ") + p.message);
  out.resize(bytes);
  return out;
}

namespace {

void put_u32(std::string& out, uint32_t v) {
  for (int shift = 24; shift >= 0; shift -= 8) out.push_back(char((v >> shift) & 0xff));
}

// A PNG chunk: length, type, data, CRC-32 of type and data.
void put_chunk(std::string& out, const char* type, const std::string& data) {
  put_u32(out, uint32_t(data.size()));
  const size_t start = out.size();
  out.append(type, 4);
  out += data;
  const uLong crc = crc32(0L, reinterpret_cast<const Bytef*>(out.data() + start), uInt(out.size() - start));
  put_u32(out, uint32_t(crc));
}

}  // namespace

std::string encode_png_fast(const Image& image) {
  PhaseScope timing(Phase::Write);
  if (image.width == 0 || image.height == 0 || image.rgb.size() != size_t(image.width) * image.height * 3)
    throw std::invalid_argument("encode_png_fast: empty or inconsistent image");
  const size_t row = size_t(image.width) * 3;
  z_stream z{};
  if (deflateInit2(&z, 1, Z_DEFLATED, 15, 8, Z_RLE) != Z_OK) throw std::runtime_error("PNG encoding failed: zlib init");
  struct End {
    z_stream* z;
    ~End() { deflateEnd(z); }
  } end{&z};

  std::string out("\x89PNG\r\n\x1a\n", 8);
  std::string header;
  put_u32(header, image.width);
  put_u32(header, image.height);
  header += std::string("\x08\x02\x00\x00\x00", 5);  // 8 bits, RGB, deflate, adaptive filters, no interlace
  put_chunk(out, "IHDR", header);
  // IDAT is deflated in place, into room for the worst case: only the pages deflate writes are
  // touched. Its rows are filtered in bands of about 64 KiB that stay in cache: filtering the
  // whole image into a fresh buffer first faulted in every page of it, a quarter of the time of a
  // 512² frame (4.5 -> 3.45 ms on the 2-core development machine, 2026-11-29).
  const size_t idat_at = out.size();
  const uLong raw_bytes = uLong((row + 1) * image.height);
  out.resize(idat_at + 8 + deflateBound(&z, raw_bytes) + 4);
  z.next_out = reinterpret_cast<Bytef*>(out.data() + idat_at + 8);
  z.avail_out = uInt(out.size() - idat_at - 12);
  const uint32_t band_rows = uint32_t(std::max<size_t>(1, (size_t(64) << 10) / (row + 1)));
  std::vector<char> band((row + 1) * std::min(band_rows, image.height));
  int status = Z_OK;
  for (uint32_t y0 = 0; y0 < image.height; y0 += band_rows) {
    const uint32_t rows = std::min(band_rows, image.height - y0);
    // Up-filtered rows: a rendering's background and smooth shading become runs of zeros and
    // small values, which run-length matches take at little cost.
    for (uint32_t r = 0; r < rows; ++r) {
      const uint32_t y = y0 + r;
      char* filtered = band.data() + r * (row + 1);
      const uint8_t* cur = image.rgb.data() + y * row;
      filtered[0] = 2;  // filter type Up
      if (y == 0) {
        std::memcpy(filtered + 1, cur, row);
        continue;
      }
      const uint8_t* up = cur - row;
      for (size_t x = 0; x < row; ++x) filtered[1 + x] = char(uint8_t(cur[x] - up[x]));
    }
    z.next_in = reinterpret_cast<Bytef*>(band.data());
    z.avail_in = uInt(rows * (row + 1));
    status = deflate(&z, y0 + rows == image.height ? Z_FINISH : Z_NO_FLUSH);
    if (status != Z_OK && status != Z_STREAM_END) break;
    if (z.avail_in != 0) {  // out of room: the bound holds for one stream, so never here
      status = Z_BUF_ERROR;
      break;
    }
  }
  if (status != Z_STREAM_END) throw std::runtime_error("PNG encoding failed: zlib deflate");
  const size_t idat_bytes = z.total_out;
  out.resize(idat_at + 8 + idat_bytes);  // the deflated bytes already stand after length and type
  std::string length;
  put_u32(length, uint32_t(idat_bytes));
  std::memcpy(out.data() + idat_at, length.data(), 4);
  std::memcpy(out.data() + idat_at + 4, "IDAT", 4);
  const uLong crc = crc32(0L, reinterpret_cast<const Bytef*>(out.data() + idat_at + 4), uInt(idat_bytes + 4));
  put_u32(out, uint32_t(crc));
  put_chunk(out, "IEND", "");
  return out;
}

void write_png(const std::filesystem::path& path, const Image& image) {
  write_file_atomically(path, encode_png(image));
}

BackgroundPngWriter::BackgroundPngWriter(std::size_t max_pending)
    : max_pending_(max_pending ? max_pending : std::max(1u, std::thread::hardware_concurrency())) {}

void BackgroundPngWriter::add(std::filesystem::path path, const Image& image) {
  if (pending_.size() >= max_pending_) write_oldest();
  pending_.emplace_back(std::move(path), std::async(std::launch::async, [image] {
                          const UntimedThread overlapped;  // counted as the caller's wait
                          return encode_png(image);
                        }));
}

void BackgroundPngWriter::write_oldest() {
  const PhaseScope timing(Phase::Write);
  auto [path, bytes] = std::move(pending_.front());
  pending_.pop_front();
  write_file_atomically(path, bytes.get());
}

void BackgroundPngWriter::finish() {
  while (!pending_.empty()) write_oldest();
}

namespace {

// PNG reading through libpng's full API. Its simplified API (png_image) decodes to what a display
// shows in sRGB: it converts by any gAMA chunk and takes 16-bit data without one as linear light,
// so an image compared with itself stored as 16 bits gave RMSE 53. Metrics compare the values as
// stored (as scikit-image and PIL read them), which needs transforms the simplified API does not
// offer. libpng reports errors by longjmp: every libpng call is in a function below whose frame
// holds no C++ object with a destructor, and whose caller owns the memory.
struct PngReader {
  std::string_view bytes;
  size_t at = 8;  // past the signature, checked before reading
  char message[256] = {};
  png_structp png = nullptr;
  png_infop info = nullptr;
  png_uint_32 width = 0, height = 0;
  size_t row_bytes = 0;
  int channels = 0;  // 4: RGBA after the transforms below
};

void png_read_from(png_structp png, png_bytep out, size_t n) {
  auto* r = static_cast<PngReader*>(png_get_io_ptr(png));
  if (n > r->bytes.size() - r->at) png_error(png, "the file ends inside the image data (truncated)");
  std::memcpy(out, r->bytes.data() + r->at, n);
  r->at += n;
}

[[noreturn]] void png_fail(png_structp png, png_const_charp text) {
  auto* r = static_cast<PngReader*>(png_get_error_ptr(png));
  std::snprintf(r->message, sizeof r->message, "%s", text);
  png_longjmp(png, 1);
}

void png_ignore_warning(png_structp, png_const_charp) {}

// Reads the header and sets the transforms to 8-bit RGBA as stored: palette and grey expanded,
// a tRNS chunk made alpha, 16 bits to 8 by the high byte (v >> 8: 257 v reads v), no gamma.
// False with `message` set on an error.
bool png_read_header(PngReader& r) {
  if (setjmp(png_jmpbuf(r.png))) return false;
  png_set_read_fn(r.png, &r, png_read_from);
  png_set_sig_bytes(r.png, 8);
  png_read_info(r.png, r.info);
  png_set_expand(r.png);
  png_set_strip_16(r.png);
  png_set_gray_to_rgb(r.png);
  png_set_add_alpha(r.png, 0xff, PNG_FILLER_AFTER);
  png_set_interlace_handling(r.png);
  png_read_update_info(r.png, r.info);
  r.width = png_get_image_width(r.png, r.info);
  r.height = png_get_image_height(r.png, r.info);
  r.row_bytes = png_get_rowbytes(r.png, r.info);
  r.channels = png_get_channels(r.png, r.info);
  return true;
}

bool png_read_rows(PngReader& r, png_bytepp rows) {
  if (setjmp(png_jmpbuf(r.png))) return false;
  png_read_image(r.png, rows);
  return true;
}

}  // namespace

Image decode_png(std::string_view bytes, const std::string& name) {
  if (bytes.size() < 8 || png_sig_cmp(reinterpret_cast<png_const_bytep>(bytes.data()), 0, 8) != 0)
    throw std::runtime_error(name + ": not a readable PNG (no PNG signature)");
  PngReader r;
  r.bytes = bytes;
  r.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &r, png_fail, png_ignore_warning);
  if (r.png) r.info = png_create_info_struct(r.png);
  struct Release {
    PngReader& r;
    ~Release() { png_destroy_read_struct(&r.png, r.info ? &r.info : nullptr, nullptr); }
  } release{r};
  if (!r.info) throw std::bad_alloc();
  if (!png_read_header(r)) throw std::runtime_error(name + ": not a readable PNG (" + r.message + ")");
  // The header alone says how large the image is. Its rows (one filter byte each, at least one
  // bit per pixel) come out of zlib, which cannot expand data more than 1032:1: a header claiming
  // more than that from this file's bytes is refused before anything is allocated.
  const uint64_t least_raw = uint64_t(r.height) * (1 + (uint64_t(r.width) + 7) / 8);
  if (least_raw > kMaxDeflateRatio * bytes.size() + 1024)
    throw std::runtime_error(name + ": its header claims " + std::to_string(r.width) + "x" + std::to_string(r.height) +
                             " pixels, which need at least " + std::to_string(least_raw) + " bytes of image data; the file has " +
                             std::to_string(bytes.size()) + " bytes (truncated or corrupt)");
  if (r.channels != 4 || r.row_bytes != size_t(r.width) * 4)
    throw std::runtime_error(name + ": PNG decoding failed (unexpected layout after expansion)");
  const uint64_t rgba_bytes = uint64_t(r.width) * r.height * 4;
  check_memory(rgba_bytes + rgba_bytes / 4 * 3,
               name + ": " + std::to_string(r.width) + "x" + std::to_string(r.height) + " image");
  std::vector<uint8_t> rgba(rgba_bytes);
  std::vector<png_bytep> rows(r.height);
  for (png_uint_32 y = 0; y < r.height; ++y) rows[y] = rgba.data() + size_t(y) * r.row_bytes;
  if (!png_read_rows(r, rows.data())) throw std::runtime_error(name + ": PNG decoding failed (" + r.message + ")");
  // Alpha composited over white on the stored values, as image viewers show it:
  // c a + 255 (1 - a), rounded.
  Image image;
  image.width = r.width;
  image.height = r.height;
  image.rgb.resize(uint64_t(r.width) * r.height * 3);
  for (size_t i = 0, n = size_t(r.width) * r.height; i < n; ++i) {
    const unsigned a = rgba[4 * i + 3];
    for (size_t c = 0; c < 3; ++c)
      image.rgb[3 * i + c] = uint8_t((rgba[4 * i + c] * a + 255u * (255u - a) + 127u) / 255u);
  }
  return image;
}

namespace {

// Throws std::runtime_error unless `path` is a file (libpng read a directory as "Read Error").
void require_file(const std::filesystem::path& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (!std::filesystem::exists(status)) throw std::runtime_error(path.string() + ": no such file");
  if (std::filesystem::is_directory(status)) throw std::runtime_error(path.string() + ": is a directory, not a PNG image");
}

}  // namespace

std::pair<uint32_t, uint32_t> read_png_size(const std::filesystem::path& path) {
  require_file(path);
  png_image p;
  std::memset(&p, 0, sizeof p);
  p.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&p, path.c_str()))  // reads the header only
    throw std::runtime_error(path.string() + ": not a readable PNG (" + p.message + ")");
  png_image_free(&p);
  return {p.width, p.height};
}

Image read_png(const std::filesystem::path& path) {
  PhaseScope timing(Phase::Read);  // reading and decoding: `metrics --json` timings showed none
  require_file(path);
  std::error_code ec;
  const uint64_t size = std::filesystem::file_size(path, ec);
  if (ec) throw std::runtime_error(path.string() + ": cannot read (" + ec.message() + ")");
  check_memory(size, path.string() + ": reading the file");
  return decode_png(read_file_bytes(path), path.string());
}

}  // namespace tfm
