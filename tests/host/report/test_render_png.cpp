// PNG round trips, compositing over the background, the TF plot's parts, text and panels.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <fstream>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <zlib.h>

#include "cli_runner.h"
#include "tfmatch/report/font.h"
#include "tfmatch/report/png_io.h"
#include "tfmatch/report/series_report.h"
#include "tfmatch/report/tf_plot.h"

namespace tfm {
namespace {

// The report's FreeType face (nullptr where the font is not installed); installing it is
// process-wide, so each test sets the face it wants.
const TextFace* report_face() {
  static std::unique_ptr<FreeTypeFace> face =
      report_font_file().empty() ? nullptr : std::make_unique<FreeTypeFace>(report_font_file());
  return face.get();
}

// The process-wide face, back to what it was at scope exit (the binary also runs every test in
// one process, in any order).
struct TextFaceGuard {
  const TextFace* previous = text_face();
  ~TextFaceGuard() { set_text_face(previous); }
};

TEST(RenderPng, RoundTripKeepsEveryByte) {
  test::TempDir dir;
  std::mt19937 rng(1);
  for (auto [w, h] : {std::pair{1u, 1u}, std::pair{13u, 7u}, std::pair{300u, 2u}}) {
    Image img(w, h);
    for (auto& b : img.rgb) b = uint8_t(rng());
    write_png(dir / "a.png", img);
    const Image back = read_png(dir / "a.png");
    ASSERT_EQ(back.width, w);
    ASSERT_EQ(back.height, h);
    EXPECT_EQ(back.rgb, img.rgb);
  }
}

TEST(RenderPng, BackgroundWriterWritesEveryPictureAndRethrowsFailures) {
  test::TempDir dir;
  std::mt19937 rng(2);
  std::vector<Image> images;
  for (uint32_t k = 0; k < 7; ++k) {
    Image img(5 + k, 3 + 2 * k);
    for (auto& b : img.rgb) b = uint8_t(rng());
    images.push_back(img);
  }
  {
    // Two in flight: adding the third writes the first.
    BackgroundPngWriter writer(2);
    for (size_t k = 0; k < images.size(); ++k) writer.add(dir / ("p" + std::to_string(k) + ".png"), images[k]);
    EXPECT_TRUE(std::filesystem::exists(dir / "p0.png"));
    writer.finish();
  }
  for (size_t k = 0; k < images.size(); ++k) EXPECT_EQ(read_png(dir / ("p" + std::to_string(k) + ".png")).rgb, images[k].rgb) << k;
  // A picture for a folder that does not exist: the failure names the file at finish().
  BackgroundPngWriter writer;
  writer.add(std::filesystem::path(dir / "missing") / "x.png", images[0]);
  try {
    writer.finish();
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("x.png"), std::string::npos) << e.what();
  }
}

// Interactive frames: other bytes, the same pixels, on awkward sizes and content (flat runs,
// noise, a single row; filtered in bands of about 64 KiB: several bands with a short last one, and
// rows longer than a band).
TEST(RenderPng, FastEncodingKeepsEveryPixel) {
  std::mt19937 rng(7);
  for (auto [w, h] : {std::pair{1u, 1u}, {13u, 1u}, {127u, 33u}, {512u, 260u}, {30000u, 3u}}) {
    Image img(w, h);
    for (uint32_t y = 0; y < h; ++y)
      for (uint32_t x = 0; x < w; ++x)
        if ((x / 7 + y / 5) % 3 == 0)  // patches of noise on white, as a rendering has
          img.set(int(x), int(y), {uint8_t(rng()), uint8_t(rng()), uint8_t(rng())});
    const std::string fast = encode_png_fast(img);
    const Image back = decode_png(fast, "fast");
    ASSERT_EQ(back.width, w);
    ASSERT_EQ(back.height, h);
    EXPECT_EQ(back.rgb, img.rgb) << w << "x" << h;
    EXPECT_EQ(decode_png(encode_png(img), "plain").rgb, back.rgb);
  }
  EXPECT_THROW(encode_png_fast(Image()), std::invalid_argument);
}

// draw_line visits only the band around the line: the same pixels as visiting the whole box
// (this test's brute force), for lines steep, flat, short, degenerate and leaving the image.
TEST(RenderPng, LinesDrawTheSamePixelsAsTheWholeBox) {
  auto brute = [](Image& img, double x0, double y0, double x1, double y1, Rgb8 c, double width) {
    const double r = 0.5 * width, dx = x1 - x0, dy = y1 - y0, len2 = dx * dx + dy * dy;
    for (int y = int(std::floor(std::min(y0, y1) - r - 1)); y <= int(std::ceil(std::max(y0, y1) + r + 1)); ++y)
      for (int x = int(std::floor(std::min(x0, x1) - r - 1)); x <= int(std::ceil(std::max(x0, x1) + r + 1)); ++x) {
        const double px = x + 0.5, py = y + 0.5;
        const double s = len2 > 0 ? std::clamp(((px - x0) * dx + (py - y0) * dy) / len2, 0.0, 1.0) : 0.0;
        img.blend(x, y, c, std::clamp(r + 0.5 - std::hypot(px - (x0 + s * dx), py - (y0 + s * dy)), 0.0, 1.0));
      }
  };
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> pos(-40.0, 140.0), w(0.5, 4.0);
  std::vector<std::array<double, 5>> lines = {{10, 10, 90, 11, 1}, {10, 10, 11, 90, 1}, {5, 5, 5, 5, 2},
                                              {0.5, 0.5, 99.5, 79.5, 1}, {-30, 40, 130, 41, 1.5}};
  for (int i = 0; i < 300; ++i) lines.push_back({pos(rng), pos(rng), pos(rng), pos(rng), w(rng)});
  for (const auto& l : lines) {
    Image fast(100, 80, {250, 250, 250}), slow(100, 80, {250, 250, 250});
    draw_line(fast, l[0], l[1], l[2], l[3], {20, 90, 160}, l[4]);
    brute(slow, l[0], l[1], l[2], l[3], {20, 90, 160}, l[4]);
    ASSERT_EQ(fast.rgb, slow.rgb) << l[0] << "," << l[1] << " -> " << l[2] << "," << l[3] << " width " << l[4];
  }
}

TEST(RenderPng, ReadingANonPngNamesTheFile) {
  test::TempDir dir;
  std::ofstream(dir / "x.png") << "not a png";
  try {
    read_png(dir / "x.png");
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("x.png"), std::string::npos) << e.what();
  }
  EXPECT_THROW(read_png(dir / "missing.png"), std::runtime_error);
}

// A PNG written chunk by chunk (PNG spec: signature, IHDR, optional chunks, one IDAT, IEND), so
// the reader meets what other programs write: 16-bit samples, gAMA, palettes with tRNS, alpha.
std::string png_file(uint32_t w, uint32_t h, uint8_t depth, uint8_t colour_type, const std::string& raw_rows,
                     const std::vector<std::pair<std::string, std::string>>& extra = {}) {
  auto be32 = [](uint32_t v) {
    return std::string{char(v >> 24), char(v >> 16), char(v >> 8), char(v)};
  };
  std::string out = "\x89PNG\r\n\x1a\n";
  auto chunk = [&](const std::string& type, const std::string& data) {
    std::string body = type + data;
    out += be32(uint32_t(data.size())) + body +
           be32(uint32_t(crc32(0, reinterpret_cast<const Bytef*>(body.data()), uInt(body.size()))));
  };
  chunk("IHDR", be32(w) + be32(h) + std::string{char(depth), char(colour_type), 0, 0, 0});
  for (const auto& [type, data] : extra) chunk(type, data);
  uLongf size = compressBound(uLong(raw_rows.size()));
  std::string z(size, '\0');
  compress(reinterpret_cast<Bytef*>(z.data()), &size, reinterpret_cast<const Bytef*>(raw_rows.data()),
           uLong(raw_rows.size()));
  chunk("IDAT", z.substr(0, size));
  chunk("IEND", "");
  return out;
}

// Metrics compare the values as stored: a 16-bit image (v * 257, no colour chunk) and an image
// with a gAMA chunk read as the same 8-bit values (the simplified libpng API converted both, by
// the chunk and by taking 16-bit data as linear: RMSE 53 against themselves); palettes, grey and
// alpha expand, alpha over white on the stored values ((255, 0, 0) at alpha 128: (255, 127, 127)).
TEST(RenderPng, ReadsTheValuesAsStoredWhateverTheEncoding) {
  const uint32_t w = 5, h = 3;
  std::string rgb8, rgb16, grey16, rows8, rows16, grey_rows;
  Image expected;
  expected.width = w;
  expected.height = h;
  for (uint32_t y = 0; y < h; ++y) {
    rows8 += '\0';
    rows16 += '\0';
    grey_rows += '\0';
    for (uint32_t x = 0; x < w; ++x) {
      const uint8_t v[3] = {uint8_t(17 * x + 40 * y), uint8_t(250 - 31 * x), uint8_t(3 + 60 * y)};
      for (uint8_t c : v) {
        rows8 += char(c);
        rows16 += std::string{char(c), char(c)};  // 257 c, big-endian
        expected.rgb.push_back(c);
      }
      grey_rows += std::string{char(v[0]), char(0x80)};  // 16-bit grey, low byte not 0
    }
  }
  const Image plain = decode_png(png_file(w, h, 8, 2, rows8), "plain");
  EXPECT_EQ(plain.rgb, expected.rgb);
  EXPECT_EQ(decode_png(png_file(w, h, 16, 2, rows16), "16-bit").rgb, expected.rgb);
  EXPECT_EQ(decode_png(png_file(w, h, 8, 2, rows8, {{"gAMA", std::string{0, 1, char(0x86), char(0xa0)}}}), "gAMA 1").rgb,
            expected.rgb);  // gamma 1.0 (100000)
  const Image grey = decode_png(png_file(w, h, 16, 0, grey_rows), "grey");
  for (size_t i = 0; i < size_t(w) * h; ++i)
    for (size_t c = 0; c < 3; ++c) EXPECT_EQ(grey.rgb[3 * i + c], expected.rgb[3 * i]) << i;
  // A palette of two entries, the second half transparent (tRNS): red over white.
  const std::string palette{char(255), 0, 0, 0, 0, char(255)};
  const std::string alpha{char(128), char(255)};
  const Image indexed =
      decode_png(png_file(2, 1, 8, 3, std::string{0, 0, 1}, {{"PLTE", palette}, {"tRNS", alpha}}), "palette");
  EXPECT_EQ(indexed.rgb, (std::vector<uint8_t>{255, 127, 127, 0, 0, 255}));
  // RGBA: the same, and fully transparent is white.
  const Image rgba = decode_png(png_file(2, 1, 8, 6, std::string{0, char(255), 0, 0, char(128), 0, 0, 0, 0}), "rgba");
  EXPECT_EQ(rgba.rgb, (std::vector<uint8_t>{255, 127, 127, 255, 255, 255}));
  // Truncated image data is named, not read as garbage.
  const std::string whole = png_file(w, h, 8, 2, rows8);
  EXPECT_THROW(decode_png(whole.substr(0, whole.size() - 20), "cut"), std::runtime_error);
}

TEST(RenderPng, CompositesPremultipliedColourOverTheBackground) {
  RenderedImage r;
  r.width = 2;
  r.height = 1;
  r.rgba = {0.2f, 0.1f, 0.0f, 0.5f, 0.0f, 0.0f, 0.0f, 0.0f};
  r.stop = {3, 0};
  const Image img = composite_over(r, {1.0, 0.0, 0.5});
  // C + (1 - A) * background in linear RGB: (0.7, 0.1, 0.25) and the background itself, each
  // encoded to sRGB (1.055 c^(1/2.4) - 0.055) and rounded once.
  EXPECT_EQ(img.at(0, 0)[0], 218);
  EXPECT_EQ(img.at(0, 0)[1], 89);
  EXPECT_EQ(img.at(0, 0)[2], 137);
  EXPECT_EQ(img.at(1, 0)[0], 255);
  EXPECT_EQ(img.at(1, 0)[1], 0);
  EXPECT_EQ(img.at(1, 0)[2], 188);
  EXPECT_EQ(r.samples(), 3u);
}

// srgb_byte's table gives the formula's byte everywhere: at every step's boundary and next to
// it, and on a dense random sample (uniform, and near zero where the curve is linear).
TEST(RenderPng, SrgbTableEqualsTheFormula) {
  for (int b = 0; b < 256; ++b) {
    // The formula's smallest input of byte b, by bisection on the bit patterns.
    uint64_t lo = 0, hi = std::bit_cast<uint64_t>(1.0);
    if (b == 0) hi = 0;
    while (hi - lo > 1) {
      const uint64_t mid = lo + (hi - lo) / 2;
      (srgb_byte_formula(std::bit_cast<double>(mid)) >= b ? hi : lo) = mid;
    }
    for (int64_t d = -3; d <= 3; ++d) {
      const double v = std::bit_cast<double>(uint64_t(int64_t(hi) + d));
      ASSERT_EQ(srgb_byte(v), srgb_byte_formula(v)) << "byte " << b << ", " << d << " ulp: " << v;
    }
  }
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> unit(-0.1, 1.1), small(0.0, 0.01);
  for (int i = 0; i < 2000000; ++i) {
    const double v = i % 4 ? unit(rng) : small(rng);
    ASSERT_EQ(srgb_byte(v), srgb_byte_formula(v)) << v;
  }
  for (double v : {0.0, -0.0, 1.0, std::nextafter(1.0, 0.0), double(NAN), double(INFINITY), -double(INFINITY)})
    EXPECT_EQ(srgb_byte(v), srgb_byte_formula(v)) << v;
}

TEST(RenderPng, SrgbEncodingFollowsThePiecewiseCurve) {
  // Endpoints, the linear toe (12.92 c below 0.0031308) and the power segment.
  EXPECT_EQ(srgb_byte(0.0), 0);
  EXPECT_EQ(srgb_byte(1.0), 255);
  EXPECT_EQ(srgb_byte(-0.5), 0);
  EXPECT_EQ(srgb_byte(2.0), 255);
  EXPECT_EQ(srgb_byte(NAN), 0);
  EXPECT_EQ(srgb_byte(0.002), 7);     // 12.92 * 0.002 * 255 = 6.59
  EXPECT_EQ(srgb_byte(0.5), 188);     // 0.7354 * 255 = 187.5 -> 188
  EXPECT_EQ(srgb_byte(0.2158605), 128);  // the linear value of sRGB 128/255
  // Every 8-bit sRGB code decodes and re-encodes to itself.
  for (int v = 0; v < 256; ++v) {
    const double c = v / 255.0;
    const double lin = c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
    ASSERT_EQ(srgb_byte(lin), v);
  }
}

TEST(RenderPng, TfPlotShowsHistogramCurveAndColourBar) {
  TransferFunction tf;
  for (int j = 0; j < 8; ++j) tf.rgba.push_back({j / 7.0, 0.0, 1.0 - j / 7.0, j < 4 ? 0.0 : 1.0});
  std::vector<float> values(1000, 0.25f);
  values.push_back(NAN);
  TfPlotOptions o;
  o.width = 220;
  o.height = 170;
  o.axis_label = "T [K]";
  TextFaceGuard guard;
  for (const TextFace* face : {static_cast<const TextFace*>(nullptr), report_face()}) {
    set_text_face(face);
    SCOPED_TRACE(face ? "FreeType" : "bitmap font");
    const Image img = plot_transfer_function(tf, values, {0, 1}, o);
    ASSERT_EQ(img.width, 220u);
    ASSERT_EQ(img.height, 170u);
    // The colour bar: the row with the most pure TF colours (blue at the left end, red at the right).
    int bar_y = -1, best = 0;
    for (uint32_t y = 0; y < img.height; ++y) {
      int n = 0;
      for (uint32_t x = 0; x < img.width; ++x) n += img.at(x, y)[1] == 0 && (img.at(x, y)[0] > 0 || img.at(x, y)[2] > 0);
      if (n > best) best = n, bar_y = int(y);
    }
    ASSERT_GT(best, 150) << "no colour bar";
    int left = 0, right = int(img.width) - 1;
    while (img.at(left, bar_y)[1] != 0) ++left;
    while (img.at(right, bar_y)[1] != 0) --right;
    const int plot_w = right - left + 1;
    EXPECT_GT(img.at(left, bar_y)[2], 240) << "left end of the bar is blue";
    EXPECT_GT(img.at(right, bar_y)[0], 240) << "right end of the bar is red";
    // The histogram has one full bar at t = 0.25 and nothing at t = 0.75 (just above the axis).
    const int y_low = bar_y - 8;
    const uint8_t* full = img.at(left + plot_w / 4, y_low);
    const uint8_t* empty = img.at(left + 3 * plot_w / 4, y_low);
    EXPECT_TRUE(full[0] > 200 && full[2] < 200) << "light yellow histogram bar expected";
    EXPECT_TRUE(empty[0] == 255 && empty[2] == 255) << "no histogram where there is no data";
    // The opacity curve: dark in the upper half at t = 0.9 (opacity 1).
    bool dark_top = false;
    for (int y = 0; y < bar_y / 2; ++y) dark_top |= img.at(left + int(0.9 * plot_w), y)[0] < 80;
    EXPECT_TRUE(dark_top) << "opacity curve missing at opacity 1";
    // Tick labels under the bar: dark text pixels below it.
    int ink_below = 0;
    for (uint32_t y = uint32_t(bar_y) + 14; y < img.height; ++y)
      for (uint32_t x = 0; x < img.width; ++x) ink_below += img.at(x, y)[0] < 128;
    EXPECT_GT(ink_below, 40) << "value ticks and axis label";
  }
  set_text_face(nullptr);
  EXPECT_EQ(field_histogram(values, {0, 1}, 4)[1], 1000u);
  // The histogram's scale is named on the plot: the log and linear plots differ only there
  // and in the bar heights, and both draw.
  o.log_counts = false;
  EXPECT_NO_THROW(plot_transfer_function(tf, values, {0, 1}, o));
}

// Labels longer than their room keep their end ("...grib:t,member=3") and stay whole characters;
// a TF plot's axis label is drawn inside the picture whatever its length.
TEST(RenderPng, LongLabelsKeepTheirEndInsideThePicture) {
  TextFaceGuard guard;
  for (const TextFace* face : {static_cast<const TextFace*>(nullptr), report_face()}) {
    set_text_face(face);
    SCOPED_TRACE(face ? "FreeType" : "bitmap font");
    const std::string path = "/data/era5/levels-members.grib:t@isobaricInhPa,time=0,member=3";
    EXPECT_EQ(fit_text(path, text_width(path)), path);
    const std::string fitted = fit_text(path, 120);
    EXPECT_LE(text_width(fitted), 120);
    ASSERT_GT(fitted.size(), 3u);
    EXPECT_EQ(fitted.substr(0, 3), "...");
    EXPECT_TRUE(path.ends_with(fitted.substr(3))) << fitted;
    EXPECT_GT(text_width(fitted), 120 - text_width("WW")) << "as much of the end as fits";
    // UTF-8: never half a character.
    const std::string greek = "\xce\xb8\xce\xb8\xce\xb8\xce\xb8\xce\xb8\xce\xb8 potential temperature";
    const std::string g = fit_text(greek, text_width(greek) - 1);
    EXPECT_NE(static_cast<unsigned char>(g[3]) & 0xC0, 0x80u) << g;
    EXPECT_EQ(fit_text(path, 2), "");
    // The axis label of a 240-pixel plot: no dark pixel in the outermost columns.
    TransferFunction tf;
    tf.rgba = {{0, 0, 1, 0}, {1, 0, 0, 1}};
    std::vector<float> values(100, 0.5f);
    TfPlotOptions o;
    o.width = 240;
    o.height = 170;
    o.axis_label = path + path;
    const Image img = plot_transfer_function(tf, values, {0, 1}, o);
    for (uint32_t y = 0; y < img.height; ++y)
      for (uint32_t x : {0u, 1u, img.width - 2, img.width - 1}) ASSERT_GT(img.at(x, y)[0], 200) << x << "," << y;
  }
}

// A plot too narrow for the histogram's scale beside its title puts the scale on a line of its
// own: the opacity curve of a ramp, which ends in the plot's top-right corner, stays visible there
// (a white patch over that corner hid it). An axis caption too long drops the file before the
// variable.
TEST(RenderPng, TfPlotLabelsNeverCoverTheCurve) {
  TextFaceGuard guard;
  for (const TextFace* face : {static_cast<const TextFace*>(nullptr), report_face()}) {
    set_text_face(face);
    SCOPED_TRACE(face ? "FreeType" : "bitmap font");
    TransferFunction tf;
    tf.rgba = {{0, 0, 1, 0}, {1, 0, 0, 1}};
    std::vector<float> values(100, 0.5f);
    TfPlotOptions o;
    o.width = 320;
    o.height = 240;
    o.title = "Reference TF, reference field histogram";
    ASSERT_GT(8 + text_width(o.title) + 12 + text_width("histogram: log(1 + count)"), int(o.width) - 12)
        << "the case needs a title that leaves no room beside it";
    const Image img = plot_transfer_function(tf, values, {0, 1}, o);
    // Every column of the curve's last tenth has curve ink (dark) somewhere.
    const int left = 8 + text_width("0.5") + 6, right = int(o.width) - 12, plot_w = right - left;
    for (int x = left + int(0.9 * plot_w); x < right - 3; ++x) {
      bool dark = false;
      for (uint32_t y = 0; y < img.height && !dark; ++y) dark = img.at(uint32_t(x), y)[0] < 80 && img.at(uint32_t(x), y)[2] < 80;
      EXPECT_TRUE(dark) << "the opacity curve is hidden at column " << x;
    }
    const std::string name = "era5-levels-members.grib:t@isobaricInhPa,time=0,member=3 (K)";
    EXPECT_EQ(axis_caption(name, text_width(name)), name);
    EXPECT_EQ(axis_caption(name, text_width(name) - 1), "t@isobaricInhPa,time=0,member=3 (K)");
    const std::string narrow = axis_caption(name, text_width("member=3 (K)") + text_width("..."));
    EXPECT_TRUE(narrow.starts_with("...") && name.ends_with(narrow.substr(3))) << narrow;
  }
}

// The series report's TF overlay: where every field shares one range (--shared-tf) it has a value
// axis (ticks at round values under the curves, labels beneath); else the TF coordinate alone.
TEST(RenderPng, TfOverlayHasAValueAxisWhereTheRangeIsShared) {
  TextFaceGuard guard;
  set_text_face(nullptr);
  TransferFunction tf;
  tf.rgba = {{0, 0, 1, 0}, {1, 0, 0, 1}};
  const Image plain = plot_tf_overlay({tf, tf}, 640, "the fitted TFs");
  const Image shared = plot_tf_overlay({tf}, 640, "the shared TF", FieldRange{250, 300});
  const int th = text_height(1), bottom = 8 + th + 8 + 160;  // the curves' frame, as drawn
  EXPECT_EQ(int(shared.height), int(plain.height) - (10 + 2) + 4 + 2 + th + 2) << "one strip fewer, the axis more";
  // Tick marks (frame grey) one pixel wide, 6 of them (250, 260, ..., 300), evenly spaced.
  std::vector<int> ticks;
  for (uint32_t x = 0; x < shared.width; ++x)
    if (shared.at(x, bottom + 2)[0] == 170) ticks.push_back(int(x));
  ASSERT_EQ(ticks.size(), 6u);
  for (size_t k = 1; k < ticks.size(); ++k) EXPECT_NEAR(ticks[k] - ticks[k - 1], (ticks.back() - ticks[0]) / 5.0, 1.0);
  // Labels beneath: ink in the rows under the ticks, none in the plain plot's same rows.
  auto ink = [&](const Image& img, int y0, int y1) {
    int n = 0;
    for (int y = y0; y < y1; ++y)
      for (uint32_t x = 0; x < img.width; ++x) n += img.at(x, uint32_t(y))[0] < 128;
    return n;
  };
  EXPECT_GT(ink(shared, bottom + 6, bottom + 6 + th), 30);
  for (uint32_t x = 0; x < plain.width; ++x) EXPECT_NE(plain.at(x, bottom + 2)[0], 170) << "a tick at x = " << x;
}

TEST(RenderPng, NiceTicksAreRoundAndInside) {
  const std::vector<double> unit = nice_ticks(0, 1, 5);
  ASSERT_EQ(unit.size(), 6u);
  for (size_t k = 0; k < unit.size(); ++k) EXPECT_NEAR(unit[k], 0.2 * double(k), 1e-12);
  EXPECT_EQ(nice_ticks(224.3, 305.1, 4), (std::vector<double>{240, 260, 280, 300}));
  EXPECT_EQ(nice_ticks(-1, 1, 4), (std::vector<double>{-1, -0.5, 0, 0.5, 1}));
  EXPECT_TRUE(nice_ticks(1, 1).empty());
  for (double v : nice_ticks(-3.7e-5, 9.1e-5, 6)) {
    EXPECT_GE(v, -3.7e-5);
    EXPECT_LE(v, 9.1e-5);
  }
}

// The report font: DejaVu Sans through FreeType, anti-aliased, legible (13 px body text).
TEST(RenderPng, FreeTypeFaceDrawsAntiAliasedText) {
  const TextFace* face = report_face();
  if (!face) GTEST_SKIP() << "DejaVu Sans (fonts-dejavu-core) not installed: reports use the bitmap font";
  Image img(120, 30);
  const int w = face->draw(img, 2, 2, "Temperature", {0, 0, 0}, 1);
  EXPECT_EQ(w, face->width("Temperature", 1));
  EXPECT_GT(w, 60);
  EXPECT_LT(w, 100);
  EXPECT_GE(face->height(1), 13);
  EXPECT_LE(face->height(1), 18);
  EXPECT_GT(face->height(2), face->height(1));
  int black = 0, grey = 0;
  for (size_t i = 0; i < img.rgb.size(); i += 3) black += img.rgb[i] < 40, grey += img.rgb[i] >= 40 && img.rgb[i] < 215;
  EXPECT_GT(black, 40);
  EXPECT_GT(grey, 20) << "anti-aliased edges";
  // Non-ASCII text (degree sign, UTF-8) draws a glyph, not nothing.
  EXPECT_GT(face->width("\xC2\xB0", 1), 2);
}

TEST(RenderPng, TextAndPanels) {
  TextFaceGuard guard;
  set_text_face(nullptr);  // the bitmap font's exact sizes
  Image img(40, 12);
  const int w = draw_text(img, 1, 1, "Ab1", {0, 0, 0});
  EXPECT_EQ(w, 18);
  EXPECT_EQ(text_width("Ab1"), 17);
  int dark = 0;
  for (size_t i = 0; i < img.rgb.size(); i += 3) dark += img.rgb[i] == 0;
  EXPECT_GT(dark, 15);
  const Image p = compose_panels({{Image(30, 20, {255, 0, 0}), "a"}, {Image(30, 20, {0, 0, 255}), "b"},
                                  {Image(10, 10, {0, 255, 0}), "c"}},
                                 2);
  EXPECT_GT(p.width, 60u);
  EXPECT_GT(p.height, 40u);
}

}  // namespace
}  // namespace tfm
