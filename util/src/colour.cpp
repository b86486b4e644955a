#include "phos/util/colour.h"

#include <algorithm>
#include <cmath>

namespace phos {

namespace {

// One lobe of Wyman, Sloan and Shirley's fit: a Gaussian with a different
// width on each side of its peak.
double Lobe(double nm, double mu, double sigma_low, double sigma_high) {
  const double s = (nm - mu) / (nm < mu ? sigma_low : sigma_high);
  return std::exp(-0.5 * s * s);
}

}  // namespace

Tristimulus Cie1931Cmf(double nm) {
  return {1.056 * Lobe(nm, 599.8, 37.9, 31.0) + 0.362 * Lobe(nm, 442.0, 16.0, 26.7) - 0.065 * Lobe(nm, 501.1, 20.4, 26.2),
          0.821 * Lobe(nm, 568.8, 46.9, 40.5) + 0.286 * Lobe(nm, 530.9, 16.3, 31.1),
          1.217 * Lobe(nm, 437.0, 11.8, 36.0) + 0.681 * Lobe(nm, 459.0, 26.0, 13.8)};
}

Tristimulus Cie1931CmfBandMean(double lower_nm, double upper_nm) {
  const double width_nm = upper_nm - lower_nm;
  const int steps = std::max(8, static_cast<int>(width_nm));
  Tristimulus mean = {0, 0, 0};
  for (int k = 0; k < steps; ++k) {
    const Tristimulus cmf = Cie1931Cmf(lower_nm + (k + 0.5) * width_nm / steps);
    for (int c = 0; c < 3; ++c) mean[c] += cmf[c] / steps;
  }
  return mean;
}

}  // namespace phos
