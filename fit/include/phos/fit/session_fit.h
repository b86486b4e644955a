#pragma once
// Fitting a captured sample (Sec. 8.4.2-8.4.6): the sessions that
// `phos capture all` writes, read from disk (fit never talks to devices),
// turned into a material file.
//
//  1. LVF calibration (Sec. 8.4.2): the centroid column of each line of known
//     wavelength gives the filter's centre-per-column line (least squares),
//     its spread the filter's width; the flat field under the lamp of known
//     colour temperature gives each column's response.
//  2. Emission spectrum: every well-exposed spectrum frame's column profile,
//     divided by the column response, is a blurred view of the sample's
//     radiance; the band radiances are its non-negative, lightly regularized
//     least-squares reconstruction through the filter's measured shape.
//  3. Decay (Sec. 8.4.4): frames normalized by their exposure, at the middle
//     of the exposure, saturated frames left out; FitDecay with shared rates
//     across channels, a background, and nc chosen by BIC (or fixed).
//  4. Excitation (Sec. 8.4.6), per excited state: each charge's first frame
//     and its decay tail split the response into the states (their kr from
//     the decay), FitStateExcitation gives every state's rate a_il under
//     every light and its saturated signal S_i, and ke_i per band follows
//     from the rates and the lights' band irradiances (non-negative), each
//     with its 1-sigma uncertainty.
//  5. Re-radiation (Sec. 8.4.5): the states share the emission shape (one
//     emitting centre fed by several traps) and split it by their decay
//     amplitudes A_i: Lambda_i = w_i X, w_i proportional to
//     A_i / (kr_i r_i(light-off)), the state at the decay's light-off known
//     from its charge and ke_i. X per band is L_b / sum_i w_i kr_i r_i over
//     the spectrum frames, r_i during each frame known in closed form
//     (Eq. 8.1) from the session's recorded light switches and the frame's
//     exposure. For nc = 1: Lambda = L / (kr r).
//  6. The joint refinement (any nc): every parameter above that the decay and
//     the excitation share, fitted to all their frames at once.

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "phos/fit/captured_sample.h"
#include "phos/fit/decay_fit.h"
#include "phos/fit/excitation_fit.h"
#include "phos/fit/state_excitation_fit.h"
#include "phos/model/material.h"

namespace phos {

struct LvfCalibrationFit {
  int width = 0;          // columns
  double center0_nm = 0;  // centre of column 0
  double nm_per_column = 0;
  double fwhm_nm = 0;          // the filter's pass band, from the lines' spread
  double rms_residual_nm = 0;  // of the line fit
  struct Line {
    std::string light;
    double wavelength_nm = 0, column = 0;
  };
  std::vector<Line> lines;
  std::vector<double> flat_dn_per_s;  // per column, all channels summed, dark removed
  std::vector<double> dark_dn_per_s;  // per column: the camera's dark signal, to remove from spectra
  double flat_temperature_k = 3000, flat_irradiance = 1;

  double CenterNm(double column) const { return center0_nm + nm_per_column * column; }
};

// Fits an lvf-calibration part. Fewer than two usable lines, or no flat
// field, is a UserError naming the part.
LvfCalibrationFit FitLvfCalibration(const CapturedSample::Calibration& part);

struct SpectrumFit {
  // Per well-exposed frame: band radiance (material units), its delay after
  // light-off and exposure; the measured and modelled column profiles.
  struct FrameFit {
    double delay_s = 0, exposure_s = 0, t_start_s = 0;
    std::vector<double> band_radiance;
    std::vector<double> measured, modelled;  // per column, DN/s
  };
  std::vector<FrameFit> frames;
  std::vector<double> shape;  // mean band radiance, normalized to sum 1
  std::string charge_light;
  double charge_s = 0;
};

// `dark_dn_per_s`: the camera's dark signal per second, all channels summed
// (the decay fit's background measures it best); NaN: the calibration's
// dark frame, averaged over its columns (dark current is uniform).
SpectrumFit FitEmissionSpectrum(const CapturedSample::Spectrum& part, const LvfCalibrationFit& calibration,
                                const SpectralGrid& bands, double dark_dn_per_s);

struct SessionFitOptions {
  int components = 0;  // 0: BIC chooses up to max_components
  int max_components = 3;
  Weighting weighting = Weighting::kPoisson;
  // Write the joint refinement's kr, ke, Lambda and their uncertainties (when
  // it converged), else the sequential fit's. The joint fit uses every frame
  // for every parameter and its covariance counts kr's uncertainty in ke;
  // the sequential one holds kr fixed, so its ke intervals are too narrow.
  bool joint = true;
  // The solvers' iteration limit for the decay and excitation fits; 0: each
  // fit's own default (DecayFitOptions, StateExcitationOptions).
  int max_iterations = 0;
};

// The joint refinement (any nc): every kr_i, the decay's amplitudes and
// background per channel, every S_i and every a_il, fitted at once to the
// decay frames and every excitation frame (Ceres, autodiff through the
// exact closed forms; each sample weighted for photon counting, scaled by
// its exposure, so the experiments are on one chi-square). The sequential
// fit of the paper fixes kr from the decay before the excitation sees it;
// the joint fit lets the excitation tails inform kr too. Both are evaluated
// on the same objective. Its covariance (scaled by the reduced chi-square)
// carries every source of uncertainty, kr's included, into the rates.
struct JointFit {
  std::vector<double> kr, kr_stderr;                       // per state
  std::map<std::string, std::vector<double>> a, a_stderr;  // per light, per state
  std::vector<double> S;                                   // per state
  std::vector<KeEstimate> ke;                              // per state
  std::vector<std::vector<double>> Lambda;                 // per state (empty when not known)
  // Weighted sums of squares on the joint objective: decay part, excitation
  // part, for the sequential parameters and for the joint ones.
  double decay_sequential = 0, excitation_sequential = 0, decay_joint = 0, excitation_joint = 0;
  int iterations = 0;
  bool converged = false;
  std::string termination;  // Ceres's message when it did not converge
};

struct SessionFit {
  Material material;  // with kr_stderr and ke_stderr per state
  std::optional<LvfCalibrationFit> calibration;
  std::optional<SpectrumFit> spectrum;
  std::optional<DecayFitSummary> decay;
  Curve decay_curve;  // per second of exposure at the exposure's middle, corrected for the exposure
  Curve raw_decay;    // the same, uncorrected (the joint refinement's data)
  // Excitation: per light its band irradiance and the response of each
  // charge's first frame (for plots), every measurement with its tail, the
  // per-state fit and ke per state.
  struct ExcitationLight {
    std::string light;
    std::vector<ExcitationSample> samples;
    std::vector<double> band_irradiance;
  };
  std::vector<ExcitationLight> excitation;
  std::vector<ExcitationMeasurement> excitation_measurements;
  std::optional<StateExcitationFit> state_excitation;
  std::vector<KeEstimate> ke;      // per state
  std::optional<JointFit> joint;   // with excitation data
  bool joint_written = false;      // the material is the joint refinement's
  std::vector<std::string> notes;  // what was left out or could not be fitted, and why
  // The fits the material holds that stopped at their iteration limit rather
  // than converging, each with the solver's reason: the command refuses to
  // write such a material unless asked (--keep-unconverged).
  std::vector<std::string> unconverged;
  double seconds = 0;
};

// Fits a captured sample (an `all` folder, LoadCapturedSample). What cannot
// be fitted is noted and left out; a material needs at least the decay (kr)
// and the spectrum (Lambda), else a UserError naming what is missing.
SessionFit FitSession(const CapturedSample& sample, const SessionFitOptions& options);
// The same, read from its folder first.
SessionFit FitSession(const std::filesystem::path& dir, const SessionFitOptions& options);

// The joint refinement alone (FitSession runs it): starts from the
// sequential decay fit and the per-state excitation fit. `decay_curve` is the
// decay as recorded (per second of exposure at the exposure's middle, with
// exposure_s), not corrected for the exposure.
JointFit JointRefine(const Curve& decay_curve, const DecayFitSummary& decay,
                     const std::vector<ExcitationMeasurement>& measurements, const StateExcitationFit& excitation);

// How close a fitted material is to the one a simulated sample was made of:
// kr relative error per state, the L1 distance of the normalized emission
// spectra (sum of |difference| over bands, each spectrum summing to 1), and
// the relative error of ke in every band both know.
struct MaterialComparison {
  std::vector<double> kr_relative_error;  // per state, matched fastest to fastest
  double spectrum_l1 = 0;
  std::vector<std::optional<double>> ke_relative_error;                         // per band of the first state
  std::vector<std::vector<std::optional<double>>> ke_relative_error_per_state;  // [state][band]
};
MaterialComparison CompareMaterials(const Material& fitted, const Material& truth);

// A self-contained HTML report: data against fit, residuals, uncertainties,
// the chosen nc with its reason, as inline SVG plots; with `comparison`, how
// far the fit is from a known material (`fit session --compare`).
std::string SessionReportHtml(const SessionFit& fit, const std::string& title,
                              const std::optional<MaterialComparison>& comparison = std::nullopt);

}  // namespace phos
