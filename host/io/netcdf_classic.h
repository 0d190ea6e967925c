// What tfmatch checks of a classic-format (CDF-1, CDF-2, CDF-5) NetCDF file around netCDF-C:
// before opening, that every count and length in the header fits in the file's bytes (netCDF-C
// allocates what the header says before reading it: a 2 KB file can ask for gigabytes); after
// opening, that the file is as long as its header describes (netCDF-C reads the missing bytes of
// a truncated file as zeros).
#pragma once

#include <cstdint>
#include <string>

#include "tfmatch/io/volume_formats.h"  // ByteReader

namespace tfm {

// Walks the header of a classic-format file of `size` bytes (layout of the NetCDF classic format
// specification: magic, numrecs, dim_list, gatt_list, var_list) and throws std::runtime_error
// "<name>: NetCDF header: ..." when a count of dimensions, attributes or variables, a name, or
// attribute values would need more bytes than the file has left. Files that do not start with
// the classic magic ("CDF" 1, 2 or 5) are left to netCDF-C. O(header size) reads.
void check_netcdf_classic_header(const ByteReader& read, uint64_t size, const std::string& name);

// Exact header size plus every variable's data without alignment padding (a lower bound of the
// real size). `format` is what nc_inq_format returned. Returns 0 for non-classic formats or when
// netCDF-C cannot answer, and kNetcdfSizeOverflow when the sizes pass 2^62 bytes (a header
// with 2^62 records, say): more than any file holds.
inline constexpr uint64_t kNetcdfSizeOverflow = UINT64_MAX;
uint64_t netcdf_classic_minimum_size(int ncid, int format);

}  // namespace tfm
