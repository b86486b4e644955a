// phos simulate: one point of a material under a charge-then-dark schedule
// (docs/formats.md, "What the commands write"). CSV t,r_1..r_nc,L_1..L_n or JSON {"t","r","L"};
// a physical material adds the luminance in cd/m² (luminance_cd_m2, photometry.h).

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <CLI/CLI.hpp>

#include "cli_finite.h"
#include "commands.h"
#include "phos/model/material.h"
#include "phos/model/photometry.h"
#include "phos/model/simulate.h"
#include "phos/util/atomic_file.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/svg_plot.h"

namespace phos::app {
namespace {

struct SimulateArgs {
  std::string material;
  double charge_s = 0, decay_s = 0, dt_s = 1;
  std::string irradiance;
  std::string integrator = "exact";
  std::string r0;
  std::string out, plot;
  bool json = false, allow_unstable = false;
};

// "1" means the same irradiance in every band; "a,b,..." one value per band.
std::vector<double> ParseBandValues(const std::string& text, int band_count, const std::string& option, double lower,
                                    double upper) {
  std::vector<double> values;
  std::string bad;
  if (!ParseDoubleList(text, &values, &bad))
    ThrowUserError("", option, "expected a number or a comma-separated list of numbers, got \"" + bad + "\"");
  if (values.size() == 1) values.assign(static_cast<std::size_t>(band_count), values[0]);
  if (static_cast<int>(values.size()) != band_count)
    ThrowUserError(
        "", option,
        "expected 1 value or " + std::to_string(band_count) + " (one per band), got " + std::to_string(values.size()));
  for (double v : values)
    if (v < lower || v > upper)
      ThrowUserError(
          "", option,
          "expected values in [" + FormatDouble(lower) + ", " + FormatDouble(upper) + "], got " + FormatDouble(v));
  return values;
}

// The luminance in cd/m² of every sample of a physical material (empty for a
// relative one, whose radiance has no absolute scale).
std::vector<double> LuminanceOf(const SimulationResult& result, const Material& material) {
  if (material.units != Units::kPhysical) return {};
  const std::vector<double> efficacy = PhotopicBandEfficacy(material.bands);
  std::vector<double> Y(result.sample_count(), 0.0);
  for (std::size_t m = 0; m < result.sample_count(); ++m)
    for (int b = 0; b < result.nb; ++b) Y[m] += efficacy[b] * result.radiance(m, b);
  return Y;
}

std::string ToCsv(const SimulationResult& result, const std::vector<double>& luminance) {
  std::ostringstream out;
  out << "t";
  for (int i = 1; i <= result.nc; ++i) out << ",r_" << i;
  for (int b = 1; b <= result.nb; ++b) out << ",L_" << b;
  if (!luminance.empty()) out << ",luminance_cd_m2";
  out << "\n";
  for (std::size_t m = 0; m < result.sample_count(); ++m) {
    out << FormatDouble(result.t_s[m]);
    for (int i = 0; i < result.nc; ++i) out << "," << FormatDouble(result.state(m, i));
    for (int b = 0; b < result.nb; ++b) out << "," << FormatDouble(result.radiance(m, b));
    if (!luminance.empty()) out << "," << FormatDouble(luminance[m]);
    out << "\n";
  }
  return out.str();
}

// Written by hand rather than through a JSON tree: a long run has millions of numbers.
std::string ToJson(const SimulationResult& result, const std::vector<double>& luminance,
                   const std::string& integrator) {
  std::ostringstream out;
  auto rows = [&](const std::vector<double>& data, int width) {
    out << "[";
    for (std::size_t m = 0; m < result.sample_count(); ++m) {
      out << (m ? ",[" : "[");
      for (int i = 0; i < width; ++i) out << (i ? "," : "") << FormatDouble(data[m * width + i]);
      out << "]";
    }
    out << "]";
  };
  out << "{\"t\":[";
  for (std::size_t m = 0; m < result.sample_count(); ++m) out << (m ? "," : "") << FormatDouble(result.t_s[m]);
  out << "],\"r\":";
  rows(result.r, result.nc);
  out << ",\"L\":";
  rows(result.L, result.nb);
  if (!luminance.empty()) {
    out << ",\"luminance_cd_m2\":[";
    for (std::size_t m = 0; m < luminance.size(); ++m) out << (m ? "," : "") << FormatDouble(luminance[m]);
    out << "]";
  }
  out << ",\"integrator\":\"" << integrator << "\",\"steps\":" << result.steps << ",\"warnings\":[";
  for (std::size_t w = 0; w < result.warnings.size(); ++w)
    out << (w ? "," : "") << nlohmann::json(result.warnings[w]).dump();
  out << "]}\n";
  return out.str();
}

std::string ToSvg(const SimulationResult& result, const Material& material, double charge_s) {
  std::vector<PlotSeries> series;
  PlotSeries total{"total"};
  total.color = "#000000";
  total.x = result.t_s;
  total.y.assign(result.sample_count(), 0.0);
  for (int b = 0; b < result.nb; ++b) {
    PlotSeries s{material.bands.BandName(b)};
    s.color = WavelengthColor(material.bands.center_nm(b));
    s.x = result.t_s;
    bool any = false;
    for (std::size_t m = 0; m < result.sample_count(); ++m) {
      s.y.push_back(result.radiance(m, b));
      total.y[m] += result.radiance(m, b);
      any = any || result.radiance(m, b) > 0;
    }
    if (any) series.push_back(std::move(s));
  }
  series.insert(series.begin(), total);
  PlotOptions options;
  options.title = "'" + material.name + "': emitted radiance (charge " + FormatDouble(charge_s) + " s, then dark)";
  options.x_label = "time since the start of the charge (s)";
  options.y_label = material.units == Units::kPhysical ? "emitted radiance Lp per band (W/(sr m²))"
                                                       : "emitted radiance Lp per band (unit of Lambda)";
  return PlotSvg(series, options);
}

// One sample every --dt from 0 reaches the end of the schedule only when --dt
// divides it (--dt 3 over 20 s stops at 18): then the state at the end is
// added as a last sample, stepped from the last one over what is left of the
// schedule by the same integrator. An end within rounding of the last sample
// is that sample; a charge of 1e-12 --dt alone is not (SameTime).
void SampleTheEnd(const Material& material, const std::vector<double>& E, const SimulateArgs& args,
                  const SimulationOptions& options, SimulationResult* result) {
  const double total = args.charge_s + args.decay_s, last = result->t_s.back();
  if (!(total > last) || SameTime(total, last)) return;
  SimulationOptions rest = options;
  rest.dt_s = total - last;
  rest.r0.assign(result->r.end() - result->nc, result->r.end());
  const double charge_left = std::max(0.0, args.charge_s - last);
  const SimulationResult tail = Simulate(
      material, IrradianceSchedule::ChargeThenDecay(E, charge_left, charge_left > 0 ? args.decay_s : total - last),
      rest, args.material);
  result->t_s.push_back(total);
  result->r.insert(result->r.end(), tail.r.end() - tail.nc, tail.r.end());
  result->L.insert(result->L.end(), tail.L.end() - tail.nb, tail.L.end());
  result->steps += tail.steps;
}

void RunSimulate(const SimulateArgs& args) {
  RequireOutputFile(args.out, "--out");
  RequireOutputFile(args.plot, "--plot", kSvgExtension);
  Material material = LoadMaterial(args.material);
  const int nb = material.band_count();
  if (args.charge_s < 0) ThrowUserError("", "--charge-s", "expected seconds >= 0, got " + FormatDouble(args.charge_s));
  if (args.decay_s < 0) ThrowUserError("", "--decay-s", "expected seconds >= 0, got " + FormatDouble(args.decay_s));
  if (args.charge_s + args.decay_s <= 0)
    ThrowUserError("", "--charge-s", "nothing to simulate: give --charge-s or --decay-s > 0");
  std::vector<double> E(static_cast<std::size_t>(nb), 0.0);
  if (!args.irradiance.empty())
    E = ParseBandValues(args.irradiance, nb, "--irradiance", 0.0, kMaxIrradiance);
  else if (args.charge_s > 0)
    ThrowUserError("", "--irradiance", "required when --charge-s > 0");

  SimulationOptions options;
  auto integrator = ParseIntegrator(args.integrator);
  if (!integrator)
    ThrowUserError("", "--integrator", "expected exact, euler, rk4 or reference, got \"" + args.integrator + "\"");
  options.integrator = *integrator;
  options.dt_s = args.dt_s;
  options.allow_unstable = args.allow_unstable;
  if (!args.r0.empty()) options.r0 = ParseBandValues(args.r0, material.state_count(), "--r0", 0.0, 1.0);

  SimulationResult result =
      Simulate(material, IrradianceSchedule::ChargeThenDecay(E, args.charge_s, args.decay_s), options, args.material);
  SampleTheEnd(material, E, args, options, &result);
  for (const std::string& w : result.warnings) std::fprintf(stderr, "phos simulate: warning: %s\n", w.c_str());

  const std::vector<double> luminance = LuminanceOf(result, material);
  std::string text = args.json ? ToJson(result, luminance, args.integrator) : ToCsv(result, luminance);
  if (!args.plot.empty()) WriteFileAtomically(args.plot, ToSvg(result, material, args.charge_s));
  if (args.out.empty()) {
    std::fwrite(text.data(), 1, text.size(), stdout);
  } else {
    WriteFileAtomically(args.out, text);
  }
}

}  // namespace

void RegisterSimulate(CLI::App& app) {
  auto args = std::make_shared<SimulateArgs>();
  CLI::App* cmd = app.add_subcommand("simulate", Summary("simulate"));
  cmd->add_option("--material", args->material, "material file (phos.material/1)")->required();
  cmd->add_option("--charge-s", args->charge_s, "seconds of charging under --irradiance (default 0)")->check(kFinite);
  cmd->add_option("--irradiance", args->irradiance,
                  "band-integrated irradiance E while charging: one number (every band) or a comma list,\n"
                  "one value per band of the material (W/m² for a physical material); bands whose ke is unknown\n"
                  "must get 0");
  cmd->add_option("--decay-s", args->decay_s, "seconds of darkness after the charge (default 0)")->check(kFinite);
  cmd->add_option("--dt", args->dt_s,
                  "sample interval and step in seconds (default 1); the end of the schedule is sampled too\n"
                  "when --dt does not divide it")
      ->check(kFinite);
  cmd->add_option("--integrator", args->integrator,
                  "exact (default: closed form, stable for any step), euler (the paper's; refused past\n"
                  "h*k > 2, warned past h*k > 1), rk4 (refused past h*k > 2.785), reference (adaptive\n"
                  "Dormand-Prince in long double, for studies)");
  cmd->add_option("--r0", args->r0, "initial state r per excited state (default 0), e.g. 1 to start saturated");
  cmd->add_flag("--allow-unstable", args->allow_unstable, "run euler/rk4 past their stability limit (with a warning)");
  cmd->add_flag("--json", args->json, "print one JSON object instead of CSV");
  cmd->add_option("--out", args->out, "write the CSV/JSON to this file instead of standard output");
  cmd->add_option("--plot", args->plot, "also write an SVG plot of the emitted radiance over time");
  cmd->callback([args] { RunSimulate(*args); });
}

}  // namespace phos::app
