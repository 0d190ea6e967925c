// JSON of the solvers' results (the solver library itself has no JSON dependency): solver
// details, `tfmatch optimize`'s summary and `tfmatch solvers`' comparison.
#pragma once

#include "tfmatch/io/json.h"
#include "tfmatch/solvers/details.h"
#include "tfmatch/solvers/optimize.h"
#include "tfmatch/solvers/solver_comparison.h"

namespace tfm {

// Entries as JSON members (an object, sorted by name as nlohmann::json keeps them); integers
// stay integers, lists become arrays, nested details objects.
nlohmann::json to_json(const Details& details);
nlohmann::json to_json(const DetailValue& value);
// solver, device, voxel counts, ranges, voxel losses before and after, phases, warnings, details.
nlohmann::json to_json(const OptimizeResult& result);
// device, sizes, the reference solver and one row per solver (an error row holds only "error").
nlohmann::json to_json(const ComparisonResult& result);

}  // namespace tfm
