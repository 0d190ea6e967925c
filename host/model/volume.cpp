// Grid checks of volumes.
#include "volume.h"

#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <string>

#ifdef __linux__
#include <sys/mman.h>
#endif

namespace tfm {

void reserve_field_values(std::vector<float>& values, size_t count) {
  values.reserve(count);
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  // Only whole huge pages can be huge: the advice goes to the capacity's 2 MiB-aligned interior
  // (a failure, e.g. without THP support, changes nothing but the speed).
  constexpr uintptr_t kHuge = uintptr_t(2) << 20;
  const uintptr_t begin = (reinterpret_cast<uintptr_t>(values.data()) + kHuge - 1) & ~(kHuge - 1);
  const uintptr_t end = reinterpret_cast<uintptr_t>(values.data() + values.capacity()) & ~(kHuge - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#endif
}

double axis_coordinate(const Volume& v, int axis, uint64_t i) {
  const auto& c = v.axes[axis].coordinates;
  if (i < c.size()) return c[i];
  return v.origin[axis] + double(i) * v.spacing[axis];
}

Volume empty_like(const Volume& like) {
  Volume v;
  v.dims = like.dims;
  v.spacing = like.spacing;
  v.origin = like.origin;
  v.axes = like.axes;
  v.name = like.name;
  return v;
}

void require_same_grid(const Volume& a, const Volume& b) {
  if (a.dims != b.dims) {
    std::ostringstream os;
    os << "fields are on different grids: " << a.name << " is " << a.dims[0] << "x" << a.dims[1] << "x"
       << a.dims[2] << ", " << b.name << " is " << b.dims[0] << "x" << b.dims[1] << "x" << b.dims[2];
    throw std::runtime_error(os.str());
  }
}

}  // namespace tfm
