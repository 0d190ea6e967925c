// The field-to-TF mapping of DESIGN.md in GLSL, bit-identical to the host's (host/model/field_mapping.h).
#ifndef TFMATCH_TF_COMMON_GLSL
#define TFMATCH_TF_COMMON_GLSL

// "No data" (DESIGN.md): NaN and, as no range maps them, ±Inf (an overflowed scale factor, a
// division by zero upstream): an exponent of all ones. An integer test, so no compiler setting
// that assumes finite floats can drop it. Host mirror: no_data() in host/model/field_mapping.h.
bool no_data(float v) { return (floatBitsToUint(v) & 0x7f800000u) == 0x7f800000u; }
// no_data() of four values at once, without a branch per value (the renderer's eight corners).
bvec4 no_data4(vec4 v) { return equal(floatBitsToUint(v) & uvec4(0x7f800000u), uvec4(0x7f800000u)); }

// j = min(floor(x), n-2), w = x - j for a TF coordinate x in [0, n-1]; also splits a coordinate
// stored by sparse_prepare (TFM_NO_DATA, negative, gives false). `precise` forbids fused or
// reordered arithmetic, so j and w are bit-identical to the same IEEE float32 operations on the
// host.
bool split_coordinate(float x, uint n, out uint j, out float w) {
  if (!(x >= 0.0)) { j = 0u; w = 0.0; return false; }
  float jf = min(floor(x), float(n - 2u));
  j = uint(jf);
  precise float wf = x - jf;
  w = wf;
  return true;
}

// Node-aligned TF coordinate of a field value: x = clamp((v - lo) * scale, 0, n-1), then
// split_coordinate. Returns false for no data (NaN, ±Inf).
bool tf_coordinate(float v, float lo, float scale, uint n, out uint j, out float w) {
  if (no_data(v)) { j = 0u; w = 0.0; return false; }
  precise float x = clamp((v - lo) * scale, 0.0, float(n - 1u));
  return split_coordinate(x, n, j, w);
}

#endif
