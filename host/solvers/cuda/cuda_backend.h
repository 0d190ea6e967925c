// Loading the CUDA solvers' plugin (libtfmatch_cuda.so, built by cuda/): the one place that
// opens it, on first use, so a program that never runs a CUDA solver never loads CUDA's
// libraries. Where it looks, first hit wins:
//   1. the file TFMATCH_CUDA_PLUGIN names, when set (and then only it);
//   2. beside the running program (the build tree: `tfmatch` and the plugin share build/);
//   3. <program>/../<libdir>/tfmatch/ (an installed tree moved elsewhere);
//   4. the install's <libdir>/tfmatch/ as configured.
#pragma once

#include <string>
#include <vector>

#include "tfmatch/cuda/cuda_solvers.h"

namespace tfm::cuda {

// The plugin this process uses, loaded on the first call: `path` where it was looked for and found
// (or the file TFMATCH_CUDA_PLUGIN names; empty when none was found), and either its Backend or
// the reason there is none (`error`, as backend() reports it after the caller's name).
struct PluginStatus {
  std::string path;
  const Backend* backend = nullptr;
  std::string error;
};
const PluginStatus& plugin_status();

// The plugin's Backend, loaded once per process. Throws std::runtime_error "<who>: ..." naming the
// plugin's path and what went wrong (not found: the places looked; not loadable: the loader's
// reason, e.g. a CUDA library missing; built from another cuda_solvers.h) — the same error on
// every call once a load failed.
const Backend& backend(const std::string& who);

// Where backend() looks (above), in order: the one file TFMATCH_CUDA_PLUGIN names, else the
// three places, of which backend() takes the first that exists.
std::vector<std::string> plugin_candidates();

// One load attempt of the plugin at `path`, uncached (backend() keeps the first one's result):
// std::runtime_error "the CUDA solvers' plugin <path> ..." when it fails. A loaded plugin stays
// loaded for the rest of the process.
const Backend& load_backend(const std::string& path);

}  // namespace tfm::cuda
