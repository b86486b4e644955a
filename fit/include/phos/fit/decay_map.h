#pragma once
// Per-pixel decay maps (Sec. 8.4.4, for spatially varying samples): every
// pixel of a decay session fitted with one exponential shared by its
// channels plus a background per channel,
//
//   y_c(t) = A_c exp(-k t) + B_c   (per second of exposure),
//
// into parameter images. A million pixels must take a second or two, so the
// method is variable projection on a rate grid shared by all pixels: for
// each candidate k the amplitudes and backgrounds are a 2x2 weighted linear
// least-squares problem per channel (A_c clamped at 0), solved in closed
// form from weighted sums. The sums that depend on k are, for a block of
// pixels, products of the block's weights with the grid's basis (one matrix
// product for every grid rate); the best grid rate is refined by the minimum
// of a cubic through it and three neighbours (or the vertex of a parabola
// through two), then exact Newton steps on log k (analytic derivatives of
// the basis and of the projected cost; the exponentials in FMAs, one per
// frame plus one per distinct exposure). A
// frame integrates the glow over its exposure e, so the basis is
// exp(-k t) sinh(k e / 2) / (k e / 2) at the exposure's middle, exact for
// any exposure. Rows run in parallel (TBB).
//
// Two states (options.states = 2, docs/two-state-map.md): the model of the
// two-state materials (model/synthetic.h: two traps feeding one emitting
// centre),
//
//   y_c(t) = A1_c exp(-k1 t) + A2_c exp(-k2 t) + B_c,   k1 < k2,
//
// with A1_c, A2_c >= 0 per channel. Both states share one emission colour,
// so A1 and A2 are proportional over channels in the model; the map does not
// impose it: with it the amplitudes are no longer linear (a rank-one 2 x C
// matrix) and variable projection loses its closed form, and a pixel that
// sees two materials of different colours breaks it anyway. The map first
// fits one state (exactly as above), then per block the projected cost of
// every pair of a coarse rate grid (cross sums of the basis as one more
// matrix product), then Levenberg-Marquardt on (log k1, log k2) with the
// projected cost's exact gradient and its Gauss-Newton Hessian (Kaufman's
// approximation of the variable-projection Jacobian). A pixel keeps the
// second state only if BIC says so (as FitDecay chooses components): the
// drop in cost from one state to two must pay for the C + 1 more parameters,
// N ln(cost1 / cost2) > (C + 1) ln N with N = C m samples, and both states
// must have an amplitude. Otherwise it is a one-state pixel: kr2 NaN,
// amplitude2 0, the one-state fit in kr, amplitude, background and rms.

#include <cstddef>
#include <functional>
#include <vector>

#include "phos/fit/curve.h"

namespace phos {

struct DecayMapInput {
  int width = 0, height = 0, channels = 0;
  std::vector<double> t_s;         // per frame: middle of the exposure, after light-off
  std::vector<double> exposure_s;  // per frame
  // Per frame: width * height * channels values, interleaved per pixel, in
  // signal per second of exposure (black level removed).
  std::vector<std::vector<float>> frames;
};

struct DecayMapOptions {
  int rate_grid_size = 48;  // log-spaced from 0.02 / span to 3 / smallest spacing
  bool background = true;
  Weighting weighting = Weighting::kPoisson;  // photon counting, scaled by sqrt(exposure)
  int newton_steps = 4;                       // at most; they stop when a step is below 1e-4 in log k
  int states = 1;                             // 1 or 2 (exponentials per pixel)
  // Two states: the coarse grid whose pairs start the refinement (log-spaced
  // over the same range as the rate grid), and the refinement's steps.
  int pair_grid_size = 12;  // 10 to 20 find the same fits on the tests' stacks
  // Levenberg-Marquardt, at most; they stop below 1e-4 in log k. The valley
  // of a slow state against the background is long: 12 steps left 3 of 384
  // noiseless pixels (tests/fit/decay_map_test.cpp) short of the truth.
  int pair_steps = 50;
};

struct DecayMap {
  int width = 0, height = 0, channels = 0;
  std::vector<float> kr;          // per pixel, 1/s (NaN where nothing decays)
  std::vector<float> amplitude;   // per pixel and channel, at t = 0
  std::vector<float> background;  // per pixel and channel
  std::vector<float> rms;         // per pixel: weighted rms residual per sample
  std::size_t no_decay = 0;       // pixels whose best amplitude is 0 in every channel
  // Two states only (empty for one): kr is the slow state's rate k1 and
  // amplitude its amplitudes; kr2 the fast state's (k2 > k1), NaN where one
  // state suffices; amplitude2 per pixel and channel (0 there).
  std::vector<float> kr2, amplitude2;
  std::size_t one_state = 0;  // decaying pixels where BIC keeps one state
  double seconds = 0;
};

// `progress(rows_done)` is called from worker threads as rows finish.
// Bad input (frames of unequal size, fewer than 3 frames, times not
// increasing, states other than 1 or 2) is a UserError naming `where`.
DecayMap FitDecayMap(const DecayMapInput& input, const DecayMapOptions& options, const std::string& where,
                     const std::function<void(std::size_t)>& progress = {});

// The first algorithm, for comparison only (tests, bench): pixel by pixel,
// every grid rate's sums from the samples, then `newton_steps` Newton steps
// with central differences of the cost. The same model, options and outputs
// as FitDecayMap, several times slower.
DecayMap FitDecayMapReference(const DecayMapInput& input, const DecayMapOptions& options, const std::string& where);

}  // namespace phos
