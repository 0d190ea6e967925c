// Pipeline caches kept on disk between runs, so a process finds its compute pipelines compiled
// by the previous one (the driver's compiler can take hundreds of milliseconds for tfmatch's
// kernels). One file per device identity and build of the shaders; a file that is missing,
// damaged or of another format is ignored with a note, never an error; files are replaced
// atomically, so processes running at the same time never read a half-written one.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace tfm {

// The directory for pipeline caches: $TFMATCH_PIPELINE_CACHE when set ("off" or "0": none, so
// nothing is read or written), else $XDG_CACHE_HOME/tfmatch/pipelines, else
// $HOME/.cache/tfmatch/pipelines; nullopt when disabled or no home is known.
std::optional<std::filesystem::path> pipeline_cache_directory();

// The file in `dir` for a device (Context::pipeline_cache_identity()) and a build of the shaders
// (shaders_fingerprint()).
std::filesystem::path pipeline_cache_path(const std::filesystem::path& dir, const std::string& device_identity,
                                          uint64_t shaders_fingerprint);

struct StoredPipelineCache {
  std::vector<uint8_t> data;  // the driver's cache data; empty when none was read
  std::string note;           // why a file that exists was not used; empty otherwise
};

// The cache data stored in `file`, checked for its format, length and checksum. Never throws.
StoredPipelineCache read_pipeline_cache(const std::filesystem::path& file);

// Stores `data` in `file` (creating its directory) through a temporary file renamed into place.
// Returns an empty string, or what went wrong (the caller notes it; a cache that cannot be
// written costs only time). Never throws.
std::string write_pipeline_cache(const std::filesystem::path& file, std::span<const uint8_t> data);

}  // namespace tfm
