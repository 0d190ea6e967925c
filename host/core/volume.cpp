// Grid checks of volumes.
#include "volume.h"

#include <sstream>
#include <stdexcept>
#include <string>

namespace tfm {

void require_same_grid(const Volume& a, const Volume& b) {
  if (a.dims != b.dims) {
    std::ostringstream os;
    os << "fields are on different grids: " << a.name << " is " << a.dims[0] << "x" << a.dims[1] << "x"
       << a.dims[2] << ", " << b.name << " is " << b.dims[0] << "x" << b.dims[1] << "x" << b.dims[2];
    throw std::runtime_error(os.str());
  }
}

}  // namespace tfm
