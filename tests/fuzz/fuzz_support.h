// What the fuzz targets of the library-backed readers share: a memory budget below libFuzzer's
// malloc limit (so that a header claiming gigabytes is refused by tfmatch's own check, which is
// what is under test), and loading every array a describer listed.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>

#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm::fuzz {

// tools/fuzz.sh runs with -malloc_limit_mb=1024 -rss_limit_mb=2048.
inline void limit_memory() { set_memory_budget(uint64_t(768) << 20, "fuzz target limit"); }

// Calls load(options) for the first arrays `info` lists as loadable, at time and member 0 and 1;
// errors the readers report are expected, crashes and sanitizer reports are findings.
template <class Load>
void load_each_array(const FileInfo& info, Load load);

// One input through a library-backed reader as `tfmatch info` and then loading do: describe(bytes)
// lists the arrays, load(bytes, options) reads each. The bytes are copied: netCDF-C and fmemopen
// want a writable pointer.
template <class Describe, class Load>
void describe_then_load(const uint8_t* data, size_t size, Describe describe, Load load) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  FileInfo info;
  try {
    info = describe(bytes);
  } catch (const std::runtime_error&) {
    return;
  }
  load_each_array(info, [&](const VolumeOptions& options) { load(bytes, options); });
}

template <class Load>
void load_each_array(const FileInfo& info, Load load) {
  size_t tried = 0;
  for (const ArrayInfo& a : info.arrays) {
    if (a.grid[0] == 0 || ++tried > 4) continue;
    for (uint64_t index : {0, 1}) {
      VolumeOptions options;
      options.variable = a.name;
      options.time_index = index;
      options.member_index = index;
      try {
        load(options);
      } catch (const std::runtime_error&) {
      }
    }
  }
}

}  // namespace tfm::fuzz
