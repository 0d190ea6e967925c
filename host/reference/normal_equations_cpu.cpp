// Double-precision CPU reference of the GPU normal-equation assembly.
#include "tfmatch/reference/normal_equations_cpu.h"

#include <algorithm>
#include <exception>
#include <stdexcept>
#include <thread>
#include <vector>

#include "tfmatch/shaders/shared_layout.h"  // TFM_FIXED_ONE

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

NormalEquations assemble_normal_equations_cpu_threaded(std::span<const float> ref, std::span<const float> opt,
                                                       const FieldMapping& ref_map, const FieldMapping& opt_map,
                                                       const TransferFunction& ref_tf, unsigned threads) {
  if (ref.size() != opt.size()) throw std::invalid_argument("assemble_normal_equations_cpu_threaded: size mismatch");
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  std::vector<NormalEquations> parts(threads, NormalEquations(opt_map.tf_size));
  std::vector<std::exception_ptr> errors(threads);
  {
    // jthreads: joined however this block is left; what a worker throws is rethrown below.
    std::vector<std::jthread> workers;
    for (unsigned t = 0; t < threads; ++t)
      workers.emplace_back([&, t] {
        try {
          const size_t begin = ref.size() * t / threads, end = ref.size() * (t + 1) / threads;
          // Each thread sums into a system of its own stack, not into parts[t]: the vector's
          // elements are adjacent, and the per-voxel counters of neighbouring threads shared cache
          // lines (false sharing made this loop up to 1.7x slower, depending on the struct's layout).
          NormalEquations local(opt_map.tf_size);
          accumulate_normal_equations_cpu(local, ref.subspan(begin, end - begin), opt.subspan(begin, end - begin),
                                          ref_map, opt_map, ref_tf);
          parts[t] = std::move(local);
        } catch (...) {
          errors[t] = std::current_exception();
        }
      });
  }
  for (const std::exception_ptr& e : errors)
    if (e) std::rethrow_exception(e);
  NormalEquations total = std::move(parts[0]);
  for (unsigned t = 1; t < threads; ++t) {
    for (uint32_t j = 0; j < total.n; ++j) total.diag[j] += parts[t].diag[j];
    for (uint32_t j = 0; j + 1 < total.n; ++j) total.off[j] += parts[t].off[j];
    total.rhs += parts[t].rhs;
    for (int c = 0; c < 4; ++c) total.btb[c] += parts[t].btb[c];
    total.voxels += parts[t].voxels;
  }
  return total;
}

std::vector<uint64_t> assemble_normal_equations_fixed_point(std::span<const float> ref, std::span<const float> opt,
                                                            const FieldMapping& ref_map, const FieldMapping& opt_map,
                                                            const TransferFunction& ref_tf,
                                                            const FieldMapping* before_map,
                                                            std::span<const float> weights) {
  if (ref.size() != opt.size() || (!weights.empty() && weights.size() != ref.size()))
    throw std::invalid_argument("assemble_normal_equations_fixed_point: size mismatch");
  if (ref_tf.size() != ref_map.tf_size || (before_map && before_map->tf_size != ref_map.tf_size))
    throw std::invalid_argument("assemble_normal_equations_fixed_point: TF size does not match the mapping");
  const uint32_t n = opt_map.tf_size, stb = 2 * n - 1;
  const std::vector<float> tf = ref_tf.as_floats();
  // floor(c 2^32) of a float c in [0, 1]: c 2^32 is exact in float, the conversion truncates.
  auto fixed = [](float c) { return static_cast<uint64_t>(c * float(TFM_FIXED_ONE)); };
  std::vector<uint64_t> slots(6 * n + 8, 0);  // TFM_ASSEMBLE_SLOTS(n)
  for (size_t i = 0; i < ref.size(); ++i) {
    uint32_t jr, jo;
    float wr, wo;
    if (!tf_coordinate(ref[i], ref_map, jr, wr) || !tf_coordinate(opt[i], opt_map, jo, wo)) continue;
    // A weighted term: the weight times the float term, rounded once (the kernel's `weighted`).
    const float s = weights.empty() ? 1.0f : weights[i];
    auto fx = [&](float term) { return fixed(s * term); };
    const float u = 1.0f - wo;
    slots[jo] += fx(u * u);
    slots[jo + 1] += fx(wo * wo);
    slots[n + jo] += fx(u * wo);
    for (int c = 0; c < 4; ++c) {
      const float b = std::clamp((1.0f - wr) * tf[4 * jr + c] + wr * tf[4 * (jr + 1) + c], 0.0f, 1.0f);
      slots[stb + 4 * jo + c] += fx(u * b);
      slots[stb + 4 * (jo + 1) + c] += fx(wo * b);
      slots[6 * n - 1 + c] += fx(b * b);
    }
    slots[6 * n + 3] += uint64_t(1) << 32;
    if (before_map) {
      // The loss before optimization: the same float operations as the kernel (unfused).
      uint32_t jb;
      float wb;
      tf_coordinate(opt[i], *before_map, jb, wb);
      for (int c = 0; c < 4; ++c) {
        const float b = std::clamp((1.0f - wr) * tf[4 * jr + c] + wr * tf[4 * (jr + 1) + c], 0.0f, 1.0f);
        const float v = (1.0f - wb) * tf[4 * jb + c] + wb * tf[4 * (jb + 1) + c];
        const float d = v - b;
        slots[6 * n + 4 + c] += fx(d * d);
      }
    }
  }
  return slots;
}

NormalEquations assemble_normal_equations_cpu(std::span<const float> ref, std::span<const float> opt,
                                              const FieldMapping& ref_map, const FieldMapping& opt_map,
                                              const TransferFunction& ref_tf) {
  NormalEquations eq(opt_map.tf_size);
  accumulate_normal_equations_cpu(eq, ref, opt, ref_map, opt_map, ref_tf);
  return eq;
}

std::array<double, 4> before_loss_cpu(std::span<const float> ref, std::span<const float> opt,
                                      const FieldMapping& ref_map, const FieldMapping& before_map,
                                      const TransferFunction& ref_tf) {
  if (ref.size() != opt.size()) throw std::invalid_argument("before_loss_cpu: fields differ in size");
  const std::vector<float> r = ref_tf.as_floats();
  std::array<double, 4> sum{};
  for (size_t i = 0; i < ref.size(); ++i) {
    uint32_t jr, jb;
    float wr, wb;
    if (!tf_coordinate(ref[i], ref_map, jr, wr) || !tf_coordinate(opt[i], before_map, jb, wb)) continue;
    for (int c = 0; c < 4; ++c) {
      const double b = std::clamp((1.0 - wr) * r[4 * jr + c] + double(wr) * r[4 * (jr + 1) + c], 0.0, 1.0);
      const double v = (1.0 - wb) * r[4 * jb + c] + double(wb) * r[4 * (jb + 1) + c];
      sum[c] += (v - b) * (v - b);
    }
  }
  return sum;
}

}  // namespace tfm
