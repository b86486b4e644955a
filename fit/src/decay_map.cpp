#include "phos/fit/decay_map.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>

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
    // Weighted RSS from the sums, without a second pass over the samples.
    s.cost += Syy - 2 * A * Sby - 2 * B * S1y + A * A * Sbb + 2 * A * B * Sb1 + B * B * S11;
    s.amplitude[c] = A;
    s.background[c] = B;
  }
  return s;
}

}  // namespace

DecayMap FitDecayMap(const DecayMapInput& in, const DecayMapOptions& options, const std::string& where,
                     const std::function<void(std::size_t)>& progress) {
  const auto started = std::chrono::steady_clock::now();
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
  // The rate grid, as FitDecay scans it: from a twentieth of one per span
  // to three per smallest spacing.
  const double span = in.t_s.back() - in.t_s.front();
  double spacing = span;
  for (int j = 1; j < m; ++j) spacing = std::min(spacing, in.t_s[j] - in.t_s[j - 1]);
  const double k_lo = 0.02 / span, k_hi = 3 / spacing;
  const int G = std::max(8, options.rate_grid_size);
  std::vector<double> log_k(G), basis(static_cast<std::size_t>(G) * m);
  for (int g = 0; g < G; ++g) {
    log_k[g] = std::log(k_lo) + (std::log(k_hi) - std::log(k_lo)) * g / (G - 1);
    Basis(std::exp(log_k[g]), in.t_s, in.exposure_s, &basis[static_cast<std::size_t>(g) * m]);
  }

  DecayMap map;
  map.width = in.width;
  map.height = in.height;
  map.channels = in.channels;
  map.kr.assign(pixels, std::nanf(""));
  map.amplitude.assign(pixels * in.channels, 0.0f);
  map.background.assign(pixels * in.channels, 0.0f);
  map.rms.assign(pixels, std::nanf(""));
  std::atomic<std::size_t> no_decay{0}, rows_done{0};

  tbb::parallel_for(tbb::blocked_range<int>(0, in.height), [&](const tbb::blocked_range<int>& rows) {
    std::vector<float> y_store(static_cast<std::size_t>(in.channels) * m);
    std::vector<double> w2_store(static_cast<std::size_t>(in.channels) * m), b(m);
    std::vector<const float*> y(in.channels);
    std::vector<const double*> w2(in.channels);
    for (int c = 0; c < in.channels; ++c) {
      y[c] = &y_store[static_cast<std::size_t>(c) * m];
      w2[c] = &w2_store[static_cast<std::size_t>(c) * m];
    }
    for (int row = rows.begin(); row != rows.end(); ++row) {
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
          // Photon counting: a rate's variance is value / exposure, with a
          // floor so a dark sample does not get an infinite weight.
          const double floor = std::max(1e-3 * peak, 1e-12);
          for (int j = 0; j < m; ++j)
            wc[j] = options.weighting == Weighting::kPoisson
                        ? in.exposure_s[j] / std::max<double>(std::fabs(yc[j]), floor)
                        : 1.0;
        }
        // Scan the grid, then Newton on log k with central differences.
        int best = 0;
        PixelSolution best_solution;
        for (int g = 0; g < G; ++g) {
          PixelSolution s =
              Project(&basis[static_cast<std::size_t>(g) * m], y.data(), w2.data(), in.channels, m, options.background);
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
        // It decays if some channel's fitted decay is more than rounding
        // (a millionth of the pixel's largest value) over the recorded span.
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
      if (progress) progress(++rows_done);
    }
  });
  map.no_decay = no_decay;
  map.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return map;
}

}  // namespace phos
