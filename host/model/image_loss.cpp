// The image losses of DiffDVR (host/model/image_loss.h).
#include "tfmatch/model/image_loss.h"

#include <stdexcept>

#include "tfmatch/model/parameter_names.h"

namespace tfm {

ImageLoss parse_image_loss(const std::string& name) {
  if (name == "l2") return ImageLoss::L2;
  if (name == "l1") return ImageLoss::L1;
  throw std::runtime_error(parameter("loss") + ": expected l2 or l1, got '" + name + "'");
}

const char* image_loss_name(ImageLoss loss) { return loss == ImageLoss::L2 ? "l2" : "l1"; }

}  // namespace tfm
