#include "phos/model/spectral.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {

SpectralGrid SpectralGrid::Uniform(double lower_nm, double upper_nm, int band_count) {
  PHOS_CHECK(band_count > 0 && upper_nm > lower_nm);
  SpectralGrid grid;
  grid.edges_nm.resize(static_cast<size_t>(band_count) + 1);
  for (int i = 0; i <= band_count; ++i) grid.edges_nm[i] = lower_nm + (upper_nm - lower_nm) * i / band_count;
  grid.edges_nm.back() = upper_nm;
  return grid;
}

std::string SpectralGrid::BandName(int b) const {
  return FormatDouble(lower_nm(b)) + "-" + FormatDouble(upper_nm(b)) + " nm";
}

std::string SpectralGrid::EdgesName() const {
  std::string name = "[";  // appended, not "[" + ...: GCC 12 warns falsely of an overlap there (its bug 105329)
  name += JoinComma(edges_nm, FormatDouble);
  name += "] nm";
  return name;
}

double SampledSpectrum::Evaluate(double nm) const {
  const auto& w = wavelength_nm;
  if (w.empty() || nm < w.front() || nm > w.back()) return 0.0;
  auto it = std::upper_bound(w.begin(), w.end(), nm);
  if (it == w.end()) return value.back();
  size_t i = static_cast<size_t>(it - w.begin());
  double t = (nm - w[i - 1]) / (w[i] - w[i - 1]);
  return value[i - 1] + t * (value[i] - value[i - 1]);
}

double SampledSpectrum::Integrate(double lower_nm, double upper_nm) const {
  const auto& w = wavelength_nm;
  if (w.size() < 2 || upper_nm <= lower_nm) return 0.0;
  double total = 0.0;
  for (size_t i = 0; i + 1 < w.size(); ++i) {
    double a = std::max(lower_nm, w[i]), b = std::min(upper_nm, w[i + 1]);
    if (b <= a) continue;
    // Trapezoid over the clipped piece of a linear segment is exact.
    total += 0.5 * (Evaluate(a) + Evaluate(b)) * (b - a);
  }
  return total;
}

std::vector<double> IntegrateOverBands(const SampledSpectrum& spectrum, const SpectralGrid& grid) {
  std::vector<double> out(static_cast<size_t>(grid.band_count()));
  for (int b = 0; b < grid.band_count(); ++b) out[b] = spectrum.Integrate(grid.lower_nm(b), grid.upper_nm(b));
  return out;
}

std::vector<double> AverageOverBands(const SampledSpectrum& spectrum, const SpectralGrid& grid) {
  std::vector<double> out = IntegrateOverBands(spectrum, grid);
  for (int b = 0; b < grid.band_count(); ++b) out[b] /= grid.width_nm(b);
  return out;
}

std::vector<double> RebinIntegrated(const std::vector<double>& values, const SpectralGrid& from,
                                    const SpectralGrid& to) {
  PHOS_CHECK(static_cast<int>(values.size()) == from.band_count());
  std::vector<double> out(static_cast<size_t>(to.band_count()), 0.0);
  for (int j = 0; j < to.band_count(); ++j)
    for (int i = 0; i < from.band_count(); ++i) {
      double overlap = std::min(to.upper_nm(j), from.upper_nm(i)) - std::max(to.lower_nm(j), from.lower_nm(i));
      if (overlap > 0) out[j] += values[i] * overlap / from.width_nm(i);
    }
  return out;
}

namespace {

SampledSpectrum Normalized(SampledSpectrum s) {
  const double total = s.Integrate(s.wavelength_nm.front(), s.wavelength_nm.back());
  for (double& v : s.value) v /= total;
  return s;
}

}  // namespace

SampledSpectrum GaussianSpectrum(double center_nm, double fwhm_nm, double weight) {
  SampledSpectrum s;
  const double sigma = fwhm_nm / 2.3548;  // FWHM = 2 sqrt(2 ln 2) sigma
  for (double nm = center_nm - 4 * sigma; nm <= center_nm + 4 * sigma; nm += sigma / 8) {
    s.wavelength_nm.push_back(nm);
    s.value.push_back(weight * std::exp(-0.5 * std::pow((nm - center_nm) / sigma, 2)));
  }
  return s;
}

SampledSpectrum LedSpectrum(double center_nm, double fwhm_nm) {
  return Normalized(GaussianSpectrum(center_nm, fwhm_nm));
}

SampledSpectrum WhiteLedSpectrum() {
  SampledSpectrum s;
  const SampledSpectrum blue = GaussianSpectrum(450, 20), yellow = GaussianSpectrum(560, 110, 0.6);
  for (double nm = 380; nm <= 780; nm += 2) {
    s.wavelength_nm.push_back(nm);
    s.value.push_back(blue.Evaluate(nm) + yellow.Evaluate(nm));
  }
  return Normalized(s);
}

SampledSpectrum BlackbodySpectrum(double temperature_k, double lower_nm, double upper_nm) {
  SampledSpectrum s;
  const double h = 6.62607015e-34, c = 2.99792458e8, k = 1.380649e-23;
  for (double nm = lower_nm; nm <= upper_nm + 1e-9; nm += 5) {
    const double lambda = nm * 1e-9;
    s.wavelength_nm.push_back(nm);
    s.value.push_back(1 / (std::pow(lambda, 5) * std::expm1(h * c / (lambda * k * temperature_k))));  // Planck's law
  }
  return Normalized(s);
}

}  // namespace phos
