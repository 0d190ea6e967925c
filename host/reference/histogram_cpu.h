// CPU reference of the field-histogram kernel (shaders/field_histogram.comp): the same counters,
// each value binned with the shader's float32 arithmetic (histogram_counter()), counted in 64 bits.
#pragma once

#include <cstdint>
#include <span>

#include "tfmatch/model/field_histogram.h"

namespace tfm {

FieldHistogram field_histogram_cpu(std::span<const float> values, double lo, double hi, uint32_t bins);

}  // namespace tfm
