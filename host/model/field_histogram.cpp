// A histogram as data (host/model/field_histogram.h).
#include "tfmatch/model/field_histogram.h"

namespace tfm {

uint64_t FieldHistogram::finite() const {
  uint64_t n = below + above;
  for (uint64_t c : bins) n += c;
  return n;
}

}  // namespace tfm
