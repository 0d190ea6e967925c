// What the voxel-pair kernels share (kernels/voxel_pair.h).
#include "tfmatch/kernels/voxel_pair.h"

#include <algorithm>
#include <stdexcept>

#include "tfmatch/engine/context.h"

namespace tfm {

static_assert(sizeof(gpu::VoxelPairPush) == 40, "VoxelPairPush must match the GLSL std430 block");


gpu::VoxelPairPush make_voxel_pair_push(const FieldMapping& ref, const FieldMapping& opt) {
  gpu::VoxelPairPush p{};
  p.opt_tf_size = opt.tf_size;
  p.ref_tf_size = ref.tf_size;
  p.ref_lo = ref.lo;
  p.ref_scale = ref.scale;
  p.opt_lo = opt.lo;
  p.opt_scale = opt.scale;
  return p;
}

uint32_t voxel_groups(const Context& ctx, uint64_t voxels, uint64_t lane_voxels) {
  const uint64_t per_group = uint64_t(TFM_VOXEL_WORKGROUP) * std::max<uint64_t>(1, lane_voxels);
  uint64_t groups = (voxels + per_group - 1) / per_group;
  return static_cast<uint32_t>(std::clamp<uint64_t>(groups, 1, ctx.limits().maxComputeWorkGroupCount[0]));
}

uint32_t lane_workgroup_size(const Context& ctx, uint32_t requested, const char* kernel) {
  const uint32_t limit = ctx.limits().maxComputeWorkGroupSize[0], subgroup = std::max(1u, ctx.subgroup_size());
  const uint32_t size = requested ? requested : is_cpu_device(ctx) ? std::min(subgroup, limit) : TFM_VOXEL_WORKGROUP;
  if (size == 0 || size > limit || size % subgroup != 0)
    throw std::invalid_argument(std::string(kernel) + ": workgroup size " + std::to_string(size) +
                                " is not a multiple of the subgroup size " + std::to_string(subgroup) +
                                " within the device's " + std::to_string(limit));
  return size;
}

uint32_t lane_groups(const Context& ctx, uint32_t workgroup_size, uint64_t voxels, uint64_t lane_voxels,
                     uint64_t min_lane_voxels) {
  if (workgroup_size == TFM_VOXEL_WORKGROUP) return voxel_groups(ctx, voxels);
  const uint64_t long_lanes = voxels / (uint64_t(workgroup_size) * std::max<uint64_t>(1, lane_voxels));
  const uint64_t spread =
      std::min<uint64_t>(kPrivateMinGroups, voxels / (uint64_t(workgroup_size) * std::max<uint64_t>(1, min_lane_voxels)));
  return static_cast<uint32_t>(
      std::clamp<uint64_t>(std::max(long_lanes, spread), 1, ctx.limits().maxComputeWorkGroupCount[0]));
}

uint64_t texel_range_quads(const Context& ctx, uint64_t requested, const char* kernel) {
  if (requested % 64) throw std::invalid_argument(std::string(kernel) + ": range_quads must be a multiple of 64");
  return requested ? requested : std::max<uint64_t>(64, ctx.limits().maxTexelBufferElements / 64 * 64);
}

uint64_t voxel_texel_range_quads(const Context& ctx, uint64_t requested, const char* kernel) {
  const uint64_t texels = ctx.limits().maxTexelBufferElements;
  const uint64_t limit = std::max<uint64_t>(64, (texels - std::min<uint64_t>(texels, 64)) / 4 / 64 * 64);
  const uint64_t quads = requested ? texel_range_quads(ctx, requested, kernel) : limit;
  if (quads > limit)
    throw std::invalid_argument(std::string(kernel) + ": ranges of " + std::to_string(quads) + " quads exceed the device's " +
                                std::to_string(texels) + " texels");
  return quads;
}

std::vector<QuadRange> quad_ranges(const DeviceField& field, uint64_t range_quads) {
  std::vector<uint64_t> sizes(field.chunk_count());
  for (size_t c = 0; c < sizes.size(); ++c) sizes[c] = field.chunk_size(c);
  return quad_ranges(sizes, range_quads, field.format());
}

std::vector<QuadRange> quad_ranges(std::span<const uint64_t> chunk_voxels, uint64_t range_quads, FieldFormat format) {
  const uint64_t voxel_bytes = field_format_bytes(format);
  std::vector<QuadRange> out;
  for (size_t c = 0; c < chunk_voxels.size(); ++c) {
    const uint64_t chunk = chunk_voxels[c];
    for (uint64_t first = 0; first < chunk; first += 4 * range_quads) {
      QuadRange r;
      r.chunk = c;
      r.first = first;
      r.voxels = std::min(4 * range_quads, chunk - first);
      r.format = r.voxels >= 4 ? quad_texel_format(format) : voxel_texel_format(format);
      r.bytes = r.voxels >= 4 ? r.voxels / 4 * 4 * voxel_bytes : voxel_bytes;
      out.push_back(r);
    }
  }
  return out;
}

Binding quad_texels(const DeviceField& field, const QuadRange& r) {
  const uint64_t voxel_bytes = field_format_bytes(field.format());
  const bool quads = r.voxels >= 4;
  return Binding::texels(field.chunk(r.chunk),
                         quads ? quad_texel_format(field.format()) : voxel_texel_format(field.format()),
                         r.first * voxel_bytes, quads ? r.voxels / 4 * 4 * voxel_bytes : voxel_bytes);
}

Binding voxel_texels(const DeviceField& field, size_t c) {
  return Binding::texels(field.chunk(c), voxel_texel_format(field.format()), 0,
                         field.chunk_size(c) * field_format_bytes(field.format()));
}

std::vector<double> decode_fixed_point(const std::vector<uint32_t>& words) {
  // Unsigned slots of shaders/fixed_point.glsl (signed ones: FixedPointTotals).
  std::vector<double> out(words.size() / TFM_FIXED_SLOT_WORDS);
  for (size_t k = 0; k < out.size(); ++k)
    out[k] = (double(words[2 * k + 1]) * TFM_FIXED_ONE + double(words[2 * k])) / TFM_FIXED_ONE;
  return out;
}


void bind_fields_as_images(PipelineDesc& desc, std::initializer_list<uint32_t> field_bindings) {
  for (uint32_t b : field_bindings) desc.binding_kinds.at(b) = DescriptorKind::SampledImage;
}

void check_image_field(const ImageFieldView& field, const char* kernel) {
  if (field.view == VK_NULL_HANDLE)
    throw std::invalid_argument(std::string(kernel) + ": an image field without a view (VK_NULL_HANDLE)");
  if (field.format == VK_FORMAT_UNDEFINED)
    throw std::invalid_argument(std::string(kernel) + ": an image field without its view's format "
                                "(ImageFieldView::format: R32_SFLOAT, R16_SFLOAT, R16_UNORM or R8_UNORM)");
  field_format_of(field.format, kernel);
}

uint64_t check_image_pair(const ImageFieldView& ref, const ImageFieldView& opt, const char* kernel) {
  check_image_field(ref, kernel);
  check_image_field(opt, kernel);
  const VkExtent3D& e = ref.extent;
  if (e.width != opt.extent.width || e.height != opt.extent.height || e.depth != opt.extent.depth)
    throw std::invalid_argument(std::string(kernel) + ": the two images differ in extent");
  const uint64_t voxels = uint64_t(e.width) * e.height * e.depth;
  if (voxels == 0 || voxels > UINT32_MAX)
    throw std::invalid_argument(std::string(kernel) + ": an image of " + std::to_string(voxels) +
                                " voxels (1 to 2^32 - 1 are read in place)");
  return voxels;
}

void check_voxel_pair(const DeviceField& ref, const DeviceField& opt, const char* kernel) {
  if (ref.voxel_count() != opt.voxel_count() || ref.chunk_voxels() != opt.chunk_voxels())
    throw std::invalid_argument(std::string(kernel) + ": fields differ in size or chunking");
}

}  // namespace tfm
