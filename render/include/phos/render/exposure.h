#pragma once
// "exposure": "auto" (docs/render.md, "Exposure"): one exposure for a whole
// sequence, metered on its frames after dark (no light and no sky on), so
// that the glow, the subject of a phosphor scene, is visible rather than
// black, and its fading from frame to frame stays visible too (one exposure
// per frame would scale every frame to the same brightness and hide the
// decay, and make a sequence flicker).
//
// The meter: the median luminance of the glowing pixels (linear sRGB Y > 0)
// of the metered frames, pooled, is shown as display luminance 0.18 (mid-grey,
// sRGB code 118) through the PNG's tone map (Reinhard's global operator,
// ToneMap in renderer.h). This is the key value a = 0.18 of Reinhard et al.
// 2002, "Photographic Tone Reproduction for Digital Images", who map the
// log-average luminance to it, as game engines' auto exposure does; phos takes
// the median instead, over the glowing pixels only: after dark most of a
// direct-lit frame is exactly 0, where a log-average is undefined (or, with
// an offset, set by the offset), and a median ignores the path tracer's
// fireflies.

#include <cstddef>
#include <vector>

#include "phos/render/renderer.h"

namespace phos::render {

inline constexpr double kMeteredPercentile = 0.5;         // of the glowing pixels' luminance: the median
inline constexpr double kMeteredDisplayLuminance = 0.18;  // what it is shown as: mid-grey (linear display Y)

// The exposure at which ToneMap shows scene luminance Y as display luminance
// D, in (0, 1): Reinhard's e Y / (1 + e Y) = D solved for e.
double ExposureShowingLuminanceAs(double luminance, double display_luminance);

struct AutoExposure {
  double exposure = 1.0;           // 1 when nothing glows
  double metered_luminance = 0.0;  // the median glowing pixel's luminance (0: none glows)
  std::size_t glowing_pixels = 0;  // pixels of finite luminance > 0 in the metered frames
  std::size_t metered_frames = 0;
};

// Collects the glowing pixels' luminance of the frames it is shown, then
// chooses the exposure. Holds one float per glowing pixel.
class ExposureMeter {
 public:
  void Add(const Image& rgb);  // linear sRGB, 3 channels
  // The nearest-rank median (the ceil(n / 2)-th smallest) shown as mid-grey;
  // exposure 1 when no pixel glows. Reorders the collected values.
  AutoExposure Choose();

 private:
  std::vector<float> glowing_luminance_;
  std::size_t frames_ = 0;
};

}  // namespace phos::render
