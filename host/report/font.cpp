// FreeType rendering of the report font (see font.h).
#include "tfmatch/report/font.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <mutex>
#include <stdexcept>

#include <ft2build.h>
#include FT_FREETYPE_H

namespace tfm {
namespace {

// UTF-8 to code points; a malformed byte becomes '?', so a label never stops drawing halfway.
std::u32string decode_utf8(const std::string& s) {
  std::u32string out;
  for (size_t i = 0; i < s.size();) {
    const unsigned char b = static_cast<unsigned char>(s[i]);
    const int n = b < 0x80 ? 1 : (b >> 5) == 0x6 ? 2 : (b >> 4) == 0xE ? 3 : (b >> 3) == 0x1E ? 4 : 0;
    if (n == 0 || i + n > s.size()) {
      out.push_back(U'?');
      ++i;
      continue;
    }
    char32_t cp = n == 1 ? b : b & (0x7F >> n);
    bool ok = true;
    for (int k = 1; k < n; ++k) {
      const unsigned char c = static_cast<unsigned char>(s[i + k]);
      ok &= (c >> 6) == 0x2;
      cp = (cp << 6) | (c & 0x3F);
    }
    out.push_back(ok ? cp : U'?');
    i += ok ? n : 1;
  }
  return out;
}

}  // namespace

struct FreeTypeFace::Impl {
  FT_Library library = nullptr;
  FT_Face face = nullptr;
  mutable std::mutex mutex;  // FT_Face is not thread-safe; sizes change per call
  void size(int scale) const { FT_Set_Pixel_Sizes(face, 0, FT_UInt(pixel_size(scale))); }
};

FreeTypeFace::FreeTypeFace(const std::filesystem::path& font_file) : impl_(std::make_unique<Impl>()) {
  if (FT_Init_FreeType(&impl_->library) != 0) throw std::runtime_error("FreeType: cannot initialise");
  if (FT_New_Face(impl_->library, font_file.c_str(), 0, &impl_->face) != 0) {
    FT_Done_FreeType(impl_->library);
    throw std::runtime_error(font_file.string() + ": FreeType cannot open this font");
  }
}

FreeTypeFace::~FreeTypeFace() {
  FT_Done_Face(impl_->face);
  FT_Done_FreeType(impl_->library);
}

int FreeTypeFace::height(int scale) const {
  std::lock_guard lock(impl_->mutex);
  impl_->size(scale);
  const FT_Size_Metrics& m = impl_->face->size->metrics;
  return int((m.ascender - m.descender + 63) >> 6);
}

int FreeTypeFace::width(const std::string& text, int scale) const {
  std::lock_guard lock(impl_->mutex);
  impl_->size(scale);
  long pen = 0;
  for (char32_t cp : decode_utf8(text))
    if (FT_Load_Char(impl_->face, cp, FT_LOAD_DEFAULT) == 0) pen += impl_->face->glyph->advance.x;
  return int((pen + 63) >> 6);
}

int FreeTypeFace::draw(Image& img, int x, int y, const std::string& text, Rgb8 c, int scale) const {
  std::lock_guard lock(impl_->mutex);
  impl_->size(scale);
  FT_Face face = impl_->face;
  const int baseline = y + int((face->size->metrics.ascender + 63) >> 6);
  long pen = long(x) << 6;  // 26.6 fixed point
  for (char32_t cp : decode_utf8(text)) {
    if (FT_Load_Char(face, cp, FT_LOAD_RENDER) != 0) continue;
    const FT_GlyphSlot g = face->glyph;
    const FT_Bitmap& bm = g->bitmap;
    const int gx = int(pen >> 6) + g->bitmap_left, gy = baseline - g->bitmap_top;
    // Grey coverage in [0, 255] per pixel: the text colour over the picture with that coverage.
    for (unsigned row = 0; row < bm.rows; ++row)
      for (unsigned col = 0; col < bm.width; ++col) {
        const uint8_t a = bm.buffer[row * bm.pitch + col];
        if (a) img.blend(gx + int(col), gy + int(row), c, a / 255.0);
      }
    pen += g->advance.x;
  }
  return int(((pen + 63) >> 6) - x);
}

std::filesystem::path report_font_file() {
  if (const char* env = std::getenv("TFMATCH_FONT"); env && *env) return env;
  const std::filesystem::path dejavu = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
  std::error_code ec;
  return std::filesystem::exists(dejavu, ec) ? dejavu : std::filesystem::path();
}

std::string install_report_font() {
  // Opened once; installed on every call (something may have set another face meanwhile).
  static std::once_flag once;
  static std::unique_ptr<FreeTypeFace> face;
  static std::string used;
  std::call_once(once, [] {
    const std::filesystem::path file = report_font_file();
    if (file.empty()) return;
    try {
      face = std::make_unique<FreeTypeFace>(file);
      used = file.string();
    } catch (const std::runtime_error&) {
      // An unreadable font leaves the bitmap font; the report says which font it used.
    }
  });
  if (face) set_text_face(face.get());
  return used;
}

}  // namespace tfm
