// Only the states a scene needs, measured (docs/state-trade.md): the
// sign-paint material (a t^-1 power law from 1 min to 10 h in 16 states)
// reduced to k = 1..16 states by ReduceStates (model/state_reduction.h) for
// scenes of 1 min, 10 min and 1 h, each after a 5 min charge, frames of
// 1/30 s:
//   error: the largest e(t) of state_reduction.h over the scene (the charge
//          and the dark after it), max over bands of |L_k - L_16| / sum L_16;
//   cost:  the batch kernel's time per texel step (batch.h, float, 2^20
//          texels, 3 lit bands, 8 emitted, best of 5 x 5) for k states, lit
//          (AdvanceBatch, exact) and dark (DecayBatch), in the same run, as
//          a ratio to 16 states. A kernel built for fewer than k states
//          (kMaxStates) runs k states as several calls and sums their
//          radiance, and the table says so.
// Also the fewest states ReduceStates keeps for a tolerance of 1% and 2%.
// Writes <out>/state-trade.md, state-trade.csv and state-trade.svg.
//
// Run: build/bin/phos-state-trade-study --out docs   (or: make study)

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <tbb/parallel_for.h>

#include "phos/model/batch.h"
#include "phos/model/material.h"
#include "phos/model/state_reduction.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/svg_plot.h"

namespace phos {
namespace {

constexpr double kCharge_s = 300.0, kDt_s = 1.0 / 30;
const double kScenes_s[] = {60.0, 600.0, 3600.0};
const char* kSceneNames[] = {"1 min", "10 min", "1 h"};
const std::vector<double> kLight = {1, 1, 1, 0, 0, 0, 0, 0};  // the bands where sign-paint's ke is known

// fixtures/materials/sign-paint.json as ManyTrapMaterial (model/synthetic.h)
// writes it, for a tree whose material files hold fewer than 16 states:
// the same kr, the same total Lambda per state, the same emission shape.
Material SignPaint() {
  const double kr[16] = {0.5,
                         0.2074007967059685,
                         0.08603018094854097,
                         0.03568545613897206,
                         0.014802384068077403,
                         0.006140052497733981,
                         0.002546903559692998,
                         0.0010564596548271906,
                         0.0004382211481977435,
                         0.00018177483053923252,
                         7.54004893498586e-05,
                         3.127624312636112e-05,
                         1.2973435484753731e-05,
                         5.381401711102811e-06,
                         2.2322140045551737e-06,
                         9.259259259259266e-07};
  const double total[16] = {1.8199536150974938,  1.7034818563418268,  0.9002495257442303, 0.5670674751323634,
                            0.4288630296423045,  0.3715356054364147,  0.3477560985296095, 0.33789232117411666,
                            0.33380081060999767, 0.3321036455085393,  0.3313996587201713, 0.33110764387861524,
                            0.3309865156570378,  0.33093627147772037, 0.3309154301120798, 0.5415030765099293};
  const double shape[8] = {0.0027303254264035757, 0.06228099874791298,  0.33537619752367137,    0.4431709373532448,
                           0.14485924082089702,   0.011376259907475062, 0.00020522240048331447, 8.178199117754425e-07};
  Material m;
  m.name = "sign-paint";
  m.bands = SpectralGrid::Uniform(400.0, 700.0, 8);
  for (int i = 0; i < 16; ++i) {
    ExcitedState s;
    s.kr = kr[i];
    s.ke = {0.05, 0.03, 0.01, std::nullopt, std::nullopt, std::nullopt, std::nullopt, std::nullopt};
    for (double f : shape) s.Lambda.push_back(total[i] * f);
    m.states.push_back(s);
  }
  return m;
}

double Seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Best-of-5 ns per texel step of k states: one kernel call per kMaxStates
// states, their radiance summed. lit: AdvanceBatch (exact); else DecayBatch.
double KernelNsPerTexelStep(int k, bool lit) {
  const std::size_t n = 1 << 20;
  std::vector<BatchCoefficients<float>> groups;
  std::vector<StateBatch<float>> states;
  for (int first = 0; first < k; first += kMaxStates) {
    BatchCoefficients<float> c;
    c.nc = std::min(kMaxStates, k - first);
    c.n_exc = 3;
    c.n_em = 8;
    for (int i = 0; i < c.nc; ++i) c.kr.push_back(0.5f / static_cast<float>(1 + first + i));
    c.ke.assign(static_cast<std::size_t>(3 * c.nc), 0.03f);
    c.emission.assign(static_cast<std::size_t>(8 * c.nc), 0.1f);
    groups.push_back(c);
    states.emplace_back(c.nc, n, 0.2f);
  }
  std::vector<float> E(3 * n, 1.0f), Lp(8 * n), Lp_group(8 * n);
  double best = 1e30;
  for (int repeat = 0; repeat < 5; ++repeat) {
    auto start = std::chrono::steady_clock::now();
    for (std::size_t g = 0; g < groups.size(); ++g) {
      float* out = g == 0 ? Lp.data() : Lp_group.data();
      if (lit)
        AdvanceBatch<float>(Integrator::kExact, groups[g], E.data(), n, static_cast<float>(kDt_s), states[g], out, n);
      else
        DecayBatch<float>(groups[g], static_cast<float>(kDt_s), states[g], out, n);
      if (g > 0)
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, Lp.size(), 1 << 16),
                          [&](const tbb::blocked_range<std::size_t>& range) {
                            for (std::size_t j = range.begin(); j < range.end(); ++j) Lp[j] += Lp_group[j];
                          });
    }
    best = std::min(best, Seconds(start));
  }
  return best / n * 1e9;
}

IrradianceSchedule Scene(double scene_s) { return IrradianceSchedule::ChargeThenDecay(kLight, kCharge_s, scene_s); }

StateReduction Reduce(const Material& m, double scene_s, std::optional<int> k, double tolerance) {
  StateReductionOptions options;
  options.span_s = kCharge_s + scene_s;
  options.dt_s = kDt_s;
  options.tolerance = tolerance;
  options.states = k;
  return ReduceStates(m, Scene(scene_s), options, m.name);
}

}  // namespace

namespace {

struct Measured {
  std::vector<double> lit_ns, dark_ns;         // [k - 1]
  std::vector<std::vector<double>> error;      // [scene][k - 1]
  std::vector<StateReduction> at_1pc, at_2pc;  // [scene]
};

Measured Measure(const Material& m) {
  Measured r;
  const int n = m.state_count();
  // Five sweeps over k, the best of each k kept: the machine is shared, and
  // a slow minute then costs one sweep, not the states measured in it.
  r.lit_ns.assign(n, 1e30);
  r.dark_ns.assign(n, 1e30);
  for (int sweep = 0; sweep < 5; ++sweep)
    for (int k = 1; k <= n; ++k) {
      r.lit_ns[k - 1] = std::min(r.lit_ns[k - 1], KernelNsPerTexelStep(k, true));
      r.dark_ns[k - 1] = std::min(r.dark_ns[k - 1], KernelNsPerTexelStep(k, false));
    }
  for (double scene_s : kScenes_s) {
    std::vector<double> errors;
    for (int k = 1; k <= n; ++k) errors.push_back(Reduce(m, scene_s, k, 0.01).max_error);
    r.error.push_back(errors);
    r.at_1pc.push_back(Reduce(m, scene_s, std::nullopt, 0.01));
    r.at_2pc.push_back(Reduce(m, scene_s, std::nullopt, 0.02));
  }
  return r;
}

// The first field of /proc/loadavg, "?" where there is none.
std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string first = "?";
  in >> first;
  return first;
}

std::string Short(double value, const char* format = "%.3g") {
  char text[32];
  std::snprintf(text, sizeof text, format, value);
  return text;
}

std::string Tables(const Measured& r, int n) {
  std::ostringstream md;
  md << "| states | kernel calls | lit step (ns/texel) | x 16 states | dark step (ns/texel) | x 16 states |";
  for (const char* name : kSceneNames) md << " error, " << name << " |";
  md << "\n|---|---|---|---|---|---|---|---|---|\n";
  for (int k = 1; k <= n; ++k) {
    md << "| " << k << " | " << (k + kMaxStates - 1) / kMaxStates << " | " << Short(r.lit_ns[k - 1]) << " | "
       << Short(r.lit_ns[k - 1] / r.lit_ns[n - 1], "%.2f") << " | " << Short(r.dark_ns[k - 1]) << " | "
       << Short(r.dark_ns[k - 1] / r.dark_ns[n - 1], "%.2f") << " |";
    for (const auto& errors : r.error) md << " " << Short(100 * errors[k - 1], "%.2g") << "% |";
    md << "\n";
  }
  md << "\nThe fewest states ReduceStates keeps (aiming at 0.9 x the tolerance), and the largest error they cost:\n\n"
     << "| scene | tolerance 1%: states | error | tolerance 2%: states | error |\n|---|---|---|---|---|\n";
  for (std::size_t s = 0; s < std::size(kScenes_s); ++s)
    md << "| " << kSceneNames[s] << " | " << r.at_1pc[s].states_after << " | "
       << Short(100 * r.at_1pc[s].max_error, "%.2g") << "% | " << r.at_2pc[s].states_after << " | "
       << Short(100 * r.at_2pc[s].max_error, "%.2g") << "% |\n";
  return md.str();
}

void WriteCsvAndPlot(const Measured& r, int n, const std::string& out_dir) {
  std::ostringstream csv;
  csv << "scene_s,states,max_error,lit_ns_per_texel_step,dark_ns_per_texel_step,lit_cost_vs_16,dark_cost_vs_16,"
         "kernel_calls\n";
  std::vector<PlotSeries> series;
  for (std::size_t s = 0; s < std::size(kScenes_s); ++s) {
    PlotSeries line(std::string(kSceneNames[s]) + " scene");
    line.markers = true;
    for (int k = 1; k <= n; ++k) {
      const double lit = r.lit_ns[k - 1] / r.lit_ns[n - 1], error = r.error[s][k - 1];
      csv << FormatDouble(kScenes_s[s]) << "," << k << "," << FormatDouble(error) << ","
          << FormatDouble(r.lit_ns[k - 1]) << "," << FormatDouble(r.dark_ns[k - 1]) << "," << FormatDouble(lit) << ","
          << FormatDouble(r.dark_ns[k - 1] / r.dark_ns[n - 1]) << "," << (k + kMaxStates - 1) / kMaxStates << "\n";
      line.x.push_back(lit);
      line.y.push_back(error);  // 0 at 16 states: a gap on the log axis
    }
    series.push_back(line);
  }
  PlotOptions options;
  options.log_y = true;
  options.title = "sign-paint reduced to 1-16 states: largest radiance error against solver cost";
  options.x_label = "lit step cost, ratio to 16 states (batch kernel, measured)";
  options.y_label = "max_t max_b |L_k - L_16| / sum_b L_16";
  WriteFileAtomically(out_dir + "/state-trade.csv", csv.str());
  WriteFileAtomically(out_dir + "/state-trade.svg", PlotSvg(series, options));
}

}  // namespace

int RunStudy(const std::string& out_dir, const std::string& fixtures) {
  const std::string fixture = fixtures + "/materials/sign-paint.json";
  const bool from_file = kMaxStates >= 16 && std::filesystem::exists(fixture);
  const Material m = from_file ? LoadMaterial(fixture) : SignPaint();
  const int n = m.state_count();
  const std::string load_before = LoadAverage();
  const Measured r = Measure(m);
  std::filesystem::create_directories(out_dir);
  WriteCsvAndPlot(r, n, out_dir);
  const std::string tables = Tables(r, n);
  std::printf("%s", tables.c_str());
  std::ostringstream md;
  md << "<!-- written by: build/bin/phos-state-trade-study --out " << out_dir << " (make study) -->\n"
     << "# Only the states a scene needs: error against solver cost\n\n"
     << "Material: "
     << (from_file ? std::string("fixtures/materials/sign-paint.json")
                   : "sign-paint as built in the study (fixtures/materials/sign-paint.json's kr, Lambda and ke: "
                     "this tree's material files hold at most " +
                         std::to_string(kMaxStates) + " states)")
     << ", a t^-1 power law from 1 min to 10 h in 16 states, reduced to k states by ReduceStates "
        "(model/state_reduction.h). Each scene: 5 min under E = 1 in bands 1-3, then dark for the scene's "
        "length; frames of 1/30 s. The error is the largest over the scene (the charge and the dark) of "
        "max_b |L_k,b - L_16,b| / sum_b L_16,b. Cost: the batch kernel (model/batch.h), float, 2^20 texels, 3 lit "
        "and 8 emitted bands, best of 5 sweeps x 5, 2 shared cores, this run; a kernel built for at most "
     << kMaxStates << " states (kMaxStates) runs more as several calls whose radiance one more pass sums. "
     << "Load average (1 min) before and after the timing: " << load_before << ", " << LoadAverage()
     << ": other work on the machine makes the cost columns noisy; rerun on a quiet one.\n\n"
     << tables;
  WriteFileAtomically(out_dir + "/state-trade.md", md.str());
  std::printf("\nwrote %s/state-trade.md, state-trade.csv, state-trade.svg\n", out_dir.c_str());
  return 0;
}

}  // namespace phos

int main(int argc, char** argv) {
  CLI::App app{
      "Error against solver cost of the sign-paint material reduced to 1-16 states\n"
      "(scenes of 1 min, 10 min and 1 h after a 5 min charge; frames of 1/30 s).",
      "phos-state-trade-study"};
  std::string out = "docs", fixtures = PHOS_FIXTURES_DIR;
  app.add_option("--out", out, "folder for state-trade.md, .csv and .svg (default docs)");
  app.add_option("--fixtures", fixtures, "the fixtures folder (default: the source tree's)");
  CLI11_PARSE(app, argc, argv);
  try {
    return phos::RunStudy(out, fixtures);
  } catch (const phos::UserError& e) {
    std::fprintf(stderr, "phos-state-trade-study: %s\n", e.what());
    return 2;
  }
}
