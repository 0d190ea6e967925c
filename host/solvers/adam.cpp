// Projected Adam.
#include "tfmatch/solvers/adam.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tfm {

Adam::Adam(size_t parameters, const AdamOptions& o) : o_(o), m_(parameters, 0.0), v_(parameters, 0.0) {
  if (!(o.learning_rate > 0) || !std::isfinite(o.learning_rate))
    throw std::invalid_argument("adam: the learning rate must be positive and finite");
  if (!(o.beta1 >= 0 && o.beta1 < 1) || !(o.beta2 >= 0 && o.beta2 < 1))
    throw std::invalid_argument("adam: beta1 and beta2 must be in [0, 1)");
  if (!(o.epsilon > 0)) throw std::invalid_argument("adam: epsilon must be positive");
  if (!(o.lower <= o.upper)) throw std::invalid_argument("adam: empty projection box");
}

void Adam::step(std::span<double> x, std::span<const double> g) {
  if (x.size() != m_.size() || g.size() != m_.size()) throw std::invalid_argument("adam: size mismatch");
  ++t_;
  const double c1 = 1.0 - std::pow(o_.beta1, double(t_));
  const double c2 = 1.0 - std::pow(o_.beta2, double(t_));
  for (size_t i = 0; i < x.size(); ++i) {
    m_[i] = o_.beta1 * m_[i] + (1.0 - o_.beta1) * g[i];
    v_[i] = o_.beta2 * v_[i] + (1.0 - o_.beta2) * g[i] * g[i];
    const double update = o_.learning_rate * (m_[i] / c1) / (std::sqrt(v_[i] / c2) + o_.epsilon);
    x[i] = std::clamp(x[i] - update, o_.lower, o_.upper);
  }
}

}  // namespace tfm
