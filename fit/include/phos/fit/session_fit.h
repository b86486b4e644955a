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
//  4. Excitation (Sec. 8.4.6): per light, FitExcitation with kr from the
//     decay (the delay and the exposure are in its model); ke per band from
//     the rates and the lights' band irradiances (non-negative).
//  5. Re-radiation (Sec. 8.4.5): Lambda_b = L_b / (kr r), with r the state
//     during each spectrum frame, known in closed form (Eq. 8.1) from the
//     session's recorded light switches, the ke just fitted and the frame's
//     exposure. With nc > 1, the
//     states share the shape and split it by their decay amplitudes,
//     Lambda_i = a_i Lambda* / kr_i.

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "phos/fit/decay_fit.h"
#include "phos/fit/excitation_fit.h"
#include "phos/model/material.h"

namespace phos {

struct LvfCalibrationFit {
  int width = 0;                      // columns
  double center0_nm = 0;              // centre of column 0
  double nm_per_column = 0;
  double fwhm_nm = 0;                 // the filter's pass band, from the lines' spread
  double rms_residual_nm = 0;         // of the line fit
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

// Reads an lvf-calibration session. Fewer than two usable lines, or no flat
// field, is a UserError naming the session.
LvfCalibrationFit FitLvfCalibration(const std::filesystem::path& session_dir);

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
SpectrumFit FitEmissionSpectrum(const std::filesystem::path& session_dir, const LvfCalibrationFit& calibration,
                                const SpectralGrid& bands, double dark_dn_per_s);

struct SessionFitOptions {
  int components = 0;      // 0: BIC chooses up to max_components
  int max_components = 3;
  Weighting weighting = Weighting::kPoisson;
  bool joint = false;      // write the joint refinement's kr, ke, Lambda instead of the sequential ones
};

// The joint refinement (nc = 1): kr, the decay's amplitude and background
// per channel, every light's excitation rate a and the shared saturated
// signal S, fitted at once to the decay frames and every excitation series
// (Ceres, autodiff through the exact closed forms; each sample weighted for
// photon counting, scaled by its exposure, so the experiments are on one
// chi-square). The sequential fit of the paper fixes kr from the decay
// before the excitation sees it; the joint fit lets the excitation series
// inform kr too. Both are evaluated on the same objective.
struct JointFit {
  double kr = 0;
  std::map<std::string, double> a;  // per light
  double S = 0;
  std::vector<std::optional<double>> ke;
  std::vector<double> Lambda;
  // Weighted sums of squares on the joint objective: decay part, excitation
  // part, total, for the sequential parameters and for the joint ones.
  double decay_sequential = 0, excitation_sequential = 0, decay_joint = 0, excitation_joint = 0;
  int iterations = 0;
};

struct SessionFit {
  Material material;
  std::optional<LvfCalibrationFit> calibration;
  std::optional<SpectrumFit> spectrum;
  std::optional<DecayFitSummary> decay;
  Curve decay_curve;
  struct ExcitationLight {
    std::string light;
    std::vector<ExcitationSample> samples;
    ExcitationFitSummary fit;
    std::vector<double> band_irradiance;
  };
  std::vector<ExcitationLight> excitation;
  std::optional<JointFit> joint;   // nc = 1 with excitation data
  std::vector<std::string> notes;  // what was left out or could not be fitted, and why
  double seconds = 0;
};

// Fits an `all` folder (phos capture all). What cannot be fitted is noted and
// left out; a material needs at least the decay (kr) and the spectrum
// (Lambda), else a UserError naming what is missing.
SessionFit FitSession(const std::filesystem::path& dir, const SessionFitOptions& options);

// The joint refinement alone (FitSession runs it for nc = 1): starts from the
// sequential decay fit and per-light excitation fits. `decay_curve` is the
// decay as recorded (per second of exposure at the exposure's middle, with
// exposure_s), not corrected for the exposure.
JointFit JointRefine(const Curve& decay_curve, const DecayFitSummary& decay,
                     const std::vector<SessionFit::ExcitationLight>& lights);

// How close a fitted material is to the one a simulated sample was made of:
// kr relative error per state, the L1 distance of the normalized emission
// spectra (sum of |difference| over bands, each spectrum summing to 1), and
// the relative error of ke in every band both know.
struct MaterialComparison {
  std::vector<double> kr_relative_error;
  double spectrum_l1 = 0;
  std::vector<std::optional<double>> ke_relative_error;  // per band of the first state
};
MaterialComparison CompareMaterials(const Material& fitted, const Material& truth);

// A self-contained HTML report: data against fit, residuals, uncertainties,
// the chosen nc with its reason, as inline SVG plots.
std::string SessionReportHtml(const SessionFit& fit, const std::string& title);

}  // namespace phos
