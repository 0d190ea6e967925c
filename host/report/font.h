// The report's font: DejaVu Sans (Debian's fonts-dejavu-core) rendered with FreeType, installed
// as the TextFace every plot, panel label and overview picture draws with (host/model/image.h).
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include "tfmatch/model/image.h"

namespace tfm {

// A TrueType face drawn anti-aliased in the text colour over the picture. Pixel size 13 at
// scale 1 (legible at 100 % zoom), 20 at scale 2, 7 more per step.
class FreeTypeFace : public TextFace {
 public:
  // Throws std::runtime_error naming the file when FreeType cannot open it.
  explicit FreeTypeFace(const std::filesystem::path& font_file);
  ~FreeTypeFace() override;
  FreeTypeFace(const FreeTypeFace&) = delete;
  FreeTypeFace& operator=(const FreeTypeFace&) = delete;

  int draw(Image& img, int x, int y, const std::string& text, Rgb8 c, int scale) const override;
  int width(const std::string& text, int scale) const override;
  int height(int scale) const override;
  static int pixel_size(int scale) { return 6 + 7 * scale; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The font file: $TFMATCH_FONT if set, else DejaVu Sans where fonts-dejavu-core puts it. Empty
// when neither exists.
std::filesystem::path report_font_file();

// Opens the report font once per process and installs it (set_text_face). Returns what is used:
// the font file, or an empty string when no font was found (the bitmap font draws then).
std::string install_report_font();

}  // namespace tfm
