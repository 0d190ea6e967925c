// The report's index.html (host/report/report.h): a self-contained page that shows the report's
// pictures side by side with the numbers.
#pragma once

#include <string>

#include "tfmatch/io/json.h"
#include "tfmatch/report/report.h"

namespace tfm {

// `metrics` is what metrics.json holds.
std::string report_html(const ReportInputs& inputs, const ReportSummary& summary, const nlohmann::json& metrics);

// A number with `digits` significant digits; "inf" / "n/a" for infinity / NaN.
std::string report_number(double v, int digits);
// `text` with &, <, > and " as HTML entities.
std::string html_escape(const std::string& text);
// The start of a report page up to <body>: doctype, charset, viewport, the title (escaped) and
// the style sheet (figures in grids that stack on narrow screens, tables, notes).
std::string report_head(const std::string& title);
// Whether a metric moved the better way by more than 1 % of the larger value (a residual max of
// 1.213 -> 1.212 is no gain): the cells the pages mark.
bool improved_by_a_margin(double before, double after, bool higher_is_better);

}  // namespace tfm
