// Self-test cases of the IRLS pass (irls_assemble: weighted tridiagonal sums and the l1 loss,
// every reduction mode and atomic width) against its double CPU reference (irls_cpu.h).
#include <string>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/irls.h"
#include "tfmatch/reference/irls_cpu.h"
#include "tfmatch/selftest/selftest_support.h"
#include "tfmatch/shaders/solver_layout.h"

namespace tfm::selftest {
namespace {

struct PassCase {
  size_t voxels;
  ReductionOptions path;
  uint64_t chunk_voxels = 0;
};

void pass(Context& ctx, Check& check, const PassCase& c) {
  const uint32_t n = 9;
  const std::string missing = reduction_unavailable(ctx, c.path, n, uint64_t(TFM_IRLS_LOSS_SLOT(n)) * gpu::kFixedSlotBytes);
  if (!missing.empty()) return check.skip(missing);
  const ResidualCaseInputs in(ctx, c.voxels, 71, n, c.chunk_voxels);
  const FieldPair& p = in.pair;
  const std::vector<float>& ref_tf_floats = in.ref_tf_floats;
  const FieldMapping &ref_map = in.ref_map, &opt_map = in.opt_map;
  // x, then a weight floor per channel from nearly all-equal weights to nearly l1.
  const std::array<float, 4> delta = {0.5f, 0.05f, 1e-3f, 1e-4f};
  std::vector<float> state = random_floats(4 * n, 4, 0.0f, 1.0f);
  state.insert(state.end(), delta.begin(), delta.end());
  Buffer sb = make_buffer<float>(ctx, state, "selftest IRLS state");
  Buffer accum(ctx, irls_accumulator_bytes(n), MemoryUsage::Device, "selftest IRLS accumulators");
  const IrlsKernel kernel(ctx, n, c.path);
  check.require(kernel.mode() == c.path.mode, "the kernel did not take the requested path");
  CommandBatch batch(ctx);
  batch.fill(accum, 0u);
  // The zeroed accumulators before the kernel adds to them.
  batch.barrier();
  kernel.record(batch, in.ref, in.opt, ref_map, opt_map, in.tf, sb, accum);
  batch.submit_and_wait();
  const IrlsSums sums = IrlsSums::from_words(n, read_words(ctx, accum, irls_accumulator_bytes(n) / 4));
  const IrlsPassCpu expected = irls_pass_cpu(p.ref, p.opt, ref_map, opt_map, ref_tf_floats,
                                             std::span<const float>(state).first(4 * n), delta);
  for (uint32_t ch = 0; ch < 4; ++ch) {
    for (uint32_t j = 0; j < n; ++j) {
      check.near("diagonal (4j+c)", 4 * j + ch, sums.diag[ch][j], expected.diag[ch][j], expected.diag_bound[ch][j]);
      check.near("right-hand side (4j+c)", 4 * j + ch, sums.rhs[ch][j], expected.rhs[ch][j], expected.rhs_bound[ch][j]);
      if (j + 1 < n)
        check.near("off-diagonal (4j+c)", 4 * j + ch, sums.off[ch][j], expected.off[ch][j], expected.off_bound[ch][j]);
    }
    check.near("l1 loss, channel", ch, sums.l1[ch], expected.l1[ch], expected.l1_bound[ch]);
  }
}

}  // namespace

void add_irls_cases(CaseList& cases) {
  const size_t past_group = TFM_VOXEL_WORKGROUP + 1;
  for (const ReductionOptions& path : reduction_paths()) {
    auto add = [&](PassCase c, bool quick) {
      c.path = path;
      std::string name = voxels_name(c.voxels) + reduction_name(path);
      if (c.chunk_voxels) name += ", chunks of " + std::to_string(c.chunk_voxels);
      cases.push_back({"irls_assemble", "IrlsKernel", name, quick, TFM_VOXEL_WORKGROUP,
                       [c](Context& ctx, Check& check) { pass(ctx, check, c); }});
    };
    add({13, path}, false);
    add({past_group, path}, false);
    add({5000, path, 1024}, true);
    add({100003, path}, false);
    add({100003, path, 16384}, false);
  }
  // One workgroup asked for 400 003 voxels: past lavapipe's loop budget unless raised (as gd_gradient).
  const PassCase one_group{400003, {ReductionMode::Private, AtomicWidth::Bits64, 1}};
  cases.push_back({"irls_assemble", "IrlsKernel", voxels_name(one_group.voxels) + reduction_name(one_group.path), false,
                   TFM_VOXEL_WORKGROUP, [one_group](Context& ctx, Check& check) { pass(ctx, check, one_group); }});
}

}  // namespace tfm::selftest
