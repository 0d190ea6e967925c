#!/usr/bin/python3
"""Independent values of the correlation measures for tests/host/reference/test_correlation_cpu.cpp.

Run once with Debian's python3-scipy, python3-sklearn and python3-numpy (/usr/bin/python3); the
numbers it prints are written into the test. Measures: scipy.stats pearsonr, spearmanr and
kendalltau (tau-b, every tie term), scikit-learn's KSG estimator without jitter
(sklearn.feature_selection._mutual_info._compute_mi_cc; it returns max(MI, 0), so the series are
chosen dependent enough that the estimate is positive) and a numpy plug-in binned MI with the
bins of kernels/correlation.h: B equal-width bins over each series' own min..max,
bin = min(floor((v - min) / (max - min) * B), B - 1), natural log.

Every value is a multiple of 1/4 (exact in float32 too) and each pair has ties in x and in y, but
no point has k = 3 exact copies, so every k-th neighbour distance is positive.
"""
import numpy as np
from scipy import stats
from sklearn.feature_selection._mutual_info import _compute_mi_cc


def binned_mi(x, y, bins):
    def binned(v):
        return np.minimum(np.floor((v - v.min()) / (v.max() - v.min()) * bins), bins - 1).astype(int)

    bx, by = binned(x), binned(y)
    joint = np.bincount(bx * bins + by, minlength=bins * bins).reshape(bins, bins) / x.size
    px, py = joint.sum(axis=1), joint.sum(axis=0)
    nz = joint > 0
    return float(np.sum(joint[nz] * np.log(joint[nz] / np.outer(px, py)[nz])))


def series():
    short_x = [0.5, 1.25, 1.25, 3.0, 2.0, 0.75, 2.0, 4.5, 1.25, 3.5, 0.25, 2.75]
    short_y = [1.0, 0.5, 2.25, 3.0, 2.25, 0.25, 1.75, 4.0, 1.0, 2.5, 0.75, 3.25]
    long_x = [((i * 37) % 23) / 4.0 for i in range(40)]
    long_y = [((i * 11) % 7) / 4.0 + long_x[i] / 2.0 for i in range(40)]
    return [("short", short_x, short_y), ("long", long_x, long_y)]


def main():
    np.set_printoptions(precision=17)
    for name, x, y in series():
        x, y = np.array(x, dtype=np.float64), np.array(y, dtype=np.float64)
        print(f"{name}: M = {x.size}")
        print(f"  pearson     {stats.pearsonr(x, y)[0]!r}")
        print(f"  spearman    {stats.spearmanr(x, y)[0]!r}")
        print(f"  kendall     {stats.kendalltau(x, y)[0]!r}")
        for k in (1, 3):
            print(f"  ksg k={k}     {float(_compute_mi_cc(x, y, k))!r}")
        for bins in (4, 8):
            print(f"  binned B={bins}  {binned_mi(x, y, bins)!r}")


if __name__ == "__main__":
    main()
