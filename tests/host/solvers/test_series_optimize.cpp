// Many fields against one reference (series_optimize.h): per-field fits are run_optimize's fits
// field by field; the shared fit is, bit for bit, the fit of the fields stacked into one volume
// against the reference stacked as often (the summed systems are exact); misuse is refused.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "formats_test_util.h"
#include "test_data.h"
#include "tfmatch/solvers/series_optimize.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

constexpr std::array<uint64_t, 3> kDims{13, 11, 7};

Volume reference() {
  return test::make_volume(kDims, {1, 1, 1}, "reference", [](uint64_t x, uint64_t y, uint64_t z, uint64_t) {
    return float(0.5 + 0.45 * std::sin(0.5 * x + 0.3 * y) * std::cos(0.4 * z));
  });
}

// Field k: a monotone remap of the reference into other units, a little different per field,
// with a NaN here and there.
Volume field(int k) {
  const Volume ref = reference();
  return test::make_volume(kDims, {1, 1, 1}, "field " + std::to_string(k), [&](uint64_t, uint64_t, uint64_t, uint64_t i) {
    if (i % 53 == uint64_t(k)) return NAN;
    return float(250.0 + 40.0 * std::pow(double(ref.values[i]), 1.4 + 0.3 * k) + 2.0 * k);
  });
}

bool same_tf(const TransferFunction& a, const TransferFunction& b) {
  return a.size() == b.size() && std::memcmp(a.rgba.data(), b.rgba.data(), a.size() * sizeof(Rgba)) == 0;
}

SeriesRequest request(const Volume& ref, const TransferFunction& tf, int fields) {
  SeriesRequest r;
  r.ref = &ref;
  r.ref_tf = tf;
  r.tf_size = 24;
  r.field_count = size_t(fields);
  r.load_field = [](size_t i) { return field(int(i)); };
  return r;
}

using SeriesOptimize = test::GpuTest;

TEST_F(SeriesOptimize, PerFieldFitsAreEachFieldsOwnFit) {
  const Volume ref = reference();
  const TransferFunction tf = test::random_tf(16, 3);
  const SeriesResult s = run_optimize_series(ctx(), request(ref, tf, 3));
  ASSERT_EQ(s.fields.size(), 3u);
  EXPECT_FALSE(s.shared_tf);
  for (int k = 0; k < 3; ++k) {
    const Volume f = field(k);
    OptimizeRequest r;
    r.ref = &ref;
    r.field = &f;
    r.ref_tf = tf;
    r.tf_size = 24;
    const OptimizeResult one = run_optimize(ctx(), r);
    EXPECT_TRUE(same_tf(s.fields[size_t(k)].tf, one.tf)) << "field " << k;
    EXPECT_EQ(s.fields[size_t(k)].after.rmse(), one.after.rmse());
    EXPECT_EQ(s.fields[size_t(k)].field_range.lo, one.field_range.lo);
    EXPECT_EQ(s.fields[size_t(k)].name, "field " + std::to_string(k));
    EXPECT_LT(one.after.rmse(), 0.5 * one.before.rmse());
  }
}

TEST_F(SeriesOptimize, SharedFitIsTheFitOfAllVoxelsTogether) {
  const Volume ref = reference();
  const TransferFunction tf = test::random_tf(16, 5);
  for (const char* solver : {"normal-equations", "qp"}) {
    SCOPED_TRACE(solver);
    SeriesRequest r = request(ref, tf, 3);
    r.shared_tf = true;
    r.solver = solver;
    const SeriesResult s = run_optimize_series(ctx(), r);
    ASSERT_TRUE(s.shared_tf);
    // The fields stacked along z against the reference stacked three times, one fit.
    Volume stacked_ref = ref, stacked = ref;
    stacked_ref.dims[2] = stacked.dims[2] = 3 * kDims[2];
    stacked_ref.values.clear();
    stacked.values.clear();
    for (int k = 0; k < 3; ++k) {
      const Volume f = field(k);
      stacked_ref.values.insert(stacked_ref.values.end(), ref.values.begin(), ref.values.end());
      stacked.values.insert(stacked.values.end(), f.values.begin(), f.values.end());
    }
    OptimizeRequest one;
    one.ref = &stacked_ref;
    one.field = &stacked;
    one.ref_tf = tf;
    one.tf_size = 24;
    one.solver = solver;
    const OptimizeResult whole = run_optimize(ctx(), one);
    EXPECT_EQ(s.tf.range->lo, whole.field_range.lo) << "the union of the fields' ranges";
    EXPECT_EQ(s.tf.range->hi, whole.field_range.hi);
    EXPECT_TRUE(same_tf(s.tf, whole.tf)) << "bit for bit the fit of all voxels together";
    EXPECT_NEAR(s.after.rmse(), whole.after.rmse(), 1e-12);
    EXPECT_NEAR(s.before.rmse(), whole.before.rmse(), 1e-12);
    ASSERT_EQ(s.fields.size(), 3u);
    for (const SeriesFieldResult& f : s.fields) EXPECT_TRUE(same_tf(f.tf, s.tf));
    // One TF fits each field worse than its own TF does.
    const SeriesResult own = run_optimize_series(ctx(), request(ref, tf, 3));
    ASSERT_EQ(own.fields.size(), 3u);
    for (size_t k = 0; k < 3; ++k) EXPECT_GE(s.fields[k].after.rmse(), own.fields[k].after.rmse());
  }
}

// Streamed slab by slab (three z-slices at a time here), per field and shared: the bits of the
// fits of the fields in memory.
TEST_F(SeriesOptimize, StreamedGivesTheBitsOfTheLoadedFits) {
  const Volume ref = reference();
  const TransferFunction tf = test::random_tf(16, 7);
  for (bool shared : {false, true}) {
    for (const char* solver : {"normal-equations", "qp"}) {
      SCOPED_TRACE(std::string(solver) + (shared ? ", shared" : ", per field"));
      SeriesRequest loaded = request(ref, tf, 3);
      loaded.shared_tf = shared;
      loaded.solver = solver;
      const SeriesResult a = run_optimize_series(ctx(), loaded);
      SeriesRequest streamed = loaded;
      streamed.ref = nullptr;
      streamed.load_field = nullptr;
      streamed.open_ref_slabs = [&] { return slabs_in_memory(ref); };
      streamed.open_field_slabs = [](size_t i) { return slabs_in_memory(field(int(i))); };
      streamed.slab_voxels = 3 * kDims[0] * kDims[1];
      const SeriesResult b = run_optimize_series(ctx(), streamed);
      ASSERT_EQ(a.fields.size(), 3u);
      ASSERT_EQ(b.fields.size(), 3u);
      for (size_t k = 0; k < 3; ++k) {
        EXPECT_TRUE(same_tf(a.fields[k].tf, b.fields[k].tf)) << "field " << k;
        EXPECT_EQ(a.fields[k].after.rmse(), b.fields[k].after.rmse());
        EXPECT_EQ(a.fields[k].field_range.lo, b.fields[k].field_range.lo);
      }
      if (shared) EXPECT_TRUE(same_tf(a.tf, b.tf));
    }
  }
}

TEST_F(SeriesOptimize, RefusesMixedGridsAndWhatASharedFitCannotDo) {
  const Volume ref = reference();
  const TransferFunction tf = test::random_tf(16, 5);
  SeriesRequest r = request(ref, tf, 3);
  r.load_field = [](size_t i) {
    Volume v = field(int(i));
    if (i == 2) {
      v.dims[2] -= 1;
      v.values.resize(v.dims[0] * v.dims[1] * v.dims[2]);
    }
    return v;
  };
  formats_test::expect_error([&] { run_optimize_series(ctx(), r); }, {"field 3 of 3", "field 2"});
  r = request(ref, tf, 2);
  r.shared_tf = true;
  r.solver = "cgls";
  formats_test::expect_error([&] { run_optimize_series(ctx(), r); }, {"cgls", "normal-equations or qp"});
  r.solver = "normal-equations";
  r.settings.extra["weights"] = "visibility";
  formats_test::expect_error([&] { run_optimize_series(ctx(), r); }, {"weights visibility"});
  r = request(ref, tf, 0);
  EXPECT_THROW(run_optimize_series(ctx(), r), std::runtime_error);
}

// A field without data stops the series with an error that says which field it is (a series may
// read every step from one file), in per-field and shared fits alike.
TEST_F(SeriesOptimize, AFieldWithoutDataIsNamedByItsPlace) {
  const Volume ref = reference();
  const TransferFunction tf = test::random_tf(16, 7);
  for (const bool shared : {false, true}) {
    SeriesRequest r = request(ref, tf, 3);
    r.shared_tf = shared;
    r.load_field = [](size_t i) {
      Volume v = field(int(i));
      if (i == 1) std::fill(v.values.begin(), v.values.end(), NAN);
      return v;
    };
    formats_test::expect_error([&] { run_optimize_series(ctx(), r); },
                               {"field 2 of 3", "field 1", "no finite value"});
  }
}

}  // namespace
}  // namespace tfm
