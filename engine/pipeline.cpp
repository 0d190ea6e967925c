// Shader module, descriptor-set layout, pipeline layout and pipeline for one compute kernel.
#include "tfmatch/engine/pipeline.h"

#include <mutex>
#include <shared_mutex>
#include <span>
#include <stdexcept>

#include "tfmatch/engine/context.h"
#include "tfmatch/engine/vk_check.h"
#include "tfmatch/engine/vk_dispatch.h"
#include "tfmatch/model/phase_timer.h"

namespace tfm {

VkDescriptorType descriptor_type(DescriptorKind kind) {
  switch (kind) {
    case DescriptorKind::UniformTexelBuffer: return VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER;
    case DescriptorKind::SampledImage: return VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE;
    case DescriptorKind::StorageBuffer: break;
  }
  return VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
}

std::vector<DescriptorKind> texel_binding_kinds(size_t count, std::initializer_list<uint32_t> texels) {
  std::vector<DescriptorKind> kinds(count, DescriptorKind::StorageBuffer);
  for (uint32_t b : texels) kinds.at(b) = DescriptorKind::UniformTexelBuffer;
  return kinds;
}

ComputePipeline::ComputePipeline(Context& ctx, PipelineDesc desc) : ctx_(ctx), desc_(std::move(desc)) {
  PhaseScope timing(Phase::Pipelines);
  const auto& limits = ctx.limits();
  if (desc_.workgroup_size > limits.maxComputeWorkGroupInvocations)
    throw std::runtime_error(desc_.shader + ": workgroup of " + std::to_string(desc_.workgroup_size) +
                             " invocations exceeds the device limit " +
                             std::to_string(limits.maxComputeWorkGroupInvocations));
  if (desc_.push_constant_bytes > limits.maxPushConstantsSize)
    throw std::runtime_error(desc_.shader + ": push constants exceed the device limit");
  const auto& vk = ctx.vk();
  if (desc_.spirv.empty()) throw std::invalid_argument(desc_.shader + ": no SPIR-V given");
  const std::span<const uint32_t> code = desc_.spirv;
  VkShaderModuleCreateInfo module_info{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
  module_info.codeSize = code.size_bytes();
  module_info.pCode = code.data();
  VK_CHECK(vk.vkCreateShaderModule(ctx.device(), &module_info, nullptr, &module_));

  std::vector<VkDescriptorSetLayoutBinding> bindings;
  for (uint32_t i = 0; i < desc_.binding_counts.size(); ++i) {
    VkDescriptorSetLayoutBinding b{};
    b.binding = i;
    b.descriptorType = descriptor_type(binding_kind(i));
    b.descriptorCount = desc_.binding_counts[i];
    b.stageFlags = VK_SHADER_STAGE_COMPUTE_BIT;
    bindings.push_back(b);
  }
  VkDescriptorSetLayoutCreateInfo set_info{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
  set_info.bindingCount = static_cast<uint32_t>(bindings.size());
  set_info.pBindings = bindings.data();
  VK_CHECK(vk.vkCreateDescriptorSetLayout(ctx.device(), &set_info, nullptr, &set_layout_));

  VkPushConstantRange range{VK_SHADER_STAGE_COMPUTE_BIT, 0, desc_.push_constant_bytes};
  VkPipelineLayoutCreateInfo layout_info{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  layout_info.setLayoutCount = 1;
  layout_info.pSetLayouts = &set_layout_;
  layout_info.pushConstantRangeCount = desc_.push_constant_bytes ? 1 : 0;
  layout_info.pPushConstantRanges = &range;
  VK_CHECK(vk.vkCreatePipelineLayout(ctx.device(), &layout_info, nullptr, &layout_));

  std::vector<VkSpecializationMapEntry> entries;
  for (uint32_t i = 0; i < desc_.specialization.size(); ++i)
    entries.push_back({i, static_cast<uint32_t>(i * sizeof(uint32_t)), sizeof(uint32_t)});
  VkSpecializationInfo spec{};
  spec.mapEntryCount = static_cast<uint32_t>(entries.size());
  spec.pMapEntries = entries.data();
  spec.dataSize = desc_.specialization.size() * sizeof(uint32_t);
  spec.pData = desc_.specialization.data();

  VkComputePipelineCreateInfo info{VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO};
  info.stage.sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
  info.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
  info.stage.module = module_;
  info.stage.pName = "main";
  info.stage.pSpecializationInfo = entries.empty() ? nullptr : &spec;
  info.layout = layout_;
  {
    std::shared_lock lock(ctx.pipeline_cache_mutex());
    VK_CHECK(vk.vkCreateComputePipelines(ctx.device(), ctx.pipeline_cache(), 1, &info, nullptr, &pipeline_));
  }
  ctx.set_debug_name(VK_OBJECT_TYPE_PIPELINE, reinterpret_cast<uint64_t>(pipeline_), desc_.shader.c_str());
}

ComputePipeline::~ComputePipeline() {
  const auto& vk = ctx_.vk();
  vk.vkDestroyPipeline(ctx_.device(), pipeline_, nullptr);
  vk.vkDestroyPipelineLayout(ctx_.device(), layout_, nullptr);
  vk.vkDestroyDescriptorSetLayout(ctx_.device(), set_layout_, nullptr);
  vk.vkDestroyShaderModule(ctx_.device(), module_, nullptr);
}

SharedPipeline PipelineRegistry::get(const PipelineDesc& desc) {
  std::vector<DescriptorKind> kinds = desc.binding_kinds;
  kinds.resize(desc.binding_counts.size(), DescriptorKind::StorageBuffer);  // missing kinds are storage buffers
  Key key{desc.shader,         desc.spirv.data(),       desc.spirv.size(), desc.binding_counts, std::move(kinds),
          desc.push_constant_bytes, desc.specialization, desc.workgroup_size};
  std::shared_ptr<Entry> entry;
  {
    std::lock_guard lock(mutex_);
    std::shared_ptr<Entry>& slot = entries_[std::move(key)];
    if (!slot) slot = std::make_shared<Entry>();
    entry = slot;
  }
  // Outside the lock: other pipelines are made meanwhile; askers for this one wait here. A throw
  // leaves the flag unset, so the next asker tries again (and gets the error again).
  std::call_once(entry->made, [&] { entry->pipeline = std::make_shared<const ComputePipeline>(ctx_, desc); });
  return entry->pipeline;
}

size_t PipelineRegistry::size() const {
  std::lock_guard lock(mutex_);
  return entries_.size();
}

SharedPipeline shared_pipeline(Context& ctx, const PipelineDesc& desc) { return ctx.pipelines().get(desc); }

}  // namespace tfm
