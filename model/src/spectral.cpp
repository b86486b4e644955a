#include "phos/model/spectral.h"

#include <algorithm>
#include <cstdio>

#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {

SpectralGrid SpectralGrid::Uniform(double lower_nm, double upper_nm, int band_count) {
  PHOS_CHECK(band_count > 0 && upper_nm > lower_nm);
  SpectralGrid grid;
  grid.edges_nm.resize(static_cast<size_t>(band_count) + 1);
  for (int i = 0; i <= band_count; ++i)
    grid.edges_nm[i] = lower_nm + (upper_nm - lower_nm) * i / band_count;
  grid.edges_nm.back() = upper_nm;
  return grid;
}

std::string SpectralGrid::BandName(int b) const {
  return FormatDouble(lower_nm(b)) + "-" + FormatDouble(upper_nm(b)) + " nm";
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

}  // namespace phos
