// This process as the only rank, and the split of z-slices over ranks (host/model/ranks.h).
#include "tfmatch/model/ranks.h"

#include <algorithm>

namespace tfm {

namespace {

class SingleRank final : public Ranks {
 public:
  int rank() const override { return 0; }
  int size() const override { return 1; }
  int local_rank() const override { return 0; }
  void agree(std::exception_ptr local) override {
    if (local) std::rethrow_exception(local);
  }
  void sum(std::span<uint64_t>) override {}
  void min(std::span<double>) override {}
  void max(std::span<double>) override {}
  void sum(std::span<double>) override {}
  std::vector<float> gather(std::span<const float> values) override { return {values.begin(), values.end()}; }
};

}  // namespace

Ranks& single_rank() {
  static SingleRank one;
  return one;
}

std::pair<uint64_t, uint64_t> rank_slices(uint64_t slices, int rank, int size, uint64_t block) {
  if (size < 1 || rank < 0 || rank >= size) throw std::invalid_argument("rank_slices: rank out of range");
  block = std::max<uint64_t>(1, block);
  const uint64_t blocks = (slices + block - 1) / block;
  const uint64_t r = uint64_t(rank), n = uint64_t(size);
  // The first blocks % size ranks take one block more.
  const uint64_t base = blocks / n, extra = blocks % n;
  const uint64_t first_block = r * base + std::min(r, extra);
  const uint64_t count = base + (r < extra ? 1 : 0);
  const uint64_t first = std::min(slices, first_block * block);
  return {first, std::min(slices, (first_block + count) * block)};
}

}  // namespace tfm
