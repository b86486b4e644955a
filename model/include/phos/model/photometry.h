#pragma once
// Photometry: what a luminance meter reads of phos's band radiances, and the
// band irradiances of a light given in lux. The one owner of the CIE tables
// (model/src/cie_tables.cpp names their sources; docs/formats.md, "Units").
//
// Photometric = K_m * integral of (spectral radiometric quantity) V(lambda)
// d lambda: lm from W, cd from W/sr, lx from W/m², cd/m² from W/(sr m²).
// phos keeps radiometric quantities in W and applies K_m here. pbrt-v4
// divides a light's spectrum by the integral of S ybar (SpectrumToPhotometric,
// without K_m) and multiplies by the target power or illuminance; Filament
// carries photometric units (lm, cd, lx) into a luminance image directly.
// Both leave out the 683: phos's radiances are in W/(sr m²) and its
// luminances in cd/m².
//
// Spectra are piecewise linear between their samples (SampledSpectrum) and
// integrated exactly as such. Band values assume a uniform spectral density
// inside each band, as RebinIntegrated does: the luminance of band radiances
// is K_m sum_b L[b] mean_b(V), exact when the radiance is flat inside each
// band, and an approximation (of the band grid, not of the tables) otherwise.

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "phos/model/spectral.h"

namespace phos {

// K_m, the maximum luminous efficacy of photopic vision, 683 lm/W, and K'_m,
// of scotopic vision, 1700 lm/W: the values CIE S 010/ISO 23539:2005 rounds
// them to (the SI fixes 683 lm/W at 540 THz, where V = 0.999998..., whence
// the 683.002 and 1700.06 sometimes quoted; the difference is below 4e-5).
inline constexpr double kPhotopicEfficacyLmPerW = 683.0;
inline constexpr double kScotopicEfficacyLmPerW = 1700.0;

// The CIE tables, linear between their samples and 0 outside them.
// V(lambda), the CIE 1924 photopic luminous efficiency (= ybar of the CIE
// 1931 2-degree observer), 360-830 nm at 1 nm.
const SampledSpectrum& PhotopicEfficiency();
// V'(lambda), the CIE 1951 scotopic luminous efficiency, 380-780 nm at 1 nm.
const SampledSpectrum& ScotopicEfficiency();
// CIE standard illuminant D65, 300-830 nm at 5 nm, 100 at 560 nm.
const SampledSpectrum& IlluminantD65();
// CIE illuminant F11 (a three-band fluorescent tube of 4000 K), 380-780 nm at 5 nm.
const SampledSpectrum& IlluminantF11();
// CIE standard illuminant A (a tungsten lamp at 2856 K) by its defining
// Planck formula (CIE 15:2004; ISO 11664-2:2007), 300-830 nm at 5 nm, 100 at 560 nm.
SampledSpectrum IlluminantA();

// The named sources of `phos afterglow --source`: "d65", "a", "fluorescent"
// (F11), "led405" (a Gaussian of peak 405 nm and FWHM 15 nm: a definition,
// as the simulated lab's led405, not a measurement). nullopt for another name.
std::optional<SampledSpectrum> StandardSource(std::string_view name);
// The names StandardSource knows, for messages and --help: "d65, a, fluorescent, led405".
std::string StandardSourceNames();

// A spectrum from a text table with columns wavelength_nm (increasing) and
// irradiance (>= 0, any scale: a relative spectral distribution is enough).
// A bad table is a UserError naming the file.
SampledSpectrum LoadSpectrumCsv(const std::string& path);

// The integral of a(lambda) b(lambda) over all wavelengths, exact for two
// piecewise-linear spectra (Simpson's rule on every piece between their samples).
double IntegrateProduct(const SampledSpectrum& a, const SampledSpectrum& b);
// The integral of a spectrum over its whole tabulated range.
double IntegrateAll(const SampledSpectrum& s);

// K_m times the integral of S V: the photometric value of a spectral density
// (lx of W/(m² nm), cd/m² of W/(sr m² nm), cd of W/(sr nm)). Scotopic: K'_m, V'.
double PhotopicIntegral(const SampledSpectrum& s);
double ScotopicIntegral(const SampledSpectrum& s);

// The factor k for which k S has the photometric value `photometric` (a light
// of 100 cd, 1000 lx, 5 cd/m²): photometric / PhotopicIntegral(S). A spectrum
// that V does not see (PhotopicIntegral 0) is a UserError naming `what`.
double ScaleForPhotometric(const SampledSpectrum& s, double photometric, const std::string& what);
// The factor k for which k S integrates to `radiometric` (W/m², W/sr, ...)
// over S's tabulated range.
double ScaleForRadiometric(const SampledSpectrum& s, double radiometric, const std::string& what);

// Per band, K_m times the mean of V over the band: the luminance in cd/m² of
// 1 W/(sr m²) of band radiance spread evenly over the band (and the lux of
// 1 W/m² of band irradiance). The renderer's Y = sum_b weight[b] L[b].
std::vector<double> PhotopicBandEfficacy(const SpectralGrid& grid);
// The same with K'_m and V'.
std::vector<double> ScotopicBandEfficacy(const SpectralGrid& grid);
// Luminance in cd/m² of band radiances in W/(sr m²) (one per band of grid).
double Luminance(const std::vector<double>& band_radiance_w_sr_m2, const SpectralGrid& grid);
// Scotopic luminance in scotopic cd/m².
double ScotopicLuminance(const std::vector<double>& band_radiance_w_sr_m2, const SpectralGrid& grid);

// The band integrals of a spectral shape S scaled to a photometric value
// (ScaleForPhotometric): per band, W/m² of a source at `photometric` lx (the
// E[b] of Eq. 8.1), W/sr of a light of that many cd, W/(sr m²) of a surface
// of that many cd/m². `what` names the source in errors.
std::vector<double> BandsForPhotometric(const SampledSpectrum& s, double photometric, const SpectralGrid& grid,
                                        const std::string& what);
// The same scaled to a radiometric value over S's tabulated range
// (ScaleForRadiometric): W/m² per band of a source of `radiometric` W/m².
std::vector<double> BandsForRadiometric(const SampledSpectrum& s, double radiometric, const SpectralGrid& grid,
                                        const std::string& what);

}  // namespace phos
