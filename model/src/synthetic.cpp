#include "phos/model/synthetic.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

#include "phos/util/format.h"

namespace phos {
namespace {

// Bands 1-3 (400-512.5 nm on the paper's grid): where ke is known.
constexpr int kExcitedBands = 3;

// A uniform number in [0, 1) from the top 53 bits: the same on every
// standard library (std::uniform_real_distribution is not specified to be).
double Uniform01(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }
double UniformIn(std::mt19937_64& rng, double lo, double hi) { return lo + (hi - lo) * Uniform01(rng); }
double LogUniformIn(std::mt19937_64& rng, double lo, double hi) {
  return std::exp(UniformIn(rng, std::log(lo), std::log(hi)));
}

void Require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("two-state spec: " + what);
}

// A Gaussian emission band integrated over each band and normalized to sum 1.
std::vector<double> EmissionShape(const SpectralGrid& grid, double peak_nm, double fwhm_nm) {
  const double sigma = fwhm_nm / 2.3548200450309493;
  std::vector<double> shape;
  double total = 0;
  for (int b = 0; b < grid.band_count(); ++b) {
    const double lo = (grid.lower_nm(b) - peak_nm) / (sigma * std::sqrt(2.0));
    const double hi = (grid.upper_nm(b) - peak_nm) / (sigma * std::sqrt(2.0));
    shape.push_back(0.5 * (std::erf(hi) - std::erf(lo)));
    total += shape.back();
  }
  for (double& v : shape) v /= total;
  return shape;
}

}  // namespace

Material TwoStateMaterial(const TwoStateSpec& spec) {
  Require(spec.slow_kr > 0 && std::isfinite(spec.slow_kr), "slow_kr must be > 0");
  Require(spec.rate_ratio > 1 && std::isfinite(spec.rate_ratio), "rate_ratio must be > 1");
  Require(spec.fast_share > 0 && spec.fast_share < 1, "fast_share must be in (0, 1)");
  Require(spec.fast_rho > 0 && spec.slow_rho > 0, "rho must be > 0");
  Require(spec.glow > 0, "glow must be > 0");
  Require(spec.emission_fwhm_nm > 0, "emission_fwhm_nm must be > 0");
  Require(spec.fast_excitation_shape.size() == kExcitedBands && spec.slow_excitation_shape.size() == kExcitedBands,
          "an excitation shape has one value per band 1-3");
  Material m;
  m.name = spec.name;
  m.bands = SpectralGrid::Paper();
  const int nb = m.band_count();
  const std::vector<double> shape = EmissionShape(m.bands, spec.emission_peak_nm, spec.emission_fwhm_nm);
  struct Part {
    double kr, rho, share;
    const std::vector<double>* excitation;
  };
  const Part parts[2] = {{spec.slow_kr * spec.rate_ratio, spec.fast_rho, spec.fast_share, &spec.fast_excitation_shape},
                         {spec.slow_kr, spec.slow_rho, 1 - spec.fast_share, &spec.slow_excitation_shape}};
  for (const Part& part : parts) {  // fastest first, as fits report them
    ExcitedState state;
    state.kr = part.kr;
    const double largest = *std::max_element(part.excitation->begin(), part.excitation->end());
    Require(largest > 0, "an excitation shape needs a value > 0");
    state.ke.assign(static_cast<std::size_t>(nb), std::nullopt);
    for (int b = 0; b < kExcitedBands; ++b) {
      Require((*part.excitation)[b] > 0, "excitation shape values must be > 0");
      state.ke[b] = part.rho * part.kr * (*part.excitation)[b] / largest;
    }
    // Equilibrium under unit irradiance in band 1: r = a / (a + kr) (Eq. 8.1).
    const double a = *state.ke[0], r = a / (a + part.kr);
    const double c = part.share * spec.glow / (part.kr * r);
    for (int b = 0; b < nb; ++b) state.Lambda.push_back(c * shape[b]);
    m.states.push_back(state);
  }
  m.source = "synthetic two-state material (not measured): slow kr " + FormatShort(spec.slow_kr) + "/s, rate ratio " +
             FormatShort(spec.rate_ratio) + ", fast share " + FormatShort(spec.fast_share) + ", rho " +
             FormatShort(spec.fast_rho) + "/" + FormatShort(spec.slow_rho) + ", emission " +
             FormatShort(spec.emission_peak_nm) + " nm (FWHM " + FormatShort(spec.emission_fwhm_nm) +
             "); made by phos::TwoStateMaterial (model/synthetic.h)";
  ValidateMaterial(m, m.name);
  return m;
}

TwoStateSpec RandomTwoStateSpec(std::uint64_t seed, const TwoStateRanges& r) {
  std::mt19937_64 rng(seed);
  TwoStateSpec spec;
  spec.slow_kr = LogUniformIn(rng, r.slow_kr_min, r.slow_kr_max);
  spec.rate_ratio = LogUniformIn(rng, r.rate_ratio_min, r.rate_ratio_max);
  spec.fast_share = UniformIn(rng, r.fast_share_min, r.fast_share_max);
  spec.fast_rho = LogUniformIn(rng, r.rho_min, r.rho_max);
  spec.slow_rho = LogUniformIn(rng, r.rho_min, r.rho_max);
  spec.glow = LogUniformIn(rng, r.glow_min, r.glow_max);
  spec.emission_peak_nm = UniformIn(rng, r.emission_peak_min_nm, r.emission_peak_max_nm);
  spec.emission_fwhm_nm = UniformIn(rng, r.emission_fwhm_min_nm, r.emission_fwhm_max_nm);
  for (auto* excitation : {&spec.fast_excitation_shape, &spec.slow_excitation_shape}) {
    // One band at 1, the others log-uniform below it.
    const int top = static_cast<int>(Uniform01(rng) * kExcitedBands);
    for (int b = 0; b < kExcitedBands; ++b)
      (*excitation)[b] = b == top ? 1.0 : LogUniformIn(rng, r.excitation_shape_min, 1.0);
  }
  spec.name = "random-two-state-" + std::to_string(seed);
  return spec;
}

Material RandomTwoStateMaterial(std::uint64_t seed, const TwoStateRanges& ranges) {
  return TwoStateMaterial(RandomTwoStateSpec(seed, ranges));
}

std::vector<TwoStateSpec> TwoStateFixtureSpecs() {
  auto spec = [](std::string name, double slow_kr, double ratio, double share, double peak_nm, double fwhm_nm,
                 std::vector<double> fast_u, std::vector<double> slow_u) {
    TwoStateSpec s;
    s.name = std::move(name);
    s.slow_kr = slow_kr;
    s.rate_ratio = ratio;
    s.fast_share = share;
    s.emission_peak_nm = peak_nm;
    s.emission_fwhm_nm = fwhm_nm;
    s.fast_excitation_shape = std::move(fast_u);
    s.slow_excitation_shape = std::move(slow_u);
    return s;
  };
  std::vector<TwoStateSpec> specs = {
      // Rate ratio 2, even mix: the hardest to tell apart.
      spec("two-state-ratio2", 0.02, 2, 0.5, 520, 50, {1.0, 0.4, 0.1}, {0.3, 1.0, 0.5}),
      // Rate ratio 50, little of the fast state.
      spec("two-state-ratio50-fast10", 0.02, 50, 0.1, 600, 70, {1.0, 0.6, 0.2}, {0.2, 0.5, 1.0}),
      // Rate ratio 50, mostly the fast state.
      spec("two-state-ratio50-fast90", 0.01, 50, 0.9, 480, 40, {0.5, 1.0, 0.3}, {1.0, 0.2, 0.05}),
      // Rate ratio 2, mostly the slow state.
      spec("two-state-ratio2-fast10", 0.04, 2, 0.1, 630, 80, {1.0, 1.0, 0.5}, {0.1, 0.3, 1.0}),
      // Inside: ratio 7 mostly fast, ratio 20 even.
      spec("two-state-ratio7-fast90", 0.03, 7, 0.9, 560, 60, {0.2, 1.0, 0.6}, {1.0, 0.7, 0.2}),
      spec("two-state-ratio20", 0.015, 20, 0.5, 500, 60, {1.0, 0.3, 0.3}, {0.6, 1.0, 0.1}),
  };
  specs[0].fast_rho = 0.5, specs[0].slow_rho = 1.5;
  specs[1].fast_rho = 1.0, specs[1].slow_rho = 0.6;
  specs[2].fast_rho = 2.0, specs[2].slow_rho = 0.8;
  specs[3].fast_rho = 0.8, specs[3].slow_rho = 2.0;
  specs[4].fast_rho = 0.6, specs[4].slow_rho = 1.2;
  specs[5].fast_rho = 1.5, specs[5].slow_rho = 0.5;
  return specs;
}

}  // namespace phos
