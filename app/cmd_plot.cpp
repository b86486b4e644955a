// phos plot: draws the total emitted radiance of one or more `phos simulate`
// CSV files over time, one line per file, as an SVG. Each line takes the
// colour of its material's glow: the light its L_ columns carry over the run,
// through the CIE 1931 functions (SpectrumColor), so "green" is green.

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>

#include <nlohmann/json.hpp>
#include <CLI/CLI.hpp>

#include "commands.h"
#include "phos/model/spectral.h"
#include "phos/util/atomic_file.h"
#include "phos/util/csv.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/svg_plot.h"

namespace phos::app {
namespace {

struct PlotArgs {
  std::vector<std::string> inputs;
  std::string out, title = "Emitted radiance over time", bands_nm;
  bool log_y = false, json = false;
};

// Lines whose colours are closer than this (0-255 per channel) are told apart by dashes.
constexpr double kAlikeColors = 60;

// The band edges of the L_ columns: --bands-nm, or the paper's range (400 to 700 nm) in equal bands.
std::vector<double> BandEdges(const PlotArgs& args, int bands, const std::string& input) {
  const SpectralGrid paper = SpectralGrid::Paper();
  if (args.bands_nm.empty())
    return SpectralGrid::Uniform(paper.edges_nm.front(), paper.edges_nm.back(), bands).edges_nm;
  std::vector<double> edges;
  std::string bad;
  if (!ParseDoubleList(args.bands_nm, &edges, &bad))
    ThrowUserError("", "--bands-nm", "expected a comma-separated list of wavelengths in nm, got \"" + bad + "\"");
  for (std::size_t i = 1; i < edges.size(); ++i)
    if (!(edges[i] > edges[i - 1])) ThrowUserError("", "--bands-nm", "expected increasing band edges");
  if (static_cast<int>(edges.size()) != bands + 1)
    ThrowUserError(input, "header",
                   std::to_string(bands) + " L_ columns need " + std::to_string(bands + 1) +
                       " band edges, and --bands-nm gives " + std::to_string(edges.size()));
  return edges;
}

void RunPlot(const PlotArgs& args) {
  RequireOutputFile(args.out, "--out", kSvgExtension);
  std::vector<PlotSeries> series;
  nlohmann::json described = nlohmann::json::array();
  for (const std::string& input : args.inputs) {
    CsvTable table = ReadCsv(input);
    int t = table.Find("t");
    if (t < 0) ThrowUserError(input, "header", "no column 't' (expected the output of 'phos simulate')");
    PlotSeries s{std::filesystem::path(input).stem().string()};
    s.x = table.columns[t];
    s.y.assign(table.row_count(), 0.0);
    std::vector<double> emitted;  // per band, integrated over the run (trapezoids)
    for (std::size_t c = 0; c < table.header.size(); ++c)
      if (table.header[c].rfind("L_", 0) == 0) {
        double integral = 0;
        for (std::size_t m = 0; m < table.row_count(); ++m) {
          s.y[m] += table.columns[c][m];
          if (m > 0) integral += 0.5 * (table.columns[c][m] + table.columns[c][m - 1]) * (s.x[m] - s.x[m - 1]);
        }
        emitted.push_back(table.row_count() == 1 ? table.columns[c][0] : integral);
      }
    if (emitted.empty())
      ThrowUserError(input, "header", "no columns L_1..L_n (expected the output of 'phos simulate')");
    s.color = SpectrumColor(emitted, BandEdges(args, static_cast<int>(emitted.size()), input));
    for (const PlotSeries& earlier : series)
      s.dashed = s.dashed || ColorDistance(earlier.color, s.color) < kAlikeColors;

    const auto peak = std::max_element(s.y.begin(), s.y.end());
    nlohmann::json d = {
        {"file", input}, {"label", s.label}, {"color", s.color}, {"dashed", s.dashed}, {"samples", table.row_count()}};
    if (peak != s.y.end()) {
      d["peak_radiance"] = *peak;
      d["t_peak_s"] = s.x[static_cast<std::size_t>(peak - s.y.begin())];
      d["t_end_s"] = s.x.back();
      d["end_radiance"] = s.y.back();
    }
    described.push_back(d);
    series.push_back(std::move(s));
  }
  PlotOptions options;
  options.title = args.title;
  options.x_label = "time (s)";
  // Radiance is in the unit of the material's Lambda (radiance per unit kr r, Eq. 8.2).
  options.y_label = std::string("emitted radiance, all bands (unit of Lambda)") + (args.log_y ? ", log scale" : "");
  options.log_y = args.log_y;  // the axis spans the decades the data reach
  WriteFileAtomically(args.out, PlotSvg(series, options));
  if (args.json)
    std::cout << nlohmann::json{{"out", args.out}, {"log_y", args.log_y}, {"series", described}}.dump() << "\n";
}

}  // namespace

void RegisterPlot(CLI::App& app) {
  auto args = std::make_shared<PlotArgs>();
  CLI::App* cmd = app.add_subcommand("plot", Summary("plot"));
  cmd->add_option("csv", args->inputs, "CSV files written by 'phos simulate'")->required();
  cmd->add_option("--out", args->out, "SVG file to write")->required();
  cmd->add_option("--title", args->title, "plot title")->capture_default_str();
  cmd->add_flag("--log-y", args->log_y, "logarithmic radiance axis (decays become straight lines); it spans the data");
  cmd->add_option("--bands-nm", args->bands_nm,
                  "band edges in nm of the L_ columns, for each line's colour (the light the material emits);\n"
                  "default: 400 to 700 nm in equal bands (the paper's grid for 8 columns)");
  cmd->add_flag("--json", args->json,
                "print one JSON object: out, log_y, series (file, label, color, dashed, samples, peak_radiance,\n"
                "t_peak_s, t_end_s, end_radiance)");
  cmd->callback([args] { RunPlot(*args); });
}

}  // namespace phos::app
