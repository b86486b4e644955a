// phos fit decay-curve / charge-curve: fit curves from any instrument (plain
// CSV in, JSON out), as in the DESIGN.md contracts.

#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "commands.h"
#include "phos/fit/charge_fit.h"
#include "phos/fit/decay_fit.h"
#include "phos/util/csv.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/svg_plot.h"

namespace phos::app {

Weighting ParseWeightsOption(const std::string& text) {
  auto weighting = ParseWeighting(text);
  if (!weighting) ThrowUserError("", "--weights", "expected none or poisson, got \"" + text + "\"");
  return *weighting;
}

namespace {

struct CurveArgs {
  std::string csv, weights = "none", plot;
  int components = 0, max_components = 0;
  bool json = false, background = false, amplitude_stderr = false;
};

// First column: time in seconds; every further column: one channel.
Curve LoadCurve(const std::string& path) {
  CsvTable table = ReadCsv(path);
  if (table.header.size() < 2)
    ThrowUserError(path, "header", "expected columns t,value[,value...], got " + std::to_string(table.header.size()) +
                                       " column");
  Curve curve;
  curve.t_s = table.columns[0];
  for (std::size_t c = 1; c < table.header.size(); ++c) {
    curve.channels.push_back(table.columns[c]);
    curve.names.push_back(table.header[c]);
  }
  return curve;
}

// Data against the fitted model, on a log axis (exponentials are lines there).
template <typename Model>
void WritePlot(const std::string& path, const Curve& curve, Model model, const std::string& title, bool log_y) {
  std::vector<PlotSeries> series;
  for (int c = 0; c < curve.channel_count(); ++c) {
    PlotSeries data{curve.names[c]};
    data.x = curve.t_s;
    data.y = curve.channels[c];
    data.line = false;
    data.markers = true;
    data.color = PaletteColor(c);
    PlotSeries fitted{curve.names[c] + " (fit)"};
    // Drawn over the data: black for one channel, the channel's colour dashed for several.
    fitted.color = curve.channel_count() == 1 ? "#000000" : PaletteColor(c);
    fitted.dashed = curve.channel_count() > 1;
    for (int s = 0; s <= 400; ++s) {
      const double t = curve.t_s.front() + (curve.t_s.back() - curve.t_s.front()) * s / 400.0;
      fitted.x.push_back(t);
      fitted.y.push_back(model(c, t));
    }
    series.push_back(std::move(data));
    series.push_back(std::move(fitted));
  }
  PlotOptions options;
  options.title = title;
  options.x_label = "t (s)";
  options.y_label = "value";
  options.log_y = log_y;
  WriteFileAtomically(path, PlotSvg(series, options));
}

void RunDecayCurve(const CurveArgs& args) {
  Curve curve = LoadCurve(args.csv);
  DecayFitOptions options;
  if (args.components != 0) {
    if (args.components < 1 || args.components > 4)
      ThrowUserError("", "--components", "expected 1 to 4, got " + std::to_string(args.components));
    options.components = args.components;
  }
  if (args.max_components != 0) {
    if (args.max_components < 1 || args.max_components > 4)
      ThrowUserError("", "--max-components", "expected 1 to 4, got " + std::to_string(args.max_components));
    options.max_components = args.max_components;
  }
  options.weighting = ParseWeightsOption(args.weights);
  options.background = args.background;
  options.amplitude_uncertainties = args.amplitude_stderr;
  DecayFitSummary fit = FitDecay(curve, options, args.csv);

  if (!args.plot.empty())
    WritePlot(args.plot, curve, [&](int c, double t) { return EvaluateDecay(fit, c, t); },
              "Decay fit: " + std::to_string(fit.n_components) + " component(s)", true);
  if (args.json) {
    nlohmann::json j;
    j["components"] = nlohmann::json::array();
    for (const DecayComponent& component : fit.components) {
      nlohmann::json k = {{"amplitude", component.amplitude[0]},
                          {"rate", component.rate},
                          {"rate_stderr", component.rate_stderr}};
      if (args.amplitude_stderr) k["amplitude_stderr"] = component.amplitude_stderr[0];
      if (curve.channel_count() > 1) {
        k["amplitudes"] = component.amplitude;
        if (args.amplitude_stderr) k["amplitudes_stderr"] = component.amplitude_stderr;
      }
      j["components"].push_back(k);
    }
    j["rss"] = fit.rss;
    j["weighted_rss"] = fit.weighted_rss;
    j["n_components"] = fit.n_components;
    if (options.background) j["background"] = fit.background;
    nlohmann::json bic = nlohmann::json::array();
    for (double b : fit.bic) bic.push_back(std::isnan(b) ? nlohmann::json(nullptr) : nlohmann::json(b));
    j["bic"] = bic;
    j["choice"] = fit.choice;
    j["iterations"] = fit.iterations;
    j["weights"] = WeightingName(options.weighting);
    j["channels"] = curve.names;
    j["seconds"] = fit.seconds;
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  std::printf("%d component(s) (%s), rss %s, %.3g ms\n", fit.n_components, fit.choice.c_str(),
              FormatShort(fit.rss, 6).c_str(), fit.seconds * 1e3);
  for (const DecayComponent& component : fit.components) {
    std::printf("  rate %s +- %s /s", FormatShort(component.rate, 6).c_str(), FormatShort(component.rate_stderr, 2).c_str());
    for (int c = 0; c < curve.channel_count(); ++c) {
      std::printf("  %s %s", curve.names[c].c_str(), FormatShort(component.amplitude[c], 6).c_str());
      if (args.amplitude_stderr) std::printf(" +- %s", FormatShort(component.amplitude_stderr[c], 2).c_str());
    }
    std::printf("\n");
  }
}

void RunChargeCurve(const CurveArgs& args) {
  Curve curve = LoadCurve(args.csv);
  if (curve.channel_count() > 1)
    ThrowUserError(args.csv, "header", "expected one value column (t,value), got " + std::to_string(curve.channel_count()));
  ChargeFitOptions options;
  options.weighting = ParseWeightsOption(args.weights);
  ChargeFitSummary fit = FitCharge(curve, options, args.csv);
  if (!args.plot.empty())
    WritePlot(args.plot, curve,
              [&](int, double t) { return fit.Linf - (fit.Linf - fit.L0) * std::exp(-fit.rate * t); },
              "Charge fit", false);
  if (args.json) {
    nlohmann::json j = {{"L0", fit.L0},       {"Linf", fit.Linf},     {"rate", fit.rate},
                        {"L0_stderr", fit.L0_stderr}, {"Linf_stderr", fit.Linf_stderr}, {"rate_stderr", fit.rate_stderr},
                        {"rss", fit.rss},     {"weights", WeightingName(options.weighting)}, {"seconds", fit.seconds}};
    std::printf("%s\n", j.dump().c_str());
    return;
  }
  std::printf("L(t) = Linf - (Linf - L0) exp(-rate t): L0 %s +- %s, Linf %s +- %s, rate %s +- %s /s, rss %s\n",
              FormatShort(fit.L0, 6).c_str(), FormatShort(fit.L0_stderr, 2).c_str(), FormatShort(fit.Linf, 6).c_str(),
              FormatShort(fit.Linf_stderr, 2).c_str(), FormatShort(fit.rate, 6).c_str(),
              FormatShort(fit.rate_stderr, 2).c_str(), FormatShort(fit.rss, 6).c_str());
}

}  // namespace

void RegisterFitCurve(CLI::App& fit) {
  auto decay = std::make_shared<CurveArgs>();
  CLI::App* d = fit.add_subcommand(
      "decay-curve",
      "Fit sum_i amplitude_i exp(-rate_i t) (+ background) to a decay curve; rates shared by every channel,\n"
      "amplitudes >= 0. The number of components is fixed (--components) or chosen by BIC up to\n"
      "--max-components (default 3). Uncertainties are 1 sigma, scaled by the reduced chi-square.\n"
      "JSON: {\"components\":[{\"amplitude\",\"rate\",\"rate_stderr\",..}],\"rss\",\"n_components\",\"seconds\",..}");
  d->add_option("--csv", decay->csv, "CSV with a header; first column t (s), then one column per channel")->required();
  auto fixed = d->add_option("--components", decay->components, "fit exactly N components (1-4)");
  auto chosen = d->add_option("--max-components", decay->max_components, "choose the count by BIC, up to N (1-4; default 3)");
  fixed->excludes(chosen);
  d->add_option("--weights", decay->weights, "none (default) or poisson (photon counting: weight 1/sqrt(value))");
  d->add_flag("--background", decay->background, "also fit a constant background per channel");
  d->add_flag("--amplitude-stderr", decay->amplitude_stderr,
              "also report 1-sigma amplitude uncertainties (covariance of the full problem; doubles the time)");
  d->add_option("--plot", decay->plot, "write an SVG of the data against the fit (log axis)");
  d->add_flag("--json", decay->json, "print one JSON object");
  d->callback([decay] { RunDecayCurve(*decay); });

  auto charge = std::make_shared<CurveArgs>();
  CLI::App* c = fit.add_subcommand(
      "charge-curve",
      "Fit the saturating growth L(t) = Linf - (Linf - L0) exp(-rate t) to a charge curve.\n"
      "JSON: {\"L0\",\"Linf\",\"rate\",\"rss\",\"seconds\",..}");
  c->add_option("--csv", charge->csv, "CSV with a header: t,value")->required();
  c->add_option("--weights", charge->weights, "none (default) or poisson");
  c->add_option("--plot", charge->plot, "write an SVG of the data against the fit");
  c->add_flag("--json", charge->json, "print one JSON object");
  c->callback([charge] { RunChargeCurve(*charge); });
}

}  // namespace phos::app
