#include "phos/model/photometry.h"

#include <algorithm>
#include <cmath>

#include "cie_tables.h"
#include "phos/util/csv.h"
#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {
namespace {

SampledSpectrum FromTable(const cie::UniformTable& table) {
  SampledSpectrum s;
  for (std::size_t i = 0; i < table.count; ++i) {
    s.wavelength_nm.push_back(table.first_nm + table.step_nm * static_cast<double>(i));
    s.value.push_back(table.values[i]);
  }
  return s;
}

std::vector<double> Scaled(std::vector<double> values, double scale) {
  for (double& v : values) v *= scale;
  return values;
}

double Dot(const std::vector<double>& a, const std::vector<double>& b) {
  PHOS_CHECK(a.size() == b.size());
  double sum = 0;
  for (std::size_t i = 0; i < a.size(); ++i) sum += a[i] * b[i];
  return sum;
}

}  // namespace

const SampledSpectrum& PhotopicEfficiency() {
  static const SampledSpectrum s = FromTable(cie::kPhotopicVTable);
  return s;
}

const SampledSpectrum& ScotopicEfficiency() {
  static const SampledSpectrum s = FromTable(cie::kScotopicVTable);
  return s;
}

const SampledSpectrum& IlluminantD65() {
  static const SampledSpectrum s = FromTable(cie::kD65Table);
  return s;
}

const SampledSpectrum& IlluminantF11() {
  static const SampledSpectrum s = FromTable(cie::kF11Table);
  return s;
}

SampledSpectrum IlluminantA() {
  // S_A(lambda) = 100 (560/lambda)^5 (e^{c2/(T 560 nm)} - 1) / (e^{c2/(T lambda)} - 1),
  // with the standard's own c2 = 1.435e7 nm K and T = 2848 K (2856 K on the
  // ITS-90 value of c2): the formula defines the illuminant.
  const double c2_nm_k = 1.435e7, t_k = 2848.0;
  SampledSpectrum s;
  for (int nm = 300; nm <= 830; nm += 5) {
    const double lambda = nm;
    s.wavelength_nm.push_back(lambda);
    s.value.push_back(100.0 * std::pow(560.0 / lambda, 5) * std::expm1(c2_nm_k / (t_k * 560.0)) /
                      std::expm1(c2_nm_k / (t_k * lambda)));
  }
  return s;
}

std::optional<SampledSpectrum> StandardSource(std::string_view name) {
  if (name == "d65") return IlluminantD65();
  if (name == "a") return IlluminantA();
  if (name == "fluorescent") return IlluminantF11();
  if (name == "led405") return LedSpectrum(405.0, 15.0);  // the simulated lab's led405 (acquire/src/sim_lab.cpp)
  return std::nullopt;
}

std::string StandardSourceNames() { return "d65, a, fluorescent, led405"; }

SampledSpectrum LoadSpectrumCsv(const std::string& path) {
  const CsvTable table = ReadCsv(path);
  const int nm = table.Find("wavelength_nm"), value = table.Find("irradiance");
  if (nm < 0 || value < 0) ThrowUserError(path, "", "a spectrum needs the columns wavelength_nm and irradiance");
  SampledSpectrum s{table.columns[nm], table.columns[value]};
  if (s.value.size() < 2) ThrowUserError(path, "", "a spectrum needs at least 2 rows");
  for (std::size_t i = 0; i < s.value.size(); ++i) {
    if (s.value[i] < 0) ThrowUserError(path, "irradiance", "expected values >= 0, got " + FormatDouble(s.value[i]));
    if (i > 0 && !(s.wavelength_nm[i] > s.wavelength_nm[i - 1]))
      ThrowUserError(path, "wavelength_nm",
                     "must increase (" + FormatDouble(s.wavelength_nm[i]) + " follows " +
                         FormatDouble(s.wavelength_nm[i - 1]) + ")");
  }
  return s;
}

double IntegrateProduct(const SampledSpectrum& a, const SampledSpectrum& b) {
  if (a.wavelength_nm.size() < 2 || b.wavelength_nm.size() < 2) return 0.0;
  const double lower = std::max(a.wavelength_nm.front(), b.wavelength_nm.front());
  const double upper = std::min(a.wavelength_nm.back(), b.wavelength_nm.back());
  if (!(upper > lower)) return 0.0;
  // Every sample of either inside the overlap: between two of them both are
  // linear, their product quadratic, and Simpson's rule exact.
  std::vector<double> x = {lower, upper};
  for (const SampledSpectrum* s : {&a, &b})
    for (double nm : s->wavelength_nm)
      if (nm > lower && nm < upper) x.push_back(nm);
  std::sort(x.begin(), x.end());
  x.erase(std::unique(x.begin(), x.end()), x.end());
  auto f = [&](double nm) { return a.Evaluate(nm) * b.Evaluate(nm); };
  double total = 0.0;
  for (std::size_t i = 0; i + 1 < x.size(); ++i)
    total += (x[i + 1] - x[i]) / 6.0 * (f(x[i]) + 4.0 * f(0.5 * (x[i] + x[i + 1])) + f(x[i + 1]));
  return total;
}

double IntegrateAll(const SampledSpectrum& s) {
  return s.wavelength_nm.empty() ? 0.0 : s.Integrate(s.wavelength_nm.front(), s.wavelength_nm.back());
}

double PhotopicIntegral(const SampledSpectrum& s) {
  return kPhotopicEfficacyLmPerW * IntegrateProduct(s, PhotopicEfficiency());
}

double ScotopicIntegral(const SampledSpectrum& s) {
  return kScotopicEfficacyLmPerW * IntegrateProduct(s, ScotopicEfficiency());
}

double ScaleForPhotometric(const SampledSpectrum& s, double photometric, const std::string& what) {
  const double unit = PhotopicIntegral(s);
  if (!(unit > 0))
    ThrowUserError(what, "", "its spectrum has no light V(lambda) sees (360-830 nm): no photometric value scales it");
  return photometric / unit;
}

double ScaleForRadiometric(const SampledSpectrum& s, double radiometric, const std::string& what) {
  const double unit = IntegrateAll(s);
  if (!(unit > 0)) ThrowUserError(what, "", "its spectrum integrates to 0: no irradiance scales it");
  return radiometric / unit;
}

std::vector<double> PhotopicBandEfficacy(const SpectralGrid& grid) {
  return Scaled(AverageOverBands(PhotopicEfficiency(), grid), kPhotopicEfficacyLmPerW);
}

std::vector<double> ScotopicBandEfficacy(const SpectralGrid& grid) {
  return Scaled(AverageOverBands(ScotopicEfficiency(), grid), kScotopicEfficacyLmPerW);
}

double Luminance(const std::vector<double>& band_radiance_w_sr_m2, const SpectralGrid& grid) {
  return Dot(band_radiance_w_sr_m2, PhotopicBandEfficacy(grid));
}

double ScotopicLuminance(const std::vector<double>& band_radiance_w_sr_m2, const SpectralGrid& grid) {
  return Dot(band_radiance_w_sr_m2, ScotopicBandEfficacy(grid));
}

std::vector<double> BandsForPhotometric(const SampledSpectrum& s, double photometric, const SpectralGrid& grid,
                                        const std::string& what) {
  return Scaled(IntegrateOverBands(s, grid), ScaleForPhotometric(s, photometric, what));
}

std::vector<double> BandsForRadiometric(const SampledSpectrum& s, double radiometric, const SpectralGrid& grid,
                                        const std::string& what) {
  return Scaled(IntegrateOverBands(s, grid), ScaleForRadiometric(s, radiometric, what));
}

}  // namespace phos
