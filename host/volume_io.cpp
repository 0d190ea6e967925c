// load_volume(): splits "path:VARIABLE", checks the file exists and dispatches by extension.
#include <algorithm>
#include <cctype>
#include <stdexcept>

#include "volume.h"

namespace tfm {

Volume load_volume(const std::string& spec, const VolumeOptions& options_in) {
  VolumeOptions options = options_in;
  std::filesystem::path path = spec;
  // "file.nc:VAR" selects a variable, unless the whole spec names an existing file.
  if (!std::filesystem::exists(path)) {
    auto colon = spec.rfind(':');
    if (colon != std::string::npos && colon > 0) {
      path = spec.substr(0, colon);
      if (options.variable.empty()) options.variable = spec.substr(colon + 1);
    }
  }
  if (!std::filesystem::exists(path)) throw std::runtime_error(path.string() + ": no such file");
  if (std::filesystem::is_directory(path)) throw std::runtime_error(path.string() + ": is a directory, not a volume file");
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  Volume v;
  if (ext == ".raw") v = read_raw_volume(path, options);
  else if (ext == ".dat") v = read_dat_volume(path, options);
  else
    throw std::runtime_error(path.string() + ": unknown volume format '" + ext +
                             "' (supported: .raw, .dat)");
  if (v.voxel_count() == 0) throw std::runtime_error(path.string() + ": the volume is empty");
  if (!options.variable.empty() && v.name.find(':') == std::string::npos) v.name += ":" + options.variable;
  return v;
}

}  // namespace tfm
