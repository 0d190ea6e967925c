// Streamed optimization (host/solvers/streamed_optimize.h): the system assembled slab by slab
// from raw, NetCDF classic and uncompressed VTI files is bit for bit the one of the whole fields
// on the device, so the optimized TF is the non-streamed one; previews; what cannot stream.
#include <gtest/gtest.h>

#include <bit>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "formats_test_util.h"
#include "slab_test_files.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/synthetic.h"
#include "tfmatch/solvers/optimize.h"
#include "tfmatch/solvers/streamed_optimize.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using formats_test::TempDir;

class StreamedOptimizeTest : public test::GpuTest {};

void expect_same_system(const NormalEquations& a, const NormalEquations& b) {
  ASSERT_EQ(a.n, b.n);
  EXPECT_EQ(a.voxels, b.voxels);
  for (uint32_t j = 0; j < a.n; ++j) ASSERT_EQ(a.diag[j], b.diag[j]) << "M[" << j << "][" << j << "]";
  for (uint32_t j = 0; j + 1 < a.n; ++j) ASSERT_EQ(a.off[j], b.off[j]) << "M[" << j << "][" << j + 1 << "]";
  for (uint32_t j = 0; j < a.n; ++j)
    for (int c = 0; c < 4; ++c) ASSERT_EQ(a.rhs(j, c), b.rhs(j, c)) << "S^T b[" << j << "][" << c << "]";
  EXPECT_EQ(a.btb, b.btb);
}

// Two fields of awkward size (a slice of 37 x 29 voxels, 23 slices), their mappings for a
// reference TF of 32 entries and 13 optimized ones, and their system from the whole fields in one
// add().
struct SlabProblem {
  explicit SlabProblem(Context& ctx)
      : ref(slab_test::test_field({37, 29, 23}, 0)),
        opt(slab_test::test_field({37, 29, 23}, 4)),
        tf_buffer(upload_tf(ctx, demo_transfer_function(32), "ref tf")),
        ref_map(make_mapping(resolve_range(ref.values, nullptr, "ref"), 32)),
        opt_map(make_mapping(resolve_range(opt.values, nullptr, "opt"), 13)) {
    GpuNormalEquations gpu(ctx, 13);
    gpu.add(DeviceField(ctx, ref.values, "ref"), DeviceField(ctx, opt.values, "opt"), ref_map, opt_map, tf_buffer);
    whole = gpu.result();
  }
  Volume ref, opt;
  Buffer tf_buffer;
  FieldMapping ref_map, opt_map;
  NormalEquations whole;
};

// Slabs of 1, 5 and 23 slices and device chunks of 1024 voxels, so slabs split across chunks:
// the same bits as the whole fields in one add().
TEST_F(StreamedOptimizeTest, SystemStreamedFromEachFormatIsBitIdentical) {
  TempDir dir;
  const SlabProblem p(ctx());
  const Volume& ref = p.ref;
  const Volume& opt = p.opt;
  ASSERT_GT(p.whole.voxels, 0u);
  const std::vector<std::pair<std::string, std::string>> files{
      {slab_test::write_raw(dir.path(), "ref", ref).string(), slab_test::write_raw(dir.path(), "opt", opt).string()},
      {slab_test::write_netcdf(dir.path(), "ref", ref).string() + ":T,time=1",
       slab_test::write_netcdf(dir.path(), "opt", opt).string() + ":T,time=1"},
      {slab_test::write_vti_file(dir.path(), "ref", ref, false).string(),
       slab_test::write_vti_file(dir.path(), "opt", opt, false).string()},
      // mixed formats pair voxel by voxel too
      {slab_test::write_netcdf(dir.path(), "ref2", ref).string() + ":T,time=1",
       slab_test::write_vti_file(dir.path(), "opt2", opt, false).string() + ":other"}};
  for (const auto& [r, o] : files) {
    for (uint64_t slab : {1, 5, 23}) {
      SCOPED_TRACE(r + " / " + o + ", " + std::to_string(slab) + " slices per slab");
      auto rs = open_volume_slabs(r);
      auto os = open_volume_slabs(o);
      ASSERT_TRUE(rs && os);
      expect_same_system(assemble_streamed(ctx(), *rs, *os, p.ref_map, p.opt_map, p.tf_buffer, slab, 1024), p.whole);
    }
  }
}

// A field in memory read slab by slab that records the slabs asked for, and at `z_fail` throws
// a read error or (with `cancel`) requests cancellation, as a file cut short or Ctrl-C would.
class ScriptedSlabs final : public VolumeSlabReader {
 public:
  ScriptedSlabs(const Volume& v, uint64_t z_fail, bool cancel) : values_(v.values), z_fail_(z_fail), cancel_(cancel) {
    grid_ = v;
    grid_.values.clear();
  }
  void read_slices(uint64_t z0, uint64_t nz, float* out) override {
    check_slices(z0, nz);
    reads.push_back(z0);
    if (z0 == z_fail_ && cancel_) request_cancel(0);
    if (z0 == z_fail_ && !cancel_) throw std::runtime_error("scripted.raw: read failed at slice " + std::to_string(z0));
    std::copy_n(values_.begin() + std::ptrdiff_t(z0 * slice_voxels()), nz * slice_voxels(), out);
  }
  std::vector<uint64_t> reads;  // z0 of each read, in order (one thread at a time reads)

 private:
  std::vector<float> values_;
  uint64_t z_fail_;
  bool cancel_;
};

// The next slab is read on another thread while the device works on this one: slabs are still
// read once each in z order, and a read error or a cancellation in a later slab reaches the
// caller, after which nothing more is read.
TEST_F(StreamedOptimizeTest, ReadAheadKeepsOrderAndPassesOnErrorsAndCancellation) {
  const SlabProblem p(ctx());
  const Volume& ref = p.ref;
  const Volume& opt = p.opt;
  const FieldMapping& ref_map = p.ref_map;
  const FieldMapping& opt_map = p.opt_map;
  const Buffer& tf_buffer = p.tf_buffer;
  const std::vector<uint64_t> all{0, 5, 10, 15, 20}, to_ten{0, 5, 10};
  {
    ScriptedSlabs r(ref, 99, false), o(opt, 99, false);
    expect_same_system(assemble_streamed(ctx(), r, o, ref_map, opt_map, tf_buffer, 5), p.whole);
    EXPECT_EQ(r.reads, all);
    EXPECT_EQ(o.reads, all);
  }
  {
    ScriptedSlabs r(ref, 99, false), o(opt, 10, false);
    formats_test::expect_error([&] { assemble_streamed(ctx(), r, o, ref_map, opt_map, tf_buffer, 5); },
                               {"scripted.raw", "read failed at slice 10"});
    EXPECT_EQ(o.reads, to_ten);
  }
  {
    ScriptedSlabs r(ref, 10, true), o(opt, 99, false);
    EXPECT_THROW(assemble_streamed(ctx(), r, o, ref_map, opt_map, tf_buffer, 5), Cancelled);
    reset_cancel();
    EXPECT_EQ(r.reads, to_ten);
  }
}

// run_optimize_streamed gives run_optimize's TF, ranges and voxel RMSE, for both streaming
// solvers, a reference TF of another size (second system) and given ranges (one pass).
TEST_F(StreamedOptimizeTest, SameResultAsTheWholeFields) {
  TempDir dir;
  const Volume ref = slab_test::test_field({37, 29, 23}, 0);
  const Volume opt = slab_test::test_field({37, 29, 23}, 5);
  const auto ref_file = slab_test::write_raw(dir.path(), "ref", ref).string();
  const auto opt_file = slab_test::write_netcdf(dir.path(), "opt", opt).string() + ":T,time=1";
  const Volume ref_loaded = load_volume(ref_file), opt_loaded = load_volume(opt_file);
  for (const char* solver : {"normal-equations", "qp"}) {
    for (uint32_t ref_entries : {64u, 16u}) {
      for (bool given_ranges : {false, true}) {
        SCOPED_TRACE(std::string(solver) + ", " + std::to_string(ref_entries) + " entries" +
                     (given_ranges ? ", given ranges" : ""));
        OptimizeRequest req;
        req.ref = &ref_loaded;
        req.field = &opt_loaded;
        req.ref_tf = demo_transfer_function(ref_entries);
        req.ref_tf.range.reset();  // the data's range, unless given
        req.tf_size = 64;
        req.solver = solver;
        req.settings.solve.smooth = 0.01;
        if (given_ranges) req.ref_range = FieldRange{260.0, 340.0}, req.field_range = FieldRange{270.0, 350.0};
        const OptimizeResult whole = run_optimize(ctx(), req);

        auto rs = open_volume_slabs(ref_file);
        auto os = open_volume_slabs(opt_file);
        StreamedOptimizeRequest sreq;
        sreq.ref = rs.get();
        sreq.field = os.get();
        sreq.ref_tf = req.ref_tf;
        sreq.ref_range = req.ref_range;
        sreq.field_range = req.field_range;
        sreq.tf_size = 64;
        sreq.solver = solver;
        sreq.settings = req.settings;
        sreq.slab_voxels = 37 * 29 * 4;
        sreq.max_chunk_voxels = 2048;
        const StreamedOptimizeResult s = run_optimize_streamed(ctx(), sreq);
        EXPECT_EQ(s.passes, given_ranges ? 1u : 2u);
        EXPECT_EQ(s.slab_slices, 4u);
        EXPECT_EQ(s.slabs, 6u);
        EXPECT_TRUE(s.streamed);
        ASSERT_EQ(s.result.tf.size(), whole.tf.size());
        for (size_t j = 0; j < whole.tf.size(); ++j)
          for (int c = 0; c < 4; ++c) ASSERT_EQ(s.result.tf.rgba[j][c], whole.tf.rgba[j][c]) << "entry " << j << "." << c;
        EXPECT_EQ(s.result.ref_range.lo, whole.ref_range.lo);
        EXPECT_EQ(s.result.ref_range.hi, whole.ref_range.hi);
        EXPECT_EQ(s.result.field_range.lo, whole.field_range.lo);
        EXPECT_EQ(s.result.field_range.hi, whole.field_range.hi);
        EXPECT_EQ(s.result.before.rmse(), whole.before.rmse());
        EXPECT_EQ(s.result.after.rmse(), whole.after.rmse());
        // The same warnings, but advice naming cgls says it needs the fields in memory.
        std::vector<std::string> expected = whole.warnings;
        for (std::string& w : expected)
          if (const size_t at = w.find("--solver cgls or"); at != std::string::npos)
            w.replace(at, 16, "--solver cgls (--stream off, in one process) or");
        EXPECT_EQ(s.result.warnings, expected);
        EXPECT_TRUE(std::isnan(s.result.after.mae()));
      }
    }
  }
}

// The preview: the mean of each box's finite values, NaN where a box has none.
TEST_F(StreamedOptimizeTest, PreviewIsTheBoxFilteredField) {
  Volume ref = slab_test::test_field({10, 9, 7}, 0);
  ref.spacing = {1.0, 2.0, 3.0};
  Volume opt = slab_test::test_field({10, 9, 7}, 1);
  for (uint64_t y = 0; y < 3; ++y)
    for (uint64_t x = 0; x < 3; ++x) opt.values[y * 10 + x] = NAN;  // the first 3x3x1 of a box
  auto rs = slabs_in_memory(ref);
  auto os = slabs_in_memory(opt);
  StreamedOptimizeRequest req;
  req.ref = rs.get();
  req.field = os.get();
  req.ref_tf = demo_transfer_function(16);
  req.ref_tf.range.reset();
  req.preview_voxels = 4 * 3 * 3;  // factor 3: 4 x 3 x 3 boxes
  req.slab_voxels = 10 * 9 * 2;
  const StreamedOptimizeResult s = run_optimize_streamed(ctx(), req);
  EXPECT_FALSE(s.streamed);
  ASSERT_EQ(s.preview_factor, 3u);
  ASSERT_EQ(s.ref_preview.dims, (std::array<uint64_t, 3>{4, 3, 3}));
  EXPECT_EQ(s.ref_preview.spacing, (std::array<double, 3>{3.0, 6.0, 9.0}));
  EXPECT_EQ(s.ref_preview.origin, (std::array<double, 3>{1.0, 2.0, 3.0}));
  for (uint64_t bz = 0; bz < 3; ++bz)
    for (uint64_t by = 0; by < 3; ++by)
      for (uint64_t bx = 0; bx < 4; ++bx) {
        double sum = 0;
        int n = 0;
        for (uint64_t z = 3 * bz; z < std::min<uint64_t>(7, 3 * bz + 3); ++z)
          for (uint64_t y = 3 * by; y < std::min<uint64_t>(9, 3 * by + 3); ++y)
            for (uint64_t x = 3 * bx; x < std::min<uint64_t>(10, 3 * bx + 3); ++x) {
              const float v = opt.at(x, y, z);
              if (std::isfinite(v)) sum += v, ++n;
            }
        const float got = s.field_preview.values[(bz * 3 + by) * 4 + bx];
        if (n == 0) EXPECT_TRUE(std::isnan(got));
        else EXPECT_FLOAT_EQ(got, float(sum / n)) << bx << "," << by << "," << bz;
      }
}

TEST_F(StreamedOptimizeTest, OnlySystemSolversStreamAndGridsMustMatch) {
  auto a = slabs_in_memory(slab_test::test_field({6, 5, 4}, 0));
  auto b = slabs_in_memory(slab_test::test_field({6, 5, 3}, 1));
  StreamedOptimizeRequest req;
  req.ref = a.get();
  req.field = a.get();
  req.ref_tf = demo_transfer_function(16);
  req.ref_tf.range.reset();
  req.solver = "cgls";
  formats_test::expect_error([&] { run_optimize_streamed(ctx(), req); }, {"cgls", "normal-equations and qp"});
  req.solver = "qp";
  req.field = b.get();
  EXPECT_THROW(run_optimize_streamed(ctx(), req), std::runtime_error);
  Volume constant = slab_test::test_field({6, 5, 4}, 1);
  for (float& v : constant.values) v = 2.0f;
  auto c = slabs_in_memory(constant);
  req.field = c.get();
  formats_test::expect_error([&] { run_optimize_streamed(ctx(), req); }, {"constant"});
  // Visibility weights render the whole reference: they do not stream.
  req.field = a.get();
  req.settings.extra["weights"] = "visibility";
  formats_test::expect_error([&] { run_optimize_streamed(ctx(), req); }, {"weights visibility", "does not stream"});
  EXPECT_TRUE(solver_streams("normal-equations"));
  EXPECT_FALSE(solver_streams("diffdvr"));
}

}  // namespace
}  // namespace tfm
