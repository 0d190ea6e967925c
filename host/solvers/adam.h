// Adam (Kingma & Ba 2015) on a small parameter vector in double precision, with projection onto
// a box after each step (the TF entries of image-based optimization live in [0, 1]).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace tfm {

struct AdamOptions {
  double learning_rate = 0.01;
  double beta1 = 0.9;
  double beta2 = 0.999;
  double epsilon = 1e-8;
  double lower = 0.0;  // projection box
  double upper = 1.0;
};

class Adam {
 public:
  // Throws std::invalid_argument for a non-positive rate, betas outside [0, 1) or an empty box.
  Adam(size_t parameters, const AdamOptions& options);
  // x <- clamp(x - lr * m_hat / (sqrt(v_hat) + eps), lower, upper) with the bias-corrected
  // moments of the gradients seen so far. Throws std::invalid_argument on a size mismatch.
  void step(std::span<double> x, std::span<const double> gradient);
  uint64_t steps() const { return t_; }
  const AdamOptions& options() const { return o_; }

 private:
  AdamOptions o_;
  std::vector<double> m_, v_;
  uint64_t t_ = 0;
};

}  // namespace tfm
