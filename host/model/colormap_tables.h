// The published colour tables of the built-in transfer functions (builtin_tf.h): sRGB control
// points (values in [0,1], t increasing from 0 to 1), meant to be joined by straight lines in sRGB.
#pragma once

#include <span>

#include "tfmatch/model/transfer_function.h"

namespace tfm {

std::span<const ColorStop> viridis_srgb_stops();        // matplotlib (van der Walt & Smith)
std::span<const ColorStop> inferno_srgb_stops();        // matplotlib (van der Walt & Smith)
std::span<const ColorStop> cool_warm_srgb_stops();      // Moreland 2009
std::span<const ColorStop> rdbu_reversed_srgb_stops();  // ColorBrewer RdBu, blue first
std::span<const ColorStop> grey_srgb_stops();           // black to white

}  // namespace tfm
