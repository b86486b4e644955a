// Fig. 8.16 of the method, in numbers: phosphorescence by the coupled solver
// ("ours") against a Monte Carlo baseline after Glassner (1995) that keeps no
// state and integrates each pixel's past irradiance with temporal importance
// sampling. Both are compared with the exact solution at each pixel's point
// (render/glassner.h) on the Cornell fixture, whose LED here blinks: on for
// the first 0.5 s, then for 1 s ending 1 s before every multiple of 10 s.
//
// For frames at T = 1, 60 and 600 s of animation:
//   ours:     seconds for one frame of a 30 fps sequence (advance the texels
//             from T - 1/30 to T, then look them up at every pixel), and its
//             error (texel discretization and float storage);
//   Glassner: seconds and error for 1 to 4096 time samples per pixel;
// then the error of both at equal time and the time of both at equal error
// (log-log interpolation in the sample count; beyond 4096 samples, the 1/sqrt(N)
// extrapolation, marked as such). Error: RMS over pixels and bands of
// (Lp - Lp*) over the RMS of Lp*.
//
// Two scenarios: "weak" (LED at 1% of the fixture's intensity: r stays below
// a few percent, where Glassner's linear model is right and its error is
// noise), and "saturating" (the fixture's LED: r nears 1, and the linear model
// overshoots however many samples it takes).
//
// Run: build/bin/phos-glassner-study --out docs   (or: make study)

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "phos/render/geometry.h"
#include "phos/render/glassner.h"
#include "phos/render/scene.h"
#include "phos/render/solver.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/progress.h"
#include "phos/util/svg_plot.h"

namespace phos::render {
namespace {

double Now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

double RelativeRmse(const Image& image, const Image& truth) {
  double error = 0, norm = 0;
  for (std::size_t i = 0; i < truth.pixels.size(); ++i) {
    const double d = double(image.pixels[i]) - truth.pixels[i];
    error += d * d;
    norm += double(truth.pixels[i]) * truth.pixels[i];
  }
  return std::sqrt(error / norm);
}

struct Row {
  std::string scenario;
  double T_s;
  std::string method;
  int samples;
  double seconds, rel_rmse;
};

// log-log interpolation of y at x over the points (x_k, y_k), x increasing;
// beyond the last point, the given slope.
double Interpolate(const std::vector<double>& x, const std::vector<double>& y, double at, double slope_beyond,
                   bool* extrapolated) {
  *extrapolated = false;
  if (at <= x.front()) return y.front() * std::pow(at / x.front(), (std::log(y[1] / y[0]) / std::log(x[1] / x[0])));
  for (std::size_t k = 1; k < x.size(); ++k)
    if (at <= x[k]) {
      const double w = std::log(at / x[k - 1]) / std::log(x[k] / x[k - 1]);
      return std::exp((1 - w) * std::log(y[k - 1]) + w * std::log(y[k]));
    }
  *extrapolated = true;
  return y.back() * std::pow(at / x.back(), slope_beyond);
}

// The Cornell fixture `size` pixels square with its LED blinking: on for the
// first 0.5 s, then for 1 s ending 1 s before every multiple of 10 s; at 1%
// of its intensity in the "weak" scenario.
Scene BlinkingCornell(const std::string& scenario, int size) {
  Scene scene = LoadScene(PHOS_FIXTURES_DIR "/scenes/cornell-phosphor.json");
  scene.camera.width = scene.camera.height = size;
  Light& led = scene.lights[0];
  if (scenario == "weak")
    for (double& e : led.E_per_band) e *= 0.01;
  led.schedule.keys = {{0.0, 1.0}, {0.5, 0.0}};
  for (int k = 1; k <= 61; ++k) {
    led.schedule.keys.push_back({10.0 * k - 2, 1.0});
    led.schedule.keys.push_back({10.0 * k - 1, 0.0});
  }
  return scene;
}

struct OursResult {
  double seconds, error;
};

// Ours: the step to T (once: states only move forward) plus the best of 3 lookups.
OursResult MeasureOurs(const SceneGeometry& geometry, CoupledSolver& solver, double T, const Image& truth) {
  double start = Now();
  solver.AdvanceTo(T);
  const double step_s = Now() - start;
  Image ours;
  double lookup_s = 1e9;
  for (int repeat = 0; repeat < 3; ++repeat) {
    start = Now();
    ours = EmittedRadianceOurs(geometry, solver);
    lookup_s = std::min(lookup_s, Now() - start);
  }
  return {step_s + lookup_s, RelativeRmse(ours, truth)};
}

// The baseline at 1, 2, 4, ... max_samples time samples per pixel: the best
// time of 3 runs (1 beyond 64 samples) and the error.
struct GlassnerSweep {
  std::vector<double> samples, seconds, error;
};

GlassnerSweep MeasureGlassner(const SceneGeometry& geometry, double T, const Image& truth, int max_samples,
                              const std::string& label) {
  GlassnerSweep sweep;
  ProgressBar progress(label, 13);
  for (int n = 1; n <= max_samples; n *= 2) {
    double best = 1e9;
    Image image;
    for (int repeat = 0; repeat < (n <= 64 ? 3 : 1); ++repeat) {
      const double t0 = Now();
      image = EmittedRadianceGlassner(geometry, T, n, 17 + repeat);
      best = std::min(best, Now() - t0);
    }
    sweep.samples.push_back(n);
    sweep.seconds.push_back(best);
    sweep.error.push_back(RelativeRmse(image, truth));
    progress.Advance();
  }
  progress.Finish();
  return sweep;
}

// Equal time. Time grows about linearly in N; if ours is faster than even
// one sample per pixel, compare with one sample (and say how much slower it is).
std::string EqualTimeCell(double ours_s, const GlassnerSweep& sweep) {
  if (ours_s < sweep.seconds.front())
    return "cannot take 1 sample in that time; 1 sample: error " + FormatShort(sweep.error.front(), 3) + " in " +
           FormatShort(sweep.seconds.front() / ours_s, 3) + "x ours' time";
  bool extrapolated = false;
  const double n_at_time = Interpolate(sweep.seconds, sweep.samples, ours_s, 1.0, &extrapolated);
  const double error_at_time = Interpolate(sweep.samples, sweep.error, n_at_time, -0.5, &extrapolated);
  return FormatShort(error_at_time, 3) + " (" + FormatShort(n_at_time, 3) + " samples)";
}

struct EqualErrorCells {
  std::string equal_error, time_ratio;
};

// Equal error: the samples the baseline needs for ours' error, then their time.
// Its error falls as 1/sqrt(N) until the model's bias floor; below the floor it never gets there.
EqualErrorCells EqualErrorCell(const OursResult& ours, const GlassnerSweep& sweep) {
  const std::vector<double>&n_list = sweep.samples, &error_list = sweep.error;
  const double ours_error = ours.error;
  EqualErrorCells cells{"never: its error stops at " + FormatShort(error_list.back(), 2) + " (model bias)", "-"};
  const bool still_falling = error_list.back() < 0.8 * error_list[error_list.size() - 2];
  if (ours_error >= error_list.back() || still_falling) {
    bool extrapolated = false;
    double n_needed = 1;
    if (error_list.front() > ours_error) {
      if (ours_error >= error_list.back()) {
        for (std::size_t k = 1; k < n_list.size(); ++k)
          if (error_list[k] <= ours_error) {  // log-log between the two measured points
            const double w = std::log(ours_error / error_list[k - 1]) / std::log(error_list[k] / error_list[k - 1]);
            n_needed = std::exp((1 - w) * std::log(n_list[k - 1]) + w * std::log(n_list[k]));
            break;
          }
      } else {
        extrapolated = true;  // Monte Carlo's 1/sqrt(N) beyond the last point
        n_needed = n_list.back() * std::pow(error_list.back() / ours_error, 2);
      }
    }
    bool ignored;
    const double time_needed = Interpolate(n_list, sweep.seconds, n_needed, 1.0, &ignored);
    cells.equal_error = FormatShort(time_needed, 3) + " s (" + FormatShort(n_needed, 3) + " samples" +
                        (extrapolated ? ", extrapolated" : "") + ")";
    cells.time_ratio = FormatShort(time_needed / ours.seconds, 3) + "x";
  }
  return cells;
}

// One scenario at every frame time: the rows, its table for the page and
// its plot series (colours from *colour on).
struct ScenarioResult {
  std::vector<Row> rows;
  std::string summary;
  std::vector<PlotSeries> series;
};

ScenarioResult RunScenario(const std::string& scenario, int size, int max_samples, int* colour) {
  const std::vector<double> frame_times = {1, 60, 600};
  const Scene scene = BlinkingCornell(scenario, size);
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  ScenarioResult result;
  std::ostringstream summary;
  summary << "\n### " << scenario
          << (scenario == "weak" ? " (LED at 1%: r stays small)" : " (the fixture's LED: r nears 1)")
          << "\n\n| T (s) | ours: ms/frame | ours: error | Glassner at ours' time | Glassner (1 sample) / ours: "
             "error | Glassner at ours' error | time ratio |\n"
          << "|---|---|---|---|---|---|---|\n";
  for (double T : frame_times) {
    solver.AdvanceTo(T - 1.0 / 30);
    const Image truth = EmittedRadianceReference(geometry, T);
    const OursResult ours = MeasureOurs(geometry, solver, T, truth);
    result.rows.push_back({scenario, T, "ours", 0, ours.seconds, ours.error});
    const GlassnerSweep sweep =
        MeasureGlassner(geometry, T, truth, max_samples, "glassner " + scenario + " T=" + FormatDouble(T));
    PlotSeries mc(scenario + " MC, T=" + FormatDouble(T) + "s");
    mc.markers = true;
    mc.color = PaletteColor(*colour);
    for (std::size_t k = 0; k < sweep.samples.size(); ++k) {
      result.rows.push_back(
          {scenario, T, "glassner", static_cast<int>(sweep.samples[k]), sweep.seconds[k], sweep.error[k]});
      mc.x.push_back(sweep.seconds[k]);
      mc.y.push_back(sweep.error[k]);
    }
    result.series.push_back(mc);
    PlotSeries point(scenario + " ours, T=" + FormatDouble(T) + "s");
    point.x = {ours.seconds};
    point.y = {ours.error};
    point.markers = true;
    point.line = false;
    point.color = PaletteColor((*colour)++);
    result.series.push_back(point);

    const EqualErrorCells equal_error = EqualErrorCell(ours, sweep);
    summary << "| " << FormatDouble(T) << " | " << FormatShort(ours.seconds * 1e3, 3) << " | "
            << FormatShort(ours.error, 3) << " | " << EqualTimeCell(ours.seconds, sweep) << " | "
            << FormatShort(sweep.error.front() / ours.error, 3) << "x | " << equal_error.equal_error << " | "
            << equal_error.time_ratio << " |\n";
  }
  result.summary = summary.str();
  return result;
}

std::string RowsCsv(const std::vector<Row>& rows) {
  std::ostringstream csv;
  csv << "scenario,T_s,method,samples,seconds,rel_rmse\n";
  for (const Row& r : rows)
    csv << r.scenario << "," << FormatDouble(r.T_s) << "," << r.method << "," << r.samples << ","
        << FormatDouble(r.seconds) << "," << FormatDouble(r.rel_rmse) << "\n";
  return csv.str();
}

std::string StudyMarkdown(int size, const std::string& summary) {
  std::ostringstream md;
  md << "# Coupled solver vs Glassner's Monte Carlo (Fig. 8.16 in numbers)\n\n"
     << "Written by `build/bin/phos-glassner-study --out docs` (`make study`), " << size << "x" << size
     << " pixels, on this machine (2 cores). Data: glassner-comparison.csv; plot: glassner-comparison.svg.\n"
     << "Error: RMS over pixels and bands of the emitted radiance against the exact solution at each pixel's point.\n"
     << "Ours: one frame of a 30 fps sequence (advance the texels 1/30 s, look them up). Glassner: no state; every\n"
     << "frame integrates the whole past with temporal importance sampling, one shadow ray per sample while the LED is "
        "on.\n"
     << summary;
  return md.str();
}

int Run(int argc, char** argv) {
  CLI::App app{"The coupled solver against a Monte Carlo baseline after Glassner (Fig. 8.16), in numbers."};
  std::string out = "docs";
  int size = 96, max_samples = 4096;
  app.add_option("--out", out, "Folder for glassner-comparison.{csv,md,svg}");
  app.add_option("--size", size, "Image width and height in pixels")->check(CLI::Range(8, 1024));
  app.add_option("--max-samples", max_samples, "Most time samples per pixel for the baseline")
      ->check(CLI::Range(1, 1 << 16));
  CLI11_PARSE(app, argc, argv);
  std::filesystem::create_directories(out);

  std::vector<Row> rows;
  std::string summary;
  std::vector<PlotSeries> series;
  int colour = 0;
  for (const std::string scenario : {"weak", "saturating"}) {
    ScenarioResult result = RunScenario(scenario, size, max_samples, &colour);
    rows.insert(rows.end(), result.rows.begin(), result.rows.end());
    summary += result.summary;
    series.insert(series.end(), result.series.begin(), result.series.end());
  }

  WriteFileAtomically(std::filesystem::path(out) / "glassner-comparison.csv", RowsCsv(rows));
  PlotOptions options;
  options.title = "Lp per frame: ours (dots) vs Glassner MC (1-" + std::to_string(max_samples) + " samples)";
  options.x_label = "seconds per frame (" + std::to_string(size) + "x" + std::to_string(size) + ", 2 cores)";
  options.y_label = "relative RMS error of Lp";
  options.log_x = options.log_y = true;
  WriteFileAtomically(std::filesystem::path(out) / "glassner-comparison.svg", PlotSvg(series, options));
  const std::string md = StudyMarkdown(size, summary);
  WriteFileAtomically(std::filesystem::path(out) / "glassner-comparison.md", md);
  std::printf("%s", md.c_str());
  return 0;
}

}  // namespace
}  // namespace phos::render

int main(int argc, char** argv) {
  try {
    return phos::render::Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "phos-glassner-study: %s\n", e.what());
    return 2;
  }
}
