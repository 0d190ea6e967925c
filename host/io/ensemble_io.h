// Ensembles from files: a NetCDF variable with a member dimension, the GRIB messages of one
// parameter that differ in `number`, or a list of files holding one member each.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "ensemble.h"
#include "volume_io.h"

namespace tfm {

// The members of the array `spec` selects ("FILE[:VAR]", as load_volume) along its member axis:
// a NetCDF dimension named member(s), ensemble, realization or number (or options.member_dim),
// any other single leading dimension besides time, or GRIB's `number`. Throws
// std::runtime_error "<file>: ..." when the file has no member axis or ",member=N" is given.
Ensemble load_ensemble(const std::string& spec, const VolumeOptions& options = {});

// One member per file (each "FILE[:VAR]", loaded with `options`). Throws std::runtime_error
// naming the files when they are not on one grid.
Ensemble load_ensemble_members(const std::vector<std::string>& specs, const VolumeOptions& options = {});

// Expands shell patterns (*, ?, [...]) among `args` into the files they match, sorted; other
// arguments are kept as given. Throws std::runtime_error when a pattern matches no file.
std::vector<std::string> expand_member_patterns(const std::vector<std::string>& args);

}  // namespace tfm
