// The path tracer's error against its cost ("time to a given error"): the
// Cornell fixture while its LED is on (t = 20 s) and after it went off
// (t = 40 s: only the phosphors light the box), rendered at 1 to
// 256 samples per pixel and compared with the same tracer at 4096 samples
// per pixel from another seed. Error: RMSE of the band sum, relative to the
// reference's brightest pixel (the convention of docs/dss-trade.md). Time:
// one whole frame (RenderBands) on all cores, best of two runs.
//
// Writes <out>/path-convergence.md, .csv and .svg.
// Run: build/bin/phos-path-study --out docs   (make study; about a minute)

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "phos/render/geometry.h"
#include "phos/render/renderer.h"
#include "phos/render/scene.h"
#include "phos/render/solver.h"
#include "phos/util/format.h"
#include "phos/util/svg_plot.h"

namespace phos::render {
namespace {

struct View {
  std::string name;
  double t_s;
};

struct Run {
  std::string view;
  int spp;
  double seconds;
  std::uint64_t rays;
  double rmse;
};

// Per pixel, the radiance summed over the bands.
std::vector<double> BandSums(const Image& image) {
  std::vector<double> sums(static_cast<std::size_t>(image.width) * image.height, 0.0);
  for (std::size_t p = 0; p < sums.size(); ++p)
    for (int b = 0; b < image.channels; ++b) sums[p] += image.pixels[p * image.channels + b];
  return sums;
}

double RelativeRmse(const std::vector<double>& image, const std::vector<double>& reference) {
  const double peak = *std::max_element(reference.begin(), reference.end());
  double sum = 0;
  for (std::size_t p = 0; p < image.size(); ++p) sum += (image[p] - reference[p]) * (image[p] - reference[p]);
  return std::sqrt(sum / static_cast<double>(image.size())) / peak;
}

double Now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

// The smallest measured time whose error is at most `target`, with the
// number of samples per pixel it took; none if no run got there.
const Run* FirstAtOrBelow(const std::vector<Run>& runs, const std::string& view, double target) {
  for (const Run& run : runs)
    if (run.view == view && run.rmse <= target) return &run;
  return nullptr;
}

}  // namespace
}  // namespace phos::render

int main(int argc, char** argv) {
  using namespace phos;
  using namespace phos::render;
  CLI::App app{"The path tracer's error against time per frame on the Cornell fixture (docs/path-convergence.md)"};
  std::string out = "docs";
  int size = 128, reference_spp = 4096, max_spp = 256;
  app.add_option("--out", out, "Folder for path-convergence.md, .csv and .svg")->capture_default_str();
  app.add_option("--size", size, "Image width and height in pixels")->capture_default_str()->check(CLI::Range(8, 2048));
  app.add_option("--reference-spp", reference_spp, "Samples per pixel of the reference")
      ->capture_default_str()
      ->check(CLI::Range(16, 1 << 20));
  app.add_option("--max-spp", max_spp, "Largest samples per pixel of the sweep (powers of two from 1)")
      ->capture_default_str()
      ->check(CLI::Range(1, 1 << 16));
  CLI11_PARSE(app, argc, argv);

  Scene scene = LoadScene(PHOS_FIXTURES_DIR "/scenes/cornell-phosphor.json");
  scene.camera.width = scene.camera.height = size;
  const std::vector<View> views = {{"lit (t = 20 s)", 20.0}, {"after dark (t = 40 s)", 40.0}};
  std::vector<Run> runs;
  std::vector<double> reference_seconds;
  for (const View& view : views) {
    SceneGeometry geometry(scene);
    CoupledSolver solver(scene, geometry);
    solver.AdvanceTo(view.t_s);
    FrameOptions options = DefaultFrameOptions(scene, Transport::kPath);
    options.seed = 7919;  // independent of the sweep's seed
    options.spp = reference_spp;
    std::cerr << "reference: " << view.name << ", " << reference_spp << " spp\n";
    double start = Now();
    const std::vector<double> reference = BandSums(RenderBands(geometry, &solver, options));
    reference_seconds.push_back(Now() - start);
    options.seed = scene.settings.seed;
    for (int spp = 1; spp <= max_spp; spp *= 2) {
      options.spp = spp;
      double best = 1e30;
      Image image;
      FrameStats stats;
      for (int repeat = 0; repeat < 2; ++repeat) {
        stats = FrameStats{};
        start = Now();
        image = RenderBands(geometry, &solver, options, &stats);
        best = std::min(best, Now() - start);
      }
      runs.push_back({view.name, spp, best, stats.rays, RelativeRmse(BandSums(image), reference)});
      std::cerr << "  " << spp << " spp: " << best << " s, RMSE " << runs.back().rmse << "\n";
    }
  }

  std::filesystem::create_directories(out);
  {
    std::ofstream csv(std::filesystem::path(out) / "path-convergence.csv");
    csv << "view,spp,seconds,rays,Mrays_per_s,rmse\n";
    for (const Run& r : runs)
      csv << '"' << r.view << "\"," << r.spp << ',' << r.seconds << ',' << r.rays << ','
          << static_cast<double>(r.rays) * 1e-6 / r.seconds << ',' << r.rmse << '\n';
  }
  std::vector<PlotSeries> series;
  for (const View& view : views) {
    PlotSeries s(view.name);
    s.markers = true;
    for (const Run& r : runs)
      if (r.view == view.name) {
        s.x.push_back(r.seconds);
        s.y.push_back(r.rmse);
      }
    series.push_back(s);
  }
  PlotOptions plot;
  plot.title = "Path tracer, Cornell box " + std::to_string(size) + " px: error against time per frame";
  plot.x_label = "seconds per frame (2 cores)";
  plot.y_label = "RMSE of the band sum / brightest pixel";
  plot.log_x = plot.log_y = true;
  {
    std::ofstream svg(std::filesystem::path(out) / "path-convergence.svg");
    svg << PlotSvg(series, plot);
  }
  std::ofstream md(std::filesystem::path(out) / "path-convergence.md");
  md << "<!-- written by: build/bin/phos-path-study --out " << out << " -->\n";
  md << "# The path tracer: error against time\n\n";
  md << "The Cornell fixture (fixtures/scenes/cornell-phosphor.json) at " << size << " x " << size
     << " px, path-traced at 1 to " << max_spp << " samples per pixel, against the same tracer at " << reference_spp
     << " samples per pixel from another seed. RMSE of the band sum relative to the reference's brightest pixel; "
        "time of one whole frame on both cores, best of two. The reference's own noise is about the error at "
     << reference_spp << " spp, which is the 1-spp error over " << FormatShort(std::sqrt(reference_spp), 3)
     << " (noise falls as 1 / sqrt(spp)). All runs: [path-convergence.csv](path-convergence.csv), plot "
        "[path-convergence.svg](path-convergence.svg).\n\n";
  for (std::size_t v = 0; v < views.size(); ++v) {
    md << "## " << views[v].name << "\n\n";
    md << "Reference: " << FormatShort(reference_seconds[v], 3) << " s.\n\n";
    md << "| spp | seconds | Mrays/s | RMSE | RMSE x sqrt(seconds) |\n|---|---|---|---|---|\n";
    for (const Run& r : runs)
      if (r.view == views[v].name)
        md << "| " << r.spp << " | " << FormatShort(r.seconds, 4) << " | "
           << FormatShort(static_cast<double>(r.rays) * 1e-6 / r.seconds, 3) << " | " << FormatShort(r.rmse, 4) << " | "
           << FormatShort(r.rmse * std::sqrt(r.seconds), 3) << " |\n";
    md << "\nTime to a given error (the first run of the sweep at or below it):\n\n";
    md << "| RMSE at most | spp | seconds |\n|---|---|---|\n";
    for (double target : {0.1, 0.05, 0.02, 0.01, 0.005}) {
      const Run* r = FirstAtOrBelow(runs, views[v].name, target);
      md << "| " << FormatShort(target) << " | "
         << (r ? std::to_string(r->spp) : "more than " + std::to_string(max_spp)) << " | "
         << (r ? FormatShort(r->seconds, 4) : "-") << " |\n";
    }
    md << "\n";
  }
  std::cout << "wrote " << (std::filesystem::path(out) / "path-convergence.md").string() << "\n";
  return 0;
}
