// phos fit decay-curve / charge-curve: fit curves from any instrument (plain
// text tables in, JSON out), as in the DESIGN.md contracts: one file or a
// lab's archive in one call, replicates and unsorted times accepted.

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
#include "phos/fit/charge_fit.h"
#include "phos/fit/decay_fit.h"
#include "phos/util/atomic_file.h"
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

// First column: time, in seconds unless its name says another unit ("t_min":
// converted, and said in a warning); every further column: one channel. The
// window (--from, --to, in seconds) is applied first, then the samples are
// sorted by time.
LoadedCurve LoadCurveFile(const std::string& path, std::optional<double> from_s, std::optional<double> to_s) {
  CsvTable table = ReadCsv(path);
  if (table.header.size() < 2)
    ThrowUserError(path, "header",
                   "expected columns t,value[,value...], got " + std::to_string(table.header.size()) + " column");
  LoadedCurve loaded;
  loaded.file = path;
  Curve& curve = loaded.curve;
  curve.t_s = table.columns[0];
  // A time column in minutes or milliseconds read as seconds gave a rate 60
  // times too high or 1000 times too low, with exit 0.
  if (const std::optional<TimeUnit> unit = TimeUnitOfColumn(table.header[0], path); unit && unit->seconds != 1) {
    for (double& t : curve.t_s) t *= unit->seconds;
    loaded.warnings.push_back(path + ": time column '" + table.header[0] + "' read in " + unit->name + " (" +
                              FormatDouble(unit->seconds) + " s each) and converted to seconds");
  }
  for (std::size_t c = 1; c < table.header.size(); ++c) {
    curve.channels.push_back(table.columns[c]);
    curve.names.push_back(Printable(table.header[c]));  // printed in the text: no raw ESC or newline
  }
  loaded.samples_in_file = curve.size();
  if (from_s || to_s) {
    const double from = from_s.value_or(-HUGE_VAL), to = to_s.value_or(HUGE_VAL);
    const std::vector<double> times_s = curve.t_s;
    KeepTimeWindow(&curve, from, to);
    if (curve.size() == 0 && loaded.samples_in_file > 0) {
      const auto [lo, hi] = std::minmax_element(times_s.begin(), times_s.end());
      ThrowUserError(path, from_s ? "--from" : "--to",
                     "no sample in the window (the file's times run from " + FormatDouble(*lo) + " to " +
                         FormatDouble(*hi) + " s)");
    }
  }
  loaded.order = SortByTime(&curve, path);
  return loaded;
}

namespace {

struct CurveArgs {
  std::vector<std::string> csv, positional;  // as parsed
  std::vector<std::string> files;            // both, in command-line order
  std::string weights = "none", plot;
  std::optional<double> from_s, to_s;
  int components = 0, max_components = 0;
  int max_iterations = 100;
  bool json = false, background = false, amplitude_stderr = false, keep_unconverged = false;
};

LoadedCurve LoadCurve(const std::string& path, const CurveArgs& args) {
  return LoadCurveFile(path, args.from_s, args.to_s);
}

// What sorting found, in words; empty when the file was in order without replicates.
std::string OrderNote(const TimeOrder& order) {
  if (!order.reordered && order.repeated_times == 0) return "";
  std::string note = order.reordered ? "sorted " + std::to_string(order.samples) + " samples by time"
                                     : std::to_string(order.samples) + " samples";
  if (order.repeated_times > 0) note += "; " + std::to_string(order.repeated_times) + " repeated times (replicates)";
  return note;
}

// The keys every curve fit adds to its JSON: the file, its samples, the window, the warnings.
void AddCurveJson(const LoadedCurve& loaded, const CurveArgs& args, nlohmann::json* j) {
  (*j)["file"] = loaded.file;
  (*j)["channels"] = loaded.curve.names;
  (*j)["samples"] = loaded.order.samples;
  (*j)["time_order"] = {{"reordered", loaded.order.reordered},
                        {"distinct_times", loaded.order.distinct_times},
                        {"repeated_times", loaded.order.repeated_times}};
  if (args.from_s || args.to_s) {
    nlohmann::json window = {{"samples_in_file", loaded.samples_in_file}};
    window["from"] = args.from_s ? nlohmann::json(*args.from_s) : nlohmann::json(nullptr);
    window["to"] = args.to_s ? nlohmann::json(*args.to_s) : nlohmann::json(nullptr);
    (*j)["window"] = window;
  }
  (*j)["warnings"] = loaded.warnings;
}

// The notes under a curve's text result: sorting, replicates, the window.
std::string CurveNotes(const LoadedCurve& loaded, const CurveArgs& args) {
  std::string notes;
  if (const std::string order = OrderNote(loaded.order); !order.empty()) notes += "  " + order + "\n";
  if (args.from_s || args.to_s)
    notes += "  window " + (args.from_s ? FormatDouble(*args.from_s) + " s" : std::string("the start")) + " to " +
             (args.to_s ? FormatDouble(*args.to_s) + " s" : std::string("the end")) + ": " +
             std::to_string(loaded.curve.size()) + " of " + std::to_string(loaded.samples_in_file) + " samples\n";
  return notes;
}

// A table row's samples cell: the count, and replicates or sorting if any.
std::string SamplesCell(const TimeOrder& order) {
  std::string cell = std::to_string(order.samples);
  if (order.repeated_times > 0) cell += " (" + std::to_string(order.repeated_times) + " repeated times)";
  if (order.reordered) cell += " sorted";
  return cell;
}

std::string JoinShort(const std::vector<double>& values, int digits) {
  std::string text;
  for (double v : values) text.append(text.empty() ? "" : " ").append(FormatShort(v, digits));
  return text;
}

// One file's result in the three forms a run may print.
struct CurveResult {
  nlohmann::json json;
  std::string text;              // one file, no --json
  std::vector<std::string> row;  // several files, no --json
  std::vector<std::string> warnings;
};

void PrintTable(const std::vector<std::string>& header, const std::vector<std::vector<std::string>>& rows) {
  std::vector<std::size_t> width(header.size());
  for (std::size_t c = 0; c < header.size(); ++c) {
    width[c] = header[c].size();
    for (const auto& row : rows) width[c] = std::max(width[c], row[c].size());
  }
  auto print = [&](const std::vector<std::string>& row) {
    std::string line;
    for (std::size_t c = 0; c < row.size(); ++c) {
      line += row[c];
      if (c + 1 < row.size()) line += std::string(width[c] - row[c].size() + 2, ' ');
    }
    std::printf("%s\n", Printable(line).c_str());  // column names from the file
  };
  print(header);
  for (const auto& row : rows) print(row);
}

// Fits every file in order and prints: with --json one object per line, else
// the text of one file or one table row per file. A file that cannot be
// fitted is one line on stderr and the others go on; the last such line is
// the run's UserError, so each bad file says so once and the exit code is 2.
template <typename FitOne>
void FitEachFile(const CurveArgs& args, const std::vector<std::string>& table_header, FitOne fit_one) {
  if (args.files.empty()) ThrowUserError("", "FILE", "no curve file given (name one or more files, or --csv F)");
  if (!args.plot.empty() && args.files.size() > 1)
    ThrowUserError("", "--plot", "draws one curve; got " + std::to_string(args.files.size()) + " files");
  std::vector<std::vector<std::string>> rows;
  std::optional<std::string> failure;
  for (const std::string& file : args.files) {
    try {
      const CurveResult result = fit_one(file);
      for (const std::string& warning : result.warnings)
        std::fprintf(stderr, "phos: warning: %s\n", Printable(warning).c_str());
      if (args.json)
        std::printf("%s\n", result.json.dump().c_str());
      else if (args.files.size() == 1)
        std::printf("%s", result.text.c_str());
      else
        rows.push_back(result.row);
      std::fflush(stdout);
    } catch (const UserError& e) {
      if (failure) std::fprintf(stderr, "phos: %s\n", failure->c_str());
      failure = e.what();
    }
  }
  if (!rows.empty()) PrintTable(table_header, rows);
  std::fflush(stdout);  // the table before the error line, even through a pipe
  if (failure) ThrowUserError("", "", *failure);
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

void CheckWindow(const CurveArgs& args) {
  if (args.from_s && args.to_s && *args.from_s > *args.to_s)
    ThrowUserError("", "--from", FormatDouble(*args.from_s) + " s is after --to " + FormatDouble(*args.to_s) + " s");
}

// A fit that stopped at --max-iterations, not at a tolerance, is not a
// result: the file fails (one line, exit 2 at the end) unless the user asked
// to see it anyway, and then it says so.
void RequireConverged(bool converged, const std::string& termination, const std::string& file, const CurveArgs& args,
                      LoadedCurve* loaded) {
  if (converged) return;
  if (!args.keep_unconverged)
    ThrowUserError(file, "",
                   "the fit did not converge (" + termination +
                       "): nothing reported; raise --max-iterations, or give --keep-unconverged to see it anyway");
  loaded->warnings.push_back(file + ": the fit did not converge (" + termination +
                             "); shown because of --keep-unconverged");
}

CurveResult FitDecayFile(const std::string& file, const CurveArgs& args, const DecayFitOptions& options) {
  LoadedCurve loaded = LoadCurve(file, args);
  const Curve& curve = loaded.curve;
  if (const std::optional<double> peak_s = PeakAfterRise(curve))
    loaded.warnings.push_back(file + ": the curve rises from its start to a peak at t = " + FormatShort(*peak_s, 6) +
                              " s before it falls (a charge followed by its decay?); it is fitted as a decay all the "
                              "same: fit the decay alone with --from " +
                              FormatShort(*peak_s, 6));
  const DecayFitSummary fit = FitDecay(curve, options, file);
  RequireConverged(fit.converged, fit.termination, file, args, &loaded);
  if (!args.plot.empty())
    WritePlot(
        args.plot, curve, [&](int c, double t) { return EvaluateDecay(fit, c, t); },
        "Decay fit: " + std::to_string(fit.n_components) + " component(s)", true);

  CurveResult result;
  result.warnings = loaded.warnings;
  nlohmann::json& j = result.json;
  j["components"] = nlohmann::json::array();
  for (const DecayComponent& component : fit.components) {
    nlohmann::json k = {
        {"amplitude", component.amplitude[0]}, {"rate", component.rate}, {"rate_stderr", component.rate_stderr}};
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
  j["converged"] = fit.converged;
  j["weights"] = WeightingName(options.weighting);
  j["seconds"] = fit.seconds;
  AddCurveJson(loaded, args, &j);

  char line[256];
  std::snprintf(line, sizeof line, "%d component(s) (%s), rss %s, %.3g ms\n", fit.n_components, fit.choice.c_str(),
                FormatShort(fit.rss, 6).c_str(), fit.seconds * 1e3);
  std::string& text = result.text;
  text = line;
  for (const DecayComponent& component : fit.components) {
    text += "  rate " + FormatShort(component.rate, 6) + " +- " + FormatShort(component.rate_stderr, 2) + " /s";
    for (int c = 0; c < curve.channel_count(); ++c) {
      text += "  " + curve.names[c] + " " + FormatShort(component.amplitude[c], 6);
      if (args.amplitude_stderr) text += " +- " + FormatShort(component.amplitude_stderr[c], 2);
    }
    text += "\n";
  }
  if (options.background) {
    text += "  background";
    for (int c = 0; c < curve.channel_count(); ++c)
      text += "  " + curve.names[c] + " " + FormatShort(fit.background[c], 6);
    text += "\n";
  }
  text += CurveNotes(loaded, args);

  std::vector<double> rates;
  for (const DecayComponent& component : fit.components) rates.push_back(component.rate);
  result.row = {file,
                std::to_string(fit.n_components),
                JoinShort(rates, 6),
                FormatShort(fit.rss, 6),
                options.background ? JoinShort(fit.background, 6) : "-",
                SamplesCell(loaded.order)};
  return result;
}

void RunDecayCurve(const CurveArgs& args) {
  RequireOutputFile(args.plot, "--plot", kSvgExtension);
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
  options.max_iterations = args.max_iterations;
  CheckWindow(args);
  FitEachFile(args, {"file", "nc", "rates (1/s)", "rss", "background", "samples"},
              [&](const std::string& file) { return FitDecayFile(file, args, options); });
}

CurveResult FitChargeFile(const std::string& file, const CurveArgs& args, const ChargeFitOptions& options) {
  LoadedCurve loaded = LoadCurve(file, args);
  const Curve& curve = loaded.curve;
  const ChargeFitSummary fit = FitCharge(curve, options, file);
  RequireConverged(fit.converged, fit.termination, file, args, &loaded);
  // The charge model fits a fall as well (Linf below L0): a decay given to
  // the wrong command, whose one rate would pass for a charging speed.
  if (std::all_of(fit.levels.begin(), fit.levels.end(), [](const ChargeLevels& l) { return l.Linf < l.L0; }))
    loaded.warnings.push_back(file + ": the fitted curve falls (Linf below L0" +
                              std::string(curve.channel_count() > 1 ? " in every channel" : "") +
                              "): a decay? 'phos fit decay-curve' fits a decay with its components");
  auto model = [&](int c, double t) {
    return fit.levels[c].Linf - (fit.levels[c].Linf - fit.levels[c].L0) * std::exp(-fit.rate * t);
  };
  if (!args.plot.empty()) WritePlot(args.plot, curve, model, "Charge fit", false);

  CurveResult result;
  result.warnings = loaded.warnings;
  result.json = {{"L0", fit.L0},
                 {"Linf", fit.Linf},
                 {"rate", fit.rate},
                 {"L0_stderr", fit.L0_stderr},
                 {"Linf_stderr", fit.Linf_stderr},
                 {"rate_stderr", fit.rate_stderr},
                 {"rss", fit.rss},
                 {"weights", WeightingName(options.weighting)},
                 {"converged", fit.converged},
                 {"seconds", fit.seconds}};
  if (curve.channel_count() > 1) {
    nlohmann::json levels = nlohmann::json::array();
    for (int c = 0; c < curve.channel_count(); ++c)
      levels.push_back({{"channel", curve.names[c]},
                        {"L0", fit.levels[c].L0},
                        {"Linf", fit.levels[c].Linf},
                        {"L0_stderr", fit.levels[c].L0_stderr},
                        {"Linf_stderr", fit.levels[c].Linf_stderr}});
    result.json["levels"] = levels;
  }
  AddCurveJson(loaded, args, &result.json);

  auto levels_text = [&](int c) {
    return "L0 " + FormatShort(fit.levels[c].L0, 6) + " +- " + FormatShort(fit.levels[c].L0_stderr, 2) + ", Linf " +
           FormatShort(fit.levels[c].Linf, 6) + " +- " + FormatShort(fit.levels[c].Linf_stderr, 2);
  };
  const std::string rate = "rate " + FormatShort(fit.rate, 6) + " +- " + FormatShort(fit.rate_stderr, 2) + " /s";
  if (curve.channel_count() == 1) {
    result.text = "L(t) = Linf - (Linf - L0) exp(-rate t): " + levels_text(0) + ", " + rate + ", rss " +
                  FormatShort(fit.rss, 6) + "\n";
  } else {
    result.text = "L_c(t) = Linf_c - (Linf_c - L0_c) exp(-rate t): " + rate + " (shared by " +
                  std::to_string(curve.channel_count()) + " channels), rss " + FormatShort(fit.rss, 6) + "\n";
    for (int c = 0; c < curve.channel_count(); ++c) result.text += "  " + curve.names[c] + ": " + levels_text(c) + "\n";
  }
  result.text += CurveNotes(loaded, args);

  std::vector<double> L0, Linf;
  for (const ChargeLevels& levels : fit.levels) {
    L0.push_back(levels.L0);
    Linf.push_back(levels.Linf);
  }
  result.row = {file,
                FormatShort(fit.rate, 6),
                FormatShort(fit.rate_stderr, 2),
                JoinShort(L0, 6),
                JoinShort(Linf, 6),
                FormatShort(fit.rss, 6),
                SamplesCell(loaded.order)};
  return result;
}

void RunChargeCurve(const CurveArgs& args) {
  RequireOutputFile(args.plot, "--plot", kSvgExtension);
  ChargeFitOptions options;
  options.weighting = ParseWeightsOption(args.weights);
  options.max_iterations = args.max_iterations;
  CheckWindow(args);
  FitEachFile(args, {"file", "rate (1/s)", "+-", "L0", "Linf", "rss", "samples"},
              [&](const std::string& file) { return FitChargeFile(file, args, options); });
}

// The options both curve commands share: the files, the window, the
// weights, the plot and --json. The callback sets args->files in the order
// the command line named them (--csv and positional files mixed).
void AddCurveOptions(CLI::App* command, const std::shared_ptr<CurveArgs>& args, void (*run)(const CurveArgs&)) {
  CLI::Option* positional = command->add_option("FILE", args->positional,
                                                "curve files (text tables, see above); several give one result each");
  CLI::Option* csv =
      command->add_option("--csv", args->csv, "a curve file (may repeat; same as FILE)")->allow_extra_args(false);
  command
      ->add_option("--from", args->from_s,
                   "keep samples at t >= T (s, inclusive; default: from the first); t = 0 stays the file's")
      ->check(kFinite);
  command->add_option("--to", args->to_s, "keep samples at t <= T (s, inclusive; default: to the last)")
      ->check(kFinite);
  command->add_option("--plot", args->plot, "write an SVG of the data against the fit (one file only)");
  command->add_flag("--json", args->json, "print one JSON object per file, one per line, each with \"file\"");
  command
      ->add_option("--max-iterations", args->max_iterations,
                   "the solver's iterations per refinement; a fit that has not converged by then fails")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000));
  command->add_flag("--keep-unconverged", args->keep_unconverged,
                    "report a fit that did not converge (with a warning) instead of failing the file");
  command->callback([command, args, csv, positional, run] {
    args->files.clear();
    std::size_t next_csv = 0, next_positional = 0;
    for (const CLI::Option* option : command->parse_order()) {
      if (option == csv && next_csv < args->csv.size()) args->files.push_back(args->csv[next_csv++]);
      if (option == positional && next_positional < args->positional.size())
        args->files.push_back(args->positional[next_positional++]);
    }
    run(*args);
  });
}

constexpr const char* kCurveFiles =
    "Curve files: a header line naming the columns (t, then one per channel), then rows of numbers.\n"
    "Separators are detected from the first line: comma, semicolon, tab or whitespace. A first line of\n"
    "numbers is taken as data (columns named 'column 1', ...). Times >= 0, in any order, in seconds\n"
    "unless the time column's name gives a unit (t_min, 'time (ms)', 'Time [h]': converted, with a\n"
    "warning; --from and --to stay in seconds);\n"
    "repeated times (replicates) are kept, and the samples are sorted by time (stably), which the output\n"
    "says. A file that cannot be fitted is one line on stderr; the others are fitted, and the exit\n"
    "code is 2.\n";

}  // namespace

void RegisterFitCurve(CLI::App& fit) {
  auto decay = std::make_shared<CurveArgs>();
  CLI::App* d = fit.add_subcommand(
      "decay-curve",
      std::string(
          "Fit sum_i amplitude_i exp(-rate_i t) (+ background) to a decay curve; rates shared by every channel,\n"
          "amplitudes >= 0. The number of components is fixed (--components) or chosen by BIC up to\n"
          "--max-components (default 3). Uncertainties are 1 sigma, scaled by the reduced chi-square.\n"
          "A curve that rises to a peak first (a charge before the decay) is warned about (--from the peak).\n") +
          kCurveFiles +
          "Several files: one table row each (file, nc, rates, rss, background, samples).\n"
          "JSON: {\"file\",\"components\":[{\"amplitude\",\"rate\",\"rate_stderr\",..}],\"rss\",\"n_components\",\n"
          "\"seconds\",\"samples\",\"time_order\",\"warnings\",..}");
  auto fixed = d->add_option("--components", decay->components, "fit exactly N components (1-4)");
  auto chosen =
      d->add_option("--max-components", decay->max_components, "choose the count by BIC, up to N (1-4; default 3)");
  fixed->excludes(chosen);
  d->add_option("--weights", decay->weights,
                "none or poisson (photon counting: weight 1/sqrt(value)). none by default here, unlike fit\n"
                "session: a curve file's unit is not known to be a count")
      ->capture_default_str();
  d->add_flag("--background", decay->background, "also fit a constant background per channel");
  d->add_flag("--amplitude-stderr", decay->amplitude_stderr,
              "also report 1-sigma amplitude uncertainties (covariance of the full problem; doubles the time)");
  AddCurveOptions(d, decay, RunDecayCurve);

  auto charge = std::make_shared<CurveArgs>();
  CLI::App* c = fit.add_subcommand(
      "charge-curve",
      std::string("Fit the saturating growth L_c(t) = Linf_c - (Linf_c - L0_c) exp(-rate t) to a charge curve: one\n"
                  "rate shared by every channel (further columns), levels L0_c and Linf_c per channel.\n") +
          kCurveFiles +
          "Several files: one table row each (file, rate, L0, Linf, rss, samples).\n"
          "JSON: {\"file\",\"L0\",\"Linf\",\"rate\",\"rss\",\"seconds\",\"levels\" (several channels),..}");
  c->add_option("--weights", charge->weights,
                "none or poisson (none by default: a curve's unit is not known to be a count)")
      ->capture_default_str();
  AddCurveOptions(c, charge, RunChargeCurve);

  RegisterFitSchedule(fit);
}

}  // namespace phos::app
