// `tfmatch metrics A.png B.png`: RMSE, PSNR and SSIM of two images, as text or JSON.
#include <cmath>
#include <cstdio>
#include <iostream>

#include "cli.h"
#include "output_options.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/report/metrics.h"
#include "tfmatch/report/png_io.h"

namespace tfm::cli {
namespace {

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

struct MetricsArgs {
  std::string a, b;
  std::string json;
};

int run(const MetricsArgs& args) {
  const JsonOutput json(args.json);  // first: with '-', stdout holds only the JSON
  FilePlan().input(args.a, "A").input(args.b, "B").output(json.file(), "--json").check();
  // Sizes from the headers first: two large images of other sizes are refused before decoding.
  const auto [aw, ah] = read_png_size(args.a);
  const auto [bw, bh] = read_png_size(args.b);
  if (aw != bw || ah != bh)
    throw std::runtime_error(args.b + ": size " + std::to_string(bw) + "x" + std::to_string(bh) + " differs from " +
                             args.a + " (" + std::to_string(aw) + "x" + std::to_string(ah) + ")");
  const Image a = read_png(args.a), b = read_png(args.b);
  const ImageMetrics m = compare_images(a, b);
  std::cout << "RMSE " << num(m.rmse) << " (0-255)\nPSNR " << (std::isinf(m.psnr) ? "inf" : num(m.psnr))
            << " dB\nSSIM " << (std::isnan(m.ssim) ? "n/a (images under 11x11 pixels)" : num(m.ssim)) << "\n";
  json.write(m.to_json());
  return 0;
}

CommandRegistration reg(22, [](CLI::App& app) {
  auto args = std::make_shared<MetricsArgs>();
  auto* sub = app.add_subcommand("metrics", "Image similarity of two PNGs: RMSE, PSNR (0-255 scale) and SSIM");
  sub->add_option("A", args->a, "First image (PNG)")->required();
  sub->add_option("B", args->b, "Second image (PNG)")->required();
add_json_option(sub, args->json, "{\"rmse\", \"psnr\" (\"inf\" when identical), \"ssim\"}");
  sub->footer("SSIM: Wang et al. 2004 (11x11 Gaussian window, sigma 1.5, K1 0.01, K2 0.03) on RGB, as "
              "scikit-image's structural_similarity(gaussian_weights=True, use_sample_covariance=False, "
              "data_range=255), on the 8-bit values as stored (tfmatch writes sRGB PNGs, so these are the pixels "
              "people see; 16-bit values by their high byte, no gamma conversion by a gAMA chunk). Alpha in a PNG "
              "is composited over white on those values, as image viewers show it. LPIPS is not available.");
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
