#pragma once
// "exposure": "auto" (docs/render.md, "Exposure"): one exposure for a whole
// sequence, metered on its frames after dark (no light and no sky on), so
// that the glow, the subject of a phosphor scene, is visible rather than
// black, and its fading from frame to frame stays visible too (one exposure
// per frame would scale every frame to the same brightness and hide the
// decay, and make a sequence flicker).
//
// The meter: each frame's median luminance of its glowing pixels (linear
// sRGB Y > 0); the brightest frame's (the largest of those medians) shown
// as display luminance 0.18 (mid-grey, sRGB code 118) through the PNG's
// tone map (Reinhard's global operator, ToneMap in renderer.h), so the
// glow at its brightest is seen and the later frames show its fading as
// darkening. This is the key value a = 0.18 of Reinhard et al. 2002,
// "Photographic Tone Reproduction for Digital Images", who map the
// log-average luminance to it, as game engines' auto exposure does. phos
// takes a median within a frame, over the glowing pixels only: after dark
// most of a direct-lit frame is exactly 0, where a log-average is
// undefined (or, with an offset, set by the offset), and a median ignores
// the path tracer's fireflies. One median of all frames' pixels pooled
// (before) jumped between the frames when they differed more than the
// pixels of one frame do (the glow-sign between 40 and 60 s: 4.7x apart at
// 4 and 16 samples per pixel); the log-average of the frames' medians is
// stable, but shows neither frame when they are 10^4 apart (the Cornell
// box at 40 and 90 s: the first near white, the last black).

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
  double metered_luminance = 0.0;  // the brightest frame's median glowing luminance (0: none glows)
  std::size_t glowing_pixels = 0;  // pixels of finite luminance > 0 in the metered frames
  std::size_t metered_frames = 0;
};

// Takes each frame's median glowing luminance as it is shown the frame,
// then chooses the exposure. Holds one frame's glowing pixels at a time.
class ExposureMeter {
 public:
  void Add(const Image& rgb);  // linear sRGB, 3 channels
  // The largest of the frames' nearest-rank medians (the ceil(n / 2)-th
  // smallest) shown as mid-grey; exposure 1 when no pixel glows.
  AutoExposure Choose() const;

 private:
  std::vector<float> frame_luminance_;  // scratch: the frame being added
  double brightest_median_ = 0.0;
  std::size_t glowing_pixels_ = 0;
  std::size_t frames_ = 0;
};

}  // namespace phos::render
