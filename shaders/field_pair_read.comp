// Reads two fields exactly as the normal-equation assembly does, and nothing more: the device's
// speed at the assembly's own loads, the bound `tfmatch bench` compares the assembly with (a
// buffer copy is no such bound: NVIDIA's vkCmdCopyBuffer reached 206-421 GB/s on an H100 whose
// memory does about 3 TB/s).
//
// Same access pattern as shaders/assemble_normal_equations.comp: lanes on consecutive quads in
// their subgroup's segments (quad_segments.glsl), one RGBA32F texel of each field's uniform texel
// buffer per lane and step, and invocation 0 reads the range's last count % 4 voxels from the
// storage buffers. The bits of every value are summed as integers
// (modulo 2^32), one sum per field, so no load can be dropped; each lane adds its two sums to the
// result once. Integer sums are exact and independent of order: the CPU reference
// (field_pair_bit_sums) checks that every voxel was read, and read once.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#define TFM_WANT_READ_BOUND_PUSH
#include "read_bound_layout.h"
#include "quad_segments.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;

layout(std430, binding = TFM_READ_BINDING_REF_FIELD) readonly buffer RefField { float ref_field[]; };
layout(std430, binding = TFM_READ_BINDING_OPT_FIELD) readonly buffer OptField { float opt_field[]; };
layout(binding = TFM_READ_BINDING_REF_QUADS) uniform samplerBuffer ref_quads;
layout(binding = TFM_READ_BINDING_OPT_QUADS) uniform samplerBuffer opt_quads;
layout(std430, binding = TFM_READ_BINDING_RESULT) buffer Result { uint result[]; };

void main() {
  uvec4 ref_sum = uvec4(0u), opt_sum = uvec4(0u);
  const uint quads = pc.voxel_count / 4u;
  TFM_FOR_EACH_QUAD(q, quads) {
    ref_sum += floatBitsToUint(texelFetch(ref_quads, int(q)));
    opt_sum += floatBitsToUint(texelFetch(opt_quads, int(q)));
  }
  uint r = ref_sum.x + ref_sum.y + ref_sum.z + ref_sum.w;
  uint o = opt_sum.x + opt_sum.y + opt_sum.z + opt_sum.w;
  if (gl_GlobalInvocationID.x == 0u)
    for (uint i = pc.first_voxel + 4u * quads; i < pc.first_voxel + pc.voxel_count; ++i) {
      r += floatBitsToUint(ref_field[i]);
      o += floatBitsToUint(opt_field[i]);
    }
  if (r != 0u) atomicAdd(result[0], r);
  if (o != 0u) atomicAdd(result[1], o);
}
