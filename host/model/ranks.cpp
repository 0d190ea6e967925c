// This process as the only rank, and the split of z-slices over ranks (host/model/ranks.h).
#include "tfmatch/model/ranks.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>

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

void require_same_grid_on_every_rank(Ranks& ranks, const Volume& grid, const std::string& what, uint64_t members) {
  if (ranks.size() == 1) return;
  ranks.agree(nullptr);
  constexpr size_t kValues = 10;
  const auto& d = grid.dims;
  const std::array<double, kValues> mine{double(d[0]),   double(d[1]),   double(d[2]),   grid.spacing[0],
                                         grid.spacing[1], grid.spacing[2], grid.origin[0], grid.origin[1],
                                         grid.origin[2],  double(members)};
  // Rank 0's values on every rank: a sum to which only rank 0 adds (x + 0 = x; ranks.h).
  std::array<double, kValues> first{};
  if (ranks.rank() == 0) first = mine;
  ranks.sum(first);
  bool same = true;
  for (size_t i = 0; i < kValues; ++i)
    same = same && (mine[i] == first[i] || (std::isnan(mine[i]) && std::isnan(first[i])));
  auto describe = [&](const std::array<double, kValues>& v) {
    std::ostringstream s;
    s << uint64_t(v[0]) << "x" << uint64_t(v[1]) << "x" << uint64_t(v[2]) << " (spacing " << v[3] << ", " << v[4]
      << ", " << v[5] << "; origin " << v[6] << ", " << v[7] << ", " << v[8] << ")";
    if (members) s << " of " << uint64_t(v[9]) << " members";
    return s.str();
  };
  std::exception_ptr differs;
  if (!same)
    differs = std::make_exception_ptr(std::runtime_error(
        what + ": this rank reads a grid " + describe(mine) + " where rank 0 reads " + describe(first) +
        ": every rank must read the same files (one file system every node sees, docs/mpi.md)"));
  ranks.agree(differs);
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
