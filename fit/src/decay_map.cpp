#include "phos/fit/decay_map.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Core>
#include <Eigen/LU>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <utility>

#include "phos/util/error.h"

namespace phos {
namespace {

// The exposure-averaged basis exp(-k t) sinh(k e / 2) / (k e / 2).
void Basis(double k, const std::vector<double>& t, const std::vector<double>& e, double* out) {
  for (std::size_t j = 0; j < t.size(); ++j) {
    const double x = k * e[j] / 2;
    out[j] = std::exp(-k * t[j]) * (x > 1e-8 ? std::sinh(x) / x : 1.0);
  }
}

void Validate(const DecayMapInput& in, const std::string& where) {
  const int m = static_cast<int>(in.frames.size());
  if (m < 3) ThrowUserError(where, "", "needs at least 3 frames for a decay map, has " + std::to_string(m));
  if (in.channels < 1 || in.channels > 8) ThrowUserError(where, "", "1 to 8 channels per pixel");
  if (static_cast<int>(in.t_s.size()) != m || static_cast<int>(in.exposure_s.size()) != m)
    ThrowUserError(where, "", "one time and one exposure per frame");
  const std::size_t pixels = static_cast<std::size_t>(in.width) * in.height;
  for (int j = 0; j < m; ++j) {
    if (in.frames[j].size() != pixels * in.channels)
      ThrowUserError(where, "frame " + std::to_string(j + 1), "has another size than the first");
    if (j > 0 && !(in.t_s[j] > in.t_s[j - 1]))
      ThrowUserError(where, "frame " + std::to_string(j + 1), "times must increase");
    if (!(in.exposure_s[j] > 0)) ThrowUserError(where, "frame " + std::to_string(j + 1), "exposure must be > 0");
  }
}

// The rate grid, as FitDecay scans it: from a twentieth of one per span to
// three per smallest spacing, log-spaced; basis is G rows of m samples.
struct RateGrid {
  int G = 0;
  std::vector<double> log_k, basis;
};

RateGrid MakeRateGrid(const DecayMapInput& in, const DecayMapOptions& options) {
  const int m = static_cast<int>(in.frames.size());
  const double span = in.t_s.back() - in.t_s.front();
  double spacing = span;
  for (int j = 1; j < m; ++j) spacing = std::min(spacing, in.t_s[j] - in.t_s[j - 1]);
  const double k_lo = 0.02 / span, k_hi = 3 / spacing;
  RateGrid grid;
  grid.G = std::max(8, options.rate_grid_size);
  grid.log_k.resize(grid.G);
  grid.basis.resize(static_cast<std::size_t>(grid.G) * m);
  for (int g = 0; g < grid.G; ++g) {
    grid.log_k[g] = std::log(k_lo) + (std::log(k_hi) - std::log(k_lo)) * g / (grid.G - 1);
    Basis(std::exp(grid.log_k[g]), in.t_s, in.exposure_s, &grid.basis[static_cast<std::size_t>(g) * m]);
  }
  return grid;
}

DecayMap EmptyMap(const DecayMapInput& in) {
  const std::size_t pixels = static_cast<std::size_t>(in.width) * in.height;
  DecayMap map;
  map.width = in.width;
  map.height = in.height;
  map.channels = in.channels;
  map.kr.assign(pixels, std::nanf(""));
  map.amplitude.assign(pixels * in.channels, 0.0f);
  map.background.assign(pixels * in.channels, 0.0f);
  map.rms.assign(pixels, std::nanf(""));
  return map;
}

// Photon counting: a rate's variance is value / exposure, with a floor (a
// thousandth of the channel's peak) so a dark sample does not get an
// infinite weight.
double SampleWeight(double y, double exposure, double floor, Weighting weighting) {
  return weighting == Weighting::kPoisson ? exposure / std::max(std::fabs(y), floor) : 1.0;
}
double WeightFloor(double peak) { return std::max(1e-3 * peak, 1e-12); }

// One channel's amplitude and background for one rate, from the weighted
// sums of basis b, constant 1 and values y: a 2x2 linear least-squares
// problem with A >= 0 (or A alone without a background); the cost is the
// weighted RSS from the same sums. Branch-free so that a loop over channels
// and pixels vectorises; `constant` is S1y / S11, the fit when A = 0.
struct ChannelFit {
  double amplitude, background, cost;
};
inline ChannelFit ProjectChannel(double Sbb, double Sb1, double Sby, double S11, double S1y, double Syy,
                                 double constant, bool background) {
  double A, B;
  if (background) {
    // Both sides of each choice are computed, so that it is a select.
    const double det = Sbb * S11 - Sb1 * Sb1, reciprocal = 1 / det;
    const double inverse = det > 1e-300 * Sbb * S11 ? reciprocal : 0.0;
    const double a = (Sby * S11 - Sb1 * S1y) * inverse, b = (Sbb * S1y - Sb1 * Sby) * inverse;
    const bool decays = a > 0;  // else the bound is active: a constant alone
    A = decays ? a : 0.0;
    B = decays ? b : constant;
  } else {
    const double a = Sby / Sbb;
    A = Sbb > 0 && a > 0 ? a : 0.0;
    B = 0;
  }
  return {A, B, Syy - 2 * A * Sby - 2 * B * S1y + A * A * Sbb + 2 * A * B * Sb1 + B * B * S11};
}

// ProjectChannel's cost for n pixel-channels at one rate (a loop the
// compiler vectorises: restrict pointers, no branches).
void ProjectedCosts(int n, const double* Sbb, const double* Sb1, const double* Sby, const double* S11,
                    const double* S1y, const double* Syy, const double* constant, bool background,
                    double* __restrict__ cost) {
  if (background)
    for (int i = 0; i < n; ++i)
      cost[i] = ProjectChannel(Sbb[i], Sb1[i], Sby[i], S11[i], S1y[i], Syy[i], constant[i], true).cost;
  else
    for (int i = 0; i < n; ++i)
      cost[i] = ProjectChannel(Sbb[i], Sb1[i], Sby[i], S11[i], S1y[i], Syy[i], constant[i], false).cost;
}

// Weights and weighted values of n pixel-channels at one frame, and their
// contribution to the rate-independent sums.
void WeighFrame(int n, double exposure, Weighting weighting, const double* peak, double* __restrict__ w,
                double* __restrict__ wy, double* __restrict__ S11, double* __restrict__ S1y,
                double* __restrict__ Syy) {
  for (int i = 0; i < n; ++i) {
    const double y = wy[i];  // the values, until the weights are known
    const double weight = SampleWeight(y, exposure, WeightFloor(peak[i]), weighting);
    w[i] = weight;
    wy[i] = weight * y;
    S11[i] += weight;
    S1y[i] += weight * y;
    Syy[i] += weight * y * y;
  }
}

// ---------------------------------------------------------------------------
// The fast map. Pixels go in blocks of up to kBlockPixels along a row: the
// rate-independent sums (S11, S1y, Syy) once per pixel and channel, the
// rate-dependent ones (Sbb, Sb1, Sby) for every grid rate at once as two
// matrix products of the block's weights with the basis and its square;
// then per pixel a parabola through the best grid rate and its neighbours
// and exact Newton steps on u = log k of the variable-projection cost.

constexpr int kBlockPixels = 128;

using Matrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic>;  // column-major
using Array = Eigen::ArrayXd;

// Frame times split into what the basis derivatives need: start s and
// exposure e of every frame, as arrays.
struct FrameTimes {
  Array s, e, s_plus_e, s2, two_s_plus_e;
};

FrameTimes MakeFrameTimes(const DecayMapInput& in) {
  const int m = static_cast<int>(in.frames.size());
  FrameTimes f;
  f.e = Eigen::Map<const Array>(in.exposure_s.data(), m);
  f.s = Eigen::Map<const Array>(in.t_s.data(), m) - f.e / 2;
  f.s_plus_e = f.s + f.e;
  f.s2 = f.s * f.s;
  f.two_s_plus_e = 2 * f.s + f.e;
  return f;
}

// The basis b = (exp(-k s) - exp(-k (s + e))) / (k e) (the same exposure
// average as Basis) and its first two derivatives in u = log k:
//   b_u  = -k s b + Q - b,
//   b_uu = k^2 s^2 b - k (2 s + e) Q - b_u,   with Q = exp(-k (s + e)).
// Eigen's exp is vectorised; the difference of exponentials loses at most
// 1e-16 / (k e) relatively, 2e-11 at the grid's slowest rate.
struct BasisWithDerivatives {
  Array b, b_u, b_uu;
};

void EvaluateBasis(double u, const FrameTimes& f, BasisWithDerivatives& out) {
  const double k = std::exp(u);
  const Array P = (-k * f.s).exp();
  const Array Q = (-k * f.s_plus_e).exp();
  out.b = (P - Q) / (k * f.e);
  out.b_u = -k * f.s * out.b + Q - out.b;
  out.b_uu = k * k * f.s2 * out.b - k * f.two_s_plus_e * Q - out.b_u;
}

// One pixel's samples, contiguous per channel: weights w and weighted values
// w y, and the rate-independent sums.
struct PixelData {
  int channels = 0, m = 0;
  Matrix w, wy;  // m x channels
  double S11[8], S1y[8], Syy[8], constant[8], peak[8];
};

// The variable-projection cost at one rate, with its first two derivatives
// in u, and the amplitudes and backgrounds that attain it.
struct RateFit {
  double u = 0, cost = std::numeric_limits<double>::infinity(), d1 = 0, d2 = 0;
  double decay_span = 0;  // b at the first frame minus b at the last
  double amplitude[8] = {}, background[8] = {};
};

// Per channel, with theta = (A, B), M = [[Sbb, Sb1], [Sb1, S11]] and
// r = (Sby, S1y), the cost is Syy - r^T M^-1 r. Its derivatives (' = d/du):
//   C'  = -2 A Sby' + A^2 Sbb' + 2 A B Sb1',
//   C'' = -2 A Sby'' + A^2 Sbb'' + 2 A B Sb1'' - 2 g^T M^-1 g,
// where g = r' - M' theta is what moves theta (theta' = M^-1 g). A channel
// held at A = 0 is a constant: no derivative.
RateFit EvaluateRate(double u, const PixelData& px, const FrameTimes& f, bool background,
                     BasisWithDerivatives& basis) {
  EvaluateBasis(u, f, basis);
  const Array b2 = basis.b.square();
  const Array bb_u = basis.b * basis.b_u;
  const Array bb_uu = basis.b_u.square() + basis.b * basis.b_uu;
  RateFit fit;
  fit.u = u;
  fit.cost = 0;
  fit.decay_span = basis.b(0) - basis.b(px.m - 1);
  for (int c = 0; c < px.channels; ++c) {
    const auto w = px.w.col(c).array(), wy = px.wy.col(c).array();
    const double Sbb = (w * b2).sum(), Sb1 = (w * basis.b).sum(), Sby = (wy * basis.b).sum();
    const ChannelFit cf =
        ProjectChannel(Sbb, Sb1, Sby, px.S11[c], px.S1y[c], px.Syy[c], px.constant[c], background);
    fit.amplitude[c] = cf.amplitude;
    fit.background[c] = cf.background;
    fit.cost += cf.cost;
    if (!(cf.amplitude > 0)) continue;
    const double A = cf.amplitude, B = cf.background;
    const double dSbb = 2 * (w * bb_u).sum(), dSb1 = (w * basis.b_u).sum(), dSby = (wy * basis.b_u).sum();
    const double ddSbb = 2 * (w * bb_uu).sum(), ddSb1 = (w * basis.b_uu).sum(), ddSby = (wy * basis.b_uu).sum();
    fit.d1 += -2 * A * dSby + A * A * dSbb + 2 * A * B * dSb1;
    double move;  // g^T M^-1 g
    if (background) {
      const double g1 = dSby - dSbb * A - dSb1 * B, g2 = -dSb1 * A;
      const double det = Sbb * px.S11[c] - Sb1 * Sb1;
      move = (px.S11[c] * g1 * g1 - 2 * Sb1 * g1 * g2 + Sbb * g2 * g2) / det;
    } else {
      const double g1 = dSby - dSbb * A;
      move = g1 * g1 / Sbb;
    }
    fit.d2 += -2 * A * ddSby + A * A * ddSbb + 2 * A * B * ddSb1 - 2 * move;
  }
  return fit;
}

// Newton on u from the best grid rate. The start is the vertex of the
// parabola through that rate's cost and its neighbours' (at most half a grid
// step away); from there exact steps converge quadratically, so they stop
// once a step is below 1e-4 in log k (what remains is of order 1e-8) or
// when a step does not lower the cost.
RateFit RefinePixel(const PixelData& px, const FrameTimes& f, const RateGrid& grid, const double* grid_cost,
                    const DecayMapOptions& options, BasisWithDerivatives& basis) {
  int best = 0;
  for (int g = 1; g < grid.G; ++g)
    if (grid_cost[g] < grid_cost[best]) best = g;
  const double h = grid.log_k[1] - grid.log_k[0];
  double u0 = grid.log_k[best];
  if (best > 0 && best < grid.G - 1) {
    const double lo = grid_cost[best - 1], mid = grid_cost[best], hi = grid_cost[best + 1];
    const double curvature = lo - 2 * mid + hi;
    if (curvature > 0) u0 += h * (lo - hi) / (2 * curvature);
  }
  RateFit fit = EvaluateRate(u0, px, f, options.background, basis);
  if (!(fit.cost <= grid_cost[best]) && u0 != grid.log_k[best])
    fit = EvaluateRate(grid.log_k[best], px, f, options.background, basis);
  for (int step = 0; step < options.newton_steps; ++step) {
    if (!(fit.d2 > 0)) break;
    const double next = std::clamp(fit.u - fit.d1 / fit.d2, grid.log_k.front(), grid.log_k.back());
    if (next == fit.u) break;
    const RateFit trial = EvaluateRate(next, px, f, options.background, basis);
    if (!(trial.cost < fit.cost)) break;
    const bool converged = std::fabs(next - fit.u) < 1e-4;
    fit = trial;
    if (converged) break;
  }
  return fit;
}

// Per-thread work space for one block of pixels: n = pixel * channels +
// channel indexes the block's pixel-channels.
struct BlockWork {
  Matrix w, wy;         // n x m
  Matrix rate_sums;     // n x 2G: Sb1 for every grid rate, then Sbb
  Matrix value_sums;    // n x G: Sby
  Array S11, S1y, Syy, constant, peak;  // per n
  Matrix pixel_cost;    // G x pixels
  Array channel_cost;   // per n
  PixelData pixel;
  BasisWithDerivatives basis;
  Array one_state_cost;  // per pixel of the block: the one-state fit's cost (two states compare with it)
  // Two states: sums of the pair grid, the pairs' costs, a pixel's two bases.
  Matrix pair_sums, pair_value_sums, pair_cost;
  Array b1, d1, b2, d2;  // exp(-k s), exp(-k (s + e)) of the two rates
  Matrix pair_products, pair_weighted, pair_values;
};

// Pixel p of the block's sums (C channels), channel by channel, into px (sized for them and the frames).
void LoadPixel(const BlockWork& work, int p, int C, PixelData& px) {
  for (int c = 0; c < C; ++c) {
    const int i = p * C + c;
    px.w.col(c) = work.w.row(i).transpose();
    px.wy.col(c) = work.wy.row(i).transpose();
    px.S11[c] = work.S11(i);
    px.S1y[c] = work.S1y(i);
    px.Syy[c] = work.Syy(i);
    px.constant[c] = work.constant(i);
    px.peak[c] = work.peak(i);
  }
}

void FitBlock(const DecayMapInput& in, const DecayMapOptions& options, const RateGrid& grid, const Matrix& grid_basis,
              const FrameTimes& times, std::size_t first_pixel, int count, BlockWork& work, DecayMap& map,
              std::atomic<std::size_t>& no_decay) {
  const int C = in.channels, m = static_cast<int>(in.frames.size()), G = grid.G;
  const int n = count * C;
  work.w.resize(n, m);
  work.wy.resize(n, m);
  work.peak.setZero(n);
  for (int j = 0; j < m; ++j) {
    const float* frame = &in.frames[j][first_pixel * C];
    for (int i = 0; i < n; ++i) {
      work.wy(i, j) = frame[i];  // the values, until the weights are known
      work.peak(i) = std::max(work.peak(i), std::fabs(work.wy(i, j)));
    }
  }
  work.S11.setZero(n);
  work.S1y.setZero(n);
  work.Syy.setZero(n);
  for (int j = 0; j < m; ++j)
    WeighFrame(n, in.exposure_s[j], options.weighting, work.peak.data(), &work.w(0, j), &work.wy(0, j),
               work.S11.data(), work.S1y.data(), work.Syy.data());
  work.constant = (work.S11 > 0).select(work.S1y / work.S11, 0.0);

  work.rate_sums.noalias() = work.w * grid_basis;
  work.value_sums.noalias() = work.wy * grid_basis.leftCols(G);

  work.pixel_cost.resize(G, count);
  work.channel_cost.resize(n);
  work.one_state_cost.resize(count);
  for (int g = 0; g < G; ++g) {
    ProjectedCosts(n, &work.rate_sums(0, G + g), &work.rate_sums(0, g), &work.value_sums(0, g), work.S11.data(),
                   work.S1y.data(), work.Syy.data(), work.constant.data(), options.background,
                   work.channel_cost.data());
    for (int p = 0; p < count; ++p) work.pixel_cost(g, p) = work.channel_cost.segment(p * C, C).sum();
  }

  PixelData& px = work.pixel;
  px.channels = C;
  px.m = m;
  px.w.resize(m, C);
  px.wy.resize(m, C);
  for (int p = 0; p < count; ++p) {
    LoadPixel(work, p, C, px);
    const RateFit fit = RefinePixel(px, times, grid, &work.pixel_cost(0, p), options, work.basis);
    work.one_state_cost(p) = fit.cost;
    // It decays if some channel's fitted decay is more than rounding (a
    // millionth of the pixel's largest value) over the recorded span.
    const std::size_t pixel = first_pixel + p;
    bool decays = false;
    for (int c = 0; c < C; ++c) {
      map.amplitude[pixel * C + c] = static_cast<float>(fit.amplitude[c]);
      map.background[pixel * C + c] = static_cast<float>(fit.background[c]);
      decays = decays || fit.amplitude[c] * fit.decay_span > 1e-6 * px.peak[c];
    }
    if (decays)
      map.kr[pixel] = static_cast<float>(std::exp(fit.u));
    else
      ++no_decay;
    map.rms[pixel] = static_cast<float>(std::sqrt(std::max(0.0, fit.cost) / (C * m)));
  }
}

// ---------------------------------------------------------------------------
// Two states (options.states = 2): y_c = A1_c b(k1) + A2_c b(k2) + B_c.

// One channel's normal equations for the basis pair (b1, b2) and the
// constant c: the Gram entries s.., the right-hand sides r.. and y'Wy.
struct PairGram {
  double s11, s12, s22, s1c, s2c, scc, r1, r2, rc, yy;
};
struct PairChannelFit {
  double a1, a2, background, cost;
};

// Non-negative least squares for (A1, A2) with B free, as SolveSmallNnls
// does it (every support's unconstrained solution; the best feasible one is
// the optimum), written out for 3 unknowns and branch-free so that a loop
// over pixel-channels vectorises. The cost of a support's solution x is
// yy - x'r. A support whose Gram is singular to rounding (k1 = k2) is left
// out: the one-rate supports cover it.
[[gnu::always_inline]] inline PairChannelFit ProjectPair(const PairGram& g, bool background) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  PairChannelFit best{0, 0, 0, g.yy};
  auto take = [&best](bool ok, double a1, double a2, double b, double cost) {
    const bool better = ok & (cost < best.cost);  // & not &&: no branch
    best.a1 = better ? a1 : best.a1;
    best.a2 = better ? a2 : best.a2;
    best.background = better ? b : best.background;
    best.cost = better ? cost : best.cost;
  };
  if (background) {
    best.cost = inf;
    const double c11 = g.s22 * g.scc - g.s2c * g.s2c, c12 = g.s1c * g.s2c - g.s12 * g.scc,
                 c13 = g.s12 * g.s2c - g.s22 * g.s1c, c22 = g.s11 * g.scc - g.s1c * g.s1c,
                 c23 = g.s12 * g.s1c - g.s11 * g.s2c, c33 = g.s11 * g.s22 - g.s12 * g.s12;
    const double det = g.s11 * c11 + g.s12 * c12 + g.s1c * c13, inverse = 1 / det;
    const double x1 = (c11 * g.r1 + c12 * g.r2 + c13 * g.rc) * inverse,
                 x2 = (c12 * g.r1 + c22 * g.r2 + c23 * g.rc) * inverse,
                 x3 = (c13 * g.r1 + c23 * g.r2 + c33 * g.rc) * inverse;
    take((det > 1e-9 * g.s11 * g.s22 * g.scc) & (x1 > 0) & (x2 > 0), x1, x2, x3, g.yy - x1 * g.r1 - x2 * g.r2 - x3 * g.rc);
    const double d1 = g.s11 * g.scc - g.s1c * g.s1c, i1 = 1 / d1;
    const double a1 = (g.r1 * g.scc - g.s1c * g.rc) * i1, b1 = (g.s11 * g.rc - g.s1c * g.r1) * i1;
    take((d1 > 1e-12 * g.s11 * g.scc) & (a1 > 0), a1, 0, b1, g.yy - a1 * g.r1 - b1 * g.rc);
    const double d2 = g.s22 * g.scc - g.s2c * g.s2c, i2 = 1 / d2;
    const double a2 = (g.r2 * g.scc - g.s2c * g.rc) * i2, b2 = (g.s22 * g.rc - g.s2c * g.r2) * i2;
    take((d2 > 1e-12 * g.s22 * g.scc) & (a2 > 0), 0, a2, b2, g.yy - a2 * g.r2 - b2 * g.rc);
    const double b0 = g.rc / std::max(g.scc, 1e-300);  // scc > 0: every weight is
    take(true, 0, 0, b0, g.yy - b0 * g.rc);
  } else {
    const double det = g.s11 * g.s22 - g.s12 * g.s12, inverse = 1 / det;
    const double x1 = (g.r1 * g.s22 - g.s12 * g.r2) * inverse, x2 = (g.s11 * g.r2 - g.s12 * g.r1) * inverse;
    take((det > 1e-9 * g.s11 * g.s22) & (x1 > 0) & (x2 > 0), x1, x2, 0, g.yy - x1 * g.r1 - x2 * g.r2);
    const double a1 = g.r1 / g.s11, a2 = g.r2 / g.s22;
    take((g.s11 > 0) & (a1 > 0), a1, 0, 0, g.yy - a1 * g.r1);
    take((g.s22 > 0) & (a2 > 0), 0, a2, 0, g.yy - a2 * g.r2);
  }
  return best;
}

// ProjectPair's cost for n pixel-channels at one pair of rates (a loop the
// compiler vectorises, as ProjectedCosts).
template <bool kBackground>
void PairCostsOf(int n, const double* s11, const double* s12, const double* s22, const double* s1c,
                 const double* s2c, const double* scc, const double* r1, const double* r2, const double* rc,
                 const double* yy, double* __restrict__ cost) {
  for (int j = 0; j < n; ++j)
    cost[j] = ProjectPair({s11[j], s12[j], s22[j], s1c[j], s2c[j], scc[j], r1[j], r2[j], rc[j], yy[j]}, kBackground).cost;
}
void PairCosts(int n, const double* s11, const double* s12, const double* s22, const double* s1c, const double* s2c,
               const double* scc, const double* r1, const double* r2, const double* rc, const double* yy,
               bool background, double* __restrict__ cost) {
  if (background)
    PairCostsOf<true>(n, s11, s12, s22, s1c, s2c, scc, r1, r2, rc, yy, cost);
  else
    PairCostsOf<false>(n, s11, s12, s22, s1c, s2c, scc, r1, r2, rc, yy, cost);
}

// The pairs (i < j) of a coarse rate grid over the rate grid's range, and
// their basis as one m x (2 P + P (P - 1) / 2) matrix: every rate's samples,
// their squares, then the products of every pair, so that one product with
// a block's weights gives every Gram entry that depends on the rates.
struct PairGrid {
  int P = 0;
  std::vector<double> log_k;
  std::vector<std::pair<int, int>> pairs;
  Matrix basis;
};

PairGrid MakePairGrid(const DecayMapInput& in, const RateGrid& grid, const DecayMapOptions& options) {
  const int m = static_cast<int>(in.frames.size());
  PairGrid pg;
  pg.P = std::max(4, options.pair_grid_size);
  pg.basis.resize(m, 2 * pg.P + pg.P * (pg.P - 1) / 2);
  std::vector<double> b(m);
  for (int i = 0; i < pg.P; ++i) {
    pg.log_k.push_back(grid.log_k.front() + (grid.log_k.back() - grid.log_k.front()) * i / (pg.P - 1));
    Basis(std::exp(pg.log_k[i]), in.t_s, in.exposure_s, b.data());
    for (int j = 0; j < m; ++j) {
      pg.basis(j, i) = b[j];
      pg.basis(j, pg.P + i) = b[j] * b[j];
    }
  }
  int column = 2 * pg.P;
  for (int i = 0; i < pg.P; ++i)
    for (int k = i + 1; k < pg.P; ++k, ++column) {
      pg.pairs.emplace_back(i, k);
      pg.basis.col(column) = pg.basis.col(i).cwiseProduct(pg.basis.col(k));
    }
  return pg;
}

// A pixel's two-state fit at (u1, u2) = (log k1, log k2): the projected cost,
// its gradient (exact: the envelope theorem, the amplitudes being optimal)
// and its Gauss-Newton Hessian with Kaufman's projection, per channel
//   H += 2 (J'WJ - J'W Phi M^-1 Phi'WJ),   J = [A1 b1_u, A2 b2_u],
// Phi the basis columns on the channel's support and M their Gram.
struct PairFit {
  double u1 = 0, u2 = 0, cost = std::numeric_limits<double>::infinity();
  double g[2] = {}, H[2][2] = {};
  double a1[8] = {}, a2[8] = {}, background[8] = {};
};

void EvaluateBasisAndSlope(double u, const FrameTimes& f, Array& P, Array& Q, double* b, double* b_u) {
  const double k = std::exp(u);
  const int m = static_cast<int>(f.s.size());
  P = (-k * f.s).exp();
  Q = (-k * f.s_plus_e).exp();
  for (int j = 0; j < m; ++j) {
    b[j] = (P[j] - Q[j]) / (k * f.e[j]);
    b_u[j] = -k * f.s[j] * b[j] + Q[j] - b[j];
  }
}

// The columns of `products` (m x 14): b1, b2, b1_u, b2_u, then the products
// whose weighted sums the Gram, the gradient and the Hessian need; one
// product with a pixel's weights (C x m) gives every channel's sums at once.
enum PairColumn { kB1, kB2, kD1, kD2, kB1B1, kB1B2, kB2B2, kB1D1, kB2D1, kB1D2, kB2D2, kD1D1, kD2D2, kD1D2, kPairColumns };

PairFit EvaluatePair(double u1, double u2, const PixelData& px, const FrameTimes& f, bool background,
                     BlockWork& work) {
  const int m = px.m;
  Matrix& V = work.pair_products;
  V.resize(m, kPairColumns);
  EvaluateBasisAndSlope(u1, f, work.b1, work.d1, &V(0, kB1), &V(0, kD1));
  EvaluateBasisAndSlope(u2, f, work.b2, work.d2, &V(0, kB2), &V(0, kD2));
  const auto b1 = V.col(kB1).array(), b2 = V.col(kB2).array(), d1 = V.col(kD1).array(), d2 = V.col(kD2).array();
  V.col(kB1B1).array() = b1 * b1;
  V.col(kB1B2).array() = b1 * b2;
  V.col(kB2B2).array() = b2 * b2;
  V.col(kB1D1).array() = b1 * d1;
  V.col(kB2D1).array() = b2 * d1;
  V.col(kB1D2).array() = b1 * d2;
  V.col(kB2D2).array() = b2 * d2;
  V.col(kD1D1).array() = d1 * d1;
  V.col(kD2D2).array() = d2 * d2;
  V.col(kD1D2).array() = d1 * d2;
  Matrix& S = work.pair_weighted;  // C x 14: sum w v
  Matrix& R = work.pair_values;    // C x 4: sum w y v
  S.noalias() = px.w.transpose().lazyProduct(V);
  R.noalias() = px.wy.transpose().lazyProduct(V.leftCols(4));
  PairFit fit;
  fit.u1 = u1;
  fit.u2 = u2;
  fit.cost = 0;
  for (int c = 0; c < px.channels; ++c) {
    const PairGram gram{S(c, kB1B1), S(c, kB1B2), S(c, kB2B2), S(c, kB1), S(c, kB2),
                        px.S11[c],   R(c, kB1),   R(c, kB2),   px.S1y[c], px.Syy[c]};
    const PairChannelFit cf = ProjectPair(gram, background);
    fit.a1[c] = cf.a1;
    fit.a2[c] = cf.a2;
    fit.background[c] = cf.background;
    fit.cost += cf.cost;
    if (!(cf.a1 > 0) && !(cf.a2 > 0)) continue;
    const double wd1 = S(c, kD1), wd2 = S(c, kD2);
    const double b1d1 = S(c, kB1D1), b2d1 = S(c, kB2D1), b1d2 = S(c, kB1D2), b2d2 = S(c, kB2D2);
    const double B = cf.background;
    // sum w r b_i_u, r the residual
    const double rd1 = R(c, kD1) - cf.a1 * b1d1 - cf.a2 * b2d1 - B * wd1;
    const double rd2 = R(c, kD2) - cf.a1 * b1d2 - cf.a2 * b2d2 - B * wd2;
    fit.g[0] += -2 * cf.a1 * rd1;
    fit.g[1] += -2 * cf.a2 * rd2;
    const bool on[3] = {cf.a1 > 0, cf.a2 > 0, background};
    Eigen::Matrix3d M;
    M << gram.s11, gram.s12, gram.s1c, gram.s12, gram.s22, gram.s2c, gram.s1c, gram.s2c, gram.scc;
    Eigen::Matrix<double, 3, 2> PhiJ;
    PhiJ << cf.a1 * b1d1, cf.a2 * b1d2, cf.a1 * b2d1, cf.a2 * b2d2, cf.a1 * wd1, cf.a2 * wd2;
    for (int i = 0; i < 3; ++i)
      if (!on[i]) {
        M.row(i).setZero();
        M.col(i).setZero();
        M(i, i) = 1;
        PhiJ.row(i).setZero();
      }
    const Eigen::Matrix2d projected = PhiJ.transpose() * M.inverse() * PhiJ;
    fit.H[0][0] += 2 * (cf.a1 * cf.a1 * S(c, kD1D1) - projected(0, 0));
    fit.H[0][1] += 2 * (cf.a1 * cf.a2 * S(c, kD1D2) - projected(0, 1));
    fit.H[1][1] += 2 * (cf.a2 * cf.a2 * S(c, kD2D2) - projected(1, 1));
  }
  fit.H[1][0] = fit.H[0][1];
  return fit;
}

// Levenberg-Marquardt on (u1, u2) from the best pair of the coarse grid:
// a step is kept only if it lowers the cost; they stop once a step is below
// 1e-4 in log k. Rates stay inside the rate grid's range.
PairFit RefinePair(const PixelData& px, const FrameTimes& f, const RateGrid& grid, const PairGrid& pg,
                   const double* pair_cost, const DecayMapOptions& options, BlockWork& work) {
  int best = 0;
  const int pairs = static_cast<int>(pg.pairs.size());
  for (int q = 1; q < pairs; ++q)
    if (pair_cost[q] < pair_cost[best]) best = q;
  PairFit fit = EvaluatePair(pg.log_k[pg.pairs[best].first], pg.log_k[pg.pairs[best].second], px, f,
                             options.background, work);
  const double lo = grid.log_k.front(), hi = grid.log_k.back();
  double lambda = 1e-3;
  for (int step = 0; step < options.pair_steps; ++step) {
    const double floor = 1e-12 * (std::fabs(fit.H[0][0]) + std::fabs(fit.H[1][1])) + 1e-300;
    const double h00 = fit.H[0][0] + lambda * std::max(fit.H[0][0], floor),
                 h11 = fit.H[1][1] + lambda * std::max(fit.H[1][1], floor), h01 = fit.H[0][1];
    const double det = h00 * h11 - h01 * h01;
    if (!(det > 0)) {
      lambda *= 10;
      if (lambda > 1e10) break;
      continue;
    }
    const double du1 = -(h11 * fit.g[0] - h01 * fit.g[1]) / det, du2 = -(h00 * fit.g[1] - h01 * fit.g[0]) / det;
    const double u1 = std::clamp(fit.u1 + du1, lo, hi), u2 = std::clamp(fit.u2 + du2, lo, hi);
    if (u1 == fit.u1 && u2 == fit.u2) break;
    const PairFit trial = EvaluatePair(u1, u2, px, f, options.background, work);
    if (trial.cost < fit.cost) {
      const bool converged = std::max(std::fabs(u1 - fit.u1), std::fabs(u2 - fit.u2)) < 1e-4;
      fit = trial;
      lambda = std::max(lambda / 4, 1e-9);
      if (converged) break;
    } else {
      lambda *= 8;
      if (lambda > 1e10) break;
    }
  }
  if (fit.u1 > fit.u2) {  // the slow state first
    std::swap(fit.u1, fit.u2);
    std::swap(fit.a1, fit.a2);
  }
  return fit;
}

// The block's second pass: the pair grid's costs for every pixel-channel
// (from the weights FitBlock left in `work`), then per pixel the refinement
// and BIC's choice between the one-state fit already in `map` and two states.
void FitBlockPairs(const DecayMapInput& in, const DecayMapOptions& options, const RateGrid& grid, const PairGrid& pg,
                   const FrameTimes& times, std::size_t first_pixel, int count, BlockWork& work, DecayMap& map,
                   std::atomic<std::size_t>& one_state) {
  const int C = in.channels, m = static_cast<int>(in.frames.size()), P = pg.P;
  const int n = count * C, pairs = static_cast<int>(pg.pairs.size());
  work.pair_sums.noalias() = work.w * pg.basis;
  work.pair_value_sums.noalias() = work.wy * pg.basis.leftCols(P);
  work.pair_cost.setZero(pairs, count);
  for (int q = 0; q < pairs; ++q) {
    const int i = pg.pairs[q].first, k = pg.pairs[q].second;
    const double *s1 = &work.pair_sums(0, i), *s2 = &work.pair_sums(0, k), *s11 = &work.pair_sums(0, P + i),
                 *s22 = &work.pair_sums(0, P + k), *s12 = &work.pair_sums(0, 2 * P + q),
                 *r1 = &work.pair_value_sums(0, i), *r2 = &work.pair_value_sums(0, k);
    PairCosts(n, s11, s12, s22, s1, s2, work.S11.data(), r1, r2, work.S1y.data(), work.Syy.data(), options.background,
              work.channel_cost.data());
    for (int p = 0; p < count; ++p) work.pair_cost(q, p) = work.channel_cost.segment(p * C, C).sum();
  }

  PixelData& px = work.pixel;
  const double N = static_cast<double>(C) * m;
  for (int p = 0; p < count; ++p) {
    const std::size_t pixel = first_pixel + p;
    if (std::isnan(map.kr[pixel])) continue;  // nothing decays: no state at all
    LoadPixel(work, p, C, px);
    const PairFit fit = RefinePair(px, times, grid, pg, &work.pair_cost(0, p), options, work);
    // Both states must decay by more than rounding over the recorded span (as
    // one state must), and BIC must prefer two: N ln(cost1 / cost2) > (C + 1) ln N.
    const double k1 = std::exp(fit.u1), k2 = std::exp(fit.u2);
    const double t0 = in.t_s.front(), t1 = in.t_s.back();
    const double span1 = std::exp(-k1 * t0) - std::exp(-k1 * t1), span2 = std::exp(-k2 * t0) - std::exp(-k2 * t1);
    bool slow = false, fast = false;
    for (int c = 0; c < C; ++c) {
      slow = slow || fit.a1[c] * span1 > 1e-6 * px.peak[c];
      fast = fast || fit.a2[c] * span2 > 1e-6 * px.peak[c];
    }
    const double cost1 = work.one_state_cost(p);
    const bool two = slow && fast && fit.u2 > fit.u1 && fit.cost < cost1 &&
                     N * std::log(cost1 / std::max(fit.cost, 1e-300)) > (C + 1) * std::log(N);
    if (!two) {
      ++one_state;
      continue;
    }
    map.kr[pixel] = static_cast<float>(k1);
    map.kr2[pixel] = static_cast<float>(k2);
    for (int c = 0; c < C; ++c) {
      map.amplitude[pixel * C + c] = static_cast<float>(fit.a1[c]);
      map.amplitude2[pixel * C + c] = static_cast<float>(fit.a2[c]);
      map.background[pixel * C + c] = static_cast<float>(fit.background[c]);
    }
    map.rms[pixel] = static_cast<float>(std::sqrt(std::max(0.0, fit.cost) / (C * m)));
  }
}

// ---------------------------------------------------------------------------
// The reference: the first algorithm, pixel by pixel, kept as it was (every
// grid rate's sums from the samples, then Newton with central differences
// of the cost), for the tests and the bench to compare the fast map with.

struct PixelSolution {
  double cost = std::numeric_limits<double>::infinity();
  double amplitude[8] = {}, background[8] = {};
};

// For one rate's basis: per channel, weighted least squares for (A, B) with
// A >= 0; returns the summed weighted cost.
PixelSolution Project(const double* basis, const float* const* y, const double* const* w2, int channels, int m,
                      bool background) {
  PixelSolution s;
  s.cost = 0;
  for (int c = 0; c < channels; ++c) {
    double Sbb = 0, Sb1 = 0, S11 = 0, Sby = 0, S1y = 0, Syy = 0;
    for (int j = 0; j < m; ++j) {
      const double w = w2[c][j], b = basis[j], v = y[c][j];
      Sbb += w * b * b;
      Sb1 += w * b;
      S11 += w;
      Sby += w * b * v;
      S1y += w * v;
      Syy += w * v * v;
    }
    double A = 0, B = 0;
    if (background) {
      const double det = Sbb * S11 - Sb1 * Sb1;
      if (det > 1e-300 * Sbb * S11) {
        A = (Sby * S11 - Sb1 * S1y) / det;
        B = (Sbb * S1y - Sb1 * Sby) / det;
      }
      if (!(A > 0)) {  // the bound is active: a constant alone
        A = 0;
        B = S11 > 0 ? S1y / S11 : 0;
      }
    } else {
      A = Sbb > 0 ? std::max(0.0, Sby / Sbb) : 0;
    }
    s.cost += Syy - 2 * A * Sby - 2 * B * S1y + A * A * Sbb + 2 * A * B * Sb1 + B * B * S11;
    s.amplitude[c] = A;
    s.background[c] = B;
  }
  return s;
}

void FitRowsReference(const DecayMapInput& in, const DecayMapOptions& options, const RateGrid& grid, int row_begin,
                      int row_end, DecayMap& map, std::atomic<std::size_t>& no_decay) {
  const int m = static_cast<int>(in.frames.size()), G = grid.G;
  const std::vector<double>& log_k = grid.log_k;
  std::vector<float> y_store(static_cast<std::size_t>(in.channels) * m);
  std::vector<double> w2_store(static_cast<std::size_t>(in.channels) * m), b(m);
  std::vector<const float*> y(in.channels);
  std::vector<const double*> w2(in.channels);
  for (int c = 0; c < in.channels; ++c) {
    y[c] = &y_store[static_cast<std::size_t>(c) * m];
    w2[c] = &w2_store[static_cast<std::size_t>(c) * m];
  }
  for (int row = row_begin; row != row_end; ++row) {
    for (int x = 0; x < in.width; ++x) {
      const std::size_t p = static_cast<std::size_t>(row) * in.width + x;
      for (int c = 0; c < in.channels; ++c) {
        float* yc = &y_store[static_cast<std::size_t>(c) * m];
        double* wc = &w2_store[static_cast<std::size_t>(c) * m];
        float peak = 0;
        for (int j = 0; j < m; ++j) {
          yc[j] = in.frames[j][p * in.channels + c];
          peak = std::max(peak, std::fabs(yc[j]));
        }
        for (int j = 0; j < m; ++j) wc[j] = SampleWeight(yc[j], in.exposure_s[j], WeightFloor(peak), options.weighting);
      }
      int best = 0;
      PixelSolution best_solution;
      for (int g = 0; g < G; ++g) {
        PixelSolution s = Project(&grid.basis[static_cast<std::size_t>(g) * m], y.data(), w2.data(), in.channels, m,
                                  options.background);
        if (s.cost < best_solution.cost) best_solution = s, best = g;
      }
      double u = log_k[best];
      const double h0 = (log_k[1] - log_k[0]) / 4;
      auto cost_at = [&](double log_rate) {
        Basis(std::exp(log_rate), in.t_s, in.exposure_s, b.data());
        return Project(b.data(), y.data(), w2.data(), in.channels, m, options.background);
      };
      for (int step = 0; step < options.newton_steps; ++step) {
        const double h = h0 / (1 << step);
        const double c0 = cost_at(u).cost, cm = cost_at(u - h).cost, cp = cost_at(u + h).cost;
        const double d1 = (cp - cm) / (2 * h), d2 = (cp - 2 * c0 + cm) / (h * h);
        if (!(d2 > 0)) break;
        const double next = std::clamp(u - d1 / d2, log_k.front(), log_k.back());
        const PixelSolution s = cost_at(next);
        if (!(s.cost < best_solution.cost)) break;
        best_solution = s;
        u = next;
      }
      bool decays = false;
      Basis(std::exp(u), in.t_s, in.exposure_s, b.data());
      for (int c = 0; c < in.channels; ++c) {
        map.amplitude[p * in.channels + c] = static_cast<float>(best_solution.amplitude[c]);
        map.background[p * in.channels + c] = static_cast<float>(best_solution.background[c]);
        float peak = 0;
        for (int j = 0; j < m; ++j) peak = std::max(peak, std::fabs(y[c][j]));
        decays = decays || best_solution.amplitude[c] * (b[0] - b[m - 1]) > 1e-6 * peak;
      }
      if (decays)
        map.kr[p] = static_cast<float>(std::exp(u));
      else
        ++no_decay;
      map.rms[p] = static_cast<float>(std::sqrt(std::max(0.0, best_solution.cost) / (in.channels * m)));
    }
  }
}

}  // namespace

DecayMap FitDecayMap(const DecayMapInput& in, const DecayMapOptions& options, const std::string& where,
                     const std::function<void(std::size_t)>& progress) {
  const auto started = std::chrono::steady_clock::now();
  Validate(in, where);
  if (options.states != 1 && options.states != 2)
    ThrowUserError(where, "states", "must be 1 or 2, got " + std::to_string(options.states));
  // Two states have 2 + 3 C parameters: the rates need more than 4 frames.
  if (options.states == 2 && in.frames.size() < 6)
    ThrowUserError(where, "", "needs at least 6 frames for a two-state map, has " + std::to_string(in.frames.size()));
  const RateGrid grid = MakeRateGrid(in, options);
  const int m = static_cast<int>(in.frames.size());
  // The basis as an m x 2G matrix: every grid rate's samples, then their
  // squares, so that one product gives Sb1 and Sbb for a block.
  Matrix grid_basis(m, 2 * grid.G);
  grid_basis.leftCols(grid.G) = Eigen::Map<const Matrix>(grid.basis.data(), m, grid.G);
  grid_basis.rightCols(grid.G) = grid_basis.leftCols(grid.G).array().square().matrix();
  const FrameTimes times = MakeFrameTimes(in);

  const bool two_states = options.states == 2;
  const PairGrid pair_grid = two_states ? MakePairGrid(in, grid, options) : PairGrid{};

  DecayMap map = EmptyMap(in);
  if (two_states) {
    map.kr2.assign(map.kr.size(), std::nanf(""));
    map.amplitude2.assign(map.amplitude.size(), 0.0f);
  }
  std::atomic<std::size_t> no_decay{0}, one_state{0}, rows_done{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, in.height), [&](const tbb::blocked_range<int>& rows) {
    BlockWork work;
    for (int row = rows.begin(); row != rows.end(); ++row) {
      for (int x = 0; x < in.width; x += kBlockPixels) {
        const int count = std::min(kBlockPixels, in.width - x);
        const std::size_t first = static_cast<std::size_t>(row) * in.width + x;
        FitBlock(in, options, grid, grid_basis, times, first, count, work, map, no_decay);
        if (two_states) FitBlockPairs(in, options, grid, pair_grid, times, first, count, work, map, one_state);
      }
      if (progress) progress(++rows_done);
    }
  });
  map.no_decay = no_decay;
  map.one_state = one_state;
  map.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return map;
}

DecayMap FitDecayMapReference(const DecayMapInput& in, const DecayMapOptions& options, const std::string& where) {
  const auto started = std::chrono::steady_clock::now();
  Validate(in, where);
  const RateGrid grid = MakeRateGrid(in, options);
  DecayMap map = EmptyMap(in);
  std::atomic<std::size_t> no_decay{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, in.height), [&](const tbb::blocked_range<int>& rows) {
    FitRowsReference(in, options, grid, rows.begin(), rows.end(), map, no_decay);
  });
  map.no_decay = no_decay;
  map.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return map;
}

}  // namespace phos
