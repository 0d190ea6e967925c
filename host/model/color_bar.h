// A colour bar beneath a rendering: which colour is which value, for a picture that stands alone
// (a residual map's PNG, a render with --color-bar), where no TF plot is beside it.
#pragma once

#include <array>
#include <optional>
#include <string>

#include "tfmatch/model/image.h"
#include "tfmatch/model/transfer_function.h"

namespace tfm {

// The strip a colour bar adds beneath a picture, and the narrowest picture that takes one.
inline constexpr uint32_t kColorBarStripHeight = 30, kColorBarMinWidth = 120;

// `picture` with a strip of kColorBarStripHeight pixels beneath it, in the background's colour
// (`background`, linear RGB, as the render's): `title` on the left, then a horizontal bar of the
// TF's colours at full strength (T(t) for t across [0, 1], linear RGB shown as sRGB, as the TF
// plots show them) with round values of `range` ticked and labelled beneath it. Beneath, not over
// the picture: a framed map fills its picture, and a legend laid over it would hide data and the
// coordinate labels. Text is in the fixed 5x7 font (the same pixels from every command), dark on
// a light background and light on a dark one; a title too long for its room drops the file
// before its first ':' (the variable and its units are what the bar shows), then keeps its end.
// Nothing when the picture is narrower than kColorBarMinWidth. Throws std::invalid_argument for
// an empty TF or range.
std::optional<Image> with_color_bar(const Image& picture, const TransferFunction& tf, const FieldRange& range,
                                    const std::string& title, const std::array<double, 3>& background);

}  // namespace tfm
