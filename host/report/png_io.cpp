// PNG encoding and decoding through libpng's simplified (png_image) API.
#include "png_io.h"

#include <cstring>
#include <stdexcept>

#include <png.h>

#include "atomic_file.h"
#include "memory_budget.h"
#include "phase_timer.h"
#include "volume_formats.h"  // read_file_bytes, kMaxDeflateRatio

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

void write_png(const std::filesystem::path& path, const Image& image) {
  write_file_atomically(path, encode_png(image));
}

Image decode_png(std::string_view bytes, const std::string& name) {
  png_image p;
  std::memset(&p, 0, sizeof p);
  p.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&p, bytes.data(), bytes.size()))
    throw std::runtime_error(name + ": not a readable PNG (" + p.message + ")");
  struct Release {
    png_image* p;
    ~Release() { png_image_free(p); }
  } release{&p};
  // The header alone says how large the image is. Its rows (one filter byte each, at least one
  // bit per pixel) come out of zlib, which cannot expand data more than 1032:1: a header claiming
  // more than that from this file's bytes is refused before anything is allocated.
  const uint64_t least_raw = uint64_t(p.height) * (1 + (uint64_t(p.width) + 7) / 8);
  if (least_raw > kMaxDeflateRatio * bytes.size() + 1024)
    throw std::runtime_error(name + ": its header claims " + std::to_string(p.width) + "x" + std::to_string(p.height) +
                             " pixels, which need at least " + std::to_string(least_raw) + " bytes of image data; the file has " +
                             std::to_string(bytes.size()) + " bytes (truncated or corrupt)");
  p.format = PNG_FORMAT_RGB;
  const uint64_t image_bytes = uint64_t(p.width) * p.height * 3;
  check_memory(image_bytes, name + ": " + std::to_string(p.width) + "x" + std::to_string(p.height) + " image");
  Image image;
  image.width = p.width;
  image.height = p.height;
  image.rgb.resize(image_bytes);
  const png_color white{255, 255, 255};
  if (!png_image_finish_read(&p, &white, image.rgb.data(), 0, nullptr))
    throw std::runtime_error(name + ": PNG decoding failed (" + p.message + ")");
  return image;
}

Image read_png(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw std::runtime_error(path.string() + ": no such file");
  const uint64_t size = std::filesystem::file_size(path, ec);
  if (ec) throw std::runtime_error(path.string() + ": cannot read (" + ec.message() + ")");
  check_memory(size, path.string() + ": reading the file");
  return decode_png(read_file_bytes(path), path.string());
}

}  // namespace tfm
