// The least size a classic-format (CDF-1, CDF-2, CDF-5) NetCDF file must have, from its header as
// netCDF-C reports it: netCDF-C reads a truncated classic file without complaint (the missing
// bytes read as zeros), so the reader checks the real size against this first.
#pragma once

#include <cstdint>

namespace tfm {

// Exact header size plus every variable's data without alignment padding (a lower bound of the
// real size). `format` is what nc_inq_format returned. Returns 0 for non-classic formats or when
// netCDF-C cannot answer.
uint64_t netcdf_classic_minimum_size(int ncid, int format);

}  // namespace tfm
