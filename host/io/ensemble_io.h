// Ensembles from files: a NetCDF variable with a member dimension, the GRIB messages of one
// parameter that differ in `number`, or a list of files holding one member each.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/ensemble.h"

namespace tfm {

// The members of the array `spec` selects ("FILE[:VAR]", as load_volume) along its member axis:
// a NetCDF dimension named member(s), ensemble, realization or number (or options.member_dim),
// any other single leading dimension besides time, or GRIB's `number`. Throws
// std::runtime_error "<file>: ..." when the file has no member axis or ",member=N" is given.
Ensemble load_ensemble(const std::string& spec, const VolumeOptions& options = {});

// One member per file (each "FILE[:VAR]", loaded with `options`). Throws std::runtime_error
// naming the files when they are not on one grid.
Ensemble load_ensemble_members(const std::vector<std::string>& specs, const VolumeOptions& options = {});

// The members of an ensemble as slab readers (host/model/volume_slabs.h), for a correlation read
// a slab of z-slices at a time: of the array `spec` selects (its member axis, as load_ensemble),
// or one per file of `specs`. Members of formats that do not stream (GRIB, NRRD, compressed VTI)
// are loaded whole behind the same interface. Throws as load_ensemble does, and std::runtime_error
// naming the files when the members are not on one grid. `name` is set to what messages call the
// ensemble. Raises this process's open-file limit to its hard limit (a reader holds its file open).
struct EnsembleSlabs {
  std::vector<std::unique_ptr<VolumeSlabReader>> members;
  std::vector<std::string> member_names;
  std::string name;
  const Volume& grid() const { return members.front()->grid(); }
  bool streams() const;  // every member is read from its file as asked
};
// With `streaming_only`, a member that cannot be read slab by slab makes the result empty (no
// members) instead of being loaded.
EnsembleSlabs open_ensemble_slabs(const std::string& spec, const VolumeOptions& options = {},
                                  bool streaming_only = false);
EnsembleSlabs open_ensemble_member_slabs(const std::vector<std::string>& specs, const VolumeOptions& options = {},
                                         bool streaming_only = false);

// The files a shell pattern (*, ?, [...]; glob(3)'s rules) matches, in natural order: runs of
// digits compare as numbers, so step2 comes before step10, as ParaView orders a file series (the
// shell orders them as text). Empty when nothing matches; throws std::runtime_error when a
// directory on the way cannot be read.
std::vector<std::string> match_files(const std::string& pattern);

// Expands shell patterns among `args` into the files they match (match_files); other arguments
// are kept as given. Throws std::runtime_error when a pattern matches no file.
std::vector<std::string> expand_member_patterns(const std::vector<std::string>& args);

}  // namespace tfm
