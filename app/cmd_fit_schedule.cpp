// phos fit schedule-curve: the rate equation (Eq. 8.1) fitted to one curve
// measured under a known light schedule (fit/schedule_fit.h), read as the
// other curve fits read theirs (app/curve_file.h).

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <CLI/CLI.hpp>

#include "cli_finite.h"
#include "commands.h"
#include "curve_file.h"
#include "phos/fit/schedule_fit.h"
#include "phos/util/atomic_file.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/svg_plot.h"

namespace phos::app {
namespace {

struct ScheduleArgs {
  std::string file, csv, weights = "none", plot;
  std::vector<std::string> light_on;  // T0:T1, as given
  std::optional<int> states, max_states;
  std::optional<double> predict_charge_s;
  int max_iterations = 200;
  bool json = false, keep_unconverged = false;
};

// "T0:T1" in seconds, T0 < T1, both finite.
LightWindow ParseLightOn(const std::string& text) {
  const std::size_t colon = text.find(':');
  const auto number = [&](const std::string& part, double* value) {
    char* end = nullptr;
    *value = std::strtod(part.c_str(), &end);
    return !part.empty() && end == part.c_str() + part.size() && std::isfinite(*value);
  };
  LightWindow window;
  if (colon == std::string::npos || !number(text.substr(0, colon), &window.on_s) ||
      !number(text.substr(colon + 1), &window.off_s))
    ThrowUserError("", "--light-on", "expected T0:T1 (seconds, the light on from T0 to T1), got \"" + text + "\"");
  if (!(window.on_s < window.off_s))
    ThrowUserError("", "--light-on", text + ": the light must go off after it goes on (T0 < T1)");
  return window;
}

// The options as the library takes them; a value out of range is one line naming its option.
ScheduleFitOptions OptionsOf(const ScheduleArgs& args) {
  ScheduleFitOptions options;
  for (const std::string& text : args.light_on) options.lights.push_back(ParseLightOn(text));
  std::sort(options.lights.begin(), options.lights.end(),
            [](const LightWindow& x, const LightWindow& y) { return x.on_s < y.on_s; });
  if (args.states && (*args.states < 1 || *args.states > 8))
    ThrowUserError("", "--states", "expected 1 to 8, got " + std::to_string(*args.states));
  if (args.max_states && (*args.max_states < 1 || *args.max_states > 8))
    ThrowUserError("", "--max-states", "expected 1 to 8, got " + std::to_string(*args.max_states));
  options.states = args.states.value_or(0);
  options.max_states = args.max_states.value_or(options.max_states);
  options.weighting = ParseWeightsOption(args.weights);
  options.max_iterations = args.max_iterations;
  options.keep_unconverged = args.keep_unconverged;
  if (args.predict_charge_s && !(*args.predict_charge_s > 0))
    ThrowUserError("", "--predict-charge-s",
                   "expected a charge of more than 0 s, got " + FormatShort(*args.predict_charge_s, 6));
  return options;
}

// The predicted curve after a charge of charge_s from a dark sample: 20
// times through the charge, then 10 a decade from the curve's smallest step
// after the switch-off to the longest dark part after a light in the curve.
struct Prediction {
  double charge_s = 0;
  std::vector<double> t_s;                  // from the light going on
  std::vector<std::vector<double>> values;  // per channel
};

Prediction Predict(const ScheduleFitSummary& fit, const Curve& curve, const std::vector<LightWindow>& lights,
                   double charge_s) {
  double longest_dark = 0;
  for (std::size_t w = 0; w < lights.size(); ++w)
    longest_dark =
        std::max(longest_dark, (w + 1 < lights.size() ? lights[w + 1].on_s : curve.t_s.back()) - lights[w].off_s);
  const double first = std::min(SmallestTimeStep(curve), longest_dark / 10);
  Prediction prediction;
  prediction.charge_s = charge_s;
  for (int k = 0; k < 20; ++k) prediction.t_s.push_back(charge_s * k / 20);
  const int decades = static_cast<int>(std::ceil(10 * std::log10(longest_dark / first)));
  prediction.t_s.push_back(charge_s);
  for (int k = 0; k <= decades; ++k) prediction.t_s.push_back(charge_s + first * std::pow(10.0, k / 10.0));
  prediction.values = EvaluateSchedule(fit, {{0, charge_s}}, 0, prediction.t_s);
  return prediction;
}

nlohmann::json StatesJson(const ScheduleFitSummary& fit) {
  nlohmann::json states = nlohmann::json::array();
  for (const ScheduleState& s : fit.states)
    states.push_back({{"kr", s.kr},
                      {"kr_stderr", s.kr_stderr},
                      {"charge_rate", s.charge_rate},
                      {"charge_rate_stderr", s.charge_rate_stderr},
                      {"emission", s.emission},
                      {"emission_stderr", s.emission_stderr}});
  return states;
}

nlohmann::json ResultJson(const LoadedCurve& loaded, const ScheduleFitOptions& options, const ScheduleFitSummary& fit,
                          const std::optional<Prediction>& prediction, const std::vector<std::string>& warnings) {
  nlohmann::json j;
  j["file"] = loaded.file;
  j["channels"] = loaded.curve.names;
  j["samples"] = loaded.curve.size();
  j["lights"] = nlohmann::json::array();
  for (const LightWindow& w : options.lights) j["lights"].push_back({{"on_s", w.on_s}, {"off_s", w.off_s}});
  j["initial_state"] = "dark (r = 0) at the first sample";
  j["n_states"] = fit.n_states;
  j["states"] = StatesJson(fit);
  j["prompt"] = fit.prompt;
  j["prompt_stderr"] = fit.prompt_stderr;
  j["background"] = fit.background;
  j["background_stderr"] = fit.background_stderr;
  j["residual_by_decade"] = nlohmann::json::array();
  for (const DecadeResidual& d : fit.residual_by_decade)
    j["residual_by_decade"].push_back({{"light", d.light + 1},
                                       {"from_s", d.from_s},
                                       {"to_s", d.to_s},
                                       {"samples", d.samples},
                                       {"rms_relative", d.rms_relative}});
  nlohmann::json bic = nlohmann::json::array();
  for (double b : fit.bic) bic.push_back(std::isnan(b) ? nlohmann::json(nullptr) : nlohmann::json(b));
  j["bic"] = bic;
  j["choice"] = fit.choice;
  j["rss"] = fit.rss;
  j["weighted_rss"] = fit.weighted_rss;
  j["weights"] = WeightingName(options.weighting);
  j["converged"] = fit.converged;
  j["iterations"] = fit.iterations;
  j["seconds"] = fit.seconds;
  if (prediction)
    j["prediction"] = {{"charge_s", prediction->charge_s}, {"t_s", prediction->t_s}, {"values", prediction->values}};
  j["warnings"] = warnings;
  return j;
}

std::string WithError(double value, double error) { return FormatShort(value, 6) + " +- " + FormatShort(error, 2); }

std::string ResultText(const LoadedCurve& loaded, const ScheduleFitSummary& fit,
                       const std::optional<Prediction>& prediction) {
  const Curve& curve = loaded.curve;
  char line[512];
  std::snprintf(line, sizeof line, "%d state(s) (%s), rss %s, %zu samples, %.3g s%s\n", fit.n_states,
                fit.choice.c_str(), FormatShort(fit.rss, 6).c_str(), curve.size(), fit.seconds,
                fit.converged ? "" : " (did not converge)");
  std::string text = line;
  for (std::size_t i = 0; i < fit.states.size(); ++i) {
    const ScheduleState& s = fit.states[i];
    text += "  state " + std::to_string(i + 1) + ": kr " + WithError(s.kr, s.kr_stderr) + " /s, charge rate " +
            WithError(s.charge_rate, s.charge_rate_stderr) + " /s, emission";
    for (int c = 0; c < curve.channel_count(); ++c)
      text += " " + curve.names[c] + " " + WithError(s.emission[c], s.emission_stderr[c]);
    text += "\n";
  }
  for (const auto& [name, values, errors] : {std::tuple{"prompt", &fit.prompt, &fit.prompt_stderr},
                                             std::tuple{"background", &fit.background, &fit.background_stderr}}) {
    text += std::string("  ") + name;
    for (int c = 0; c < curve.channel_count(); ++c)
      text += " " + curve.names[c] + " " + WithError((*values)[c], (*errors)[c]);
    text += "\n";
  }
  for (const DecadeResidual& d : fit.residual_by_decade)
    text += "  residual " + FormatShort(d.from_s, 3) + "-" + FormatShort(d.to_s, 3) + " s after light " +
            std::to_string(d.light + 1) + " off: " + FormatShort(100 * d.rms_relative, 3) + "% (" +
            std::to_string(d.samples) + " samples)\n";
  if (prediction) {
    text +=
        "  predicted after a charge of " + FormatShort(prediction->charge_s, 6) + " s from dark (t from light on):\n";
    text += "  t_s,light";
    for (const std::string& name : curve.names) text += "," + name;
    text += "\n";
    for (std::size_t j = 0; j < prediction->t_s.size(); ++j) {
      text += "  " + FormatShort(prediction->t_s[j], 6) + (prediction->t_s[j] < prediction->charge_s ? ",1" : ",0");
      for (const auto& channel : prediction->values) text += "," + FormatShort(channel[j], 6);
      text += "\n";
    }
  }
  return text;
}

// The data and the fit at every sample, on a log axis, the light windows as a line at the top.
void WritePlot(const std::string& path, const LoadedCurve& loaded, const ScheduleFitOptions& options,
               const ScheduleFitSummary& fit) {
  const Curve& curve = loaded.curve;
  const auto model = EvaluateSchedule(fit, options.lights, curve.t_s.front(), curve.t_s);
  std::vector<PlotSeries> series;
  for (int c = 0; c < curve.channel_count(); ++c) {
    PlotSeries data{curve.names[c]};
    data.x = curve.t_s;
    data.y = curve.channels[c];
    data.line = false;
    data.markers = true;
    data.color = PaletteColor(c);
    PlotSeries fitted{curve.names[c] + " (fit)"};
    fitted.color = curve.channel_count() == 1 ? "#000000" : PaletteColor(c);
    fitted.dashed = curve.channel_count() > 1;
    fitted.x = curve.t_s;
    fitted.y = model[c];
    series.push_back(std::move(data));
    series.push_back(std::move(fitted));
  }
  PlotOptions plot;
  plot.title = "Schedule fit: " + std::to_string(fit.n_states) + " state(s), " + std::to_string(options.lights.size()) +
               " light(s)";
  plot.x_label = "t (s)";
  plot.y_label = "value";
  plot.log_y = true;
  WriteFileAtomically(path, PlotSvg(series, plot));
}

void RunScheduleCurve(const ScheduleArgs& args) {
  RequireOutputFile(args.plot, "--plot", kSvgExtension);
  if (args.file.empty() == args.csv.empty()) ThrowUserError("", "FILE", "give one curve file (FILE or --csv F)");
  if (args.light_on.empty()) ThrowUserError("", "--light-on", "give at least one light window T0:T1 (seconds)");
  const ScheduleFitOptions options = OptionsOf(args);
  const LoadedCurve loaded = LoadCurveFile(args.file.empty() ? args.csv : args.file);
  ValidateCurve(loaded.curve, 4, loaded.file);
  ValidateSchedule(loaded.curve, options.lights, loaded.file, "--light-on");
  const ScheduleFitSummary fit = FitSchedule(loaded.curve, options, loaded.file);
  std::vector<std::string> warnings = loaded.warnings;
  for (const std::string& warning : fit.warnings) warnings.push_back(loaded.file + ": " + warning);
  if (!fit.converged)
    warnings.push_back(loaded.file +
                       ": the fit did not converge (the iteration limit); shown because of "
                       "--keep-unconverged");
  for (const std::string& warning : warnings) std::fprintf(stderr, "phos: warning: %s\n", Printable(warning).c_str());
  std::optional<Prediction> prediction;
  if (args.predict_charge_s) prediction = Predict(fit, loaded.curve, options.lights, *args.predict_charge_s);
  if (!args.plot.empty()) WritePlot(args.plot, loaded, options, fit);
  if (args.json)
    std::printf("%s\n", ResultJson(loaded, options, fit, prediction, warnings).dump().c_str());
  else
    std::printf("%s", ResultText(loaded, fit, prediction).c_str());
}

constexpr const char* kScheduleHelp =
    "Fit the rate equation (Eq. 8.1) to one curve measured while a light of constant level switches on and\n"
    "off (--light-on T0:T1, repeatable): per state its decay rate kr, its charge rate a = ke E under that\n"
    "light and its signal at r = 1 per channel; per channel a prompt term (a signal while the light is on)\n"
    "and a background. The sample is assumed dark (r = 0) at the curve's first sample: start the curve\n"
    "before the first light, after the sample has rested. The number of states is chosen by BIC up to\n"
    "--max-states (default 6) or fixed (--states); more states than the curve supports are fitted fewer,\n"
    "with a warning; so are counts whose fit did not converge (--max-iterations, --keep-unconverged).\n"
    "Uncertainties are 1 sigma, scaled by the reduced chi-square. The residual is\n"
    "reported per decade of time after each light's switch-off.\n"
    "Curve file: a header line (t, then one column per channel), rows of numbers; times in seconds unless\n"
    "the time column's name gives a unit.\n"
    "JSON: {\"file\",\"states\":[{\"kr\",\"kr_stderr\",\"charge_rate\",\"charge_rate_stderr\",\"emission\",\n"
    "\"emission_stderr\"}],\"prompt\",\"background\",\"residual_by_decade\":[{\"light\",\"from_s\",\"to_s\","
    "\"samples\",\n"
    "\"rms_relative\"}],\"n_states\",\"bic\",\"choice\",\"rss\",\"prediction\" (--predict-charge-s),\"warnings\",..}";

}  // namespace

void RegisterFitSchedule(CLI::App& fit) {
  auto args = std::make_shared<ScheduleArgs>();
  CLI::App* s = fit.add_subcommand("schedule-curve", kScheduleHelp);
  s->add_option("FILE", args->file, "the curve file");
  s->add_option("--csv", args->csv, "the curve file (same as FILE)");
  s->add_option("--light-on", args->light_on, "the light on from T0 to T1 seconds (T0:T1; repeat for each light)")
      ->allow_extra_args(false);
  auto fixed = s->add_option("--states", args->states, "fit exactly N states (1-8)");
  auto chosen = s->add_option("--max-states", args->max_states, "choose the count by BIC, up to N (1-8; default 6)");
  fixed->excludes(chosen);
  s->add_option("--weights", args->weights, "none or poisson (photon counting: weight 1/sqrt(value))")
      ->capture_default_str();
  s->add_option("--predict-charge-s", args->predict_charge_s,
                "also print the fitted model's curve after a charge of S seconds from dark (the same light)")
      ->check(kFinite);
  s->add_option("--max-iterations", args->max_iterations,
                "the solver's iterations per refinement; a count of states whose fit has not converged by then is "
                "not chosen")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000));
  s->add_flag("--keep-unconverged", args->keep_unconverged,
              "let fits that did not converge count (with a warning) instead of passing them over");
  s->add_option("--plot", args->plot, "write an SVG of the data against the fit");
  s->add_flag("--json", args->json, "print one JSON object");
  s->callback([args] { RunScheduleCurve(*args); });
}

}  // namespace phos::app
