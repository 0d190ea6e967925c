// The device side of a ViewSession's state (private to host/viewer): what derive() builds and
// install() swaps in whole, shared by the session's files.
#pragma once

#include <memory>
#include <optional>

#include "tfmatch/engine/device_field.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/model/camera.h"
#include "tfmatch/viewer/view_session.h"

namespace tfm {

// Everything on the device for the current fields and TFs, made by derive() off to the side and
// installed whole, so a picture never mixes one state's field with another's TF.
struct ViewSession::Derived {
  VolumeGeometry geometry;
  std::array<GridAxis, 3> axes;  // the reference's: coordinate ticks on the pictures
  // The two fields on the device with their renderers: shared with the next Derived when a job
  // changes only TFs (an optimization, a reference-TF edit), so they are uploaded once per field.
  std::shared_ptr<const DeviceField> ref, field;
  std::shared_ptr<const GpuRenderer> ref_renderer, field_renderer;
  std::unique_ptr<DeviceField> residual_before, residual_after;
  std::optional<Buffer> ref_tf, opt_tf, res_tf;
  FieldMapping ref_map{}, field_ref_map{}, field_opt_map{}, res_map{};
  std::unique_ptr<GpuRenderer> res_before_renderer, res_after_renderer;
  Volume res_before, res_after;  // host copies: slices, histograms, downloads
  FieldRange res_range;
  TransferFunction res_tf_table;
};

}  // namespace tfm
