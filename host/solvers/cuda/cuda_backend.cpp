// Loading the CUDA solvers' plugin (cuda_backend.h). dlopen by hand: there is no lazy loading of
// a shared library's dependencies on Linux, and linking libcudart/libcusparse/libnvJitLink into
// the program cost every process ~24 ms of start-up for solvers few commands use.
#include "tfmatch/cuda/cuda_backend.h"

#include <dlfcn.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <stdexcept>

#ifndef TFMATCH_CUDA_INTERFACE_TAG
#error "TFMATCH_CUDA_INTERFACE_TAG (the hash of cuda_solvers.h) is set by host/CMakeLists.txt"
#endif

namespace tfm::cuda {

std::vector<std::string> plugin_candidates() {
  if (const char* chosen = std::getenv("TFMATCH_CUDA_PLUGIN"); chosen && *chosen) return {chosen};
  std::vector<std::string> candidates;
  std::error_code error;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", error);
  if (!error) {
    candidates.push_back((self.parent_path() / TFM_CUDA_PLUGIN_NAME).string());
    candidates.push_back((self.parent_path().parent_path() / TFM_CUDA_PLUGIN_LIBDIR / TFM_CUDA_PLUGIN_NAME).string());
  }
  candidates.emplace_back(TFM_CUDA_PLUGIN_INSTALLED);
  return candidates;
}

const Backend& load_backend(const std::string& path) {
  const std::string plugin = "the CUDA solvers' plugin " + path;
  // RTLD_LOCAL: the plugin's symbols (and CUDA's) never interpose on the program's.
  void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle) {
    const char* why = dlerror();
    throw std::runtime_error(plugin + " cannot be loaded: " + (why ? why : "unknown reason"));
  }
  const auto entry = reinterpret_cast<BackendEntry>(dlsym(handle, kBackendEntryName));
  if (!entry) {
    dlclose(handle);
    throw std::runtime_error(plugin + " has no entry point " + kBackendEntryName + ": not a tfmatch CUDA plugin");
  }
  const Backend* backend = entry(TFMATCH_CUDA_INTERFACE_TAG);
  if (!backend) {
    dlclose(handle);
    throw std::runtime_error(plugin + " was built from another version of cuda_solvers.h than this program (" +
                             TFMATCH_CUDA_INTERFACE_TAG + "): rebuild or reinstall both together");
  }
  return *backend;  // the handle stays open: the plugin lives as long as the process
}

const PluginStatus& plugin_status() {
  // The first caller's outcome, kept: a plugin is loaded at most once, a failure reported alike.
  static const PluginStatus status = [] {
    PluginStatus st;
    const std::vector<std::string> candidates = plugin_candidates();
    if (const char* chosen = std::getenv("TFMATCH_CUDA_PLUGIN"); chosen && *chosen) {
      st.path = candidates.front();  // that file, or an error naming it
    } else {
      std::string looked;
      for (const std::string& candidate : candidates) {
        if (st.path.empty() && access(candidate.c_str(), F_OK) == 0) st.path = candidate;
        looked += (looked.empty() ? "" : ", ") + candidate;
      }
      if (st.path.empty()) {
        st.error = "the CUDA solvers' plugin is not installed (looked for " + looked +
                   "; TFMATCH_CUDA_PLUGIN may name it)";
        return st;
      }
    }
    try {
      st.backend = &load_backend(st.path);
    } catch (const std::runtime_error& e) {
      st.error = e.what();
    }
    return st;
  }();
  return status;
}

const Backend& backend(const std::string& who) {
  const PluginStatus& status = plugin_status();
  if (!status.backend) throw std::runtime_error(who + ": " + status.error);
  return *status.backend;
}

}  // namespace tfm::cuda
