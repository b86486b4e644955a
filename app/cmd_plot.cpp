// phos plot: draws the total emitted radiance of one or more `phos simulate`
// CSV files over time, one line per file, as an SVG.

#include <algorithm>
#include <filesystem>
#include <memory>

#include "commands.h"
#include "phos/util/csv.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "phos/util/svg_plot.h"

namespace phos::app {
namespace {

struct PlotArgs {
  std::vector<std::string> inputs;
  std::string out, title = "Emitted radiance over time";
  bool log_y = false;
};

void RunPlot(const PlotArgs& args) {
  std::vector<PlotSeries> series;
  for (const std::string& input : args.inputs) {
    CsvTable table = ReadCsv(input);
    int t = table.Find("t");
    if (t < 0) ThrowUserError(input, "header", "no column 't' (expected the output of 'phos simulate')");
    PlotSeries s{std::filesystem::path(input).stem().string()};
    s.x = table.columns[t];
    s.y.assign(table.row_count(), 0.0);
    int emitted = 0;
    for (std::size_t c = 0; c < table.header.size(); ++c)
      if (table.header[c].rfind("L_", 0) == 0) {
        ++emitted;
        for (std::size_t m = 0; m < table.row_count(); ++m) s.y[m] += table.columns[c][m];
      }
    if (emitted == 0) ThrowUserError(input, "header", "no columns L_1..L_n (expected the output of 'phos simulate')");
    series.push_back(std::move(s));
  }
  PlotOptions options;
  options.title = args.title;
  options.x_label = "time (s)";
  options.y_label = args.log_y ? "total emitted radiance (log)" : "total emitted radiance";
  options.log_y = args.log_y;
  if (args.log_y) {
    // Eight decades below the brightest point: a long decay would otherwise
    // squeeze what the eye can see into the top of the plot.
    double peak = 0;
    for (const PlotSeries& s : series)
      for (double y : s.y) peak = std::max(peak, y);
    if (peak > 0) options.y_min = peak * 1e-8;
  }
  WriteFileAtomically(args.out, PlotSvg(series, options));
}

}  // namespace

void RegisterPlot(CLI::App& app) {
  auto args = std::make_shared<PlotArgs>();
  CLI::App* cmd = app.add_subcommand("plot",
                                     "Plot the total emitted radiance (sum of the L_ columns) of 'phos simulate'\n"
                                     "CSV files over time, one line per file, into an SVG.");
  cmd->add_option("csv", args->inputs, "CSV files written by 'phos simulate'")->required();
  cmd->add_option("--out", args->out, "SVG file to write")->required();
  cmd->add_option("--title", args->title, "plot title");
  cmd->add_flag("--log-y", args->log_y, "logarithmic radiance axis (decays become straight lines)");
  cmd->callback([args] { RunPlot(*args); });
}

}  // namespace phos::app
