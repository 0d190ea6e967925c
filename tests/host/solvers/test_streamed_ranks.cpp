// The streamed optimize split over ranks (host/solvers/streamed_optimize.h with Ranks,
// host/model/ranks.h), the ranks being threads of this process (tests/support/thread_ranks.h),
// each with its own device: every rank count gives every rank the one-process result bit for
// bit (TF, ranges, losses, the box-filtered previews), also a rank with no slices; a rank whose
// file fails makes every rank throw the same RankFailure. The same over MPI processes is
// tests/tools/test_mpi_cli.cpp.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "formats_test_util.h"
#include "slab_test_files.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/ranks.h"
#include "tfmatch/model/synthetic.h"
#include "tfmatch/solvers/streamed_optimize.h"
#include "thread_ranks.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using formats_test::TempDir;

TEST(RankSlices, CoverTheSlicesInOrderOnWholeBlocks) {
  for (uint64_t slices : {1u, 7u, 23u, 100u})
    for (int size : {1, 2, 3, 4, 9})
      for (uint64_t block : {1u, 3u, 6u}) {
        uint64_t next = 0;
        for (int r = 0; r < size; ++r) {
          const auto [first, end] = rank_slices(slices, r, size, block);
          EXPECT_EQ(first, next) << slices << " slices, rank " << r << " of " << size << ", blocks of " << block;
          EXPECT_LE(first, end);
          if (first != end && end != slices) EXPECT_EQ((end - first) % block, 0u);
          next = end;
        }
        EXPECT_EQ(next, slices);
      }
  EXPECT_THROW(rank_slices(10, 2, 2), std::invalid_argument);
}

bool same_bits(const Volume& a, const Volume& b) {
  return a.dims == b.dims && a.values.size() == b.values.size() &&
         std::memcmp(a.values.data(), b.values.data(), a.values.size() * sizeof(float)) == 0;
}

// A pair of awkward size streamed from raw files in slabs of 2 slices, with previews of boxes of
// 6 voxels (so ranks take whole 6-slice blocks and boxes straddle slabs).
struct RankedProblem {
  RankedProblem()
      : ref_file(slab_test::write_raw(dir.path(), "ref", slab_test::test_field({37, 29, 23}, 0)).string()),
        opt_file(slab_test::write_raw(dir.path(), "opt", slab_test::test_field({37, 29, 23}, 5)).string()) {}
  StreamedOptimizeRequest request(VolumeSlabReader& ref, VolumeSlabReader& opt, Ranks* ranks) const {
    StreamedOptimizeRequest req;
    req.ref = &ref;
    req.field = &opt;
    req.ref_tf = demo_transfer_function(16);
    req.ref_tf.range.reset();  // a range pass over the data
    req.tf_size = 48;
    req.settings.solve.smooth = 0.01;
    req.slab_voxels = 37 * 29 * 2;
    req.max_chunk_voxels = 2048;
    req.preview_voxels = 200;
    req.ranks = ranks;
    return req;
  }
  TempDir dir;
  std::string ref_file, opt_file;
};

// Each rank's own device, made one after the other before the ranks start.
std::vector<std::unique_ptr<Context>> devices(int ranks) {
  std::vector<std::unique_ptr<Context>> out;
  ContextOptions options;
  options.validation = test::context().validation_enabled();
  for (int r = 0; r < ranks; ++r) out.push_back(Context::create(options));
  return out;
}

TEST(StreamedOptimizeRanks, EveryRankCountGivesEveryRankTheOneProcessBits) {
  const RankedProblem p;
  auto ref = open_volume_slabs(p.ref_file), opt = open_volume_slabs(p.opt_file);
  const StreamedOptimizeResult one = run_optimize_streamed(test::context(), p.request(*ref, *opt, nullptr));
  ASSERT_EQ(one.preview_factor, 6u);
  ASSERT_EQ(one.slab_slices, 2u);
  // 23 slices in blocks of 6: 4 blocks, so at 5 ranks the last one has no slice.
  for (int size : {2, 3, 4, 5}) {
    SCOPED_TRACE(std::to_string(size) + " ranks");
    auto contexts = devices(size);
    std::vector<StreamedOptimizeResult> results(static_cast<size_t>(size));
    std::vector<std::string> errors(static_cast<size_t>(size));
    test::ThreadRanks::run(size, [&](test::ThreadRanks& ranks) {
      const size_t r = size_t(ranks.rank());
      try {
        auto rs = open_volume_slabs(p.ref_file), os = open_volume_slabs(p.opt_file);
        results[r] = run_optimize_streamed(*contexts[r], p.request(*rs, *os, &ranks));
      } catch (const std::exception& e) {
        errors[r] = e.what();
      }
    });
    for (int r = 0; r < size; ++r) {
      SCOPED_TRACE("rank " + std::to_string(r));
      ASSERT_EQ(errors[size_t(r)], "");
      const StreamedOptimizeResult& s = results[size_t(r)];
      ASSERT_EQ(s.result.tf.size(), one.result.tf.size());
      for (size_t j = 0; j < one.result.tf.size(); ++j)
        for (int c = 0; c < 4; ++c) ASSERT_EQ(s.result.tf.rgba[j][c], one.result.tf.rgba[j][c]) << "entry " << j;
      EXPECT_EQ(s.result.ref_range.lo, one.result.ref_range.lo);
      EXPECT_EQ(s.result.ref_range.hi, one.result.ref_range.hi);
      EXPECT_EQ(s.result.field_range.lo, one.result.field_range.lo);
      EXPECT_EQ(s.result.field_range.hi, one.result.field_range.hi);
      EXPECT_EQ(s.result.before.rmse(), one.result.before.rmse());
      EXPECT_EQ(s.result.after.rmse(), one.result.after.rmse());
      EXPECT_TRUE(same_bits(s.ref_preview, one.ref_preview));
      EXPECT_TRUE(same_bits(s.field_preview, one.field_preview));
      if (size == 5 && r == 4) EXPECT_EQ(s.first_slice, s.end_slice) << "the fifth rank has no slice";
    }
    // The ranks' shares tile the slices in order, on whole preview boxes.
    for (int r = 0; r + 1 < size; ++r) EXPECT_EQ(results[size_t(r)].end_slice, results[size_t(r) + 1].first_slice);
    EXPECT_EQ(results.back().end_slice, 23u);
  }
}

// A reader that fails when it reads, as a file cut short after it was opened does.
class BrokenReader final : public VolumeSlabReader {
 public:
  explicit BrokenReader(const Volume& grid) { grid_ = empty_like(grid); }
  void read_slices(uint64_t, uint64_t, float*) override {
    throw std::runtime_error("broken_37x29x23_float32.raw: expected 4 bytes more, the file ends");
  }
};

// Runs the streamed optimize on `size` ranks (threads), each with the readers `open(rank)` gives,
// and returns what each caught: the failing rank and message of its RankFailure (-1 and "not a
// RankFailure: ..." for any other exception).
using Readers = std::pair<std::unique_ptr<VolumeSlabReader>, std::unique_ptr<VolumeSlabReader>>;
std::vector<std::pair<int, std::string>> failures_of_ranks(const RankedProblem& p, int size,
                                                           const std::function<Readers(size_t)>& open) {
  auto contexts = devices(size);
  std::vector<std::pair<int, std::string>> caught(size_t(size), {-1, ""});
  test::ThreadRanks::run(size, [&](test::ThreadRanks& ranks) {
    const size_t r = size_t(ranks.rank());
    Readers readers = open(r);
    try {
      run_optimize_streamed(*contexts[r], p.request(*readers.first, *readers.second, &ranks));
    } catch (const RankFailure& f) {
      caught[r] = {f.failing_rank(), f.what()};
    } catch (const std::exception& e) {
      caught[r] = {-1, std::string("not a RankFailure: ") + e.what()};
    }
  });
  return caught;
}

TEST(StreamedOptimizeRanks, AFailingRankStopsEveryRankWithItsMessage) {
  const RankedProblem p;
  const auto caught = failures_of_ranks(p, 3, [&](size_t r) {
    Readers readers{open_volume_slabs(p.ref_file), open_volume_slabs(p.opt_file)};
    if (r == 1) readers.second = std::make_unique<BrokenReader>(readers.second->grid());
    return readers;
  });
  for (size_t r = 0; r < caught.size(); ++r) {
    EXPECT_EQ(caught[r].first, 1) << "rank " << r;
    EXPECT_EQ(caught[r].second, "rank 1: broken_37x29x23_float32.raw: expected 4 bytes more, the file ends")
        << "rank " << r;
  }
}

// A rank that reads another grid (a node with another copy of the files) stops every rank before
// any work, with both grids in the message, instead of adding its share of another field.
TEST(StreamedOptimizeRanks, ARankReadingAnotherGridStopsEveryRank) {
  const RankedProblem p;
  TempDir other;
  const std::string ref2 = slab_test::write_raw(other.path(), "ref", slab_test::test_field({37, 29, 24}, 0)).string();
  const std::string opt2 = slab_test::write_raw(other.path(), "opt", slab_test::test_field({37, 29, 24}, 5)).string();
  const auto caught = failures_of_ranks(p, 3, [&](size_t r) {
    return Readers{open_volume_slabs(r == 2 ? ref2 : p.ref_file), open_volume_slabs(r == 2 ? opt2 : p.opt_file)};
  });
  for (size_t r = 0; r < caught.size(); ++r) {
    EXPECT_EQ(caught[r].first, 2) << "rank " << r;
    EXPECT_NE(caught[r].second.find("rank 2: "), std::string::npos) << caught[r].second;
    EXPECT_NE(caught[r].second.find("reads a grid 37x29x24 (spacing 1, 1, 1; origin 0, 0, 0) where rank 0 reads "
                                    "37x29x23"),
              std::string::npos)
        << caught[r].second;
  }
  // The same grid everywhere passes, with one rank or several.
  Volume grid = slab_test::test_field({3, 4, 5}, 0);
  EXPECT_NO_THROW(require_same_grid_on_every_rank(single_rank(), grid, "x"));
  test::ThreadRanks::run(2, [&](test::ThreadRanks& ranks) {
    Volume mine = grid;
    mine.origin[0] = ranks.rank() == 0 ? -0.0 : 0.0;  // equal values
    EXPECT_NO_THROW(require_same_grid_on_every_rank(ranks, mine, "x", 7));
  });
}

}  // namespace
}  // namespace tfm
