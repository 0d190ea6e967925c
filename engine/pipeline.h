// Compute pipelines built from the embedded SPIR-V, with storage-buffer or uniform-texel-buffer
// bindings, push constants and specialization constants.
#pragma once

#include <cstdint>
#include <initializer_list>
#include <map>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <tuple>
#include <vector>

#include <vulkan/vulkan_core.h>

namespace tfm {

class Context;

// What a binding of a pipeline holds. Texel buffers are read through the device's texture path:
// on CPU devices (lavapipe) a texel fetch is a vector gather where a storage-buffer load with a
// per-invocation index is a loop over the SIMD lanes, so the voxel-streaming kernels read their
// fields and TFs as texel buffers.
// A sampled image is read by texel fetch without a sampler (a host's 3D volume, recording path).
enum class DescriptorKind : uint8_t { StorageBuffer, UniformTexelBuffer, SampledImage };
VkDescriptorType descriptor_type(DescriptorKind kind);
// Kinds of `count` bindings: uniform texel buffers at the bindings `texels` names, storage buffers
// elsewhere (PipelineDesc::binding_kinds). Throws std::out_of_range for a binding past `count`.
std::vector<DescriptorKind> texel_binding_kinds(size_t count, std::initializer_list<uint32_t> texels);

struct PipelineDesc {
  std::string shader;                      // name, for messages and debug labels
  std::span<const uint32_t> spirv;         // SPIR-V words (shaders/shader_registry.h; must outlive the call)
  std::vector<uint32_t> binding_counts;    // descriptors per binding 0..n-1
  std::vector<DescriptorKind> binding_kinds;  // kind of binding i; empty or shorter: storage buffers
  uint32_t push_constant_bytes = 0;
  std::vector<uint32_t> specialization;    // value of constant_id i (32-bit each)
  uint32_t workgroup_size = 1;             // invocations per workgroup (for limit checks)
};

class ComputePipeline {
 public:
  // Throws std::runtime_error if the workgroup or push constants exceed the device's limits,
  // std::invalid_argument when no SPIR-V is given.
  ComputePipeline(Context& ctx, PipelineDesc desc);
  ~ComputePipeline();
  ComputePipeline(const ComputePipeline&) = delete;
  ComputePipeline& operator=(const ComputePipeline&) = delete;

  DescriptorKind binding_kind(uint32_t binding) const {
    return binding < desc_.binding_kinds.size() ? desc_.binding_kinds[binding] : DescriptorKind::StorageBuffer;
  }
  VkPipeline pipeline() const { return pipeline_; }
  VkPipelineLayout layout() const { return layout_; }
  VkDescriptorSetLayout set_layout() const { return set_layout_; }
  const PipelineDesc& desc() const { return desc_; }

 private:
  Context& ctx_;
  PipelineDesc desc_;
  VkShaderModule module_ = VK_NULL_HANDLE;
  VkDescriptorSetLayout set_layout_ = VK_NULL_HANDLE;
  VkPipelineLayout layout_ = VK_NULL_HANDLE;
  VkPipeline pipeline_ = VK_NULL_HANDLE;
};

// A pipeline shared by the kernels that ask for the same description (PipelineRegistry).
using SharedPipeline = std::shared_ptr<const ComputePipeline>;

// The compute pipelines of one context: a kernel asks for the pipeline of a description and gets
// the one made first for the same description (shader name, SPIR-V, bindings, push constants,
// specialization constants, workgroup), so kernels made again — each solver of `tfmatch solvers`,
// each fit in the viewer, the assembly a solver and the loss both need — do not have the driver
// create it again (lavapipe turns SPIR-V into its own code at every vkCreateComputePipelines,
// ~120 ms for the assembly, and its VkPipelineCache holds nothing; a GPU driver's cache makes a
// second creation cheap, not free). Pipelines live as long as the context. Thread-safe: a second
// asker for a pipeline being made waits for it; a creation that throws is not kept.
class PipelineRegistry {
 public:
  explicit PipelineRegistry(Context& ctx) : ctx_(ctx) {}
  PipelineRegistry(const PipelineRegistry&) = delete;
  PipelineRegistry& operator=(const PipelineRegistry&) = delete;
  SharedPipeline get(const PipelineDesc& desc);
  size_t size() const;  // descriptions asked for: pipelines made, being made, or whose creation failed

 private:
  using Key = std::tuple<std::string, const uint32_t*, size_t, std::vector<uint32_t>, std::vector<DescriptorKind>,
                         uint32_t, std::vector<uint32_t>, uint32_t>;
  struct Entry {
    std::once_flag made;
    SharedPipeline pipeline;
  };
  Context& ctx_;
  mutable std::mutex mutex_;
  std::map<Key, std::shared_ptr<Entry>> entries_;
};

// ctx.pipelines().get(desc): the context's pipeline for `desc`, made on first use.
SharedPipeline shared_pipeline(Context& ctx, const PipelineDesc& desc);

}  // namespace tfm
