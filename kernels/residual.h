// Residual maps (DESIGN.md) computed on the device and returned as volumes, and the simple TF
// they are rendered with.
#pragma once

#include "tfmatch/engine/context.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm {

// Residual of device fields already uploaded; the result has `grid`'s dims and spacing.
Volume residual_map_gpu(Context& ctx, const Volume& grid, const DeviceField& ref, const DeviceField& opt,
                        const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                        const Buffer& opt_tf);

// Uploads both fields and TFs and computes || premul(T_r(F_r)) - premul(T_o(F_o)) ||_2 per voxel.
// Throws std::runtime_error when the grids differ.
Volume residual_map(Context& ctx, const Volume& ref, const TransferFunction& ref_tf, const FieldRange& ref_range,
                    const Volume& field, const TransferFunction& field_tf, const FieldRange& field_range);

// The TF residual maps are rendered with: opacity linear in the residual (as in the paper's
// figures), colour from light yellow through orange to dark red.
TransferFunction residual_transfer_function(uint32_t n = 64);
// What a residual's value axis is called beside its colours (TF plots, colour bars).
inline constexpr const char* kResidualValueLabel = "residual (RGBA distance)";

// The least top of a residual display range: one 8-bit step of a colour channel. A residual
// below it is no difference any picture shows; scaled to its own maximum, float rounding
// between two identical fields (2e-7) filled the residual picture with saturated red.
inline constexpr double kResidualDisplayFloor = 1.0 / 255.0;

// Display range [0, max] over residual maps shown side by side (one scale for all of them),
// max at least kResidualDisplayFloor; [0, 1] when every residual is 0.
FieldRange residual_display_range(std::initializer_list<const Volume*> residuals);

}  // namespace tfm
