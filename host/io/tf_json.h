// tfmatch's own transfer-function file format (JSON), read and written atomically.
#pragma once

#include <filesystem>
#include <string>

#include "tfmatch/model/transfer_function.h"

namespace tfm {

// Reads {"rgba": [[r,g,b,a], ...], "range": [lo, hi]?}. Throws std::runtime_error naming the
// file for unreadable JSON, fewer than 2 entries, rows that are not 4 numbers, values outside
// [0,1] or not finite.
TransferFunction read_tf_json(const std::filesystem::path& path);
TransferFunction parse_tf_json(const std::string& text, const std::string& source_name);
// Writes atomically (temporary file, then rename), so a failure leaves no half-written file.
void write_tf_json(const std::filesystem::path& path, const TransferFunction& tf);
std::string tf_to_json(const TransferFunction& tf);

}  // namespace tfm
