// Compute pipelines built from the embedded SPIR-V, with storage-buffer bindings, push constants
// and specialization constants.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <vulkan/vulkan_core.h>

namespace tfm {

class Context;

struct PipelineDesc {
  std::string shader;                      // name, for messages and debug labels
  std::span<const uint32_t> spirv;         // SPIR-V words (shaders/shader_registry.h; must outlive the call)
  std::vector<uint32_t> binding_counts;    // descriptors per storage-buffer binding 0..n-1
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

}  // namespace tfm
