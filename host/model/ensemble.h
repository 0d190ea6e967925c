// Ensembles: one variable on one grid with a member axis (DESIGN.md "Ensembles and correlation
// fields"), held member-major as the correlation kernels read them (kernels/correlation.h).
// Files: host/io/ensemble_io.h; a synthetic one: host/model/synthetic_ensemble.h.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "tfmatch/model/correlation_measure.h"
#include "tfmatch/model/volume.h"

namespace tfm {

struct Ensemble {
  Volume grid;                            // dims, spacing, origin, axes and name; no values
  uint32_t member_count = 0;
  std::vector<float> values;              // member m's voxel v at m * voxel_count + v; NaN = no data
  std::vector<std::string> member_names;  // where each member came from, for messages

  uint64_t voxel_count() const { return grid.voxel_count(); }
  EnsembleView view() const { return {values.data(), member_count, voxel_count()}; }
  // One member as a volume on the ensemble's grid.
  Volume member(uint32_t m) const;
};

}  // namespace tfm
