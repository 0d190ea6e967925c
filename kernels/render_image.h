// Wrapper of shaders/render_image.comp: one dispatch renders a band of image rows of one field
// from `view_count` cameras (gpu::RenderView, gpu::RenderPush of shaders/render_layout.h, packed
// from the camera model of host/model/camera.h by make_render_view and make_render_push below).
#pragma once

#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/kernels/voxel_pair.h"
#include "tfmatch/model/camera.h"
#include "tfmatch/shaders/render_layout.h"

namespace tfm {

class Context;

// The marching kernels (renderer, DiffDVR passes) read the field's chunks and the TF as texel
// buffers (shaders/raymarch.glsl): the kinds of a pipeline's bindings with those two, and the
// bindings themselves.
std::vector<DescriptorKind> march_binding_kinds(size_t bindings, uint32_t field_binding, uint32_t tf_binding);
Binding march_field_binding(const DeviceField& field);
Binding march_tf_binding(const Buffer& tf, uint32_t tf_size);
// The pipeline of shaders/render_image.comp over a field of `field_chunks` buffers in `mode`
// (TFM_RENDER_MODE_*): the renderer's, and DiffDVR's forward pass, which stores (C, T) from the
// same march. Throws std::runtime_error, starting with `who`, when the chunks are 0 or more than
// the march binds.
PipelineDesc render_image_pipeline_desc(uint32_t field_chunks, uint32_t mode, const char* who);

// Throws std::runtime_error, starting with `who`, when one invocation of a marching kernel would
// run more loop iterations than the device lets it (Context::loop_iteration_limit: llvmpipe ends
// every loop of an invocation after 65535 in all, silently): `loops_per_sample` loop iterations a
// sample (several rays an invocation, or a ray whose samples and runs both loop) over up to
// push.max_steps samples, and `other_loops` iterations besides. The message names the smallest
// step that fits this volume. Does nothing on devices without such a limit.
void check_march_loops(const Context& ctx, const gpu::RenderPush& push, uint32_t loops_per_sample,
                       uint64_t other_loops, const char* who);
// Whether check_march_loops would let rays of `max_steps` samples through.
bool march_loops_fit(const Context& ctx, uint32_t max_steps, uint32_t loops_per_sample, uint64_t other_loops);

// The sample ranges [first_sample, sample_end) in which a kernel marching one ray an invocation,
// one loop iteration a sample and `other_loops` besides, records rays of push.max_steps samples:
// one range {0, 0} (whole rays) where they fit (march_loops_fit), else consecutive ranges of at
// most what one invocation may loop, in marching order (each dispatch resumes the rays where the
// one before left them; RenderPush's first_sample, sample_end). `max_part` > 0 caps the parts'
// samples on any device (tests: parts on short rays).
std::vector<std::pair<uint32_t, uint32_t>> march_parts(const Context& ctx, uint32_t max_steps, uint64_t other_loops,
                                                       uint32_t max_part = 0);

// Records render_image.comp's `pipeline` (forward or DiffDVR-state mode) for `push`'s rays in
// march_parts() (other loops 0; parts of at most `max_part` samples when > 0), with barriers
// between the parts.
void dispatch_forward_parts(const Context& ctx, CommandBatch& batch, const ComputePipeline& pipeline,
                            const std::vector<Binding>& bindings, gpu::RenderPush push, const Groups& groups,
                            uint32_t max_part = 0);

class RenderImageKernel {
 public:
  // `field_chunks`: chunks of the fields this pipeline renders (1..TFM_RENDER_MAX_CHUNKS);
  // `mode`: TFM_RENDER_MODE_FORWARD, or TFM_RENDER_MODE_INVERSE_CHECK (tests).
  // `max_part_samples` > 0: forward rays longer than that are marched in parts on any device
  // (tests; as on llvmpipe for rays longer than one invocation may loop).
  RenderImageKernel(Context& ctx, uint32_t field_chunks, uint32_t mode = TFM_RENDER_MODE_FORWARD,
                    uint32_t max_part_samples = 0);
  // The TFM_FIELD_IMAGE variant (forward mode): the field is a host's 3D image read in place
  // (record with an ImageFieldView), sampled with the same trilinear weights and bits.
  struct ImageField {};
  RenderImageKernel(Context& ctx, ImageField);
  uint32_t field_chunks() const { return chunks_; }
  // Records one dispatch over rows [row_begin, row_begin + row_count) of every view. `image`
  // holds width*height*views vec4, `stop` as many uints. On a device that limits an invocation's
  // loops (llvmpipe), rays longer than it allows take several dispatches with barriers between,
  // each resuming from the state the one before left in `image` and `stop`. Throws
  // std::invalid_argument when the field's chunk count or a buffer size does not fit, and
  // std::runtime_error (check_march_loops) when the inverse check's rays are too long for it.
  void record(CommandBatch& batch, const DeviceField& field, const Buffer& tf, const Buffer& views,
              gpu::RenderPush push, Buffer& image, Buffer& stop, uint32_t row_begin, uint32_t row_count) const;
  // The same from the image variant: `field`'s extent is the push block's grid.
  void record(CommandBatch& batch, const ImageFieldView& field, const Buffer& tf, const Buffer& views,
              gpu::RenderPush push, Buffer& image, Buffer& stop, uint32_t row_begin, uint32_t row_count) const;
  // record()'s checks of the field against this pipeline and the push block's grid alone
  // (std::invalid_argument), for callers that must refuse before they record anything.
  void check_field(const DeviceField& field, const gpu::RenderPush& push) const;
  void check_field(const ImageFieldView& field, const gpu::RenderPush& push) const;

 private:
  Context& ctx_;
  uint32_t chunks_;
  uint32_t rays_per_pixel_ = 1;  // 2 in TFM_RENDER_MODE_INVERSE_CHECK: the march, then its inversion
  uint32_t max_part_samples_ = 0;
  bool image_field_ = false;
  SharedPipeline pipeline_;
  void record_with(CommandBatch& batch, const Binding& field, const Buffer& tf, const Buffer& views,
                   gpu::RenderPush push, Buffer& image, Buffer& stop, uint32_t row_begin, uint32_t row_count) const;
};

// The GPU records of a camera frame and of one render dispatch (shaders/render_layout.h).
gpu::RenderView make_render_view(const CameraFrame& frame);
// Throws std::runtime_error when the grid has 2^32 voxels or more (32-bit voxel indices).
gpu::RenderPush make_render_push(const VolumeGeometry& geometry, const MarchConstants& march,
                                 const FieldMapping& mapping, const DeviceField& field, uint32_t width,
                                 uint32_t height, uint32_t view_count);
// The same for a field held in a 3D image (std::invalid_argument unless its extent is the grid).
gpu::RenderPush make_render_push(const VolumeGeometry& geometry, const MarchConstants& march,
                                 const FieldMapping& mapping, const ImageFieldView& field, uint32_t width,
                                 uint32_t height, uint32_t view_count);

}  // namespace tfm
