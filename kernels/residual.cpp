// Residual maps on the device.
#include "tfmatch/kernels/residual.h"

#include <algorithm>
#include <cmath>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/device_memory.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/residual_map.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm {

Volume residual_map_gpu(Context& ctx, const Volume& grid, const DeviceField& ref, const DeviceField& opt,
                        const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                        const Buffer& opt_tf) {
  DeviceField out(ctx, ref.voxel_count(), "residual map", ref.chunk_voxels());
  ResidualMapKernel kernel(ctx);
  CommandBatch batch(ctx);
  kernel.record(batch, ref, opt, ref_map, opt_map, ref_tf, opt_tf, out);
  batch.submit_and_wait();
  Volume v = empty_like(grid);
  v.name = "residual map";
  v.values.resize(out.voxel_count());
  for (size_t c = 0; c < out.chunk_count(); ++c)
    readback(ctx, out.chunk(c), v.values.data() + out.chunk_begin(c), out.chunk_size(c) * sizeof(float));
  return v;
}

Volume residual_map(Context& ctx, const Volume& ref, const TransferFunction& ref_tf, const FieldRange& ref_range,
                    const Volume& field, const TransferFunction& field_tf, const FieldRange& field_range) {
  require_same_grid(ref, field);
  // Both fields (unless read in place) and the map on the device, and the map read back: one
  // check of the sum where the device's memory is the host's (two checks of 3 and 1 volumes let a
  // run 18-30 % over pass).
  const uint64_t volume_bytes = ref.values.size() * sizeof(float);
  const uint64_t device_volumes = DeviceField::reads_host_memory(ctx) ? 1 : 3;
  check_device_memory(ctx, device_volumes * volume_bytes, "residual map of " + ref.name);
  check_memory((device_memory_is_host(ctx) ? device_volumes + 1 : 1) * volume_bytes, "residual map of " + ref.name);
  const DeviceField ref_dev = field_over_host_values(ctx, ref.values, "residual: reference field");
  const DeviceField opt_dev = field_over_host_values(ctx, field.values, "residual: second field", ref_dev.chunk_voxels());
  Buffer ref_tf_buf = upload_tf(ctx, ref_tf, "residual: reference TF");
  Buffer opt_tf_buf = upload_tf(ctx, field_tf, "residual: field TF");
  return residual_map_gpu(ctx, ref, ref_dev, opt_dev, make_mapping(ref_range, uint32_t(ref_tf.size())),
                          make_mapping(field_range, uint32_t(field_tf.size())), ref_tf_buf, opt_tf_buf);
}

TransferFunction residual_transfer_function(uint32_t n) {
  TransferFunction tf;
  tf.rgba.resize(n);
  const double stops[3][3] = {{1.00, 0.88, 0.45}, {0.95, 0.45, 0.08}, {0.55, 0.00, 0.05}};
  for (uint32_t j = 0; j < n; ++j) {
    const double t = double(j) / (n - 1);
    const int k = t < 0.5 ? 0 : 1;
    const double w = t < 0.5 ? 2 * t : 2 * t - 1;
    for (int c = 0; c < 3; ++c) tf.rgba[j][c] = (1 - w) * stops[k][c] + w * stops[k + 1][c];
    tf.rgba[j][3] = t;
  }
  return tf;
}

FieldRange residual_display_range(std::initializer_list<const Volume*> residuals) {
  double hi = 0.0;
  for (const Volume* v : residuals)
    for (float x : v->values)
      if (std::isfinite(x)) hi = std::max(hi, double(x));
  return hi > 0.0 ? FieldRange{0.0, std::max(hi, kResidualDisplayFloor)} : FieldRange{0.0, 1.0};
}

}  // namespace tfm
