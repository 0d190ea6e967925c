// Output files appear whole or not at all: written to a temporary name, then renamed.
#pragma once

#include <filesystem>
#include <string_view>

namespace tfm {

// Throws std::runtime_error naming `path` when it cannot be written.
void write_file_atomically(const std::filesystem::path& path, std::string_view bytes);

}  // namespace tfm
