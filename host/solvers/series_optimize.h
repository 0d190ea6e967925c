// Many fields against one reference (`tfmatch optimize` with several --field): time steps of a
// simulation or members of an ensemble, each fitted against the one reference and its TF — one TF
// per field — or, with a shared TF, one TF fitted to all of them jointly. The fields are loaded
// one at a time, so memory holds the reference and one field.
//
// The shared fit minimizes the sum over fields of each field's voxel least squares: the systems
// of the fields are assembled one by one and their exact 32.32 totals added as integers, so the
// summed system has the bits one assembly over all voxels would have, whatever the order or
// count of fields; it is solved once (normal-equations or qp, which work from the system alone).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tfmatch/solvers/optimize.h"
#include "tfmatch/solvers/streamed_optimize.h"

namespace tfm {

// field_range: for per-field fits each field's range (default its finite min/max); for the shared
// fit the one range all fields map through (default the union of their finite min/max: one pass
// over the fields).
struct SeriesRequest : FitSettings {
  const Volume* ref = nullptr;            // unless streamed
  bool shared_tf = false;
  // The fields: `field_count` of them, field i loaded by load_field(i) when needed (on the grid
  // of `ref`, else the run stops naming it). Called once per field, twice for a shared fit
  // without a field range.
  size_t field_count = 0;
  std::function<Volume(size_t index)> load_field;
  // Streamed (streamed_optimize.h; normal-equations and qp): the reference and field i opened as
  // slab readers each time they are read, instead of `ref` and load_field, so that memory does not
  // grow with the volumes. Per-field fits are run_optimize_streamed's; the shared fit sums the
  // fields' exact totals as the loaded one does (the same bits).
  std::function<std::unique_ptr<VolumeSlabReader>()> open_ref_slabs;
  std::function<std::unique_ptr<VolumeSlabReader>(size_t index)> open_field_slabs;
  uint64_t slab_voxels = 0;               // voxels read per slab; 0: kDefaultSlabVoxels
  bool streamed() const { return bool(open_ref_slabs); }
};

struct SeriesFieldResult {
  std::string name;                       // the loaded volume's name
  FieldRange field_range;                 // its own range (per-field fits) or the shared one
  TransferFunction tf;                    // its TF (per-field fits; the shared TF otherwise)
  VoxelLoss before, after;                // with the reference TF / with its fitted TF
  std::vector<std::string> warnings;
};

struct SeriesResult {
  std::vector<SeriesFieldResult> fields;  // in the order given
  bool shared_tf = false;
  TransferFunction tf;                    // the shared TF (shared fit only)
  FieldRange ref_range;
  std::string solver, device;
  std::vector<std::string> warnings;      // the shared fit's: ranges, the solver's
  std::vector<PhaseTime> phases;          // the shared fit's (per-field fits: none)
  Details details;                        // the shared fit's solver details
  VoxelLoss before, after;                // over all fields' voxels together
};

// Throws std::runtime_error for unusable input (no fields, grids that differ from the reference,
// naming the field; a shared fit with a solver that needs the fields themselves, or with voxel
// weights; the errors of run_optimize).
SeriesResult run_optimize_series(Context& ctx, const SeriesRequest& request);

// The solvers a shared fit can use (they work from the summed system alone).
bool solver_fits_shared(std::string_view solver);

}  // namespace tfm
