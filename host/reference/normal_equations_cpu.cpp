// Double-precision CPU reference of the GPU normal-equation assembly.
#include "normal_equations_cpu.h"

#include <algorithm>
#include <stdexcept>
#include <vector>

namespace tfm {

void accumulate_normal_equations_cpu(NormalEquations& eq, std::span<const float> ref, std::span<const float> opt,
                                     const FieldMapping& ref_map, const FieldMapping& opt_map,
                                     const TransferFunction& ref_tf) {
  if (ref.size() != opt.size()) throw std::invalid_argument("assemble_normal_equations_cpu: size mismatch");
  if (ref_tf.size() != ref_map.tf_size || eq.n != opt_map.tf_size)
    throw std::invalid_argument("assemble_normal_equations_cpu: TF sizes do not match the mappings");
  const uint32_t n = eq.n;
  // Reference TF as float, as the GPU stores it.
  std::vector<float> tf = ref_tf.as_floats();
  for (size_t i = 0; i < ref.size(); ++i) {
    uint32_t jr, jo;
    float wr, wo;
    if (!tf_coordinate(ref[i], ref_map, jr, wr) || !tf_coordinate(opt[i], opt_map, jo, wo)) continue;
    const double u = 1.0 - double(wo), w = wo;
    eq.diag[jo] += u * u;
    eq.diag[jo + 1] += w * w;
    eq.off[jo] += u * w;
    for (int c = 0; c < 4; ++c) {
      double b = (1.0 - double(wr)) * tf[4 * jr + c] + double(wr) * tf[4 * (jr + 1) + c];
      b = std::clamp(b, 0.0, 1.0);
      eq.rhs(jo, c) += u * b;
      eq.rhs(jo + 1, c) += w * b;
      eq.btb[c] += b * b;
    }
    ++eq.voxels;
  }
  (void)n;
}

NormalEquations assemble_normal_equations_cpu(std::span<const float> ref, std::span<const float> opt,
                                              const FieldMapping& ref_map, const FieldMapping& opt_map,
                                              const TransferFunction& ref_tf) {
  NormalEquations eq(opt_map.tf_size);
  accumulate_normal_equations_cpu(eq, ref, opt, ref_map, opt_map, ref_tf);
  return eq;
}

}  // namespace tfm
