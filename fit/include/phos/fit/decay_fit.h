#pragma once
// Decay fits (Sec. 8.4.4): a sum of nc exponentials whose rates are shared by
// every channel, with non-negative amplitudes and an optional constant
// background per channel,
//
//   y_c(t) = sum_i A_ci exp(-k_i t) + B_c.
//
// Method: variable projection, then a bounded refinement.
//  1. Components are added one at a time. For each new one, a log-spaced grid
//     of rates (from 0.02 / span to 3 / smallest spacing) is scanned with the
//     other rates held; for every candidate the amplitudes are solved exactly
//     as a non-negative least-squares problem, so no initial amplitude is
//     ever guessed and the start does not hinge on one guess.
//  2. From the best candidate, the rates (as log k, so they stay positive)
//     are refined by Levenberg-Marquardt on the variable-projection problem
//     (amplitudes >= 0 and backgrounds solved exactly at every step), with
//     Kaufman's Jacobian, on its nc x nc normal equations.
//  3. The number of components, when not fixed, is the one with the lowest
//     Bayesian information criterion, BIC = N ln(wRSS / N) + P ln N, among
//     fits whose components are all present (some amplitude > 0) and
//     distinct (rates more than 2% apart).
//  4. 1-sigma uncertainties come from the pseudo-inverse of J'J (so a
//     degenerate direction does not fail it), scaled by the reduced
//     chi-square: for the rates, of the variable-projection problem (their
//     marginal covariance); for the amplitudes, on request, of the full one
//     (ceres::Covariance, dense SVD).
// Components are sorted fastest first.

#include <string>
#include <vector>

#include "phos/fit/curve.h"

namespace phos {

struct DecayFitOptions {
  // Fixed number of components (1..4), or 0 to choose up to max_components.
  int components = 0;
  int max_components = 3;
  Weighting weighting = Weighting::kNone;
  // Fit a constant background per channel (dark signal, offset).
  bool background = false;
  // Rates scanned per added component.
  int rate_grid_size = 48;
  // 1-sigma uncertainty of each rate (cheap: an nc-column problem).
  bool compute_uncertainties = true;
  // 1-sigma uncertainty of each amplitude too (the full problem's covariance:
  // about as costly as the fit itself).
  bool amplitude_uncertainties = false;
  int max_iterations = 100;

  bool IsValid(std::string* error) const;
};

struct DecayComponent {
  double rate = 0, rate_stderr = 0;                 // 1/s
  std::vector<double> amplitude, amplitude_stderr;  // per channel, at t = 0 (stderr 0 unless requested)
};

struct DecayFitSummary {
  std::vector<DecayComponent> components;  // fastest first
  std::vector<double> background;          // per channel (zeros unless fitted)
  double rss = 0;                          // plain sum of squared residuals, data units
  double weighted_rss = 0;                 // what the fit minimized
  int n_components = 0;
  std::vector<double> bic;  // per nc tried (index nc - 1); NaN where invalid
  std::string choice;       // how n_components was chosen, in words
  int iterations = 0;       // Ceres iterations, all stages
  double seconds = 0;       // wall time of the fit
  // Whether the chosen fit's refinement stopped at a tolerance (Ceres's
  // CONVERGENCE) rather than at max_iterations; termination says why not.
  bool converged = true;
  std::string termination;
};

// Fits the curve; bad data (too few samples, constant, not decaying) is a
// UserError naming `where`.
DecayFitSummary FitDecay(const Curve& curve, const DecayFitOptions& options, const std::string& where);

// The same fit with Ceres for every refinement and for the rates' covariance
// (the first implementation, several times slower on small curves): the
// reference the tests hold FitDecay to.
DecayFitSummary FitDecayReference(const Curve& curve, const DecayFitOptions& options, const std::string& where);

// The fitted model at time t for channel c.
double EvaluateDecay(const DecayFitSummary& fit, int channel, double t_s);

}  // namespace phos
