// One member of an ensemble as a volume.
#include "tfmatch/model/ensemble.h"

#include <stdexcept>

namespace tfm {

Volume Ensemble::member(uint32_t m) const {
  if (m >= member_count) throw std::out_of_range("Ensemble::member: no member " + std::to_string(m));
  Volume v = empty_like(grid);
  v.name = member_names[m];
  const auto first = values.begin() + std::ptrdiff_t(uint64_t(m) * voxel_count());
  v.values.assign(first, first + std::ptrdiff_t(voxel_count()));
  return v;
}

}  // namespace tfm
