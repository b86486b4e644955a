#include "phos/render/exposure.h"

#include <algorithm>
#include <cmath>

#include "phos/util/colour.h"
#include "phos/util/error.h"

namespace phos::render {

double ExposureShowingLuminanceAs(double luminance, double display_luminance) {
  PHOS_CHECK(luminance > 0 && display_luminance > 0 && display_luminance < 1);
  return display_luminance / (1 - display_luminance) / luminance;
}

void ExposureMeter::Add(const Image& rgb) {
  PHOS_CHECK(rgb.channels == 3);
  frame_luminance_.clear();
  for (std::size_t p = 0; p < rgb.pixels.size() / 3; ++p) {
    const float* c = &rgb.pixels[3 * p];
    const double Y = LinearSrgbLuminance(c[0], c[1], c[2]);
    // Black (nothing glows there) and non-finite pixels say nothing about the glow.
    if (std::isfinite(Y) && Y > 0) frame_luminance_.push_back(static_cast<float>(Y));
  }
  ++frames_;
  const std::size_t n = frame_luminance_.size();
  if (n == 0) return;
  const auto nth = frame_luminance_.begin() + static_cast<std::ptrdiff_t>(
                                                  std::ceil(kMeteredPercentile * static_cast<double>(n)) - 1);  // 1-based rank
  std::nth_element(frame_luminance_.begin(), nth, frame_luminance_.end());
  brightest_median_ = std::max(brightest_median_, static_cast<double>(*nth));
  glowing_pixels_ += n;
}

AutoExposure ExposureMeter::Choose() const {
  AutoExposure chosen;
  chosen.metered_frames = frames_;
  chosen.glowing_pixels = glowing_pixels_;
  if (glowing_pixels_ == 0) return chosen;
  chosen.metered_luminance = brightest_median_;
  chosen.exposure = ExposureShowingLuminanceAs(chosen.metered_luminance, kMeteredDisplayLuminance);
  return chosen;
}

}  // namespace phos::render
