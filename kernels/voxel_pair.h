// What the voxel-pair kernels share (assemble_normal_equations.h, voxel_loss.h, residual_map.h,
// histogram.h, gradient_descent.h, sparse_ops.h): their push block, how their lanes and
// workgroups cover a range of voxels, the ranges and texel views of a field's chunks, and the
// decoding of 32.32 fixed-point accumulators.
#pragma once

#include <array>
#include <cstdint>
#include <initializer_list>
#include <span>
#include <vector>
#include <memory>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/kernels/reduction.h"
#include "tfmatch/shaders/shared_layout.h"

namespace tfm {

class Context;

gpu::VoxelPairPush make_voxel_pair_push(const FieldMapping& ref, const FieldMapping& opt);

// Voxels each lane of a voxel kernel's TFM_VOXEL_WORKGROUP-sized groups takes by default: enough to
// amortize a workgroup's flush of its shared accumulators (not yet tuned on a GPU: `tfmatch bench
// --lane-voxels` measures others).
inline constexpr uint64_t kVoxelLaneVoxels = 64;
// Workgroups of TFM_VOXEL_WORKGROUP for one dispatch over `voxels`, each lane taking about
// `lane_voxels` of them (quad_segments.glsl spreads a dispatch's quads over all its lanes).
uint32_t voxel_groups(const Context& ctx, uint64_t voxels, uint64_t lane_voxels = kVoxelLaneVoxels);

// Workgroup size of a quad kernel whose lanes each keep their own sums or write their own voxels
// (voxel loss, residual map, the CGLS prepare and gather): `requested` if given, else one subgroup on a CPU device — which
// runs a workgroup on one thread and its invocations as coroutines between barriers (lavapipe,
// 41.5 M voxels, both voxel losses: 0.41 s in groups of 256, 0.19-0.21 s in groups of 8) — and
// TFM_VOXEL_WORKGROUP elsewhere. Throws std::invalid_argument naming `kernel` unless the size is
// a multiple of the subgroup size (quad_segments.glsl strides by it) within the device's limit.
uint32_t lane_workgroup_size(const Context& ctx, uint32_t requested, const char* kernel);
// Workgroups of `workgroup_size` for one dispatch over `voxels`: voxel_groups() at
// TFM_VOXEL_WORKGROUP; smaller groups get lanes of about `lane_voxels` voxels, but at least
// kPrivateMinGroups groups (lanes of `min_lane_voxels` or more) so that every core has work.
inline constexpr uint64_t kLaneVoxels = 4096;
uint32_t lane_groups(const Context& ctx, uint32_t workgroup_size, uint64_t voxels, uint64_t lane_voxels = kLaneVoxels,
                     uint64_t min_lane_voxels = 64);

// Kernels that read a chunk's voxels in quads, as RGBA32F texels (the assembly, its read bound,
// the voxel loss, the residual map, the CGLS gather), dispatch once per range of at most
// `range_quads` quads: `requested` if given (a multiple of 64, else std::invalid_argument naming
// `kernel`), else the device's maxTexelBufferElements rounded down to 64, so ranges start at
// multiples of 1024 bytes (every device's minTexelBufferOffsetAlignment is at most 256).
uint64_t texel_range_quads(const Context& ctx, uint64_t requested, const char* kernel);
// The same for kernels that see a voxel as one texel (an RGBA vector per voxel, or a field viewed
// from up to 64 texels before the range to meet the offset alignment): ranges of at most
// maxTexelBufferElements - 64 voxels; a `requested` beyond that also throws.
uint64_t voxel_texel_range_quads(const Context& ctx, uint64_t requested, const char* kernel);
struct QuadRange {
  size_t chunk = 0;
  uint64_t first = 0, voxels = 0;  // within the chunk
  // The texel view over the range's quads, from byte first * (bytes a voxel); a range of fewer
  // than 4 voxels has no quads, and its view is one voxel that is never read.
  VkFormat format = VK_FORMAT_R32G32B32A32_SFLOAT;
  uint64_t bytes = 0;
};
// The ranges of every chunk of `field`, in order (views in the field's format); of chunks of the
// given sizes and format.
std::vector<QuadRange> quad_ranges(const DeviceField& field, uint64_t range_quads);
std::vector<QuadRange> quad_ranges(std::span<const uint64_t> chunk_voxels, uint64_t range_quads,
                                   FieldFormat format = FieldFormat::Float32);
// The view of range `r`'s quads of `field`, in the field's format (a range of fewer than 4 voxels:
// one voxel, never read).
Binding quad_texels(const DeviceField& field, const QuadRange& r);
// The view of chunk `c` of `field` as one texel a voxel in its format (the kernels read a range's
// last voxel_count % 4 voxels through it, by their index in the chunk).
Binding voxel_texels(const DeviceField& field, size_t c);

// A host's 3D image read in place by the assembly and the residual map (recording path): a 3D
// view of mip 0, layer 0
// in R32_SFLOAT, R16_SFLOAT, R16_UNORM or R8_UNORM (a texel fetch gives the float the buffer
// formats give), the layout it is in while the work runs, its extent (at most 2^32 voxels).
struct ImageFieldView {
  VkImageView view = VK_NULL_HANDLE;
  VkImageLayout layout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
  VkExtent3D extent{0, 0, 0};  // the image's, which Vulkan cannot tell from a view: the host's word
  // The view's format: one of field_format_of()'s (R32_SFLOAT, R16_SFLOAT, R16_UNORM, R8_UNORM).
  // Required: any other format (a colour volume's RGBA8, an integer format) would read as some
  // other number, silently or as undefined behaviour.
  VkFormat format = VK_FORMAT_UNDEFINED;
};

// The TFM_FIELD_IMAGE variant of a voxel-pair kernel: its four field bindings (the voxels and
// the quads of both fields) hold sampled images.
void bind_fields_as_images(PipelineDesc& desc, std::initializer_list<uint32_t> field_bindings);

// Throws std::invalid_argument (naming `kernel`) unless the image has a view and a field format.
void check_image_field(const ImageFieldView& field, const char* kernel);
// Throws std::invalid_argument (naming `kernel`) unless both images have views of a field format
// and one extent of 1 to 2^32 - 1 voxels; returns the voxel count.
uint64_t check_image_pair(const ImageFieldView& ref, const ImageFieldView& opt, const char* kernel);

// Throws std::invalid_argument (naming `kernel`) unless the two fields have the same voxel count
// and chunking.
void check_voxel_pair(const DeviceField& ref, const DeviceField& opt, const char* kernel);

// Decodes `slots` 32.32 fixed-point accumulators read back as 2*slots uint32 words.
std::vector<double> decode_fixed_point(const std::vector<uint32_t>& words);

}  // namespace tfm
