#include "phos/fit/session_fit.h"

#include <ceres/ceres.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <map>
#include <numeric>

#include "phos/model/spectral.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/svg_plot.h"
#include "solver_options.h"

namespace phos {
namespace {

namespace fs = std::filesystem;

std::vector<double> ColumnRate(const nlohmann::json& line) {
  std::vector<double> profile = line.at("column_mean_dn").get<std::vector<double>>();
  const double exposure = line.at("exposure_s").get<double>();
  for (double& v : profile) v /= exposure;
  return profile;
}

bool Clipped(const nlohmann::json& line) { return line.value("saturated_fraction", 0.0) > 0; }

double SumSignal(const nlohmann::json& line) {
  double sum = 0;
  for (double v : line.at("mean_signal_dn")) sum += v;
  return sum;
}

// Centroid and spread (in columns) of the peak of a profile: a window of
// +-3 sigma around the centroid, refined a few times, so the tails and the
// far baseline do not pull it.
void PeakMoments(const std::vector<double>& p, double* centroid, double* sigma) {
  const int n = static_cast<int>(p.size());
  const int peak = static_cast<int>(std::max_element(p.begin(), p.end()) - p.begin());
  double c = peak, s = 2;
  for (int iteration = 0; iteration < 5; ++iteration) {
    const int lo = std::max(0, static_cast<int>(std::floor(c - 3 * s))), hi = std::min(n - 1, static_cast<int>(std::ceil(c + 3 * s)));
    double w = 0, wx = 0, wxx = 0;
    for (int x = lo; x <= hi; ++x) {
      const double v = std::max(0.0, p[x]);
      w += v;
      wx += v * x;
      wxx += v * x * x;
    }
    if (w <= 0) break;
    c = wx / w;
    s = std::sqrt(std::max(0.25, wxx / w - c * c));
  }
  *centroid = c;
  *sigma = s;
}

// min sum_r (w_r (A x - y)_r)^2 + alpha |D x|^2 over x >= 0 (D: first
// differences), as a bounded Ceres problem: the non-negative, regularized
// reconstruction of a spectrum from blurred samples.
struct LinearRow {
  LinearRow(std::vector<double> row, double target, double weight) : row_(std::move(row)), target_(target), weight_(weight) {}
  template <typename T>
  bool operator()(T const* const* x, T* residual) const {
    T sum = T(-target_);
    for (std::size_t i = 0; i < row_.size(); ++i) sum += row_[i] * x[0][i];
    residual[0] = weight_ * sum;
    return true;
  }
  std::vector<double> row_;
  double target_, weight_;
};

std::vector<double> SolveNonNegative(const std::vector<std::vector<double>>& A, const std::vector<double>& y,
                                     const std::vector<double>& weight, double alpha) {
  const std::size_t n = A.empty() ? 0 : A[0].size();
  std::vector<double> x(n, 0.0);
  // Start: the unconstrained scale of a flat spectrum.
  double ay = 0, aa = 0;
  for (std::size_t r = 0; r < A.size(); ++r) {
    const double a = std::accumulate(A[r].begin(), A[r].end(), 0.0);
    ay += a * y[r] * weight[r] * weight[r];
    aa += a * a * weight[r] * weight[r];
  }
  std::fill(x.begin(), x.end(), aa > 0 ? std::max(ay / aa, 0.0) : 0.0);
  ceres::Problem problem;
  auto add = [&](std::vector<double> row, double target, double w) {
    auto* cost = new ceres::DynamicAutoDiffCostFunction<LinearRow>(new LinearRow(std::move(row), target, w));
    cost->AddParameterBlock(static_cast<int>(n));
    cost->SetNumResiduals(1);
    problem.AddResidualBlock(cost, nullptr, x.data());
  };
  for (std::size_t r = 0; r < A.size(); ++r) add(A[r], y[r], weight[r]);
  for (std::size_t i = 0; i + 1 < n && alpha > 0; ++i) {
    std::vector<double> row(n, 0.0);
    row[i] = -1;
    row[i + 1] = 1;
    add(row, 0.0, std::sqrt(alpha));
  }
  for (std::size_t i = 0; i < n; ++i) problem.SetParameterLowerBound(x.data(), static_cast<int>(i), 0.0);
  ceres::Solver::Options options = SmallDenseSolverOptions(200, 1e-14);
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  return x;
}

nlohmann::json SessionStart(const fs::path& dir) {
  if (!fs::is_regular_file(dir / "session.json"))
    ThrowUserError(dir.string(), "", "is not a capture session (no session.json)");
  return ReadJsonFile(dir / "session.json");
}

std::string StopHow(const fs::path& dir) {
  if (!fs::exists(dir / "stop.json")) return "none (killed, or still running)";
  return ReadJsonFile(dir / "stop.json").value("how", "?");
}


// ---- the joint refinement -------------------------------------------------

// One decay sample of one channel: w (A e^{-k t} sinh(ke/2)/(ke/2) + B - y).
struct JointDecayResidual {
  double t, e, y, w;
  template <typename T>
  bool operator()(const T* log_k, const T* amplitude_background, T* residual) const {
    const T k = exp(log_k[0]);
    const T x = k * e / 2.0;
    const T factor = x > T(1e-8) ? sinh(x) / x : T(1.0);
    residual[0] = w * (amplitude_background[0] * exp(-k * t) * factor + amplitude_background[1] - y);
    return true;
  }
};

// One excitation sample: w (S r(t_c) D - y), the closed forms of excitation_fit.h.
struct JointExcitationResidual {
  double tc, td, te, y, w;
  template <typename T>
  bool operator()(const T* log_k, const T* log_a, const T* S, T* residual) const {
    const T k = exp(log_k[0]), a = exp(log_a[0]);
    const T r = a / (a + k) * (1.0 - exp(-(a + k) * tc));
    const T D = te > 0 ? exp(-k * td) * (1.0 - exp(-k * te)) / (k * te) : exp(-k * td);
    residual[0] = w * (S[0] * r * D - y);
    return true;
  }
};

double PoissonWeight(double value, double exposure, double floor) {
  return std::sqrt(exposure / std::max(std::fabs(value), floor));
}

}  // namespace

JointFit JointRefine(const Curve& decay_curve, const DecayFitSummary& decay,
                     const std::vector<SessionFit::ExcitationLight>& lights) {
  JointFit joint;
  const int C = decay_curve.channel_count();
  double log_k = std::log(decay.components[0].rate);
  std::vector<std::array<double, 2>> ab(static_cast<std::size_t>(C));
  for (int c = 0; c < C; ++c) ab[c] = {decay.components[0].amplitude[c], decay.background.empty() ? 0.0 : decay.background[c]};
  std::map<std::string, double> log_a;
  double S = 0;
  for (const auto& light : lights)
    if (light.fit.a > 0) {
      log_a[light.light] = std::log(light.fit.a);
      S = light.fit.scale;
    }
  if (log_a.empty()) ThrowUserError("", "joint refinement", "no light excites the sample");
  std::vector<double> log_a_values;
  for (auto& [name, value] : log_a) log_a_values.push_back(value);

  ceres::Problem problem;
  std::vector<ceres::ResidualBlockId> decay_blocks, excitation_blocks;
  for (int c = 0; c < C; ++c) {
    double peak = 0;
    for (double v : decay_curve.channels[c]) peak = std::max(peak, std::fabs(v));
    for (std::size_t j = 0; j < decay_curve.size(); ++j) {
      const double e = j < decay_curve.exposure_s.size() ? decay_curve.exposure_s[j] : 1.0;
      const double y = decay_curve.channels[c][j];
      decay_blocks.push_back(problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<JointDecayResidual, 1, 1, 2>(
              new JointDecayResidual{decay_curve.t_s[j], e, y, PoissonWeight(y, e, 1e-3 * peak)}),
          nullptr, &log_k, ab[c].data()));
    }
  }
  std::size_t index = 0;
  for (auto& [name, value] : log_a) {
    double* parameter = &log_a_values[index++];
    for (const auto& light : lights) {
      if (light.light != name) continue;
      double peak = 0;
      for (const ExcitationSample& s : light.samples) peak = std::max(peak, std::fabs(s.value));
      for (const ExcitationSample& s : light.samples)
        excitation_blocks.push_back(problem.AddResidualBlock(
            new ceres::AutoDiffCostFunction<JointExcitationResidual, 1, 1, 1, 1>(new JointExcitationResidual{
                s.charge_s, s.delay_s, s.exposure_s, s.value,
                PoissonWeight(s.value, std::max(s.exposure_s, 1e-6), 1e-3 * peak)}),
            nullptr, &log_k, parameter, &S));
    }
  }
  for (int c = 0; c < C; ++c) problem.SetParameterLowerBound(ab[c].data(), 0, 0.0);
  auto cost_of = [&](const std::vector<ceres::ResidualBlockId>& blocks) {
    if (blocks.empty()) return 0.0;
    ceres::Problem::EvaluateOptions evaluate;
    evaluate.residual_blocks = blocks;
    double cost = 0;
    problem.Evaluate(evaluate, &cost, nullptr, nullptr, nullptr);
    return 2 * cost;  // Ceres reports half the sum of squares
  };
  joint.decay_sequential = cost_of(decay_blocks);
  joint.excitation_sequential = cost_of(excitation_blocks);
  ceres::Solver::Options options = SmallDenseSolverOptions(200, 1e-12);
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  joint.iterations = static_cast<int>(summary.iterations.size());
  joint.decay_joint = cost_of(decay_blocks);
  joint.excitation_joint = cost_of(excitation_blocks);
  joint.kr = std::exp(log_k);
  joint.S = S;
  index = 0;
  for (auto& [name, value] : log_a) joint.a[name] = std::exp(log_a_values[index++]);
  for (const auto& light : lights)
    if (!joint.a.count(light.light)) joint.a[light.light] = 0;  // did not excite: stays 0
  return joint;
}

namespace {
}  // namespace

LvfCalibrationFit FitLvfCalibration(const fs::path& dir) {
  const nlohmann::json start = SessionStart(dir);
  const nlohmann::json settings = start.value("settings", nlohmann::json::object());
  LvfCalibrationFit fit;
  fit.flat_temperature_k = settings.value("flat_temperature_k", 3000.0);
  fit.flat_irradiance = settings.value("flat_irradiance", 1.0);
  // The last unclipped frame of each source is its well-exposed one.
  std::map<std::string, nlohmann::json> last;
  for (const nlohmann::json& line : ReadJsonLines(dir / "frames.jsonl")) {
    if (!line.contains("column_mean_dn") || Clipped(line)) continue;
    last[line.value("kind", "") == "dark" ? std::string("(dark)") : line.value("light", "")] = line;
  }
  std::vector<double> dark;
  if (last.count("(dark)")) dark = ColumnRate(last["(dark)"]);
  fit.dark_dn_per_s = dark;
  // Dark current is uniform: its mean over the columns, not each noisy column.
  double dark_mean = 0;
  for (double d : dark) dark_mean += d / dark.size();
  auto rate = [&](const nlohmann::json& line) {
    std::vector<double> p = ColumnRate(line);
    for (double& v : p) v -= dark_mean;
    return p;
  };
  std::vector<double> sigmas;
  for (const auto& [light, line] : last) {
    if (line.value("kind", "") == "line") {
      const std::vector<double> p = rate(line);
      fit.width = static_cast<int>(p.size());
      double c = 0, s = 0;
      PeakMoments(p, &c, &s);
      fit.lines.push_back({light, line.at("wavelength_nm").get<double>(), c});
      sigmas.push_back(std::sqrt(std::max(0.0, s * s - 1.0 / 12)));  // less the pixel's own width
    } else if (line.value("kind", "") == "flat") {
      fit.flat_dn_per_s = rate(line);
    }
  }
  if (fit.lines.size() < 2)
    ThrowUserError(dir.string(), "lvf-calibration", "needs well-exposed frames of at least 2 lines, has " +
                                                         std::to_string(fit.lines.size()));
  if (fit.flat_dn_per_s.empty()) ThrowUserError(dir.string(), "lvf-calibration", "has no unclipped flat-field frame");
  // centre(x) = c0 + c1 x by least squares over the lines.
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  const double n = static_cast<double>(fit.lines.size());
  for (const auto& line : fit.lines) {
    sx += line.column;
    sy += line.wavelength_nm;
    sxx += line.column * line.column;
    sxy += line.column * line.wavelength_nm;
  }
  const double denominator = n * sxx - sx * sx;
  if (!(std::fabs(denominator) > 1e-12))
    ThrowUserError(dir.string(), "lvf-calibration", "all lines fall on one column: the filter's line cannot be fitted");
  fit.nm_per_column = (n * sxy - sx * sy) / denominator;
  fit.center0_nm = (sy - fit.nm_per_column * sx) / n;
  double sq = 0;
  for (const auto& line : fit.lines) sq += std::pow(fit.CenterNm(line.column) - line.wavelength_nm, 2);
  fit.rms_residual_nm = std::sqrt(sq / n);
  double mean_sigma = 0;
  for (double s : sigmas) mean_sigma += s / static_cast<double>(sigmas.size());
  fit.fwhm_nm = 2.3548 * mean_sigma * std::fabs(fit.nm_per_column);
  return fit;
}

SpectrumFit FitEmissionSpectrum(const fs::path& dir, const LvfCalibrationFit& calibration, const SpectralGrid& bands,
                                double dark_dn_per_s) {
  if (!std::isfinite(dark_dn_per_s)) {
    dark_dn_per_s = 0;
    for (double d : calibration.dark_dn_per_s) dark_dn_per_s += d / calibration.dark_dn_per_s.size();
  }
  const nlohmann::json start = SessionStart(dir);
  const nlohmann::json settings = start.value("settings", nlohmann::json::object());
  const nlohmann::json exposure = settings.value("exposure", nlohmann::json::object());
  const double low = exposure.value("low_fraction", 0.15), high = exposure.value("high_fraction", 0.7);
  SpectrumFit fit;
  fit.charge_light = settings.value("charge_light", "");
  fit.charge_s = settings.value("charge_s", 0.0);
  const int nb = bands.band_count();
  const double sigma = calibration.fwhm_nm / 2.3548;
  if (!(sigma > 0)) ThrowUserError(dir.string(), "spectrum", "the LVF calibration gives no pass-band width");
  // What one column sees of a radiance density L(lambda) is
  //   y(x) = integral L(lambda) u(lambda) G_x(lambda) dlambda,
  // G_x the filter's pass band (centre and width from the lines) and u the
  // camera's sensitivity times the filter's peak transmission, unknown. The
  // flat field, a lamp of known colour temperature and irradiance on the
  // white reference (radiance E B(lambda) / pi), gives u: a non-negative,
  // smooth reconstruction on nodes every 5 nm. Dividing by the flat column
  // by column instead would assume u constant across each pass band, which
  // it is not where a colour filter's edge falls.
  const SampledSpectrum lamp = BlackbodySpectrum(calibration.flat_temperature_k, 350, 800);
  const int width = static_cast<int>(calibration.flat_dn_per_s.size());
  const double flat_max = *std::max_element(calibration.flat_dn_per_s.begin(), calibration.flat_dn_per_s.end());
  constexpr double kNodeNm = 5, kStepNm = 0.25;
  const double lo_nm = std::min(calibration.CenterNm(0), calibration.CenterNm(width - 1)) - 4 * sigma;
  const double hi_nm = std::max(calibration.CenterNm(0), calibration.CenterNm(width - 1)) + 4 * sigma;
  const int nodes = static_cast<int>(std::ceil((hi_nm - lo_nm) / kNodeNm)) + 1;
  // Hat function of node k at lambda.
  auto hat = [&](int k, double nm) { return std::max(0.0, 1.0 - std::fabs((nm - lo_nm) / kNodeNm - k)); };
  std::vector<bool> usable(static_cast<std::size_t>(width), false);
  std::vector<std::vector<double>> flat_rows;
  std::vector<double> flat_targets, flat_weights;
  for (int x = 0; x < width; ++x) {
    // Columns the lamp barely lights are too noisy to learn from: left out.
    usable[x] = calibration.flat_dn_per_s[x] > 0.02 * flat_max;
    if (!usable[x]) continue;
    const double c = calibration.CenterNm(x);
    std::vector<double> row(static_cast<std::size_t>(nodes), 0.0);
    for (double nm = c - 4 * sigma; nm <= c + 4 * sigma; nm += kStepNm) {
      const double seen = calibration.flat_irradiance * lamp.Evaluate(nm) / M_PI *
                          std::exp(-0.5 * std::pow((nm - c) / sigma, 2)) * kStepNm;
      const int k0 = static_cast<int>(std::floor((nm - lo_nm) / kNodeNm));
      for (int k = std::max(0, k0); k <= std::min(nodes - 1, k0 + 1); ++k) row[k] += seen * hat(k, nm);
    }
    flat_rows.push_back(row);
    flat_targets.push_back(calibration.flat_dn_per_s[x]);
    flat_weights.push_back(1.0 / std::sqrt(calibration.flat_dn_per_s[x]));
  }
  double flat_diag = 0;
  for (std::size_t r = 0; r < flat_rows.size(); ++r)
    for (double a : flat_rows[r]) flat_diag += a * a * flat_weights[r] * flat_weights[r];
  const std::vector<double> u = SolveNonNegative(flat_rows, flat_targets, flat_weights, 1e-5 * flat_diag / nodes);
  auto sensitivity = [&](double nm) {
    const int k0 = static_cast<int>(std::floor((nm - lo_nm) / kNodeNm));
    double value = 0;
    for (int k = std::max(0, k0); k <= std::min(nodes - 1, k0 + 1); ++k) value += u[k] * hat(k, nm);
    return value;
  };
  // The sample's radiance density is uniform inside each band (the model's
  // own assumption): A[x][b] = integral over band b of u G_x / width_b.
  std::vector<std::vector<double>> A(static_cast<std::size_t>(width), std::vector<double>(nb, 0.0));
  for (int x = 0; x < width; ++x) {
    if (!usable[x]) continue;
    const double c = calibration.CenterNm(x);
    for (int b = 0; b < nb; ++b) {
      const double lo = std::max(bands.lower_nm(b), c - 4 * sigma), hi = std::min(bands.upper_nm(b), c + 4 * sigma);
      for (double nm = lo + kStepNm / 2; nm < hi; nm += kStepNm)
        A[x][b] += sensitivity(nm) * std::exp(-0.5 * std::pow((nm - c) / sigma, 2)) * kStepNm / bands.width_nm(b);
    }
  }
  for (const nlohmann::json& line : ReadJsonLines(dir / "frames.jsonl")) {
    if (line.value("kind", "") != "spectrum" || !line.contains("column_mean_dn") || Clipped(line)) continue;
    const double peak = line.value("peak_column_fraction", 0.0);
    if (peak < low || peak > high) continue;  // not well exposed: the protocol stepped past it
    std::vector<double> y = ColumnRate(line);
    for (double& v : y) v -= dark_dn_per_s;
    if (static_cast<int>(y.size()) != width)
      ThrowUserError(dir.string(), "spectrum", "frames and the LVF calibration differ in width");
    std::vector<std::vector<double>> rows;
    std::vector<double> targets, weights;
    const double y_max = *std::max_element(y.begin(), y.end());
    for (int x = 0; x < width; ++x) {
      if (!usable[x]) continue;
      rows.push_back(A[x]);
      targets.push_back(y[x]);
      weights.push_back(1.0 / std::sqrt(std::max(std::fabs(y[x]), 0.01 * y_max)));  // photon counting
    }
    // A whisper of smoothness (1e-4 of the data's weight) keeps bands the
    // filter barely separates from trading off; it does not shape the rest.
    double diag = 0;
    for (std::size_t r = 0; r < rows.size(); ++r)
      for (double a : rows[r]) diag += a * a * weights[r] * weights[r];
    const std::vector<double> L = SolveNonNegative(rows, targets, weights, 1e-4 * diag / std::max(1, nb));
    SpectrumFit::FrameFit frame;
    frame.delay_s = line.value("delay_after_light_off_s", 0.0);
    frame.exposure_s = line.value("exposure_s", 0.0);
    frame.t_start_s = line.value("t_start_s", 0.0);
    frame.band_radiance = L;
    frame.measured = y;
    frame.modelled.assign(static_cast<std::size_t>(width), std::nan(""));
    for (int x = 0; x < width; ++x)
      if (usable[x]) frame.modelled[x] = std::inner_product(A[x].begin(), A[x].end(), L.begin(), 0.0);
    fit.frames.push_back(std::move(frame));
  }
  if (fit.frames.empty()) ThrowUserError(dir.string(), "spectrum", "has no well-exposed, unclipped frame");
  fit.shape.assign(static_cast<std::size_t>(nb), 0.0);
  for (const auto& frame : fit.frames) {
    const double total = std::accumulate(frame.band_radiance.begin(), frame.band_radiance.end(), 0.0);
    for (int b = 0; b < nb && total > 0; ++b) fit.shape[b] += frame.band_radiance[b] / total / fit.frames.size();
  }
  return fit;
}

SessionFit FitSession(const fs::path& dir, const SessionFitOptions& options) {
  const auto started = std::chrono::steady_clock::now();
  const nlohmann::json top = SessionStart(dir);
  if (top.value("protocol", "") != "all")
    ThrowUserError(dir.string(), "", "is a '" + top.value("protocol", "?") +
                                         "' session; fit session takes the folder of 'phos capture all'");
  SessionFit result;
  const std::string top_how = StopHow(dir);
  if (top_how != "complete")
    result.notes.push_back("the capture did not complete (stop: " + top_how + "); fitting what it recorded");
  // The bands: the simulated sample's grid, or the paper's.
  const nlohmann::json devices = top.value("devices", nlohmann::json::object());
  SpectralGrid bands = SpectralGrid::Paper();
  if (devices.contains("bands_nm")) bands.edges_nm = devices["bands_nm"].get<std::vector<double>>();
  const int nb = bands.band_count();
  auto part_ok = [&](const std::string& part) {
    if (!fs::exists(dir / part / "session.json")) {
      result.notes.push_back(part + ": not captured");
      return false;
    }
    const std::string how = StopHow(dir / part);
    if (how != "complete") result.notes.push_back(part + ": stopped '" + how + "'; using the frames it kept");
    return true;
  };

  // 1-2. LVF calibration and the emission spectrum.
  if (part_ok("lvf-calibration")) {
    try {
      result.calibration = FitLvfCalibration(dir / "lvf-calibration");
    } catch (const UserError& e) {
      result.notes.push_back(e.what());
    }
  }
  // 3. Decay.
  Curve raw_decay;
  if (part_ok("decay")) {
    Curve& curve = raw_decay;
    std::vector<double> exposures;
    int clipped = 0;
    for (const nlohmann::json& line : ReadJsonLines(dir / "decay" / "frames.jsonl")) {
      if (!line.contains("mean_signal_dn")) continue;
      if (Clipped(line)) {
        ++clipped;
        continue;
      }
      const std::vector<double> means = line["mean_signal_dn"].get<std::vector<double>>();
      const double exposure = line.at("exposure_s").get<double>();
      if (curve.channels.empty()) {
        curve.channels.resize(means.size());
        for (std::size_t c = 0; c < means.size(); ++c) curve.names.push_back(means.size() == 3 ? std::string(1, "RGB"[c]) : "Y");
      }
      // Signal per second of exposure, at the middle of the exposure.
      curve.t_s.push_back(line.value("delay_after_light_off_s", 0.0) + exposure / 2);
      exposures.push_back(exposure);
      curve.exposure_s.push_back(exposure);
      for (std::size_t c = 0; c < means.size() && c < curve.channels.size(); ++c) curve.channels[c].push_back(means[c] / exposure);
    }
    if (clipped > 0) result.notes.push_back("decay: " + std::to_string(clipped) + " clipped frame(s) left out");
    if (curve.size() == 0) result.notes.push_back("decay: no unclipped frame to fit");
    else try {
      DecayFitOptions decay_options;
      decay_options.components = options.components;
      decay_options.max_components = options.max_components;
      decay_options.weighting = options.weighting;
      decay_options.background = true;  // dark current
      // A frame integrates the glow over its exposure e: per second it reads
      // A exp(-k (d + e/2)) sinh(k e / 2) / (k e / 2). The middle of the
      // exposure alone leaves that last factor, 1 + (k e)^2 / 24, which a
      // mean over thousands of pixels resolves and BIC would take for a
      // second state. So: fit, divide by the factor at the fitted rate of
      // the dominant state, fit again (the factor moves by far less then).
      Curve corrected = curve;
      DecayFitSummary first = FitDecay(curve, decay_options, (dir / "decay").string());
      for (int pass = 0; pass < 2; ++pass) {
        std::size_t dominant = 0;
        double best = -1;
        for (std::size_t i = 0; i < first.components.size(); ++i) {
          const double total = std::accumulate(first.components[i].amplitude.begin(), first.components[i].amplitude.end(), 0.0);
          if (total > best) best = total, dominant = i;
        }
        const double k = first.components[dominant].rate;
        for (std::size_t j = 0; j < curve.size(); ++j) {
          const double x = k * exposures[j] / 2;
          const double factor = x > 1e-8 ? std::sinh(x) / x : 1.0;
          for (int c = 0; c < curve.channel_count(); ++c) corrected.channels[c][j] = curve.channels[c][j] / factor;
        }
        first = FitDecay(corrected, decay_options, (dir / "decay").string());
      }
      result.decay = first;
      result.decay_curve = corrected;
    } catch (const UserError& e) {
      result.notes.push_back(e.what());
    }
  }
  // 2. The spectrum, with the dark signal the decay measured.
  if (result.calibration && part_ok("spectrum")) {
    try {
      double dark = std::nan("");
      if (result.decay) {
        dark = 0;
        for (double b : result.decay->background) dark += b;
      }
      result.spectrum = FitEmissionSpectrum(dir / "spectrum", *result.calibration, bands, dark);
    } catch (const UserError& e) {
      result.notes.push_back(e.what());
    }
  }

  if (!result.decay) {
    std::string why;
    for (const std::string& note : result.notes)
      if (note.find("decay") != std::string::npos) why.append(why.empty() ? "" : "; ").append(note);
    ThrowUserError(dir.string(), "", "no decay could be fitted, so no kr: nothing to write" +
                                         (why.empty() ? std::string() : " (" + why + ")"));
  }
  const DecayFitSummary& decay = *result.decay;
  // The state that carries most of the glow stands for all in the excitation fit.
  std::vector<double> share;
  for (const DecayComponent& c : decay.components) share.push_back(std::accumulate(c.amplitude.begin(), c.amplitude.end(), 0.0));
  const double share_total = std::accumulate(share.begin(), share.end(), 0.0);
  const std::size_t main = static_cast<std::size_t>(std::max_element(share.begin(), share.end()) - share.begin());
  const double kr = decay.components[main].rate;
  if (decay.n_components > 1)
    result.notes.push_back("nc = " + std::to_string(decay.n_components) +
                           ": one excitation rate per light is fitted with the dominant state's kr, and every state "
                           "gets the same ke");

  // 4. Excitation and ke per band.
  std::vector<std::optional<double>> ke(static_cast<std::size_t>(nb));
  if (part_ok("excitation")) {
    const nlohmann::json exc_devices = SessionStart(dir / "excitation").value("devices", devices);
    const nlohmann::json irradiance = exc_devices.value("light_band_irradiance", nlohmann::json::object());
    // The decay's background is the camera's dark signal per second (dark
    // current): the excitation frames carry it too, under the same camera.
    double dark = 0;
    for (double b : decay.background) dark += b;
    std::map<std::string, SessionFit::ExcitationLight> by_light;
    for (const nlohmann::json& line : ReadJsonLines(dir / "excitation" / "frames.jsonl")) {
      if (!line.contains("light") || !line.contains("mean_signal_dn")) continue;
      if (Clipped(line)) {
        result.notes.push_back("excitation: a clipped frame of '" + line["light"].get<std::string>() + "' left out");
        continue;
      }
      SessionFit::ExcitationLight& light = by_light[line["light"].get<std::string>()];
      light.light = line["light"];
      const double exposure = line.at("exposure_s").get<double>();
      light.samples.push_back({line.at("charge_s").get<double>(), line.value("delay_after_light_off_s", 0.0), exposure,
                               SumSignal(line) / exposure - dark});
    }
    // S, the signal of a saturated sample, is the same under every light:
    // it comes from the light that charges the sample highest (its level and
    // speed pin S best), and every other light's rate is fitted with S
    // known, so a light that barely charges is read from the level it
    // reaches, not from a charging speed that hardly differs from kr (the
    // weak spot Sec. 8.4.6 names). A light whose response stays below 0.1%
    // of the best one's excites nothing this camera resolves: a = 0.
    auto peak_of = [](const SessionFit::ExcitationLight& light) {
      double peak = 0;
      for (const ExcitationSample& s : light.samples) peak = std::max(peak, s.value);
      return peak;
    };
    std::string best;
    for (const auto& [name, light] : by_light)
      if (best.empty() || peak_of(light) > peak_of(by_light[best])) best = name;
    std::optional<double> S;
    std::vector<std::vector<double>> E_per_light;
    std::vector<double> a_per_light;
    auto fit_light = [&](SessionFit::ExcitationLight& light) {
      std::sort(light.samples.begin(), light.samples.end(),
                [](const ExcitationSample& a, const ExcitationSample& b) { return a.charge_s < b.charge_s; });
      const std::string where = (dir / "excitation").string() + " (" + light.light + ")";
      if (S && peak_of(light) < 1e-3 * peak_of(by_light[best])) {
        light.fit = ExcitationFitSummary{};
        light.fit.scale = *S;
        light.fit.note = "no response above 0.1% of " + best + "'s: a = 0";
      } else {
        ExcitationFitOptions excitation_options;
        excitation_options.kr = kr;
        excitation_options.saturated_signal = S;
        light.fit = FitExcitation(light.samples, excitation_options, where);
      }
      if (!irradiance.contains(light.light)) {
        result.notes.push_back("excitation: no band irradiance recorded for '" + light.light +
                               "' (a bench's lab config must give it): its rate is reported, not turned into ke");
      } else {
        light.band_irradiance = irradiance[light.light].get<std::vector<double>>();
        if (static_cast<int>(light.band_irradiance.size()) == nb) {
          E_per_light.push_back(light.band_irradiance);
          a_per_light.push_back(light.fit.a);
        }
      }
      result.excitation.push_back(light);
    };
    if (!best.empty()) {
      try {
        fit_light(by_light[best]);
        S = result.excitation.back().fit.scale;
        for (auto& [name, light] : by_light)
          if (name != best) {
            try {
              fit_light(light);
            } catch (const UserError& e) {
              result.notes.push_back(e.what());
            }
          }
      } catch (const UserError& e) {
        result.notes.push_back(e.what());
      }
    }
    if (!E_per_light.empty()) {
      try {
        ke = KeFromExcitationRates(E_per_light, a_per_light, (dir / "excitation").string());
      } catch (const UserError& e) {
        result.notes.push_back(e.what());
      }
    }
  }

  // 5. Lambda from the spectrum, the state during each spectrum frame known
  //    from its charge (Eq. 8.1 in closed form) and the ke just fitted.
  Material& material = result.material;
  const nlohmann::json sample = top.value("sample", nlohmann::json::object());
  material.name = (sample.contains("material") ? sample["material"].value("name", std::string("sample")) : std::string("sample")) + " (fitted)";
  material.bands = bands;
  // Lambda per band for a given kr and ke (the sequential fit's, or the
  // joint refinement's); nullopt when the state during the spectrum is not
  // known.
  auto lambda_for = [&](double kr_value, const std::vector<std::optional<double>>& ke_value, bool note)
      -> std::optional<std::vector<double>> {
    if (!result.spectrum) return std::nullopt;
    const nlohmann::json spectrum_devices = SessionStart(dir / "spectrum").value("devices", devices);
    const nlohmann::json irradiance = spectrum_devices.value("light_band_irradiance", nlohmann::json::object());
    double a_charge = 0;
    bool known = irradiance.contains(result.spectrum->charge_light);
    if (known) {
      const std::vector<double> E = irradiance[result.spectrum->charge_light].get<std::vector<double>>();
      for (int b = 0; b < nb && b < static_cast<int>(E.size()); ++b) {
        if (E[b] <= 0) continue;
        if (!ke_value[b]) known = false;
        else a_charge += *ke_value[b] * E[b];
      }
    }
    if (!known || a_charge <= 0) {
      if (note)
        result.notes.push_back("spectrum: the charge light's excitation is not known in every band it reaches, so the "
                               "state during the spectrum is not, nor Lambda's scale");
      return std::nullopt;
    }
    // The state through the recorded switches (r = 0 before the first: the
    // calibration before it kept the sample dark), then averaged over each
    // frame's exposure in the dark.
    struct Switch {
      double t_s;
      bool on;
    };
    std::vector<Switch> switches;
    for (const nlohmann::json& event : ReadJsonLines(dir / "spectrum" / "events.jsonl"))
      if (event.value("event", "") == "light" && event.value("channel", "") == result.spectrum->charge_light)
        switches.push_back({event.value("t_s", 0.0), event.value("on", false)});
    std::vector<double> per_kr_r(static_cast<std::size_t>(nb), 0.0);
    for (const auto& frame : result.spectrum->frames) {
      double r = 0, t = switches.empty() ? frame.t_start_s : switches.front().t_s;
      bool on = false;
      for (const Switch& sw : switches) {
        if (sw.t_s > frame.t_start_s) break;
        const double a = on ? a_charge : 0.0, k = a + kr_value, dt = sw.t_s - t;
        r = a / k + (r - a / k) * std::exp(-k * dt);  // Eq. 8.1, exact over a constant interval
        t = sw.t_s;
        on = sw.on;
      }
      const double a = on ? a_charge : 0.0, k = a + kr_value;
      r = a / k + (r - a / k) * std::exp(-k * (frame.t_start_s - t));
      const double e = std::max(frame.exposure_s, 1e-12);
      const double r_mean = r * -std::expm1(-kr_value * e) / (kr_value * e);
      for (int b = 0; b < nb; ++b)
        per_kr_r[b] += frame.band_radiance[b] / (kr_value * r_mean) / result.spectrum->frames.size();
    }
    return per_kr_r;
  };
  const std::optional<std::vector<double>> lambda_sequential = lambda_for(kr, ke, true);
  const bool have_lambda = lambda_sequential.has_value();
  const std::vector<double> band_radiance_per_kr_r = have_lambda ? *lambda_sequential : std::vector<double>();
  if (!have_lambda)
    ThrowUserError(dir.string(), "", "no emission spectrum with a known excitation: Lambda cannot be fitted" +
                                         std::string(result.notes.empty() ? "" : " (" + result.notes.back() + ")"));
  for (std::size_t i = 0; i < decay.components.size(); ++i) {
    ExcitedState state;
    state.kr = decay.components[i].rate;
    state.ke = ke;
    // Sec. 8.4.5: the states share the emission shape, split by their decay
    // amplitudes, Lambda_i = a_i Lambda* / kr_i (for nc = 1 simply Lambda*).
    const double fraction = share_total > 0 ? share[i] / share_total : 1.0 / decay.components.size();
    for (int b = 0; b < nb; ++b)
      state.Lambda.push_back(decay.n_components == 1 ? band_radiance_per_kr_r[b]
                                                     : fraction * band_radiance_per_kr_r[b] * kr / state.kr);
    material.states.push_back(state);
  }
  material.source = "phos fit session " + dir.string() + ": nc = " + std::to_string(decay.n_components) + " (" +
                    decay.choice + ")";
  ValidateMaterial(material, dir.string());

  // 6. The joint refinement, beside the sequential fit: one problem over the
  //    decay and every excitation series at once.
  if (decay.n_components == 1 && !result.excitation.empty()) {
    try {
      result.joint = JointRefine(raw_decay, decay, result.excitation);
      JointFit& joint = *result.joint;
      std::vector<std::vector<double>> E_per_light;
      std::vector<double> a_per_light;
      for (const auto& light : result.excitation)
        if (static_cast<int>(light.band_irradiance.size()) == nb && joint.a.count(light.light)) {
          E_per_light.push_back(light.band_irradiance);
          a_per_light.push_back(joint.a[light.light]);
        }
      if (!E_per_light.empty()) joint.ke = KeFromExcitationRates(E_per_light, a_per_light, dir.string() + " (joint)");
      else joint.ke = ke;
      if (auto lambda = lambda_for(joint.kr, joint.ke, false)) joint.Lambda = *lambda;
      if (options.joint && !joint.Lambda.empty()) {
        material.states[0].kr = joint.kr;
        material.states[0].ke = joint.ke;
        material.states[0].Lambda = joint.Lambda;
        material.source += "; joint refinement over the decay and excitation";
        ValidateMaterial(material, dir.string());
      }
    } catch (const UserError& e) {
      result.notes.push_back(std::string("joint refinement: ") + e.what());
    }
  }
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return result;
}

MaterialComparison CompareMaterials(const Material& fitted, const Material& truth) {
  MaterialComparison c;
  for (std::size_t i = 0; i < fitted.states.size() && i < truth.states.size(); ++i)
    c.kr_relative_error.push_back(std::fabs(fitted.states[i].kr - truth.states[i].kr) / truth.states[i].kr);
  // Emission per unit state: sum over states of kr Lambda (what a saturated
  // sample shows at light-off), normalized.
  auto shape = [](const Material& m) {
    std::vector<double> s(static_cast<std::size_t>(m.band_count()), 0.0);
    for (const ExcitedState& state : m.states)
      for (int b = 0; b < m.band_count(); ++b) s[b] += state.Lambda[b] * state.kr;
    const double total = std::accumulate(s.begin(), s.end(), 0.0);
    for (double& v : s) v /= total > 0 ? total : 1;
    return s;
  };
  const std::vector<double> a = shape(fitted), b = shape(truth);
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) c.spectrum_l1 += std::fabs(a[i] - b[i]);
  // ke relative to the truth, with a floor of 5% of its largest ke: a band
  // that barely charges is judged on the scale of the ones that do.
  double largest = 0;
  for (const auto& k : truth.states[0].ke) largest = std::max(largest, k.value_or(0.0));
  for (std::size_t band = 0; band < truth.states[0].ke.size(); ++band) {
    const auto& t = truth.states[0].ke[band];
    const auto& f = band < fitted.states[0].ke.size() ? fitted.states[0].ke[band] : std::nullopt;
    if (t && f) c.ke_relative_error.push_back(std::fabs(*f - *t) / std::max(*t, 0.05 * largest));
    else c.ke_relative_error.push_back(std::nullopt);
  }
  return c;
}

namespace {

std::string Escape(const std::string& text) {
  std::string out;
  for (char ch : text) {
    if (ch == '<') out += "&lt;";
    else if (ch == '>') out += "&gt;";
    else if (ch == '&') out += "&amp;";
    else out += ch;
  }
  return out;
}

}  // namespace

std::string SessionReportHtml(const SessionFit& fit, const std::string& title) {
  std::string html;
  html.append("<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>").append(Escape(title)).append(
      "</title>\n<style>body{font-family:sans-serif;max-width:900px;margin:2em auto;color:#222}"
      "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}"
      "th{background:#f4f4f4}.note{color:#a33}</style></head><body>\n");
  html.append("<h1>").append(Escape(title)).append("</h1>\n");
  const Material& m = fit.material;
  html.append("<p>Fitted in ").append(FormatShort(fit.seconds)).append(" s. ").append(Escape(m.source)).append("</p>\n");
  for (const std::string& note : fit.notes) html.append("<p class=\"note\">").append(Escape(note)).append("</p>\n");

  // The material.
  html.append("<h2>Material</h2>\n<table><tr><th>state</th><th>kr (1/s)</th><th>&plusmn; 1&sigma;</th></tr>\n");
  for (std::size_t i = 0; i < m.states.size(); ++i) {
    const double stderr_kr = fit.decay ? fit.decay->components[i].rate_stderr : 0;
    html.append("<tr><td>").append(std::to_string(i + 1)).append("</td><td>").append(FormatShort(m.states[i].kr))
        .append("</td><td>").append(FormatShort(stderr_kr)).append("</td></tr>\n");
  }
  html.append("</table>\n<table><tr><th>band (nm)</th><th>ke</th><th>&Lambda; (state 1)</th></tr>\n");
  for (int b = 0; b < m.band_count(); ++b) {
    const auto& ke = m.states[0].ke[b];
    html.append("<tr><td>").append(m.bands.BandName(b)).append("</td><td>").append(ke ? FormatShort(*ke) : "not measured")
        .append("</td><td>").append(FormatShort(m.states[0].Lambda[b])).append("</td></tr>\n");
  }
  html.append("</table>\n");

  // Decay: data against fit, and residuals.
  if (fit.decay) {
    const DecayFitSummary& d = *fit.decay;
    html.append("<h2>Decay</h2>\n<p>nc = ").append(std::to_string(d.n_components)).append(": ").append(Escape(d.choice))
        .append(". BIC per nc: ");
    for (std::size_t i = 0; i < d.bic.size(); ++i)
      html.append(i ? ", " : "").append(std::to_string(i + 1)).append(": ").append(std::isfinite(d.bic[i]) ? FormatShort(d.bic[i]) : "invalid");
    html.append(". rss ").append(FormatShort(d.rss)).append(" (DN/s)&sup2;.</p>\n");
    std::vector<PlotSeries> data_fit, residuals;
    for (int c = 0; c < fit.decay_curve.channel_count(); ++c) {
      PlotSeries data(fit.decay_curve.names[c] + " measured"), model(fit.decay_curve.names[c] + " fit"),
          residual(fit.decay_curve.names[c]);
      data.markers = true;
      data.line = false;
      data.color = model.color = residual.color = PaletteColor(c);
      model.dashed = true;
      residual.markers = true;
      for (std::size_t j = 0; j < fit.decay_curve.size(); ++j) {
        const double t = fit.decay_curve.t_s[j], y = fit.decay_curve.channels[c][j], f = EvaluateDecay(d, c, t);
        data.x.push_back(t);
        data.y.push_back(y);
        model.x.push_back(t);
        model.y.push_back(f);
        residual.x.push_back(t);
        residual.y.push_back(y - f);
      }
      data_fit.push_back(data);
      data_fit.push_back(model);
      residuals.push_back(residual);
    }
    PlotOptions o;
    o.title = "Decay after saturation: data and fit";
    o.x_label = "time after light-off (s)";
    o.y_label = "signal / exposure (DN/s)";
    o.log_y = true;
    html.append(PlotSvg(data_fit, o)).append("\n");
    o.title = "Decay residuals";
    o.log_y = false;
    o.y_label = "data - fit (DN/s)";
    o.height_px = 280;
    html.append(PlotSvg(residuals, o)).append("\n");
  }

  // Excitation per light.
  if (!fit.excitation.empty()) {
    html.append("<h2>Excitation</h2>\n<table><tr><th>light</th><th>a (1/s)</th><th>&plusmn; 1&sigma;</th><th>samples</th><th>note</th></tr>\n");
    std::vector<PlotSeries> series;
    int index = 0;
    for (const auto& light : fit.excitation) {
      html.append("<tr><td>").append(Escape(light.light)).append("</td><td>").append(FormatShort(light.fit.a))
          .append("</td><td>").append(FormatShort(light.fit.a_stderr)).append("</td><td>")
          .append(std::to_string(light.samples.size())).append("</td><td>").append(Escape(light.fit.note)).append("</td></tr>\n");
      PlotSeries data(light.light + " measured"), model(light.light + " fit");
      data.markers = true;
      data.line = false;
      data.color = model.color = PaletteColor(index++);
      model.dashed = true;
      for (const ExcitationSample& s : light.samples) {
        data.x.push_back(s.charge_s);
        data.y.push_back(s.value);
        model.x.push_back(s.charge_s);
        model.y.push_back(ExcitationSignal(light.fit.a, fit.material.states[0].kr, light.fit.scale, s));
      }
      series.push_back(data);
      series.push_back(model);
    }
    html.append("</table>\n");
    PlotOptions o;
    o.title = "Excitation: response after charging for t, and the fit";
    o.x_label = "charge time t (s)";
    o.y_label = "signal / exposure (DN/s)";
    o.log_x = true;
    html.append(PlotSvg(series, o)).append("\n");
  }

  // The joint refinement beside the sequential fit.
  if (fit.joint) {
    const JointFit& j = *fit.joint;
    html.append("<h2>Joint refinement</h2>\n<p>kr, the decay amplitudes and backgrounds, every light's a and the "
                "shared S fitted at once to the decay and all excitation series (one photon-counting chi-square), "
                "beside the sequential fit of the paper (kr from the decay alone, then each light). ")
        .append(std::to_string(j.iterations)).append(" Ceres iterations.</p>\n<table><tr><th></th><th>sequential</th><th>joint</th></tr>\n");
    html.append("<tr><td>kr (1/s)</td><td>").append(FormatShort(m.states.empty() || !fit.decay ? 0 : fit.decay->components[0].rate))
        .append("</td><td>").append(FormatShort(j.kr)).append("</td></tr>\n");
    for (const auto& light : fit.excitation) {
      const auto it = j.a.find(light.light);
      html.append("<tr><td>a under ").append(Escape(light.light)).append(" (1/s)</td><td>").append(FormatShort(light.fit.a))
          .append("</td><td>").append(it == j.a.end() ? "-" : FormatShort(it->second)).append("</td></tr>\n");
    }
    html.append("<tr><td>weighted SS, decay</td><td>").append(FormatShort(j.decay_sequential)).append("</td><td>")
        .append(FormatShort(j.decay_joint)).append("</td></tr>\n<tr><td>weighted SS, excitation</td><td>")
        .append(FormatShort(j.excitation_sequential)).append("</td><td>").append(FormatShort(j.excitation_joint))
        .append("</td></tr>\n<tr><th>weighted SS, total</th><th>")
        .append(FormatShort(j.decay_sequential + j.excitation_sequential)).append("</th><th>")
        .append(FormatShort(j.decay_joint + j.excitation_joint)).append("</th></tr>\n</table>\n<p>")
        .append(j.decay_joint + j.excitation_joint < j.decay_sequential + j.excitation_sequential
                    ? "The joint fit fits the data better (lower total)."
                    : "The sequential fit is already at the joint optimum.")
        .append("</p>\n");
  }

  // LVF calibration and spectrum.
  if (fit.calibration) {
    const LvfCalibrationFit& c = *fit.calibration;
    html.append("<h2>LVF calibration</h2>\n<p>centre(x) = ").append(FormatShort(c.center0_nm)).append(" nm + ")
        .append(FormatShort(c.nm_per_column)).append(" nm &times; column; pass band ").append(FormatShort(c.fwhm_nm))
        .append(" nm FWHM; line residual rms ").append(FormatShort(c.rms_residual_nm)).append(" nm.</p>\n");
    PlotSeries lines("lines"), model("fitted line");
    lines.markers = true;
    lines.line = false;
    for (const auto& line : c.lines) {
      lines.x.push_back(line.column);
      lines.y.push_back(line.wavelength_nm);
    }
    model.x = {0.0, static_cast<double>(c.width - 1)};
    model.y = {c.CenterNm(0), c.CenterNm(c.width - 1)};
    PlotOptions o;
    o.title = "LVF: known lines against their centroid column";
    o.x_label = "column";
    o.y_label = "wavelength (nm)";
    o.height_px = 320;
    html.append(PlotSvg({lines, model}, o)).append("\n");
  }
  if (fit.spectrum && !fit.spectrum->frames.empty()) {
    const auto& frame = fit.spectrum->frames.front();
    PlotSeries measured("measured (first frame)"), modelled("reconstruction through the filter");
    measured.markers = true;
    measured.line = false;
    for (std::size_t x = 0; x < frame.measured.size(); ++x) {
      const double nm = fit.calibration->CenterNm(static_cast<double>(x));
      measured.x.push_back(nm);
      measured.y.push_back(frame.measured[x]);
      modelled.x.push_back(nm);
      modelled.y.push_back(frame.modelled[x]);
    }
    PlotOptions o;
    o.title = "Emission spectrum through the LVF";
    o.x_label = "wavelength (nm)";
    o.y_label = "column signal (DN/s)";
    html.append("<h2>Emission spectrum</h2>\n").append(PlotSvg({measured, modelled}, o)).append("\n");
    PlotSeries shape("normalized band radiance");
    shape.markers = true;
    for (int b = 0; b < m.band_count(); ++b) {
      shape.x.push_back(m.bands.center_nm(b));
      shape.y.push_back(fit.spectrum->shape[b]);
    }
    o.title = "Emission spectrum per band (normalized)";
    o.y_label = "share of the emission";
    o.height_px = 320;
    html.append(PlotSvg({shape}, o)).append("\n");
  }
  html.append("</body></html>\n");
  return html;
}

}  // namespace phos
