// Test support: the paper's synthetic cube (host/model/synthetic_cube.h) as a fitting problem —
// the reference of two halves, the second field with an inner cube of flipped values, the
// blue-to-red TF at opacity 0.4 (the interior shows faintly, as in the paper) — fitted by a
// registered solver, and the image PSNR of a TF for the second field against the reference image.
#pragma once

#include <cstdint>
#include <map>
#include <string>

#include "tfmatch/kernels/render.h"
#include "tfmatch/model/synthetic_cube.h"
#include "tfmatch/report/metrics.h"
#include "tfmatch/solvers/optimize.h"

namespace tfm::test {

struct CubeCase {
  explicit CubeCase(uint64_t size = 16)
      : ref(cube_halves(size)), field(cube_with_inner_cube(size, 0.5)), ref_tf(blue_to_red_tf(16, 0.4)) {}
  Volume ref, field;
  TransferFunction ref_tf;

  // A 16-entry TF for the field by `solver` with its options `extra`.
  OptimizeResult fit(Context& ctx, const std::string& solver, std::map<std::string, std::string> extra = {}) const {
    OptimizeRequest req;
    req.ref = &ref;
    req.field = &field;
    req.ref_tf = ref_tf;
    req.tf_size = 16;
    req.solver = solver;
    req.settings.extra = std::move(extra);
    return run_optimize(ctx, req);
  }
  // PSNR of the field rendered with `tf` against the reference image, side x side pixels from the
  // default camera.
  double image_psnr(Context& ctx, const TransferFunction& tf, uint32_t side = 64) const {
    RenderSettings s;
    s.width = s.height = side;
    const Image a = composite_over(render_volume(ctx, ref, ref_tf, {0, 1}, s), s.background);
    return compare_images(a, composite_over(render_volume(ctx, field, tf, {0, 1}, s), s.background)).psnr;
  }
};

}  // namespace tfm::test
