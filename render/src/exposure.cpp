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
  for (std::size_t p = 0; p < rgb.pixels.size() / 3; ++p) {
    const float* c = &rgb.pixels[3 * p];
    const double Y = LinearSrgbLuminance(c[0], c[1], c[2]);
    // Black (nothing glows there) and non-finite pixels say nothing about the glow.
    if (std::isfinite(Y) && Y > 0) glowing_luminance_.push_back(static_cast<float>(Y));
  }
  ++frames_;
}

AutoExposure ExposureMeter::Choose() {
  AutoExposure chosen;
  chosen.metered_frames = frames_;
  chosen.glowing_pixels = glowing_luminance_.size();
  if (glowing_luminance_.empty()) return chosen;
  const std::size_t rank = static_cast<std::size_t>(
      std::ceil(kMeteredPercentile * static_cast<double>(glowing_luminance_.size())));  // 1-based
  const auto nth = glowing_luminance_.begin() + static_cast<std::ptrdiff_t>(std::max<std::size_t>(rank, 1) - 1);
  std::nth_element(glowing_luminance_.begin(), nth, glowing_luminance_.end());
  chosen.metered_luminance = *nth;
  chosen.exposure = ExposureShowingLuminanceAs(chosen.metered_luminance, kMeteredDisplayLuminance);
  return chosen;
}

}  // namespace phos::render
