#include "phos/fit/decay_map.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Core>
#include <Eigen/LU>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <utility>

#include "phos/model/closed_form.h"
#include "phos/util/error.h"

namespace phos {
namespace {

// The exposure-averaged basis at the exposure's middle t: the glow's mean
// over the exposure e, DecayFactor(k, t - e/2, e) (model/closed_form.h),
// which is exp(-k t) sinh(k e / 2) / (k e / 2).
void Basis(double k, const std::vector<double>& t, const std::vector<double>& e, double* out) {
  for (std::size_t j = 0; j < t.size(); ++j) out[j] = DecayFactor(k, t[j] - e[j] / 2, e[j]);
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
// infinite weight. Relative only: the values may be radiances of 1e-12 and
// below, and a floor in absolute units gave their samples equal weights. A
// channel that is 0 throughout gets equal weights (any floor does).
double SampleWeight(double y, double exposure, double floor, Weighting weighting) {
  return weighting == Weighting::kPoisson ? exposure / std::max(std::fabs(y), floor) : 1.0;
}
double WeightFloor(double peak) { return peak > 0 ? 1e-3 * peak : 1.0; }

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

// ProjectChannel's cost for n pixel-channels at one rate, four at a time in
// GCC's vector extensions (GCC leaves the plain loop scalar: under
// -ftrapping-math it does not turn the comparisons into selects, and
// Eigen 3.4's select is not vectorised either), the rest one by one.
typedef double Double4 __attribute__((vector_size(32)));

inline Double4 Load4(const double* p) {
  Double4 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

void ProjectedCosts(int n, const double* Sbb, const double* Sb1, const double* Sby, const double* S11,
                    const double* S1y, const double* Syy, const double* constant, bool background,
                    double* __restrict__ cost) {
  const Double4 zero = {0, 0, 0, 0};
  int i = 0;
  for (; i + 4 <= n; i += 4) {
    const Double4 sbb = Load4(Sbb + i), sb1 = Load4(Sb1 + i), sby = Load4(Sby + i), s11 = Load4(S11 + i),
                  s1y = Load4(S1y + i), syy = Load4(Syy + i);
    Double4 A, B;
    if (background) {
      const Double4 det = sbb * s11 - sb1 * sb1, reciprocal = 1 / det;
      const Double4 inverse = det > 1e-300 * sbb * s11 ? reciprocal : zero;
      const Double4 a = (sby * s11 - sb1 * s1y) * inverse, b = (sbb * s1y - sb1 * sby) * inverse;
      const auto decays = a > zero;
      A = decays ? a : zero;
      B = decays ? b : Load4(constant + i);
    } else {
      const Double4 a = sby / sbb;
      A = (sbb > zero) & (a > zero) ? a : zero;
      B = zero;
    }
    const Double4 c = syy - 2 * A * sby - 2 * B * s1y + A * A * sbb + 2 * A * B * sb1 + B * B * s11;
    std::memcpy(cost + i, &c, sizeof c);
  }
  for (; i < n; ++i)
    cost[i] = ProjectChannel(Sbb[i], Sb1[i], Sby[i], S11[i], S1y[i], Syy[i], constant[i], background).cost;
}

// Per pixel, the sum over channels of per pixel-channel costs in a block's
// order (channel c of pixel p at c * count + p), into pixel_cost.
void SumChannels(int count, int C, const double* channel_cost, double* __restrict__ pixel_cost) {
  for (int p = 0; p < count; ++p) pixel_cost[p] = channel_cost[p];
  for (int c = 1; c < C; ++c)
    for (int p = 0; p < count; ++p) pixel_cost[p] += channel_cost[c * count + p];
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
// then per pixel a cubic (or parabola) through the best grid rate and its
// neighbours and exact Newton steps on u = log k of the variable-projection
// cost.

constexpr int kBlockPixels = 128;

using Matrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic>;  // column-major
using Array = Eigen::ArrayXd;

// Frame times split into what the basis derivatives need: start s and
// exposure e of every frame, as arrays.
struct FrameTimes {
  Array s, e, s_plus_e, s2, two_s_plus_e;
  // The distinct exposures, their reciprocals, and each frame's among them.
  Array exposures, inverse_exposures;
  std::vector<int> exposure_of;
};

FrameTimes MakeFrameTimes(const DecayMapInput& in) {
  const int m = static_cast<int>(in.frames.size());
  FrameTimes f;
  f.e = Eigen::Map<const Array>(in.exposure_s.data(), m);
  f.s = Eigen::Map<const Array>(in.t_s.data(), m) - f.e / 2;
  f.s_plus_e = f.s + f.e;
  f.s2 = f.s * f.s;
  f.two_s_plus_e = 2 * f.s + f.e;
  std::vector<double> exposures;
  for (int j = 0; j < m; ++j) {
    const auto same = std::find(exposures.begin(), exposures.end(), in.exposure_s[j]);
    f.exposure_of.push_back(static_cast<int>(same - exposures.begin()));
    if (same == exposures.end()) exposures.push_back(in.exposure_s[j]);
  }
  f.exposures = Eigen::Map<const Array>(exposures.data(), static_cast<Eigen::Index>(exposures.size()));
  f.inverse_exposures = f.exposures.inverse();
  return f;
}

// exp of four values to 1 ulp (std::exp's to 0.5), in FMAs: x = n ln 2 + r
// with |r| <= ln 2 / 2, e^r by its Taylor series to r^13 (the remainder is
// below 1e-17 relatively), times 2^n put into the exponent bits. Below
// e^-708 it gives 0 (std::exp: subnormals down to e^-745), above e^709 it
// stops at e^709 (std::exp: inf). Eigen's exp of doubles, which divides,
// took about 1.5 times as long (the exponentials of a Newton step: 210 ns
// against 140 ns on the 2.3 GHz host), and they are most of a step's time.
typedef std::uint64_t Bits4 __attribute__((vector_size(32)));  // unsigned: the shift below wraps, no UB

inline Double4 Exp4(Double4 x) {
  const Double4 lo = Double4{} - 708.0, hi = Double4{} + 709.0, shift = Double4{} + 0x1.8p52;
  const Double4 clamped = x < lo ? lo : (x > hi ? hi : x);
  const Double4 shifted = clamped * 1.4426950408889634 + shift;  // n in the low bits of the mantissa
  const Double4 n = shifted - shift;
  const Double4 r = (clamped - n * 0.693147180559945286226764) - n * 2.319046813846299558e-17;
  Double4 p = r * (1.0 / 6227020800.0) + 1.0 / 479001600.0;
  p = p * r + 1.0 / 39916800.0;
  p = p * r + 1.0 / 3628800.0;
  p = p * r + 1.0 / 362880.0;
  p = p * r + 1.0 / 40320.0;
  p = p * r + 1.0 / 5040.0;
  p = p * r + 1.0 / 720.0;
  p = p * r + 1.0 / 120.0;
  p = p * r + 1.0 / 24.0;
  p = p * r + 1.0 / 6.0;
  p = p * r + 0.5;
  p = p * r + 1.0;
  p = p * r + 1.0;
  Bits4 bits;
  std::memcpy(&bits, &shifted, sizeof bits);
  bits = (bits + 1023) << 52;  // 2^n: n + 1023 is in [1, 2046]
  Double4 scale;
  std::memcpy(&scale, &bits, sizeof scale);
  return x < lo ? Double4{} : p * scale;
}

// The basis b = (exp(-k s) - exp(-k (s + e))) / (k e) (the same exposure
// average as Basis) and its first two derivatives in u = log k:
//   b_u  = -k s b + Q - b,
//   b_uu = k^2 s^2 b - k (2 s + e) Q - b_u,   with Q = exp(-k (s + e)).
// As P = exp(-k s) times E = exp(-k e), b = P (1 - E) / (k e) and Q = P E,
// with E and (1 - E) / (k e) once per distinct exposure (a session has few:
// 7 for 36 frames in the bench): m + (distinct exposures) exponentials, not
// 2 m. 1 - E loses at most 1e-16 / (k e) relatively (as P - Q would), 2e-11
// at the grid's slowest rate. The frames go four at a time (Exp4), the rest
// one by one; b_u and b_uu only if `derivatives`. Every array keeps its size
// from call to call, so that an evaluation allocates nothing.
struct BasisWithDerivatives {
  Array b, b_u, b_uu;
  Array E, D;  // per distinct exposure: exp(-k e), (1 - E) / (k e)
};

void EvaluateBasis(double u, const FrameTimes& f, bool derivatives, BasisWithDerivatives& out) {
  const double k = std::exp(u), inverse_k = 1 / k;
  const int m = static_cast<int>(f.s.size()), exposures = static_cast<int>(f.exposures.size());
  out.b.resize(m);
  out.b_u.resize(m);
  out.b_uu.resize(m);
  out.E.resize(exposures);
  out.D.resize(exposures);
  int d = 0;
  for (; d + 4 <= exposures; d += 4) {
    const Double4 E = Exp4(-k * Load4(&f.exposures[d])), D = (1 - E) * (inverse_k * Load4(&f.inverse_exposures[d]));
    std::memcpy(&out.E[d], &E, sizeof E);
    std::memcpy(&out.D[d], &D, sizeof D);
  }
  for (; d < exposures; ++d) {
    out.E[d] = std::exp(-k * f.exposures[d]);
    out.D[d] = (1 - out.E[d]) * (inverse_k * f.inverse_exposures[d]);
  }
  const int* of = f.exposure_of.data();
  int j = 0;
  for (; j + 4 <= m; j += 4) {
    const Double4 s = Load4(&f.s[j]), P = Exp4(-k * s);
    const Double4 b = P * Double4{out.D[of[j]], out.D[of[j + 1]], out.D[of[j + 2]], out.D[of[j + 3]]};
    std::memcpy(&out.b[j], &b, sizeof b);
    if (!derivatives) continue;
    const Double4 Q = P * Double4{out.E[of[j]], out.E[of[j + 1]], out.E[of[j + 2]], out.E[of[j + 3]]};
    const Double4 b_u = -k * s * b + Q - b;
    const Double4 b_uu = k * k * Load4(&f.s2[j]) * b - k * Load4(&f.two_s_plus_e[j]) * Q - b_u;
    std::memcpy(&out.b_u[j], &b_u, sizeof b_u);
    std::memcpy(&out.b_uu[j], &b_uu, sizeof b_uu);
  }
  for (; j < m; ++j) {
    const double P = std::exp(-k * f.s[j]), Q = P * out.E[of[j]];
    out.b[j] = P * out.D[of[j]];
    out.b_u[j] = -k * f.s[j] * out.b[j] + Q - out.b[j];
    out.b_uu[j] = k * k * f.s2[j] * out.b[j] - k * f.two_s_plus_e[j] * Q - out.b_u[j];
  }
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
// The nine weighted sums of one channel that EvaluateRate needs, in one pass
// over the frames (four at a time, the rest one by one): sum w b^2, w b,
// w y b, then the same of the first and second derivatives (w b b_u, w b_u,
// w y b_u; w (b_u^2 + b b_uu), w b_uu, w y b_uu), those only if kDerivatives.
struct ChannelSums {
  double bb = 0, b1 = 0, by = 0, d_bb = 0, d_b1 = 0, d_by = 0, dd_bb = 0, dd_b1 = 0, dd_by = 0;
};

inline double Sum4(Double4 v) { return (v[0] + v[1]) + (v[2] + v[3]); }

template <bool kDerivatives>
ChannelSums SumChannel(int m, const double* w, const double* wy, const BasisWithDerivatives& basis) {
  const double *b = basis.b.data(), *b_u = basis.b_u.data(), *b_uu = basis.b_uu.data();
  Double4 bb{}, b1{}, by{}, d_bb{}, d_b1{}, d_by{}, dd_bb{}, dd_b1{}, dd_by{};
  int j = 0;
  for (; j + 4 <= m; j += 4) {
    const Double4 pw = Load4(w + j), pwy = Load4(wy + j), pb = Load4(b + j), wb = pw * pb;
    bb += wb * pb;
    b1 += wb;
    by += pwy * pb;
    if (!kDerivatives) continue;
    const Double4 pb_u = Load4(b_u + j), pb_uu = Load4(b_uu + j);
    d_bb += wb * pb_u;
    d_b1 += pw * pb_u;
    d_by += pwy * pb_u;
    dd_bb += pw * pb_u * pb_u + wb * pb_uu;
    dd_b1 += pw * pb_uu;
    dd_by += pwy * pb_uu;
  }
  ChannelSums s{Sum4(bb), Sum4(b1), Sum4(by), Sum4(d_bb), Sum4(d_b1), Sum4(d_by), Sum4(dd_bb), Sum4(dd_b1), Sum4(dd_by)};
  for (; j < m; ++j) {
    const double wb = w[j] * b[j];
    s.bb += wb * b[j];
    s.b1 += wb;
    s.by += wy[j] * b[j];
    if (!kDerivatives) continue;
    s.d_bb += wb * b_u[j];
    s.d_b1 += w[j] * b_u[j];
    s.d_by += wy[j] * b_u[j];
    s.dd_bb += w[j] * b_u[j] * b_u[j] + wb * b_uu[j];
    s.dd_b1 += w[j] * b_uu[j];
    s.dd_by += wy[j] * b_uu[j];
  }
  return s;
}

// Without `derivatives`, the cost and its amplitudes alone (d1 = d2 = 0).
RateFit EvaluateRate(double u, const PixelData& px, const FrameTimes& f, bool background, bool derivatives,
                     BasisWithDerivatives& basis) {
  EvaluateBasis(u, f, derivatives, basis);
  RateFit fit;
  fit.u = u;
  fit.cost = 0;
  fit.decay_span = basis.b(0) - basis.b(px.m - 1);
  for (int c = 0; c < px.channels; ++c) {
    const ChannelSums sums = derivatives ? SumChannel<true>(px.m, &px.w(0, c), &px.wy(0, c), basis)
                                         : SumChannel<false>(px.m, &px.w(0, c), &px.wy(0, c), basis);
    const double Sbb = sums.bb, Sb1 = sums.b1, Sby = sums.by;
    const ChannelFit cf =
        ProjectChannel(Sbb, Sb1, Sby, px.S11[c], px.S1y[c], px.Syy[c], px.constant[c], background);
    fit.amplitude[c] = cf.amplitude;
    fit.background[c] = cf.background;
    fit.cost += cf.cost;
    if (!derivatives || !(cf.amplitude > 0)) continue;
    const double A = cf.amplitude, B = cf.background;
    const double dSbb = 2 * sums.d_bb, dSb1 = sums.d_b1, dSby = sums.d_by;
    const double ddSbb = 2 * sums.dd_bb, ddSb1 = sums.dd_b1, ddSby = sums.dd_by;
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

// Newton on u from the best grid rate. The start is the minimum of the
// cubic through that rate's cost, its neighbours' and the next one's on the
// side of the minimum, or, where there is no such point or no such minimum
// within a grid step, the vertex of the parabola through the three (at most
// half a grid step away). From the parabola's vertex most pixels took three
// steps, from the cubic's two (1 MP bench: 4.1 evaluations per pixel before,
// 3.0 after). Exact steps converge quadratically, so they stop once a step
// is below 1e-4 in log k (what remains is of order 1e-8) or when a step
// does not lower the cost.
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
    if (curvature > 0) {
      double x = (lo - hi) / (2 * curvature);  // the parabola's vertex, in grid steps from best
      // Where the grid has a fourth point on the vertex's side, the minimum of
      // the cubic through the four: closer (h^4 rather than h^3), which saves
      // a Newton step on most pixels. Kept only if it is a minimum within a step.
      const int side = x >= 0 ? 1 : -1, far = best + 2 * side;
      if (far >= 0 && far < grid.G) {
        // In x' = side * x: f(-1) = a, f(0) = mid, f(1) = c, f(2) = d.
        const double a = side > 0 ? lo : hi, c = side > 0 ? hi : lo, d = grid_cost[far];
        const double c2 = (a + c) / 2 - mid, c3 = (d - 3 * c + 3 * mid - a) / 6, c1 = (c - a) / 2 - c3;
        const double discriminant = c2 * c2 - 3 * c1 * c3;
        if (c2 > 0 && discriminant >= 0) {
          const double cubic = -c1 / (c2 + std::sqrt(discriminant));
          if (std::fabs(cubic) <= 1) x = side * cubic;
        }
      }
      u0 += h * x;
    }
  }
  // A fit from which no step follows (the last step's, or one after a step
  // below 1e-4) needs no derivatives.
  const bool steps = options.newton_steps > 0;
  RateFit fit = EvaluateRate(u0, px, f, options.background, steps, basis);
  if (!(fit.cost <= grid_cost[best]) && u0 != grid.log_k[best])
    fit = EvaluateRate(grid.log_k[best], px, f, options.background, steps, basis);
  for (int step = 0; step < options.newton_steps; ++step) {
    if (!(fit.d2 > 0)) break;
    const double next = std::clamp(fit.u - fit.d1 / fit.d2, grid.log_k.front(), grid.log_k.back());
    if (next == fit.u) break;
    const bool converged = std::fabs(next - fit.u) < 1e-4;
    const RateFit trial =
        EvaluateRate(next, px, f, options.background, !converged && step + 1 < options.newton_steps, basis);
    if (!(trial.cost < fit.cost)) break;
    fit = trial;
    if (converged) break;
  }
  return fit;
}

// Per-thread work space for one block of `count` pixels: n = channel *
// count + pixel indexes the block's pixel-channels (channel by channel, so
// that a pixel's cost over its channels is a sum of contiguous runs).
struct BlockWork {
  Matrix w, wy;         // n x m
  Matrix rate_sums;     // n x 2G: Sb1 for every grid rate, then Sbb
  Matrix value_sums;    // n x G: Sby
  Array S11, S1y, Syy, constant, peak;  // per n
  Matrix pixel_cost;    // G x pixels
  Array channel_cost;   // per n
  Array cost_of_pixels;  // per pixel, one grid rate's
  PixelData pixel;
  BasisWithDerivatives basis;
  Array one_state_cost;  // per pixel of the block: the one-state fit's cost (two states compare with it)
  // Two states: sums of the pair grid, the pairs' costs, a pixel's two bases.
  Matrix pair_sums, pair_value_sums, pair_cost;
  Array b1, d1, b2, d2;  // per distinct exposure, E and D (EvaluateBasisAndSlope) of the two rates
  Matrix pair_products;   // m x 4: a pixel's two bases and their slopes
};

// Pixel p of the block's sums (C channels), channel by channel, into px (sized for them and the frames).
void LoadPixel(const BlockWork& work, int p, int C, PixelData& px) {
  const int count = static_cast<int>(work.w.rows()) / C;
  for (int c = 0; c < C; ++c) {
    const int i = c * count + p;
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
    double* values = &work.wy(0, j);  // the values, until the weights are known
    for (int p = 0; p < count; ++p)
      for (int c = 0; c < C; ++c) values[c * count + p] = frame[p * C + c];
    for (int i = 0; i < n; ++i) work.peak(i) = std::max(work.peak(i), std::fabs(values[i]));
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
  work.cost_of_pixels.resize(count);
  work.one_state_cost.resize(count);
  for (int g = 0; g < G; ++g) {
    ProjectedCosts(n, &work.rate_sums(0, G + g), &work.rate_sums(0, g), &work.value_sums(0, g), work.S11.data(),
                   work.S1y.data(), work.Syy.data(), work.constant.data(), options.background,
                   work.channel_cost.data());
    SumChannels(count, C, work.channel_cost.data(), work.cost_of_pixels.data());
    work.pixel_cost.row(g) = work.cost_of_pixels.matrix().transpose();
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

// ProjectPair's cost of four pixel-channels, the same arithmetic in GCC's
// vector extensions (GCC leaves the scalar loop over ProjectPair scalar,
// as it did ProjectedCosts's: see there).
template <bool kBackground>
inline Double4 PairCost4(Double4 s11, Double4 s12, Double4 s22, Double4 s1c, Double4 s2c, Double4 scc, Double4 r1,
                         Double4 r2, Double4 rc, Double4 yy) {
  using Mask4 = decltype(s11 < s11);
  const Double4 zero{};
  Double4 best;
  auto take = [&best](Mask4 ok, Double4 cost) { best = ok & (cost < best) ? cost : best; };
  if (kBackground) {
    best = zero + std::numeric_limits<double>::infinity();
    const Double4 c11 = s22 * scc - s2c * s2c, c12 = s1c * s2c - s12 * scc, c13 = s12 * s2c - s22 * s1c,
                  c22 = s11 * scc - s1c * s1c, c23 = s12 * s1c - s11 * s2c, c33 = s11 * s22 - s12 * s12;
    const Double4 det = s11 * c11 + s12 * c12 + s1c * c13, inverse = 1 / det;
    const Double4 x1 = (c11 * r1 + c12 * r2 + c13 * rc) * inverse, x2 = (c12 * r1 + c22 * r2 + c23 * rc) * inverse,
                  x3 = (c13 * r1 + c23 * r2 + c33 * rc) * inverse;
    take((det > 1e-9 * s11 * s22 * scc) & (x1 > zero) & (x2 > zero), yy - x1 * r1 - x2 * r2 - x3 * rc);
    const Double4 d1 = s11 * scc - s1c * s1c, i1 = 1 / d1;
    const Double4 a1 = (r1 * scc - s1c * rc) * i1, b1 = (s11 * rc - s1c * r1) * i1;
    take((d1 > 1e-12 * s11 * scc) & (a1 > zero), yy - a1 * r1 - b1 * rc);
    const Double4 d2 = s22 * scc - s2c * s2c, i2 = 1 / d2;
    const Double4 a2 = (r2 * scc - s2c * rc) * i2, b2 = (s22 * rc - s2c * r2) * i2;
    take((d2 > 1e-12 * s22 * scc) & (a2 > zero), yy - a2 * r2 - b2 * rc);
    const Double4 floor = zero + 1e-300, b0 = rc / (scc < floor ? floor : scc);  // std::max(scc, 1e-300)
    take(zero == zero, yy - b0 * rc);
  } else {
    best = yy;
    const Double4 det = s11 * s22 - s12 * s12, inverse = 1 / det;
    const Double4 x1 = (r1 * s22 - s12 * r2) * inverse, x2 = (s11 * r2 - s12 * r1) * inverse;
    take((det > 1e-9 * s11 * s22) & (x1 > zero) & (x2 > zero), yy - x1 * r1 - x2 * r2);
    const Double4 a1 = r1 / s11, a2 = r2 / s22;
    take((s11 > zero) & (a1 > zero), yy - a1 * r1);
    take((s22 > zero) & (a2 > zero), yy - a2 * r2);
  }
  return best;
}

// ProjectPair's cost for n pixel-channels at one pair of rates, four at a
// time (PairCost4), the rest one by one.
template <bool kBackground>
void PairCostsOf(int n, const double* s11, const double* s12, const double* s22, const double* s1c,
                 const double* s2c, const double* scc, const double* r1, const double* r2, const double* rc,
                 const double* yy, double* __restrict__ cost) {
  int j = 0;
  for (; j + 4 <= n; j += 4) {
    const Double4 c = PairCost4<kBackground>(Load4(s11 + j), Load4(s12 + j), Load4(s22 + j), Load4(s1c + j),
                                             Load4(s2c + j), Load4(scc + j), Load4(r1 + j), Load4(r2 + j),
                                             Load4(rc + j), Load4(yy + j));
    std::memcpy(cost + j, &c, sizeof c);
  }
  for (; j < n; ++j)
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

// A rate's basis b and its slope b_u (as EvaluateBasis: P = exp(-k s)
// times the exposure's E = exp(-k e) and (1 - E) / (k e), held in E and D
// per distinct exposure, the frames four at a time in Exp4), into b and b_u.
void EvaluateBasisAndSlope(double u, const FrameTimes& f, Array& E, Array& D, double* b, double* b_u) {
  const double k = std::exp(u), inverse_k = 1 / k;
  const int m = static_cast<int>(f.s.size()), exposures = static_cast<int>(f.exposures.size());
  E.resize(exposures);
  D.resize(exposures);
  int d = 0;
  for (; d + 4 <= exposures; d += 4) {
    const Double4 e = Exp4(-k * Load4(&f.exposures[d])), q = (1 - e) * (inverse_k * Load4(&f.inverse_exposures[d]));
    std::memcpy(&E[d], &e, sizeof e);
    std::memcpy(&D[d], &q, sizeof q);
  }
  for (; d < exposures; ++d) {
    E[d] = std::exp(-k * f.exposures[d]);
    D[d] = (1 - E[d]) * (inverse_k * f.inverse_exposures[d]);
  }
  const int* of = f.exposure_of.data();
  int j = 0;
  for (; j + 4 <= m; j += 4) {
    const Double4 s = Load4(&f.s[j]), P = Exp4(-k * s);
    const Double4 v = P * Double4{D[of[j]], D[of[j + 1]], D[of[j + 2]], D[of[j + 3]]};
    const Double4 Q = P * Double4{E[of[j]], E[of[j + 1]], E[of[j + 2]], E[of[j + 3]]};
    const Double4 v_u = -k * s * v + Q - v;
    std::memcpy(b + j, &v, sizeof v);
    std::memcpy(b_u + j, &v_u, sizeof v_u);
  }
  for (; j < m; ++j) {
    const double P = std::exp(-k * f.s[j]), Q = P * E[of[j]];
    b[j] = P * D[of[j]];
    b_u[j] = -k * f.s[j] * b[j] + Q - b[j];
  }
}

// The weighted sums a channel needs: sum w v for v in b1, b2, b1_u, b2_u
// and the products the Gram, the gradient and the Hessian need (S, indexed
// by PairColumn), and sum w y v for the first four (R); one pass over the
// frames, four at a time, the rest one by one.
enum PairColumn { kB1, kB2, kD1, kD2, kB1B1, kB1B2, kB2B2, kB1D1, kB2D1, kB1D2, kB2D2, kD1D1, kD2D2, kD1D2, kPairColumns };

struct PairSums {
  double S[kPairColumns], R[4];
};

PairSums SumPairChannel(int m, const double* w, const double* wy, const double* b1, const double* b2,
                        const double* d1, const double* d2) {
  Double4 s[kPairColumns] = {}, r[4] = {};
  int j = 0;
  for (; j + 4 <= m; j += 4) {
    const Double4 pw = Load4(w + j), pwy = Load4(wy + j), v1 = Load4(b1 + j), v2 = Load4(b2 + j),
                  u1 = Load4(d1 + j), u2 = Load4(d2 + j);
    const Double4 w1 = pw * v1, w2 = pw * v2, wu1 = pw * u1, wu2 = pw * u2;
    s[kB1] += w1;
    s[kB2] += w2;
    s[kD1] += wu1;
    s[kD2] += wu2;
    s[kB1B1] += w1 * v1;
    s[kB1B2] += w1 * v2;
    s[kB2B2] += w2 * v2;
    s[kB1D1] += w1 * u1;
    s[kB2D1] += w2 * u1;
    s[kB1D2] += w1 * u2;
    s[kB2D2] += w2 * u2;
    s[kD1D1] += wu1 * u1;
    s[kD2D2] += wu2 * u2;
    s[kD1D2] += wu1 * u2;
    r[kB1] += pwy * v1;
    r[kB2] += pwy * v2;
    r[kD1] += pwy * u1;
    r[kD2] += pwy * u2;
  }
  PairSums out;
  for (int i = 0; i < kPairColumns; ++i) out.S[i] = Sum4(s[i]);
  for (int i = 0; i < 4; ++i) out.R[i] = Sum4(r[i]);
  for (; j < m; ++j) {
    const double w1 = w[j] * b1[j], w2 = w[j] * b2[j], wu1 = w[j] * d1[j], wu2 = w[j] * d2[j];
    out.S[kB1] += w1;
    out.S[kB2] += w2;
    out.S[kD1] += wu1;
    out.S[kD2] += wu2;
    out.S[kB1B1] += w1 * b1[j];
    out.S[kB1B2] += w1 * b2[j];
    out.S[kB2B2] += w2 * b2[j];
    out.S[kB1D1] += w1 * d1[j];
    out.S[kB2D1] += w2 * d1[j];
    out.S[kB1D2] += w1 * d2[j];
    out.S[kB2D2] += w2 * d2[j];
    out.S[kD1D1] += wu1 * d1[j];
    out.S[kD2D2] += wu2 * d2[j];
    out.S[kD1D2] += wu1 * d2[j];
    out.R[kB1] += wy[j] * b1[j];
    out.R[kB2] += wy[j] * b2[j];
    out.R[kD1] += wy[j] * d1[j];
    out.R[kD2] += wy[j] * d2[j];
  }
  return out;
}

PairFit EvaluatePair(double u1, double u2, const PixelData& px, const FrameTimes& f, bool background,
                     BlockWork& work) {
  const int m = px.m;
  Matrix& V = work.pair_products;  // m x 4: b1, b2, b1_u, b2_u
  V.resize(m, 4);
  EvaluateBasisAndSlope(u1, f, work.b1, work.d1, &V(0, kB1), &V(0, kD1));
  EvaluateBasisAndSlope(u2, f, work.b2, work.d2, &V(0, kB2), &V(0, kD2));
  PairFit fit;
  fit.u1 = u1;
  fit.u2 = u2;
  fit.cost = 0;
  for (int c = 0; c < px.channels; ++c) {
    const PairSums sums = SumPairChannel(m, &px.w(0, c), &px.wy(0, c), &V(0, kB1), &V(0, kB2), &V(0, kD1), &V(0, kD2));
    const double *S = sums.S, *R = sums.R;
    const PairGram gram{S[kB1B1], S[kB1B2], S[kB2B2], S[kB1], S[kB2], px.S11[c], R[kB1], R[kB2], px.S1y[c], px.Syy[c]};
    const PairChannelFit cf = ProjectPair(gram, background);
    fit.a1[c] = cf.a1;
    fit.a2[c] = cf.a2;
    fit.background[c] = cf.background;
    fit.cost += cf.cost;
    if (!(cf.a1 > 0) && !(cf.a2 > 0)) continue;
    const double wd1 = S[kD1], wd2 = S[kD2];
    const double b1d1 = S[kB1D1], b2d1 = S[kB2D1], b1d2 = S[kB1D2], b2d2 = S[kB2D2];
    const double B = cf.background;
    // sum w r b_i_u, r the residual
    const double rd1 = R[kD1] - cf.a1 * b1d1 - cf.a2 * b2d1 - B * wd1;
    const double rd2 = R[kD2] - cf.a1 * b1d2 - cf.a2 * b2d2 - B * wd2;
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
    fit.H[0][0] += 2 * (cf.a1 * cf.a1 * S[kD1D1] - projected(0, 0));
    fit.H[0][1] += 2 * (cf.a1 * cf.a2 * S[kD1D2] - projected(0, 1));
    fit.H[1][1] += 2 * (cf.a2 * cf.a2 * S[kD2D2] - projected(1, 1));
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
    SumChannels(count, C, work.channel_cost.data(), work.cost_of_pixels.data());
    work.pair_cost.row(q) = work.cost_of_pixels.matrix().transpose();
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
