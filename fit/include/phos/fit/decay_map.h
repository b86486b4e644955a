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
// product for every grid rate); the best grid rate is refined by the vertex
// of a parabola through it and its neighbours, then exact Newton steps on
// log k (analytic derivatives of the basis and of the projected cost). A
// frame integrates the glow over its exposure e, so the basis is
// exp(-k t) sinh(k e / 2) / (k e / 2) at the exposure's middle, exact for
// any exposure. Rows run in parallel (TBB).

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
  int newton_steps = 4;  // at most; they stop when a step is below 1e-4 in log k
};

struct DecayMap {
  int width = 0, height = 0, channels = 0;
  std::vector<float> kr;          // per pixel, 1/s (NaN where nothing decays)
  std::vector<float> amplitude;   // per pixel and channel, at t = 0
  std::vector<float> background;  // per pixel and channel
  std::vector<float> rms;         // per pixel: weighted rms residual per sample
  std::size_t no_decay = 0;       // pixels whose best amplitude is 0 in every channel
  double seconds = 0;
};

// `progress(rows_done)` is called from worker threads as rows finish.
// Bad input (frames of unequal size, fewer than 3 frames, times not
// increasing) is a UserError naming `where`.
DecayMap FitDecayMap(const DecayMapInput& input, const DecayMapOptions& options, const std::string& where,
                     const std::function<void(std::size_t)>& progress = {});

// The first algorithm, for comparison only (tests, bench): pixel by pixel,
// every grid rate's sums from the samples, then `newton_steps` Newton steps
// with central differences of the cost. The same model, options and outputs
// as FitDecayMap, several times slower.
DecayMap FitDecayMapReference(const DecayMapInput& input, const DecayMapOptions& options, const std::string& where);

}  // namespace phos
