// Histogram matching, the baseline users try first: T_o(v) = T_r(F_r^-1(F_o(v))), where F_o and
// F_r are the cumulative distributions of the field's and the reference's finite values. It maps
// each quantile of the field to the same quantile of the reference, so it can only match fields
// related by an increasing function of the value; a field that is a decreasing function of the
// reference (a reversed ramp, the paper's counter-example) keeps a large residual that least
// squares removes.
//
// The distributions come from histograms (kernels/histogram.h) of each field over the range its
// TF mapping uses: values below or above count at the ends, where the TF clamps them anyway, and
// within a bin the distribution is taken as uniform (a piecewise-linear CDF). NaN voxels are left
// out of each field's own distribution.
#pragma once

#include "tfmatch/kernels/histogram.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/transfer_function.h"

namespace tfm {

// Fraction of the finite values at or below v, for v in [h.lo, h.hi]: the piecewise-linear CDF
// through the bin edges (h.below counts at h.lo). Throws std::invalid_argument for a histogram
// without finite values.
double histogram_cdf(const FieldHistogram& h, double v);

// The inverse: the smallest value whose CDF reaches q (q in [0, 1]), interpolated within its bin;
// h.lo when q is within the mass at or below h.lo, h.hi when within the mass above.
double histogram_quantile(const FieldHistogram& h, double q);

// The TF of `opt_map.tf_size` entries: entry j at the field value of TF node j (opt_map) takes
// T_r at the reference's value of the same quantile (ref_tf through ref_map, linear interpolation
// as the kernels classify).
TransferFunction histogram_matching_tf(const FieldHistogram& ref, const FieldHistogram& opt,
                                       const TransferFunction& ref_tf, const FieldMapping& ref_map,
                                       const FieldMapping& opt_map);

// The value range a mapping covers: [lo, lo + (N - 1) / scale].
FieldRange mapping_range(const FieldMapping& m);

}  // namespace tfm
