#include "phos/model/synthetic.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

#include "phos/model/closed_form.h"
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

void Require(bool ok, const std::string& what, const char* spec = "two-state spec") {
  if (!ok) throw std::invalid_argument(std::string(spec) + ": " + what);
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

void RequireManyTrap(bool ok, const std::string& what) { Require(ok, what, "many-trap spec"); }

void CheckManyTrapSpec(const ManyTrapSpec& spec) {
  RequireManyTrap(spec.power > 0 && std::isfinite(spec.power), "power must be > 0");
  RequireManyTrap(spec.from_s > 0 && spec.to_s > spec.from_s && std::isfinite(spec.to_s),
                  "the span needs 0 < from_s < to_s");
  RequireManyTrap(spec.states >= 2 && spec.states <= kMaxStates, "states must be 2 to " + std::to_string(kMaxStates));
  RequireManyTrap(spec.margin >= 1 && std::isfinite(spec.margin), "margin must be >= 1");
  RequireManyTrap(spec.glow > 0 && std::isfinite(spec.glow), "glow must be > 0");
  RequireManyTrap(spec.ke > 0 && std::isfinite(spec.ke), "ke must be > 0");
  RequireManyTrap(spec.emission_fwhm_nm > 0, "emission_fwhm_nm must be > 0");
  RequireManyTrap(spec.excitation_shape.size() == kExcitedBands, "the excitation shape has one value per band 1-3");
  for (double u : spec.excitation_shape) RequireManyTrap(u > 0 && u <= 1, "excitation shape values must be in (0, 1]");
}

}  // namespace

ManyTrapStates ManyTrapRates(const ManyTrapSpec& spec) {
  CheckManyTrapSpec(spec);
  const double u_slow = std::log(1 / (spec.margin * spec.to_s)), u_fast = std::log(spec.margin / spec.from_s);
  const int n = spec.states;
  const double step = (u_fast - u_slow) / (n - 1);
  ManyTrapStates states;
  double total = 0;
  for (int i = 0; i < n; ++i) {  // fastest first
    const double kr = std::exp(u_fast - step * i);
    const double node = i == 0 || i == n - 1 ? step / 2 : step;  // the trapezoid rule in ln k
    double share = std::pow(kr, spec.power) * node;
    if (i == n - 1) share += std::pow(kr, spec.power) / spec.power;  // every rate below k_min
    states.kr.push_back(kr);
    states.share.push_back(share);
    total += share;
  }
  for (double& share : states.share) share /= total;
  return states;
}

Material ManyTrapMaterial(const ManyTrapSpec& spec) {
  const ManyTrapStates rates = ManyTrapRates(spec);
  Material m;
  m.name = spec.name;
  m.bands = SpectralGrid::Paper();
  const int nb = m.band_count(), n = spec.states;
  const double largest = *std::max_element(spec.excitation_shape.begin(), spec.excitation_shape.end());
  for (int i = 0; i < n; ++i) {
    ExcitedState state;
    state.kr = rates.kr[i];
    state.ke.assign(static_cast<std::size_t>(nb), std::nullopt);
    for (int b = 0; b < kExcitedBands; ++b) state.ke[b] = spec.ke * spec.excitation_shape[b] / largest;
    // The peak moves with ln kr, fastest (i = 0) to slowest.
    const double along = static_cast<double>(i) / (n - 1);
    const double peak_nm =
        spec.emission_peak_fast_nm + along * (spec.emission_peak_slow_nm - spec.emission_peak_fast_nm);
    const std::vector<double> shape = EmissionShape(m.bands, peak_nm, spec.emission_fwhm_nm);
    // Equilibrium under unit irradiance in band 1 (Eq. 8.1): A_i = kr r Lambda summed.
    const double r = SteadyState(*state.ke[0], state.kr);
    const double c = rates.share[i] * spec.glow / (state.kr * r);
    for (int b = 0; b < nb; ++b) state.Lambda.push_back(c * shape[b]);
    m.states.push_back(std::move(state));
  }
  m.source = "synthetic many-trap material (not measured): L ~ t^-" + FormatShort(spec.power) + " from " +
             FormatShort(spec.from_s) + " s to " + FormatShort(spec.to_s) + " s after a long charge, " +
             std::to_string(n) + " states, ke " + FormatShort(spec.ke) + ", emission " +
             FormatShort(spec.emission_peak_fast_nm) + " to " + FormatShort(spec.emission_peak_slow_nm) + " nm (FWHM " +
             FormatShort(spec.emission_fwhm_nm) + "); made by phos::ManyTrapMaterial (model/synthetic.h)";
  ValidateMaterial(m, m.name);
  return m;
}

ManyTrapSpec RandomManyTrapSpec(std::uint64_t seed, const ManyTrapRanges& r) {
  std::mt19937_64 rng(seed);
  ManyTrapSpec spec;
  spec.power = UniformIn(rng, r.power_min, r.power_max);
  spec.from_s = LogUniformIn(rng, r.from_min_s, r.from_max_s);
  spec.to_s = spec.from_s * std::pow(10.0, UniformIn(rng, r.decades_min, r.decades_max));
  spec.ke = LogUniformIn(rng, r.ke_min, r.ke_max);
  spec.glow = LogUniformIn(rng, r.glow_min, r.glow_max);
  spec.emission_peak_fast_nm = UniformIn(rng, r.emission_peak_min_nm, r.emission_peak_max_nm);
  const double slow_peak_nm = UniformIn(rng, r.emission_peak_min_nm, r.emission_peak_max_nm);
  spec.emission_peak_slow_nm = r.per_state_spectra ? slow_peak_nm : spec.emission_peak_fast_nm;
  spec.emission_fwhm_nm = UniformIn(rng, r.emission_fwhm_min_nm, r.emission_fwhm_max_nm);
  spec.name = "random-many-trap-" + std::to_string(seed);
  return spec;
}

Material RandomManyTrapMaterial(std::uint64_t seed, const ManyTrapRanges& ranges) {
  return ManyTrapMaterial(RandomManyTrapSpec(seed, ranges));
}

std::vector<ManyTrapSpec> ManyTrapFixtureSpecs() {
  ManyTrapSpec sign;  // SrAl2O4:Eu,Dy-like: t^-1 from 1 min to 10 h, green at 520 nm
  sign.name = "sign-paint";
  sign.power = 1;
  sign.from_s = 60;
  sign.to_s = 36000;
  return {sign};
}

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
