#include "phos/render/spectral_upsampling.h"

#include <algorithm>

#include "phos/util/colour.h"

namespace phos::render {

namespace {

// Each primary's share of the reflectance at 1 nm steps from kFirst_nm: its
// clipped linear-sRGB matching function over the three's sum. In the tails,
// where ybar is below a hundredth of its peak (before 430 nm, after 685 nm),
// the fit's ratios drift from the CIE tables' (Wyman et al.'s red fell below
// its green past 690 nm and turned negative past 750 nm, so a red object
// went dark there, where the tables keep it red): the share of the nearest
// wavelength inside is carried out to the ends instead.
constexpr int kFirst_nm = 360, kLast_nm = 830;
std::vector<std::array<double, 3>> PrimaryShares() {
  std::vector<std::array<double, 3>> share(kLast_nm - kFirst_nm + 1);
  int first = -1, last = -1;
  for (int i = 0; i < static_cast<int>(share.size()); ++i) {
    const double wavelength = kFirst_nm + i;
    const Tristimulus xyz = Cie1931Cmf(wavelength);
    const Tristimulus rgb = XyzToLinearSrgb(xyz);
    const double r = std::max(0.0, rgb[0]), g = std::max(0.0, rgb[1]), b = std::max(0.0, rgb[2]);
    const double total = r + g + b;
    if (xyz[1] < 1e-2 || !(total > 0)) continue;  // ybar peaks at 1
    share[i] = {r / total, g / total, b / total};
    if (first < 0) first = i;
    last = i;
  }
  for (int i = 0; i < first; ++i) share[i] = share[first];
  for (int i = last + 1; i < static_cast<int>(share.size()); ++i) share[i] = share[last];
  return share;
}

}  // namespace

RgbToBands::RgbToBands(const SpectralGrid& bands) {
  static const std::vector<std::array<double, 3>> share = PrimaryShares();
  for (int b = 0; b < bands.band_count(); ++b) {
    // The shares averaged over the band (midpoint rule, about 1 nm steps).
    const double lower = bands.lower_nm(b), upper = bands.upper_nm(b);
    const int steps = std::max(8, static_cast<int>(std::ceil(upper - lower)));
    double red = 0, blue = 0;
    for (int i = 0; i < steps; ++i) {
      const double wavelength = lower + (i + 0.5) * (upper - lower) / steps;
      const int k = std::clamp(static_cast<int>(std::lround(wavelength)) - kFirst_nm, 0, kLast_nm - kFirst_nm);
      red += share[k][0];
      blue += share[k][2];
    }
    red_.push_back(static_cast<float>(red / steps));
    blue_.push_back(static_cast<float>(blue / steps));
  }
}

void RgbToBands::Albedo(const float rgb[3], float* bands) const {
  const float r = std::clamp(rgb[0], 0.0f, 1.0f), g = std::clamp(rgb[1], 0.0f, 1.0f),
              b = std::clamp(rgb[2], 0.0f, 1.0f);
  // g + share_r (r - g) + share_b (b - g): a grey is exactly itself, white
  // exactly 1; the clamp only catches rounding.
  for (std::size_t k = 0; k < red_.size(); ++k)
    bands[k] = std::clamp(g + red_[k] * (r - g) + blue_[k] * (b - g), 0.0f, 1.0f);
}

std::vector<double> RgbToBands::Albedo(const std::array<double, 3>& rgb) const {
  const float in[3] = {static_cast<float>(rgb[0]), static_cast<float>(rgb[1]), static_cast<float>(rgb[2])};
  std::vector<float> out(red_.size());
  Albedo(in, out.data());
  return {out.begin(), out.end()};
}

}  // namespace phos::render
