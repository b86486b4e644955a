#include "phos/render/night_vision.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <opencv2/imgproc.hpp>

#include "phos/util/colour.h"
#include "phos/util/error.h"

namespace phos::render {

double ScotopicLuminosity(double wavelength_nm) {
  const double um = wavelength_nm * 1e-3;
  return 0.992 * std::exp(-321.9 * (um - 0.503) * (um - 0.503));
}

Image NightVision(const Image& bands, const Image& rgb, const SpectralGrid& grid, const NightVisionOptions& options) {
  const int nb = grid.band_count(), width = rgb.width, height = rgb.height;
  PHOS_CHECK(bands.channels == nb && rgb.channels == 3 && bands.width == width && bands.height == height);
  // Band weights for V, normalized like Y (radiance 1 in every band has V = 1),
  // so that a flat grey has V = Y and only the spectrum's shape moves V.
  std::vector<double> v_weight(nb, 0.0);
  double total = 0;
  for (int b = 0; b < nb; ++b) {
    const int steps = std::max(8, static_cast<int>(grid.width_nm(b)));
    for (int k = 0; k < steps; ++k)
      v_weight[b] += ScotopicLuminosity(grid.lower_nm(b) + (k + 0.5) * grid.width_nm(b) / steps) / steps;
    total += v_weight[b];
  }
  for (double& w : v_weight) w /= total;

  const std::size_t pixels = std::size_t(width) * height;
  cv::Mat V(height, width, CV_32F), share(height, width, CV_32F);
  const double log_scotopic = std::log10(0.001), log_photopic = std::log10(3.0);
  double mean_share = 0;
  for (std::size_t p = 0; p < pixels; ++p) {
    const float* c = &rgb.pixels[3 * p];
    const double Y = std::max(0.0, LinearSrgbLuminance(c[0], c[1], c[2]));
    double v = 0;
    for (int b = 0; b < nb; ++b) v += v_weight[b] * bands.pixels[p * nb + b];
    V.at<float>(static_cast<int>(p)) = static_cast<float>(std::max(0.0, v) * options.exposure);
    // The rods' share: 1 below 0.001 cd/m^2, 0 above 3, linear in log luminance between.
    const double log_cd = std::log10(std::max(Y * options.cd_per_unit, 1e-12));
    const double s = std::clamp((log_photopic - log_cd) / (log_photopic - log_scotopic), 0.0, 1.0);
    share.at<float>(static_cast<int>(p)) = static_cast<float>(s);
    mean_share += s;
  }
  mean_share /= static_cast<double>(pixels);

  // Loss of acuity: blur by the scene's mean rod share (one kernel per frame).
  cv::Mat blurred = V;
  const double sigma = options.acuity_sigma_px * mean_share;
  if (sigma > 0.05) cv::GaussianBlur(V, blurred, cv::Size(0, 0), sigma, sigma, cv::BORDER_REFLECT);
  // Edges: base = G(blurred), detail d = blurred - base, put back as sign(d) |d|^(1/gamma).
  cv::Mat base;
  cv::GaussianBlur(blurred, base, cv::Size(0, 0), std::max(1.0, 2 * sigma), std::max(1.0, 2 * sigma),
                   cv::BORDER_REFLECT);
  std::mt19937_64 random(options.seed);
  std::normal_distribution<float> noise(0.0f, static_cast<float>(options.noise_sigma));
  // The bluish grey of chromaticity (x, y) = (0.25, 0.25): XYZ = (1, 1, 2) in linear sRGB.
  const Tristimulus tint = XyzToLinearSrgb({1, 1, 2});
  Image out(width, height, 3);
  for (std::size_t p = 0; p < pixels; ++p) {
    const int i = static_cast<int>(p);
    const double d = blurred.at<float>(i) - base.at<float>(i);
    const double edge = (d < 0 ? -1.0 : 1.0) * std::pow(std::abs(d), 1.0 / options.gamma);
    const double s = share.at<float>(i);
    double rod = base.at<float>(i) + edge;
    // Grain like photon noise: its deviation grows as the square root of the signal.
    if (s > 0 && options.noise_sigma > 0) rod += s * std::sqrt(std::max(0.0, rod)) * noise(random);
    rod = std::max(0.0, rod);
    for (int k = 0; k < 3; ++k)
      out.pixels[3 * p + k] =
          static_cast<float>((1 - s) * options.exposure * rgb.pixels[3 * p + k] + s * rod * tint[k]);
  }
  return out;
}

}  // namespace phos::render
