// phos afterglow: the standard test of a glow product, simulated
// (docs/afterglow.md). A physical material starts dark (fully discharged), is
// charged for --charge-s under a source at --illuminance-lux (or
// --irradiance-w-m2), and is then read in the dark, as DIN 67510-1 measures a
// product: the luminance at --at-min minutes after the light went off, the
// time until it falls below --threshold-mcd, and the marking L10/L60 - t.
//
// Everything is closed form (closed_form.h): the charge from r = 0 under a
// constant excitation rate a_i = sum_b ke_i[b] E[b] is ChargedState (Eq. 8.1),
// the dark that follows multiplies each state by DecayFactor = e^{-kr t}, Eq.
// 8.2 gives the band radiance, and photometry.h its luminance.

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "cli_finite.h"
#include "commands.h"
#include "phos/model/closed_form.h"
#include "phos/model/material.h"
#include "phos/model/photometry.h"
#include "phos/model/schedule.h"
#include "phos/model/simulate.h"
#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos::app {
namespace {

struct AfterglowArgs {
  std::string material;
  std::string source = "d65";
  double illuminance_lux = 1000, irradiance_w_m2 = 0, charge_s = 300, threshold_mcd = 0.3;
  std::vector<double> at_min = {2, 10, 30, 60};
  bool json = false;
  CLI::Option* lux_option = nullptr;
  CLI::Option* w_m2_option = nullptr;
};

// A search for the threshold gives up past this many seconds (32,000 years).
constexpr double kLongestSearch_s = 1e12;

// The source's spectral shape: a named one (photometry.h) or a spectrum file.
SampledSpectrum SourceSpectrum(const std::string& source) {
  if (std::optional<SampledSpectrum> named = StandardSource(source)) return *named;
  if (source == "xenon")
    ThrowUserError("", "--source",
                   "xenon: phos ships no sourced xenon-lamp table; give the lamp's measured spectrum as a file "
                   "(columns wavelength_nm,irradiance)");
  std::error_code ec;
  if (!std::filesystem::exists(source, ec))
    ThrowUserError(
        "", "--source",
        "expected " + StandardSourceNames() + " or a spectrum file (wavelength_nm,irradiance), got \"" + source + "\"");
  return LoadSpectrumCsv(source);
}

// What the charge was: the source's band irradiance E[b] in W/m² on the
// material's grid, its illuminance and its irradiance over its whole spectrum.
struct Charge {
  std::vector<double> E;
  double lux = 0, w_m2 = 0;
  double lower_nm = 0, upper_nm = 0;  // the spectrum's range, over which w_m2 is given
};

Charge ChargeOf(const AfterglowArgs& args, const Material& material) {
  if (args.lux_option->count() > 0 && args.w_m2_option->count() > 0)
    ThrowUserError("", "--irradiance-w-m2", "give --illuminance-lux or --irradiance-w-m2, not both");
  const SampledSpectrum spectrum = SourceSpectrum(args.source);
  const std::string what = "--source " + args.source;
  const bool radiometric = args.w_m2_option->count() > 0;
  const double scale = radiometric ? ScaleForRadiometric(spectrum, args.irradiance_w_m2, what)
                                   : ScaleForPhotometric(spectrum, args.illuminance_lux, what);
  Charge charge;
  charge.E = IntegrateOverBands(spectrum, material.bands);
  for (double& e : charge.E) e *= scale;
  // The value given is reported as given; the other follows from the spectrum.
  charge.lux = radiometric ? scale * PhotopicIntegral(spectrum) : args.illuminance_lux;
  charge.w_m2 = radiometric ? args.irradiance_w_m2 : scale * IntegrateAll(spectrum);
  charge.lower_nm = spectrum.wavelength_nm.front();
  charge.upper_nm = spectrum.wavelength_nm.back();
  for (int b = 0; b < material.band_count(); ++b)
    if (charge.E[b] > kMaxIrradiance)
      ThrowUserError("", radiometric ? "--irradiance-w-m2" : "--illuminance-lux",
                     "gives " + FormatShort(charge.E[b]) + " W/m² in band " + material.bands.BandName(b) +
                         ", above the limit of " + FormatDouble(kMaxIrradiance));
  return charge;
}

// Every state at the end of the charge, from dark (r = 0): Eq. 8.1 in closed form.
std::vector<double> ChargedStates(const Material& material, const Charge& charge, const AfterglowArgs& args) {
  const std::vector<double> a =
      ExcitationRates(material, charge.E, args.material, "measure ke there, or use a source without light there",
                      [&](int b) { return "--source " + args.source + " (" + FormatShort(charge.E[b]) + " W/m²)"; });
  std::vector<double> r(a.size());
  for (std::size_t i = 0; i < a.size(); ++i) r[i] = ChargedState(a[i], material.states[i].kr, args.charge_s);
  return r;
}

// The luminance in cd/m² t_s seconds after the light went off: each state
// decays as e^{-kr t} (DecayFactor), Eq. 8.2 gives the band radiance.
double LuminanceAfter(const Material& material, const std::vector<double>& r_end, double t_s) {
  std::vector<double> r(r_end.size());
  for (std::size_t i = 0; i < r.size(); ++i) r[i] = r_end[i] * DecayFactor(material.states[i].kr, t_s);
  return Luminance(EmittedRadiance(material, r.data()), material.bands);
}

// The time after which the luminance is below `threshold` cd/m²: a sum of
// decaying exponentials with weights >= 0 never rises, so bisection finds it
// (0 if it starts below; nullopt past kLongestSearch_s).
std::optional<double> TimeToThreshold(const Material& material, const std::vector<double>& r_end, double threshold) {
  auto above = [&](double t_s) { return LuminanceAfter(material, r_end, t_s) >= threshold; };
  if (!above(0)) return 0.0;
  double lo = 0, hi = 1;
  while (above(hi)) {
    if (hi >= kLongestSearch_s) return std::nullopt;
    lo = hi;
    hi *= 2;
  }
  while (hi - lo > 1e-12 * hi) {
    const double mid = 0.5 * (lo + hi);
    if (mid <= lo || mid >= hi) break;  // no double between them
    (above(mid) ? lo : hi) = mid;
  }
  return hi;
}

// A luminance as a sign's label gives it: 3 significant digits, no exponent.
std::string ThreeDigits(double value) {
  const int decimals = value > 0 ? std::max(0, 2 - static_cast<int>(std::floor(std::log10(value)))) : 0;
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", decimals, value);
  return text;
}

// DIN 67510-1's form "L10/L60 - t": mcd/m² at 10 and 60 min, and the whole
// minutes until the threshold.
std::string Marking(double l10_mcd, double l60_mcd, std::optional<double> t_s) {
  const std::string minutes = t_s ? std::to_string(static_cast<long long>(std::floor(*t_s / 60))) : "never";
  return ThreeDigits(l10_mcd) + "/" + ThreeDigits(l60_mcd) + " - " + minutes;
}

void RunAfterglow(const AfterglowArgs& args) {
  const Material material = LoadMaterial(args.material);
  if (material.units != Units::kPhysical)
    ThrowUserError(args.material, "units",
                   "a relative material has no luminance in cd/m²: phos afterglow needs \"units\": \"physical\" "
                   "(ke in 1/s per W/m², Lambda in W/(sr m²) per 1/s of kr r)");
  const Charge charge = ChargeOf(args, material);
  const std::vector<double> r_end = ChargedStates(material, charge, args);
  nlohmann::ordered_json out;  // keys in the order docs/formats.md gives them
  out["at_s"] = nlohmann::ordered_json::array();
  out["luminance_mcd_m2"] = nlohmann::ordered_json::array();
  for (double minutes : args.at_min) {
    out["at_s"].push_back(60 * minutes);
    out["luminance_mcd_m2"].push_back(1e3 * LuminanceAfter(material, r_end, 60 * minutes));
  }
  const std::optional<double> t_s = TimeToThreshold(material, r_end, 1e-3 * args.threshold_mcd);
  out["time_to_threshold_s"] = t_s ? nlohmann::json(*t_s) : nlohmann::json(nullptr);
  out["threshold_mcd_m2"] = args.threshold_mcd;
  out["source"] = args.source;
  out["illuminance_lux"] = charge.lux;
  out["irradiance_w_m2"] = charge.w_m2;
  out["charge_s"] = args.charge_s;
  out["marking"] =
      Marking(1e3 * LuminanceAfter(material, r_end, 600), 1e3 * LuminanceAfter(material, r_end, 3600), t_s);
  if (args.json) {
    std::printf("%s\n", out.dump().c_str());
    return;
  }
  std::printf("'%s' from dark, charged %s s by %s at %s lx (%s W/m² over %s-%s nm), then dark:\n",
              material.name.c_str(), FormatShort(args.charge_s).c_str(), args.source.c_str(),
              FormatShort(charge.lux).c_str(), FormatShort(charge.w_m2).c_str(), FormatShort(charge.lower_nm).c_str(),
              FormatShort(charge.upper_nm).c_str());
  for (std::size_t m = 0; m < args.at_min.size(); ++m)
    std::printf("  %8s min  %s mcd/m²\n", FormatShort(args.at_min[m]).c_str(),
                ThreeDigits(out["luminance_mcd_m2"][m].get<double>()).c_str());
  const std::string threshold = FormatShort(args.threshold_mcd) + " mcd/m²";
  if (t_s)
    std::printf("below %s after %s s (%s min)\n", threshold.c_str(), FormatShort(*t_s, 6).c_str(),
                FormatShort(std::floor(*t_s / 6) / 10, 6).c_str());
  else
    std::printf("still above %s after %s s\n", threshold.c_str(), FormatShort(kLongestSearch_s).c_str());
  std::printf("marking (DIN 67510-1 style, L10/L60 - t(%s) in mcd/m² and min): %s\n",
              FormatShort(args.threshold_mcd).c_str(), out["marking"].get<std::string>().c_str());
}

}  // namespace

void RegisterAfterglow(CLI::App& app) {
  auto args = std::make_shared<AfterglowArgs>();
  CLI::App* cmd = app.add_subcommand("afterglow", Summary("afterglow"));
  cmd->add_option("material", args->material, "material file (phos.material/1, \"units\": \"physical\")")->required();
  cmd->add_option("--source", args->source,
                  "the charging light: " + StandardSourceNames() +
                      " (CIE D65, CIE A, CIE F11 of 4000 K, a 405 nm LED),\n"
                      "or a spectrum file (columns wavelength_nm,irradiance; any scale)")
      ->capture_default_str();
  args->lux_option = cmd->add_option("--illuminance-lux", args->illuminance_lux, "illuminance of the source, lx")
                         ->check(kPositive)
                         ->capture_default_str();
  args->w_m2_option = cmd->add_option("--irradiance-w-m2", args->irradiance_w_m2,
                                      "instead of --illuminance-lux: irradiance over the source's whole spectrum, W/m²")
                          ->check(kPositive);
  cmd->add_option("--charge-s", args->charge_s, "seconds of charging, from dark (fully discharged)")
      ->check(kPositive)
      ->capture_default_str();
  cmd->add_option("--at-min", args->at_min, "minutes after the light goes off at which to read the luminance")
      ->delimiter(',')
      ->check(kNonNegative)
      ->capture_default_str();
  cmd->add_option("--threshold-mcd", args->threshold_mcd, "the luminance whose time is sought, mcd/m²")
      ->check(kPositive)
      ->capture_default_str();
  cmd->add_flag("--json", args->json, "print one JSON object");
  cmd->callback([args] { RunAfterglow(*args); });
}

}  // namespace phos::app
