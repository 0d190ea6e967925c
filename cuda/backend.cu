// The plugin's entry point: the Backend of cuda_solvers.h over this plugin's device objects and
// calls. The loader (host/solvers/cuda/cuda_backend.cpp) finds it by name with dlsym.
#include <stdexcept>

#include "tfmatch/cuda/cuda_common.cuh"

#ifndef TFMATCH_CUDA_INTERFACE_TAG
#error "TFMATCH_CUDA_INTERFACE_TAG (the hash of cuda_solvers.h) is set by cuda/CMakeLists.txt"
#endif

namespace tfm::cuda {
namespace {

// Objects passed back in were made here (by upload or build_system): anything else is refused.
template <class Made, class Interface>
const Made& made_here(const Interface& object, const char* what) {
  const Made* made = dynamic_cast<const Made*>(&object);
  if (!made) throw std::invalid_argument(std::string("CUDA backend: ") + what + " not made by this backend");
  return *made;
}

class RuntimeBackend final : public Backend {
 public:
  bool device_available(std::string* why) const override { return cuda::device_available(why); }
  void require_device(const std::string& who) const override { cuda::require_device(who); }
  std::string device_name() const override { return cuda::device_name(); }
  std::unique_ptr<DeviceFields> upload(std::span<const float> ref, std::span<const float> opt) const override {
    return std::make_unique<FieldsOnDevice>(ref, opt);
  }
  std::unique_ptr<DeviceSystem> build_system(const DeviceFields& fields, const FieldMapping& ref_map,
                                             const FieldMapping& opt_map,
                                             std::span<const float> ref_tf_rgba) const override {
    return std::make_unique<SystemOnDevice>(made_here<FieldsOnDevice>(fields, "fields"), ref_map, opt_map,
                                            ref_tf_rgba);
  }
  CusparseAssembly assemble_cusparse(const DeviceSystem& system) const override {
    return cuda::assemble_cusparse(made_here<SystemOnDevice>(system, "system"));
  }
  DirectAssembly assemble_direct(const DeviceFields& fields, const FieldMapping& ref_map, const FieldMapping& opt_map,
                                 std::span<const float> ref_tf_rgba) const override {
    return cuda::assemble_direct(made_here<FieldsOnDevice>(fields, "fields"), ref_map, opt_map, ref_tf_rgba);
  }
  CglsOutcome cgls(const DeviceSystem& system, const CglsParams& params) const override {
    return cuda::cgls(made_here<SystemOnDevice>(system, "system"), params);
  }
};

}  // namespace
}  // namespace tfm::cuda

// The only symbol the plugin exports (cuda/CMakeLists.txt hides the rest).
extern "C" __attribute__((visibility("default"))) const tfm::cuda::Backend* tfmatch_cuda_backend(
    const char* interface_tag) {
  static const tfm::cuda::RuntimeBackend backend;
  if (!interface_tag || std::string(interface_tag) != TFMATCH_CUDA_INTERFACE_TAG) return nullptr;
  return &backend;
}
