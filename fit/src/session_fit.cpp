#include "phos/fit/session_fit.h"

#include <ceres/ceres.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <numeric>
#include <tuple>

#include "phos/acquire/session_records.h"
#include "phos/model/closed_form.h"
#include "phos/model/rate_equation.h"
#include "phos/model/spectral.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/math.h"
#include "excitation_model.h"
#include "relative_covariance.h"
#include "solver_options.h"

namespace phos {
namespace {

namespace fs = std::filesystem;

// A frame's column profile per second of exposure.
std::vector<double> ColumnRate(const FrameRecord& frame, const FrameSignal& signal) {
  std::vector<double> profile = signal.column_mean_dn;
  for (double& v : profile) v /= frame.exposure_s;
  return profile;
}

// Centroid and spread (in columns) of the peak of a profile: a window of
// +-3 sigma around the centroid, refined a few times, so the tails and the
// far baseline do not pull it.
void PeakMoments(const std::vector<double>& p, double* centroid, double* sigma) {
  const int n = static_cast<int>(p.size());
  const int peak = static_cast<int>(std::max_element(p.begin(), p.end()) - p.begin());
  double c = peak, s = 2;
  for (int iteration = 0; iteration < 5; ++iteration) {
    const int lo = std::max(0, static_cast<int>(std::floor(c - 3 * s))),
              hi = std::min(n - 1, static_cast<int>(std::ceil(c + 3 * s)));
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
// reconstruction of a spectrum from blurred samples. A row is linear, so its
// Jacobian is the row itself: written out, not autodiffed. Autodiff of a
// dynamic block of n parameters evaluated each row n/4 times with Jets it
// allocated afresh: a fifth of `phos fit session` in Release and two thirds
// under the sanitizers (perf). The fitted values move by rounding only
// (5e-14 relative at most on orange, white and a two-state fixture).
class LinearRow : public ceres::CostFunction {
 public:
  LinearRow(std::vector<double> row, double target, double weight)
      : row_(std::move(row)), target_(target), weight_(weight) {
    set_num_residuals(1);
    mutable_parameter_block_sizes()->push_back(static_cast<std::int32_t>(row_.size()));
  }
  bool Evaluate(double const* const* x, double* residual, double** jacobian) const override {
    double sum = -target_;
    for (std::size_t i = 0; i < row_.size(); ++i) sum += row_[i] * x[0][i];
    residual[0] = weight_ * sum;
    if (jacobian != nullptr && jacobian[0] != nullptr)
      for (std::size_t i = 0; i < row_.size(); ++i) jacobian[0][i] = weight_ * row_[i];
    return true;
  }

 private:
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
    problem.AddResidualBlock(new LinearRow(std::move(row), target, w), nullptr, x.data());
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

// How a part stopped, for the notes.
std::string StopHow(const std::string& stop) { return stop.empty() ? "none (killed, or still running)" : stop; }

}  // namespace

LvfCalibrationFit FitLvfCalibration(const CapturedSample::Calibration& part) {
  const fs::path dir = part.source;
  LvfCalibrationFit fit;
  fit.flat_temperature_k = part.settings.flat_temperature_k;
  fit.flat_irradiance = part.settings.flat_irradiance;
  // The last unclipped frame of each source is its well-exposed one.
  using Kind = LvfCalibrationFrameFields::Kind;
  std::map<std::string, const ProtocolFrame<LvfCalibrationFrameFields>*> last;
  for (const auto& frame : part.frames)
    if (!frame.fields.signal.clipped())
      last[frame.fields.kind == Kind::kDark ? std::string("(dark)") : frame.fields.light] = &frame;
  auto rate_of = [](const ProtocolFrame<LvfCalibrationFrameFields>* frame) {
    return ColumnRate(frame->record, frame->fields.signal);
  };
  std::vector<double> dark;
  if (last.count("(dark)")) dark = rate_of(last["(dark)"]);
  fit.dark_dn_per_s = dark;
  // Dark current is uniform: its mean over the columns, not each noisy column.
  double dark_mean = 0;
  for (double d : dark) dark_mean += d / dark.size();
  auto rate = [&](const ProtocolFrame<LvfCalibrationFrameFields>* frame) {
    std::vector<double> p = rate_of(frame);
    for (double& v : p) v -= dark_mean;
    return p;
  };
  std::vector<double> sigmas;
  for (const auto& [light, frame] : last) {
    if (frame->fields.kind == Kind::kLine) {
      const std::vector<double> p = rate(frame);
      fit.width = static_cast<int>(p.size());
      double c = 0, s = 0;
      PeakMoments(p, &c, &s);
      fit.lines.push_back({light, frame->fields.wavelength_nm, c});
      sigmas.push_back(std::sqrt(std::max(0.0, s * s - 1.0 / 12)));  // less the pixel's own width
    } else if (frame->fields.kind == Kind::kFlat) {
      fit.flat_dn_per_s = rate(frame);
    }
  }
  if (fit.lines.size() < 2)
    ThrowUserError(dir.string(), "lvf-calibration",
                   "needs well-exposed frames of at least 2 lines, has " + std::to_string(fit.lines.size()));
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

SpectrumFit FitEmissionSpectrum(const CapturedSample::Spectrum& part, const LvfCalibrationFit& calibration,
                                const SpectralGrid& bands, double dark_dn_per_s) {
  const fs::path dir = part.source;
  if (!std::isfinite(dark_dn_per_s)) {
    dark_dn_per_s = 0;
    for (double d : calibration.dark_dn_per_s) dark_dn_per_s += d / calibration.dark_dn_per_s.size();
  }
  const double low = part.settings.exposure.low_fraction, high = part.settings.exposure.high_fraction;
  SpectrumFit fit;
  fit.charge_light = part.settings.charge_light;
  fit.charge_s = part.settings.charge_s;
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
      const double seen = calibration.flat_irradiance * lamp.Evaluate(nm) / kPi *
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
  for (const auto& [record, line, fields] : part.frames) {
    if (fields.signal.clipped()) continue;
    const double peak = fields.signal.peak_column_fraction;
    if (peak < low || peak > high) continue;  // not well exposed: the protocol stepped past it
    std::vector<double> y = ColumnRate(record, fields.signal);
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
    frame.delay_s = fields.delay_after_light_off_s;
    frame.exposure_s = record.exposure_s;
    frame.t_start_s = record.t_start_s;
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

namespace {

// ---- stage 3: the decay --------------------------------------------------------

struct DecayStage {
  std::optional<DecayFitSummary> fit;
  Curve raw, corrected;
};

// The decay frames as a curve: signal per second of exposure, at the middle
// of the exposure; clipped frames left out (and counted in a note).
Curve ReadDecayCurve(const CapturedSample::Decay& part, std::vector<std::string>* notes) {
  Curve curve;
  int clipped = 0;
  for (const DecaySample& sample : DecaySamples(part, &clipped)) {
    const std::vector<double>& means = sample.frame->fields.signal.mean_signal_dn;
    const double exposure = sample.frame->record.exposure_s;
    if (curve.channels.empty()) {
      curve.channels.resize(means.size());
      for (std::size_t c = 0; c < means.size(); ++c)
        curve.names.push_back(means.size() == 3 ? std::string(1, "RGB"[c]) : "Y");
    }
    curve.t_s.push_back(sample.t_s);
    curve.exposure_s.push_back(exposure);
    for (std::size_t c = 0; c < means.size() && c < curve.channels.size(); ++c)
      curve.channels[c].push_back(means[c] / exposure);
  }
  if (clipped > 0) notes->push_back("decay: " + std::to_string(clipped) + " clipped frame(s) left out");
  if (curve.size() == 0) notes->push_back("decay: no unclipped frame to fit");
  return curve;
}

// A frame integrates the glow over its exposure e: per second it reads
// sum_i A_i exp(-k_i (d + e/2)) sinh(k_i e / 2) / (k_i e / 2). The middle of
// the exposure alone leaves the last factor, 1 + (k e)^2 / 24, which a mean
// over thousands of pixels resolves and BIC would take for another state.
// So each sample is divided by the amplitude-weighted factor of the fitted
// states at that sample, and the fit repeated (the factor moves by far less
// then): exact for one state, and for several as far as the mix at each
// sample is known.
Curve CorrectForExposure(const Curve& curve, const DecayFitSummary& fit) {
  Curve corrected = curve;
  for (std::size_t j = 0; j < curve.size(); ++j) {
    double weighted = 0, total = 0;
    for (const DecayComponent& component : fit.components) {
      double amplitude = 0;
      for (double v : component.amplitude) amplitude += v;
      // The glow at the exposure's middle, and its mean over the exposure.
      const double t = curve.t_s[j], e = curve.exposure_s[j];
      weighted += amplitude * DecayFactor(component.rate, t - e / 2, e);
      total += amplitude * DecayFactor(component.rate, t);
    }
    const double factor = total > 0 ? weighted / total : 1.0;
    for (int c = 0; c < curve.channel_count(); ++c) corrected.channels[c][j] = curve.channels[c][j] / factor;
  }
  return corrected;
}

DecayStage FitDecayStage(const CapturedSample::Decay& part, const SessionFitOptions& options,
                         std::vector<std::string>* notes) {
  DecayStage stage;
  stage.raw = ReadDecayCurve(part, notes);
  if (stage.raw.size() == 0) return stage;
  try {
    DecayFitOptions decay_options;
    decay_options.components = options.components;
    decay_options.max_components = options.max_components;
    decay_options.weighting = options.weighting;
    decay_options.background = true;  // dark current
    if (options.max_iterations > 0) decay_options.max_iterations = options.max_iterations;
    DecayFitSummary fit = FitDecay(stage.raw, decay_options, part.source);
    for (int pass = 0; pass < 2; ++pass) {
      stage.corrected = CorrectForExposure(stage.raw, fit);
      fit = FitDecay(stage.corrected, decay_options, part.source);
    }
    stage.fit = fit;
  } catch (const UserError& e) {
    notes->push_back(e.what());
  }
  return stage;
}

// ---- stage 4: excitation per state ------------------------------------------------

// The excitation frames grouped into measurements (one charge: its first
// frame and its tail). A measurement cut off inside its tail (an interrupted
// session that was not resumed) is left out whole; frames of a session from
// before the tails are one-frame measurements.
std::vector<ExcitationMeasurement> ReadExcitationMeasurements(const CapturedSample::Excitation& part,
                                                              double dark_dn_per_s, std::vector<std::string>* notes) {
  struct Group {
    ExcitationMeasurement measurement;
    int expected = 1, clipped = 0;
  };
  std::map<std::tuple<int, std::string, double>, Group> groups;  // (run, light, light-off time)
  for (const auto& [frame, line, fields] : part.frames) {
    Group& group = groups[{frame.run, fields.light, fields.light_off_s}];
    group.measurement.light = fields.light;
    group.measurement.run = frame.run;
    group.measurement.charge_s = fields.charge_s;
    group.measurement.light_off_s = fields.light_off_s;
    group.expected = fields.tail_frames + 1;
    if (fields.signal.clipped()) {
      // A clipped frame is left out; the rest of its tail still tells.
      ++group.clipped;
      continue;
    }
    group.measurement.frames.push_back(
        {fields.delay_after_light_off_s, frame.exposure_s, fields.signal.SumDn() / frame.exposure_s - dark_dn_per_s});
  }
  std::vector<ExcitationMeasurement> measurements;
  int cut = 0, clipped = 0;
  for (auto& [key, group] : groups) {
    const int seen = static_cast<int>(group.measurement.frames.size()) + group.clipped;
    if (seen < group.expected) {
      ++cut;
      continue;
    }
    clipped += group.clipped > 0;
    if (!group.measurement.frames.empty()) measurements.push_back(std::move(group.measurement));
  }
  if (cut > 0)
    notes->push_back("excitation: " + std::to_string(cut) + " measurement(s) cut off in their tail left out");
  if (clipped > 0) notes->push_back("excitation: " + std::to_string(clipped) + " measurement(s) with a clipped frame");
  return measurements;
}

struct ExcitationStage {
  std::vector<SessionFit::ExcitationLight> lights;
  std::vector<ExcitationMeasurement> measurements;
  std::optional<StateExcitationFit> fit;
  std::vector<KeEstimate> ke;  // per state; empty when no light's irradiance is known
};

// ke_i per band for every state from its rates under the lights whose band
// irradiance is known.
std::vector<KeEstimate> KePerState(const std::vector<SessionFit::ExcitationLight>& lights,
                                   const std::map<std::string, std::vector<double>>& a,
                                   const std::map<std::string, std::vector<double>>& a_stderr, int nc, int nb,
                                   const std::string& where) {
  std::vector<KeEstimate> ke;
  for (int i = 0; i < nc; ++i) {
    std::vector<std::vector<double>> E_per_light;
    std::vector<double> a_per_light, sigma_per_light;
    for (const auto& light : lights) {
      if (static_cast<int>(light.band_irradiance.size()) != nb || !a.count(light.light)) continue;
      E_per_light.push_back(light.band_irradiance);
      a_per_light.push_back(a.at(light.light)[i]);
      sigma_per_light.push_back(a_stderr.count(light.light) ? a_stderr.at(light.light)[i] : 0.0);
    }
    if (E_per_light.empty()) return {};
    ke.push_back(
        KeWithUncertainty(E_per_light, a_per_light, sigma_per_light, where + " (state " + std::to_string(i + 1) + ")"));
  }
  return ke;
}

ExcitationStage FitExcitationStage(const CapturedSample::Excitation& part, const DecayFitSummary& decay, int nb,
                                   const SessionFitOptions& session_options, std::vector<std::string>* notes) {
  ExcitationStage stage;
  // The decay's background is the camera's dark signal per second (dark
  // current): the excitation frames carry it too, under the same camera.
  double dark = 0;
  for (double b : decay.background) dark += b;
  stage.measurements = ReadExcitationMeasurements(part, dark, notes);
  std::map<std::string, SessionFit::ExcitationLight> by_light;
  for (const ExcitationMeasurement& m : stage.measurements) {
    SessionFit::ExcitationLight& light = by_light[m.light];
    light.light = m.light;
    const ExcitationFrame& first = m.frames.front();
    light.samples.push_back({m.charge_s, first.delay_s, first.exposure_s, first.value});
  }
  for (auto& [name, light] : by_light) {
    std::sort(light.samples.begin(), light.samples.end(),
              [](const ExcitationSample& a, const ExcitationSample& b) { return a.charge_s < b.charge_s; });
    light.band_irradiance = part.devices.BandIrradiance(name);
    if (light.band_irradiance.empty())
      notes->push_back("excitation: no band irradiance recorded for '" + name +
                       "' (a bench's lab config must give it): its rate is reported, not turned into ke");
    stage.lights.push_back(light);
  }
  if (stage.measurements.empty()) {
    notes->push_back("excitation: no whole measurement to fit");
    return stage;
  }
  StateExcitationOptions options;
  for (const DecayComponent& c : decay.components) options.kr.push_back(c.rate);
  options.weighting = session_options.weighting;
  if (session_options.max_iterations > 0) options.max_iterations = session_options.max_iterations;
  try {
    stage.fit = FitStateExcitation(stage.measurements, options, part.source);
    for (const std::string& note : stage.fit->notes) notes->push_back("excitation: " + note);
    stage.ke = KePerState(stage.lights, stage.fit->a, stage.fit->a_stderr, decay.n_components, nb, part.source);
  } catch (const UserError& e) {
    notes->push_back(e.what());
  }
  return stage;
}

// ---- stage 5: Lambda per state -------------------------------------------------------

struct LightSwitch {
  double t_s;
  bool on;
};

std::vector<LightSwitch> SwitchesOf(const std::vector<LightSwitchEvent>& events, const std::string& light) {
  std::vector<LightSwitch> switches;
  // Switches without a time (the signal handler's) end a session; none is before a fitted frame.
  for (const LightSwitchEvent& event : events)
    if (event.channel == light && std::isfinite(event.t_s)) switches.push_back({event.t_s, event.on});
  return switches;
}

// r(t) from r = 0 before the first recorded switch (each part starts dark
// after the one before), through every switch up to t: Eq. 8.1 exactly over
// each interval of constant light (model/'s update).
double StateAt(const std::vector<LightSwitch>& switches, double a_on, double kr, double t_s) {
  double r = 0, t = switches.empty() ? t_s : switches.front().t_s;
  bool on = false;
  for (const LightSwitch& sw : switches) {
    if (sw.t_s > t_s) break;
    r = ExactStep(r, on ? a_on : 0.0, kr, sw.t_s - t);
    t = sw.t_s;
    on = sw.on;
  }
  return ExactStep(r, on ? a_on : 0.0, kr, t_s - t);
}

// a_i under a light: sum_b ke_i[b] E[b]; nullopt when a band the light
// reaches has no known ke.
std::optional<double> RateUnder(const std::vector<double>& E, const std::vector<std::optional<double>>& ke) {
  double a = 0;
  for (std::size_t b = 0; b < E.size() && b < ke.size(); ++b) {
    if (E[b] <= 0) continue;
    if (!ke[b]) return std::nullopt;
    a += *ke[b] * E[b];
  }
  return a;
}

// Each state's share w_i of the emission, proportional to A_i / (kr_i r_i)
// with r_i the state at the decay's light-off. Unknown ke: r_i = 1, said.
std::vector<double> EmissionShares(const CapturedSample::Decay& decay_part, const DecayFitSummary& decay,
                                   const std::vector<std::vector<std::optional<double>>>& ke,
                                   std::vector<std::string>* notes) {
  const std::string& charge_light = decay_part.settings.charge_light;
  const std::vector<double> E = decay_part.devices.BandIrradiance(charge_light);
  const std::vector<LightSwitch> switches = SwitchesOf(decay_part.switches, charge_light);
  double light_off = 0;
  for (const LightSwitch& sw : switches)
    if (!sw.on) light_off = sw.t_s;
  std::vector<double> w;
  double total = 0;
  bool assumed = false;
  for (std::size_t i = 0; i < decay.components.size(); ++i) {
    double amplitude = 0;
    for (double v : decay.components[i].amplitude) amplitude += v;
    const double kr = decay.components[i].rate;
    std::optional<double> a = i < ke.size() && !E.empty() ? RateUnder(E, ke[i]) : std::nullopt;
    double r = 1;
    if (a && *a > 0 && !switches.empty())
      r = StateAt(switches, *a, kr, light_off);
    else
      assumed = true;
    w.push_back(amplitude / (kr * std::max(r, 1e-12)));
    total += w.back();
  }
  if (assumed && decay.components.size() > 1)
    notes->push_back(
        "spectrum: a state's charge at the decay's light-off is not known (no ke for the decay's light): "
        "taken as saturated");
  for (double& v : w) v = total > 0 ? v / total : 1.0 / static_cast<double>(w.size());
  return w;
}

// Lambda_i[b] = w_i X_b with X_b = mean over spectrum frames of
// L_b / sum_i w_i kr_i rbar_i, rbar_i the state averaged over the frame's
// exposure in the dark. nullopt when the state during the spectrum is not
// known (the charge light reaches a band without ke).
std::optional<std::vector<std::vector<double>>> LambdaPerState(
    const CapturedSample::Spectrum& spectrum_part, const SpectrumFit& spectrum, const std::vector<double>& kr,
    const std::vector<std::vector<std::optional<double>>>& ke, const std::vector<double>& shares) {
  const std::vector<double> E = spectrum_part.devices.BandIrradiance(spectrum.charge_light);
  if (E.empty() || ke.size() != kr.size()) return std::nullopt;
  std::vector<double> a;
  for (std::size_t i = 0; i < kr.size(); ++i) {
    const std::optional<double> rate = RateUnder(E, ke[i]);
    if (!rate || !(*rate > 0)) return std::nullopt;
    a.push_back(*rate);
  }
  const std::vector<LightSwitch> switches = SwitchesOf(spectrum_part.switches, spectrum.charge_light);
  const std::size_t nb = spectrum.shape.size();
  std::vector<double> X(nb, 0.0);
  for (const auto& frame : spectrum.frames) {
    double emitting = 0;  // sum_i w_i kr_i rbar_i
    const double e = std::max(frame.exposure_s, 1e-12);
    for (std::size_t i = 0; i < kr.size(); ++i) {
      const double r = StateAt(switches, a[i], kr[i], frame.t_start_s);
      emitting += shares[i] * kr[i] * r * DecayFactor(kr[i], 0.0, e);
    }
    for (std::size_t b = 0; b < nb; ++b)
      X[b] += frame.band_radiance[b] / emitting / static_cast<double>(spectrum.frames.size());
  }
  std::vector<std::vector<double>> Lambda;
  for (double share : shares) {
    Lambda.emplace_back();
    for (double x : X) Lambda.back().push_back(share * x);
  }
  return Lambda;
}

std::vector<std::vector<std::optional<double>>> KeValues(const std::vector<KeEstimate>& ke) {
  std::vector<std::vector<std::optional<double>>> values;
  for (const KeEstimate& k : ke) values.push_back(k.ke);
  return values;
}

// ---- stage 6: the joint refinement ------------------------------------------------

// One decay sample of one channel at the middle t of its exposure e:
// w (sum_i A_i DecayFactor(k_i, t - e/2, e) + B - y), the mean of the glow over the exposure.
struct JointDecayResidual {
  double t, e, y, w;
  int nc;
  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    const T* log_k = p[0];
    const T* amplitude_background = p[1];  // A_1..A_nc, B
    T sum = amplitude_background[nc];
    for (int i = 0; i < nc; ++i) {
      sum += amplitude_background[i] * DecayFactor(T(exp(log_k[i])), t - e / 2, e);
    }
    residual[0] = w * (sum - y);
    return true;
  }
};

// One excitation frame: w (sum_i S_i r_i(t_c) D_i + B - y), the closed forms of excitation_model.h.
struct JointExcitationResidual {
  double tc, td, te, y, w;
  int nc;
  std::vector<double> r0;  // each state at the charge's start (empty: 0)
  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    const T* log_k = p[0];
    const T* S = p[1];
    const T* a = p[2];
    T sum = p[3][0];
    for (int i = 0; i < nc; ++i) {
      const T k = exp(log_k[i]);
      sum += S[i] * ChargedState(a[i], k, tc, r0.empty() ? 0.0 : r0[i]) * DecayFactor(k, td, te);
    }
    residual[0] = w * (sum - y);
    return true;
  }
};

}  // namespace

JointFit JointRefine(const Curve& decay_curve, const DecayFitSummary& decay,
                     const std::vector<ExcitationMeasurement>& measurements, const StateExcitationFit& excitation) {
  JointFit joint;
  const int C = decay_curve.channel_count(), nc = decay.n_components;
  std::vector<double> log_k;
  for (const DecayComponent& c : decay.components) log_k.push_back(std::log(c.rate));
  std::vector<std::vector<double>> ab(static_cast<std::size_t>(C));
  for (int c = 0; c < C; ++c) {
    for (const DecayComponent& component : decay.components) ab[c].push_back(component.amplitude[c]);
    ab[c].push_back(decay.background.empty() ? 0.0 : decay.background[c]);
  }
  std::vector<double> S = excitation.S;
  std::map<std::string, std::vector<double>> a = excitation.a;
  double background = excitation.background;

  ceres::Problem problem;
  std::vector<ceres::ResidualBlockId> decay_blocks, excitation_blocks;
  for (int c = 0; c < C; ++c) {
    double peak = 0;
    for (double v : decay_curve.channels[c]) peak = std::max(peak, std::fabs(v));
    for (std::size_t j = 0; j < decay_curve.size(); ++j) {
      const double e = j < decay_curve.exposure_s.size() ? decay_curve.exposure_s[j] : 1.0;
      const double y = decay_curve.channels[c][j];
      auto* cost = new ceres::DynamicAutoDiffCostFunction<JointDecayResidual, 8>(
          new JointDecayResidual{decay_curve.t_s[j], e, y, PhotonCountingWeight(y, e, 1e-3 * peak), nc});
      cost->AddParameterBlock(nc);
      cost->AddParameterBlock(nc + 1);
      cost->SetNumResiduals(1);
      decay_blocks.push_back(problem.AddResidualBlock(cost, nullptr, log_k.data(), ab[c].data()));
    }
  }
  double peak = 0;
  for (const auto& m : measurements)
    for (const auto& f : m.frames) peak = std::max(peak, std::fabs(f.value));
  // Each charge's start state as the sequential fit carried it over.
  const std::vector<ExcitationMeasurement>& carried =
      excitation.fitted_measurements.size() == measurements.size() ? excitation.fitted_measurements : measurements;
  for (const auto& m : carried)
    for (const ExcitationFrame& f : m.frames) {
      auto* cost = new ceres::DynamicAutoDiffCostFunction<JointExcitationResidual, 8>(new JointExcitationResidual{
          m.charge_s, f.delay_s, f.exposure_s, f.value,
          PhotonCountingWeight(f.value, std::max(f.exposure_s, 1e-6), 1e-3 * peak), nc, m.start_state});
      cost->AddParameterBlock(nc);
      cost->AddParameterBlock(nc);
      cost->AddParameterBlock(nc);
      cost->AddParameterBlock(1);
      cost->SetNumResiduals(1);
      excitation_blocks.push_back(
          problem.AddResidualBlock(cost, nullptr, log_k.data(), S.data(), a[m.light].data(), &background));
    }
  for (int c = 0; c < C; ++c)
    for (int i = 0; i < nc; ++i) problem.SetParameterLowerBound(ab[c].data(), i, 0.0);
  for (int i = 0; i < nc; ++i) problem.SetParameterLowerBound(S.data(), i, 0.0);
  for (auto& [light, values] : a)
    if (problem.HasParameterBlock(values.data()))
      for (int i = 0; i < nc; ++i) problem.SetParameterLowerBound(values.data(), i, 0.0);
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
  joint.converged = summary.IsSolutionUsable() && summary.termination_type == ceres::CONVERGENCE;
  if (!joint.converged) joint.termination = summary.message;
  joint.decay_joint = cost_of(decay_blocks);
  joint.excitation_joint = cost_of(excitation_blocks);
  for (double v : log_k) joint.kr.push_back(std::exp(v));
  joint.S = S;
  joint.a = a;
  // 1-sigma from the covariance, scaled by the reduced chi-square, in
  // relative terms (relative_covariance.h).
  joint.kr_stderr.assign(static_cast<std::size_t>(nc), 0.0);
  for (auto& [light, values] : joint.a) joint.a_stderr[light].assign(static_cast<std::size_t>(nc), 0.0);
  std::vector<CovarianceBlock> blocks = {{log_k.data(), nc, 0}, {S.data(), nc, nc}, {&background, 1, 0}};
  for (auto& values : ab) blocks.push_back({values.data(), nc + 1, nc});  // amplitudes, then the channel's background
  std::vector<std::string> lights;
  for (auto& [light, values] : a)
    if (problem.HasParameterBlock(values.data())) {
      blocks.push_back({values.data(), nc, nc});
      lights.push_back(light);
    }
  const int n_residuals = problem.NumResiduals(), n_parameters = problem.NumParameters();
  if (n_residuals > n_parameters) {
    const double chi2 = (joint.decay_joint + joint.excitation_joint) / (n_residuals - n_parameters);
    const RelativeCovariance covariance = ComputeRelativeCovariance(problem, blocks, chi2);
    if (covariance.ok) {
      for (int i = 0; i < nc; ++i)
        joint.kr_stderr[i] = joint.kr[i] * covariance.stderr_per_block[0][i];  // d kr = kr d log kr
      for (std::size_t l = 0; l < lights.size(); ++l)
        joint.a_stderr[lights[l]] = covariance.stderr_per_block[3 + ab.size() + l];
    }
  }
  return joint;
}

namespace {

// Whether a part was captured; a note when it was not, or did not complete.
template <typename Part>
bool PartThere(const std::optional<Part>& part, const char* name, std::vector<std::string>* notes) {
  if (!part) {
    notes->push_back(std::string(name) + ": not captured");
    return false;
  }
  if (part->stop != "complete")
    notes->push_back(std::string(name) + ": stopped '" + StopHow(part->stop) + "'; using the frames it kept");
  return true;
}

// Stages 1-3: the LVF calibration, the decay and, with the dark signal the
// decay measured, the emission spectrum. What cannot be fitted is noted.
void FitCalibrationDecaySpectrum(const CapturedSample& sample, const SessionFitOptions& options, SessionFit* result) {
  std::vector<std::string>* notes = &result->notes;
  if (PartThere(sample.calibration, LvfCalibrationFrameFields::kProtocol, notes)) {
    try {
      result->calibration = FitLvfCalibration(*sample.calibration);
    } catch (const UserError& e) {
      notes->push_back(e.what());
    }
  }
  if (PartThere(sample.decay, DecayFrameFields::kProtocol, notes)) {
    DecayStage stage = FitDecayStage(*sample.decay, options, notes);
    result->decay = stage.fit;
    result->raw_decay = std::move(stage.raw);
    result->decay_curve = std::move(stage.corrected);
  }
  if (result->calibration && PartThere(sample.spectrum, SpectrumFrameFields::kProtocol, notes)) {
    try {
      double dark = std::nan("");
      if (result->decay) {
        dark = 0;
        for (double b : result->decay->background) dark += b;
      }
      result->spectrum = FitEmissionSpectrum(*sample.spectrum, *result->calibration, sample.bands, dark);
    } catch (const UserError& e) {
      notes->push_back(e.what());
    }
  }
  if (!result->decay) {
    std::string why;
    for (const std::string& note : *notes)
      if (note.find("decay") != std::string::npos) why.append(why.empty() ? "" : "; ").append(note);
    ThrowUserError(
        sample.source, "",
        "no decay could be fitted, so no kr: nothing to write" + (why.empty() ? std::string() : " (" + why + ")"));
  }
}

// Stage 5 and the material: Lambda per state from the spectrum, with kr
// from the decay and ke from the excitation (stage 4).
void WriteSequentialMaterial(const CapturedSample& sample, SessionFit* result) {
  const DecayFitSummary& decay = *result->decay;
  const int nc = decay.n_components, nb = sample.bands.band_count();
  std::vector<double> kr;
  for (const DecayComponent& c : decay.components) kr.push_back(c.rate);
  std::vector<std::vector<std::optional<double>>> ke = KeValues(result->ke);
  if (ke.empty())
    ke.assign(static_cast<std::size_t>(nc), std::vector<std::optional<double>>(static_cast<std::size_t>(nb)));
  Material& material = result->material;
  material.name = sample.name + " (fitted)";
  material.bands = sample.bands;
  std::optional<std::vector<std::vector<double>>> Lambda;
  if (result->spectrum) {
    const std::vector<double> shares = EmissionShares(*sample.decay, decay, ke, &result->notes);
    Lambda = LambdaPerState(*sample.spectrum, *result->spectrum, kr, ke, shares);
    if (!Lambda)
      result->notes.push_back(
          "spectrum: the charge light's excitation is not known in every band it reaches, so the "
          "state during the spectrum is not, nor Lambda's scale");
  }
  if (!Lambda)
    ThrowUserError(sample.source, "",
                   "no emission spectrum with a known excitation: Lambda cannot be fitted" +
                       std::string(result->notes.empty() ? "" : " (" + result->notes.back() + ")"));
  for (int i = 0; i < nc; ++i) {
    ExcitedState state;
    state.kr = kr[i];
    state.kr_stderr = decay.components[i].rate_stderr;
    state.ke = ke[i];
    if (i < static_cast<int>(result->ke.size())) state.ke_stderr = result->ke[i].ke_stderr;
    state.Lambda = (*Lambda)[i];
    material.states.push_back(state);
  }
  material.source = "phos fit session " + sample.source + ": nc = " + std::to_string(nc) + " (" + decay.choice + ")";
  ValidateMaterial(material, sample.source);
}

// Stage 6: the joint refinement, beside the sequential fit: one problem over
// the decay and every excitation frame at once; its parameters replace the
// material's when asked and when it converged.
void RefineJointly(const CapturedSample& sample, const SessionFitOptions& options, SessionFit* result) {
  if (!result->state_excitation || result->excitation_measurements.empty()) return;
  const DecayFitSummary& decay = *result->decay;
  const int nc = decay.n_components;
  try {
    result->joint = JointRefine(result->raw_decay, decay, result->excitation_measurements, *result->state_excitation);
    JointFit& joint = *result->joint;
    if (!joint.converged) result->notes.push_back("joint refinement did not converge: " + joint.termination);
    joint.ke = KePerState(result->excitation, joint.a, joint.a_stderr, nc, sample.bands.band_count(),
                          sample.source + " (joint)");
    if (!joint.ke.empty() && result->spectrum) {
      std::vector<std::string> ignored;
      const auto joint_ke = KeValues(joint.ke);
      const std::vector<double> shares = EmissionShares(*sample.decay, decay, joint_ke, &ignored);
      if (auto lambda = LambdaPerState(*sample.spectrum, *result->spectrum, joint.kr, joint_ke, shares))
        joint.Lambda = *lambda;
    }
    if (options.joint && joint.converged && !joint.Lambda.empty()) {
      Material& material = result->material;
      for (int i = 0; i < nc; ++i) {
        ExcitedState& state = material.states[i];
        state.kr = joint.kr[i];
        state.kr_stderr = joint.kr_stderr[i];
        state.ke = joint.ke[i].ke;
        state.ke_stderr = joint.ke[i].ke_stderr;
        state.Lambda = joint.Lambda[i];
      }
      material.source += "; joint refinement over the decay and excitation";
      ValidateMaterial(material, sample.source);
      result->joint_written = true;
    }
  } catch (const UserError& e) {
    result->notes.push_back(std::string("joint refinement: ") + e.what());
  }
}

// Stage 7: the solves whose result the material holds although they stopped
// at their iteration limit, not at a tolerance (the joint refinement, when
// it did not converge, is not written, so it is not among them).
void NoteUnconverged(SessionFit* result) {
  if (result->decay && !result->decay->converged)
    result->unconverged.push_back("the decay fit (" + result->decay->termination + ")");
  if (result->state_excitation && !result->state_excitation->converged && !result->joint_written)
    result->unconverged.push_back("the excitation fit (" + result->state_excitation->termination + ")");
}

}  // namespace

SessionFit FitSession(const CapturedSample& sample, const SessionFitOptions& options) {
  const auto started = std::chrono::steady_clock::now();
  SessionFit result;
  if (sample.stop != "complete")
    result.notes.push_back("the capture did not complete (stop: " + StopHow(sample.stop) +
                           "); fitting what it recorded");
  result.notes.insert(result.notes.end(), sample.notes.begin(), sample.notes.end());
  FitCalibrationDecaySpectrum(sample, options, &result);
  // 4. Excitation per state and ke per band.
  if (PartThere(sample.excitation, ExcitationFrameFields::kProtocol, &result.notes)) {
    ExcitationStage stage =
        FitExcitationStage(*sample.excitation, *result.decay, sample.bands.band_count(), options, &result.notes);
    result.excitation = std::move(stage.lights);
    result.excitation_measurements = std::move(stage.measurements);
    result.state_excitation = std::move(stage.fit);
    result.ke = std::move(stage.ke);
  }
  WriteSequentialMaterial(sample, &result);
  RefineJointly(sample, options, &result);
  NoteUnconverged(&result);
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return result;
}

SessionFit FitSession(const fs::path& dir, const SessionFitOptions& options) {
  return FitSession(LoadCapturedSample(dir), options);
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
  // ke relative to the truth, with a floor of 5% of the state's largest ke:
  // a band that barely charges is judged on the scale of the ones that do.
  for (std::size_t i = 0; i < truth.states.size() && i < fitted.states.size(); ++i) {
    const ExcitedState& t = truth.states[i];
    double largest = 0;
    for (const auto& k : t.ke) largest = std::max(largest, k.value_or(0.0));
    std::vector<std::optional<double>> errors;
    for (std::size_t band = 0; band < t.ke.size(); ++band) {
      const auto& f = band < fitted.states[i].ke.size() ? fitted.states[i].ke[band] : std::nullopt;
      if (t.ke[band] && f)
        errors.push_back(std::fabs(*f - *t.ke[band]) / std::max(*t.ke[band], 0.05 * largest));
      else
        errors.push_back(std::nullopt);
    }
    c.ke_relative_error_per_state.push_back(errors);
  }
  if (!c.ke_relative_error_per_state.empty()) c.ke_relative_error = c.ke_relative_error_per_state.front();
  return c;
}

}  // namespace phos
