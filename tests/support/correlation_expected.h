// Correlation measures of two fixed pairs of series computed independently of tfmatch, by
// tests/host/reference/correlation_expected.py (scipy.stats pearsonr / spearmanr / kendalltau,
// scikit-learn's KSG estimator _compute_mi_cc, a numpy plug-in binned MI), run once with Debian's
// python3-scipy 1.10.1, python3-sklearn 1.2.1 and python3-numpy 1.24.2; the numbers are the
// ones it printed. Values are multiples of 1/4 with ties in x and in y.
#pragma once

#include <vector>

namespace tfm::test {

struct ExpectedCorrelations {
  const char* name;
  std::vector<float> x, y;
  double pearson, spearman, kendall;
  double ksg_k1, ksg_k3;        // sklearn returns max(MI, 0); both are positive here
  double binned_4, binned_8;    // 4 and 8 bins
};

inline std::vector<ExpectedCorrelations> expected_correlations() {
  std::vector<float> long_x(40), long_y(40);
  for (int i = 0; i < 40; ++i) {
    long_x[i] = float((i * 37) % 23) / 4.0f;
    long_y[i] = float((i * 11) % 7) / 4.0f + long_x[i] / 2.0f;
  }
  return {
      {"short",
       {0.5f, 1.25f, 1.25f, 3.0f, 2.0f, 0.75f, 2.0f, 4.5f, 1.25f, 3.5f, 0.25f, 2.75f},
       {1.0f, 0.5f, 2.25f, 3.0f, 2.25f, 0.25f, 1.75f, 4.0f, 1.0f, 2.5f, 0.75f, 3.25f},
       0.8868376639067831, 0.8584191805577249, 0.6985006985010478, 1.3393217893217897, 0.7718614718614725,
       0.6648306744273791, 1.2707698310265663},
      {"long", long_x, long_y, 0.8736256884741599, 0.8742014318926583, 0.6352962887688474, 1.5194954198887567,
       2.1360576423884794, 0.5207870843877861, 1.2652601871112439},
  };
}

}  // namespace tfm::test
