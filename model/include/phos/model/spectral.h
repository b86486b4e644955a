#pragma once
// Spectral bands (Sec. 8.3). phos works on band-integrated quantities over a
// grid of bands given by their edges. The paper's grid is 8 bands of 37.5 nm
// from 400 to 700 nm; a material may carry any grid (UV LEDs excite below
// 400 nm), so the grid is data, never a constant scattered through the code.

#include <string>
#include <vector>

namespace phos {

struct SpectralGrid {
  std::vector<double> edges_nm;  // n + 1 strictly increasing edges

  // n bands of equal width from lower_nm to upper_nm.
  static SpectralGrid Uniform(double lower_nm, double upper_nm, int band_count);
  // The paper's grid: 8 bands of 37.5 nm from 400 to 700 nm.
  static SpectralGrid Paper() { return Uniform(400.0, 700.0, 8); }

  int band_count() const { return edges_nm.empty() ? 0 : static_cast<int>(edges_nm.size()) - 1; }
  double lower_nm(int b) const { return edges_nm[b]; }
  double upper_nm(int b) const { return edges_nm[b + 1]; }
  double center_nm(int b) const { return 0.5 * (edges_nm[b] + edges_nm[b + 1]); }
  double width_nm(int b) const { return edges_nm[b + 1] - edges_nm[b]; }
  // "512.5-550 nm", for messages.
  std::string BandName(int b) const;
  // "[400, 550, 700] nm": the edges, for messages.
  std::string EdgesName() const;
  bool operator==(const SpectralGrid&) const = default;
};

// A spectrum tabulated at increasing wavelengths, linear between samples and
// zero outside them (light emission spectra, camera sensitivities).
struct SampledSpectrum {
  std::vector<double> wavelength_nm;
  std::vector<double> value;

  double Evaluate(double wavelength_nm) const;
  // Exact integral of the piecewise-linear function over [lower_nm, upper_nm].
  double Integrate(double lower_nm, double upper_nm) const;
};

// Light and sensor spectra shared by the simulated lab and the renderer.
// Gaussian of peak `weight` (not normalized): camera sensitivities.
SampledSpectrum GaussianSpectrum(double center_nm, double fwhm_nm, double weight = 1.0);
// The following are normalized to unit integral, so a light's scale is its
// total irradiance (or intensity) alone.
SampledSpectrum LedSpectrum(double center_nm, double fwhm_nm);
// A phosphor-converted white LED: blue pump at 450 nm plus a broad yellow band.
SampledSpectrum WhiteLedSpectrum();
// Planck's law at temperature_k between lower_nm and upper_nm (a halogen lamp
// is 3000 K, the sun about 5778 K).
SampledSpectrum BlackbodySpectrum(double temperature_k, double lower_nm, double upper_nm);

// Band-integrated values of a spectral density (e.g. irradiance per nm ->
// irradiance per band, the E[b] of Eq. 8.1).
std::vector<double> IntegrateOverBands(const SampledSpectrum& spectrum, const SpectralGrid& grid);
// Band averages (e.g. a reflectance spectrum -> albedo per band).
std::vector<double> AverageOverBands(const SampledSpectrum& spectrum, const SpectralGrid& grid);

// Moves band-integrated values from one grid to another, assuming a uniform
// density inside each source band: the part of the total that falls inside
// both grids is conserved exactly.
std::vector<double> RebinIntegrated(const std::vector<double>& values, const SpectralGrid& from,
                                    const SpectralGrid& to);

}  // namespace phos
