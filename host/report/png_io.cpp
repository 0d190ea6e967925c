// PNG encoding and decoding through libpng's simplified (png_image) API.
#include "png_io.h"

#include <cstring>
#include <stdexcept>

#include <png.h>

#include "atomic_file.h"

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

Image read_png(const std::filesystem::path& path) {
  if (!std::filesystem::exists(path)) throw std::runtime_error(path.string() + ": no such file");
  png_image p;
  std::memset(&p, 0, sizeof p);
  p.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&p, path.c_str()))
    throw std::runtime_error(path.string() + ": not a readable PNG (" + p.message + ")");
  p.format = PNG_FORMAT_RGB;
  Image image;
  image.width = p.width;
  image.height = p.height;
  image.rgb.resize(PNG_IMAGE_SIZE(p));
  const png_color white{255, 255, 255};
  if (!png_image_finish_read(&p, &white, image.rgb.data(), 0, nullptr)) {
    png_image_free(&p);
    throw std::runtime_error(path.string() + ": PNG decoding failed (" + p.message + ")");
  }
  return image;
}

}  // namespace tfm
