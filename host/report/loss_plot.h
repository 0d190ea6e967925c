// The loss curve of an iterative image-based solve as a picture for the report: mean image loss
// per iteration on a logarithmic axis.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tfmatch/model/image.h"
#include "tfmatch/report/report.h"
#include "tfmatch/solvers/optimize.h"

namespace tfm {

// Throws std::invalid_argument for an empty curve or a plot smaller than 120 x 80 pixels.
Image plot_loss_curve(std::span<const double> curve, uint32_t width, uint32_t height, const std::string& title);

// The report figures a solver's details call for: "loss.png" when they hold a "loss_curve"
// (diffdvr), else none.
std::vector<ReportFigure> solver_report_figures(const OptimizeResult& result, uint32_t width = 512);

}  // namespace tfm
