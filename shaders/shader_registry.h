// The compute shaders compiled into tfmatch: SPIR-V words by shader name (the file stem of
// shaders/<name>.comp), embedded at build time by shaders/CMakeLists.txt.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace tfm {

// The SPIR-V of shaders/<name>.comp; throws std::logic_error for an unknown name.
std::span<const uint32_t> shader_spirv(std::string_view name);
// Every embedded shader's name, sorted.
std::vector<std::string> shader_names();
// A 64-bit hash (FNV-1a) of every embedded shader's name and words: changes with any shader or
// build of them, so a pipeline cache stored for one build is not offered to another.
uint64_t shaders_fingerprint();

}  // namespace tfm
