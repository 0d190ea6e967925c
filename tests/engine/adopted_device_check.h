// What every embedding host checks once it has its own device: tfmatch adopts it, moves data
// both ways and runs a real kernel on it, and lets go without destroying anything.
#pragma once

#include "tfmatch/engine/context.h"

namespace tfm::test {

// Adopts `external`, round-trips a buffer through staging, assembles the normal equations of a
// small field pair on the GPU and compares them with the double-precision CPU reference (gtest
// failures on any difference), then destroys the context.
void expect_adopted_device_computes(const ExternalDevice& external);

}  // namespace tfm::test
