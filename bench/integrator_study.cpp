// The speed/accuracy trade of the four integrators of Eq. 8.1
// (docs/integrator-study.md). For the eight Table 8.1 presets whose ke is known,
// under a charge-then-dark schedule, and steps from 1 ms to 100 s:
//   error: max over the samples of |L - L*| / max L*, L the total emitted
//          radiance (Eq. 8.2) and L* the closed form in long double;
//   cost:  measured ns per texel per simulated second: the batch kernel's
//          time per texel-step (float, 2^20 texels, 1 state, 3 lit bands,
//          8 emitted, timed at that step size) x steps / duration; for the
//          scalar adaptive reference, its own time per simulated second.
// Writes <out>/integrator-study.csv, integrator-study.svg (error against
// cost) and integrator-error-vs-step.svg, and prints a summary table.
//
// Run: build/bin/phos-integrator-study --out docs   (or: make study)

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "phos/model/batch.h"
#include "phos/model/material.h"
#include "phos/model/simulate.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/progress.h"
#include "phos/util/svg_plot.h"
#include "phos/model/closed_form.h"

namespace phos {
namespace {

constexpr double kCharge_s = 120.0, kDark_s = 240.0;
const std::vector<double> kLight = {1, 1, 1, 0, 0, 0, 0, 0};  // bands 1-3, where Table 8.1 measured ke
const char* kMaterials[] = {"blue", "green", "orange", "pink", "purple", "red", "white", "yellow"};
const Integrator kIntegrators[] = {Integrator::kExact, Integrator::kEuler, Integrator::kRk4, Integrator::kReference};

double Seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Total emitted radiance at t by the closed form (long double).
long double TruthL(const Material& m, double a, double t) {
  const long double kr = m.states[0].kr, a_l = a;
  const long double r = t <= kCharge_s ? ChargedState(a_l, kr, static_cast<long double>(t))
                                       : ChargedState(a_l, kr, static_cast<long double>(kCharge_s)) *
                                             DecayFactor(kr, static_cast<long double>(t - kCharge_s));
  long double lambda = 0;
  for (double l : m.states[0].Lambda) lambda += l;
  return lambda * kr * r;
}

// Best-of-5 time per texel-step of the batch kernel at step h (ns).
double KernelNsPerTexelStep(Integrator integrator, double h) {
  const std::size_t n = 1 << 20;
  BatchCoefficients<float> c;
  c.nc = 1;
  c.n_exc = 3;
  c.n_em = 8;
  c.kr = {0.05f};
  c.ke = {0.1f, 0.035f, 0.006f};
  c.emission.assign(8, 0.1f);
  std::vector<float> E(3 * n, 1.0f), Lp(8 * n);
  StateBatch<float> s(1, n, 0.2f);
  double best = 1e30;
  for (int repeat = 0; repeat < 5; ++repeat) {
    auto start = std::chrono::steady_clock::now();
    AdvanceBatch<float>(integrator, c, E.data(), n, static_cast<float>(h), s, Lp.data(), n);
    best = std::min(best, Seconds(start));
  }
  return best / n * 1e9;
}

struct Row {
  std::string material;
  Integrator integrator;
  double dt_s;
  std::int64_t steps;
  std::string status;
  double max_error, final_error, cost_ns;
};

}  // namespace

int RunStudy(const std::string& out_dir, const std::string& fixtures) {
  std::vector<double> steps_s;
  for (double decade = 1e-3; decade < 200; decade *= 10)
    for (double m : {1.0, 2.0, 5.0})
      if (m * decade <= 100.0 * (1 + 1e-9)) steps_s.push_back(m * decade);

  // Cost per texel-step of each batch integrator at each step size.
  std::map<std::pair<int, double>, double> kernel_ns;
  for (Integrator integrator : {Integrator::kExact, Integrator::kEuler, Integrator::kRk4})
    for (double h : steps_s) kernel_ns[{static_cast<int>(integrator), h}] = KernelNsPerTexelStep(integrator, h);

  std::vector<Row> rows;
  ProgressBar progress("integrator study", std::size(kMaterials) * std::size(kIntegrators) * steps_s.size());
  for (const char* name : kMaterials) {
    std::string path = fixtures + "/materials/" + name + ".json";
    Material m = LoadMaterial(path);
    const double a = ExcitationRates(m, kLight, path)[0];
    for (Integrator integrator : kIntegrators)
      for (double h : steps_s) {
        SimulationOptions options;
        options.integrator = integrator;
        options.dt_s = h;
        options.allow_unstable = true;  // record what the unstable runs give
        auto start = std::chrono::steady_clock::now();
        SimulationResult result =
            Simulate(m, IrradianceSchedule::ChargeThenDecay(kLight, kCharge_s, kDark_s), options, path);
        const double wall = Seconds(start);
        long double peak = 0;
        for (double t : result.t_s) peak = std::max(peak, TruthL(m, a, t));
        double max_error = 0, final_error = 0;
        for (std::size_t s = 0; s < result.sample_count(); ++s) {
          double L = 0;
          for (int b = 0; b < result.nb; ++b) L += result.radiance(s, b);
          const long double truth = TruthL(m, a, result.t_s[s]);
          const double error = static_cast<double>(std::fabs(L - truth) / peak);
          max_error = std::isfinite(L) ? std::max(max_error, error) : INFINITY;
          if (s + 1 == result.sample_count()) final_error = static_cast<double>(std::fabs(L - truth) / truth);
        }
        std::string status = "ok";
        for (const std::string& w : result.warnings) status = w.rfind("unstable", 0) == 0 ? "unstable" : "not-monotone";
        const double duration = kCharge_s + kDark_s;
        const double cost = integrator == Integrator::kReference
                                ? wall / duration * 1e9
                                : kernel_ns[{static_cast<int>(integrator), h}] * result.steps / duration;
        rows.push_back({name, integrator, h, result.steps, status, max_error, final_error, cost});
        progress.Advance();
      }
  }
  progress.Finish();

  // CSV: one row per run.
  std::ostringstream csv;
  csv << "material,integrator,dt_s,steps,status,max_error_rel_peak,final_error_rel,cost_ns_per_texel_per_simulated_s\n";
  for (const Row& r : rows)
    csv << r.material << "," << IntegratorName(r.integrator) << "," << FormatDouble(r.dt_s) << "," << r.steps << ","
        << r.status << "," << FormatDouble(r.max_error) << "," << FormatDouble(r.final_error) << ","
        << FormatDouble(r.cost_ns) << "\n";
  std::filesystem::create_directories(out_dir);
  WriteFileAtomically(out_dir + "/integrator-study.csv", csv.str());

  // Worst case over the materials, per integrator and step: the plots and table.
  std::vector<PlotSeries> vs_cost, vs_step;
  std::ostringstream table;
  table << "| integrator | largest step with error <= 1e-3 | its cost (ns/texel/s) | largest step with error <= 1e-6 | "
           "its cost (ns/texel/s) |\n";
  table << "|---|---|---|---|---|\n";
  for (Integrator integrator : kIntegrators) {
    PlotSeries cost_series{IntegratorName(integrator)}, step_series{IntegratorName(integrator)};
    cost_series.markers = step_series.markers = true;
    struct Best {
      double dt = 0, cost = 0;
    } loose, tight;
    for (double h : steps_s) {
      double worst = 0, cost = 0;
      bool unstable = false;
      for (const Row& r : rows)
        if (r.integrator == integrator && r.dt_s == h) {
          worst = std::max(worst, r.max_error);
          cost = std::max(cost, r.cost_ns);
          unstable = unstable || r.status == "unstable";
        }
      // Unstable runs are refused by phos: they are not a point of the trade.
      const double shown = unstable ? NAN : std::max(worst, 1e-17);
      cost_series.x.push_back(cost);
      cost_series.y.push_back(shown);
      step_series.x.push_back(h);
      step_series.y.push_back(shown);
      if (!unstable && worst <= 1e-3 && h > loose.dt) loose = {h, cost};
      if (!unstable && worst <= 1e-6 && h > tight.dt) tight = {h, cost};
    }
    auto cell = [](const Best& b) {
      char cost[32];
      std::snprintf(cost, sizeof cost, "%.3g", b.cost);
      return b.dt > 0 ? FormatDouble(b.dt) + " s | " + cost : std::string("none | -");
    };
    table << "| " << IntegratorName(integrator) << " | " << cell(loose) << " | " << cell(tight) << " |\n";
    vs_cost.push_back(cost_series);
    vs_step.push_back(step_series);
  }
  PlotOptions options;
  options.log_x = options.log_y = true;
  options.title = "Integrators of Eq. 8.1: worst error over 8 presets against cost";
  options.x_label = "cost (ns per texel per simulated second, measured)";
  options.y_label = "max |L - L*| / peak L*";
  WriteFileAtomically(out_dir + "/integrator-study.svg", PlotSvg(vs_cost, options));
  options.title = "Integrators of Eq. 8.1: worst error over 8 presets against step size";
  options.x_label = "step (s)";
  WriteFileAtomically(out_dir + "/integrator-error-vs-step.svg", PlotSvg(vs_step, options));
  std::printf("%s", table.str().c_str());
  std::ostringstream md;
  md << "<!-- written by: build/bin/phos-integrator-study --out " << out_dir << " (make study) -->\n"
     << "Worst case over the 8 presets; cost measured in the same run (batch kernel, float, 2 cores).\n\n"
     << table.str();
  WriteFileAtomically(out_dir + "/integrator-study.md", md.str());
  std::printf(
      "\nwrote %s/integrator-study.csv (%zu runs), integrator-study.md, integrator-study.svg, "
      "integrator-error-vs-step.svg\n",
      out_dir.c_str(), rows.size());
  return 0;
}

}  // namespace phos

int main(int argc, char** argv) {
  CLI::App app{
      "Error against cost of the four integrators of Eq. 8.1 on the Table 8.1 presets\n"
      "(charge 120 s under E = 1 in bands 1-3, then 240 s dark; steps 1 ms to 100 s).",
      "phos-integrator-study"};
  std::string out = "docs", fixtures = PHOS_FIXTURES_DIR;
  app.add_option("--out", out, "folder for integrator-study.csv and the SVG plots (default docs)");
  app.add_option("--fixtures", fixtures, "the fixtures folder (default: the source tree's)");
  CLI11_PARSE(app, argc, argv);
  try {
    return phos::RunStudy(out, fixtures);
  } catch (const phos::UserError& e) {
    std::fprintf(stderr, "phos-integrator-study: %s\n", e.what());
    return 2;
  }
}
