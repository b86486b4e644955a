#pragma once
// Subsurface scattering by dipole diffusion (Jensen, Marschner, Levoy and
// Hanrahan 2001), the deep-screen-space chapters' translucency effect: light
// entering a translucent material at q leaves it at x with the diffuse
// reflectance profile Rd(|x - q|), so the radiant exitance at x is
//
//   M(x) = sum over surfels q of the same object  Rd(|x - q|) E(q) A(q),
//
// and the outgoing radiance M / pi (each surfel's share integrated over its
// disk: SurfelKernel). A uniformly lit half-space returns the
// total diffuse reflectance R_d = integral of Rd over the plane (closed form
// below), which the direct and path transports use as the object's albedo, so
// that every transport agrees where the light is uniform and only dss shows
// the light bleeding across shadow edges.

#include <algorithm>
#include <cmath>

#include "phos/util/math.h"

namespace phos::render {

struct Dipole {
  float sigma_tr = 0;      // effective transport coefficient sqrt(3 sigma_a sigma_t'), 1/m
  float z_r = 0, z_v = 0;  // depths of the real and the virtual source, m
  float alpha_prime = 0;   // reduced albedo sigma_s' / sigma_t'
  float A = 1;             // internal reflection (1 + F_dr) / (1 - F_dr)

  // sigma_a and reduced scattering sigma_s' per metre, relative index of refraction eta.
  static Dipole From(double sigma_a_per_m, double sigma_s_prime_per_m, double eta) {
    Dipole d;
    const double sigma_t_prime = sigma_a_per_m + sigma_s_prime_per_m;
    const double F_dr = -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta;  // Egan and Hilgeman's fit
    d.A = static_cast<float>((1 + F_dr) / (1 - F_dr));
    d.alpha_prime = static_cast<float>(sigma_s_prime_per_m / sigma_t_prime);
    d.sigma_tr = static_cast<float>(std::sqrt(3 * sigma_a_per_m * sigma_t_prime));
    d.z_r = static_cast<float>(1 / sigma_t_prime);
    d.z_v = d.z_r * (1 + 4 * d.A / 3);
    return d;
  }
  // Diffuse reflectance per unit area at distance r (Jensen et al. 2001, Eq. 5).
  float Rd(float r) const {
    const float d_r = std::sqrt(r * r + z_r * z_r), d_v = std::sqrt(r * r + z_v * z_v);
    return alpha_prime / (4 * kPiF) *
           (z_r * (1 + sigma_tr * d_r) * std::exp(-sigma_tr * d_r) / (d_r * d_r * d_r) +
            z_v * (1 + sigma_tr * d_v) * std::exp(-sigma_tr * d_v) / (d_v * d_v * d_v));
  }
  // The integral of Rd over the annulus a <= r <= b in closed form: with
  // d^2 = r^2 + z^2 each source's term integrates to 2 pi z [e^{-sigma d} / d].
  double AnnulusIntegral(double a, double b) const {
    auto term = [&](double z) {
      const double da = std::sqrt(a * a + z * z), db = std::sqrt(b * b + z * z);
      return 2 * kPi * z * (std::exp(-sigma_tr * da) / da - (std::isinf(b) ? 0.0 : std::exp(-sigma_tr * db) / db));
    };
    return alpha_prime / (4 * kPi) * (term(z_r) + term(z_v));
  }
  // What a surfel of `area` at distance r sends to a receiver, per unit of
  // its irradiance, from the part of it farther than near_m from the
  // receiver: the integral of Rd over that part of the surfel's disk (radius
  // rho = sqrt(area / pi)). Circles about the receiver of radius
  // u < rho - r lie wholly inside the disk (closed form); the others, u in
  // [|r - rho|, r + rho], cut an arc of 2 acos((u^2 + r^2 - rho^2) / (2 u r)),
  // integrated with 12 points in t, u = mid - half cos t.
  //
  // Why near_m: surfels are wider than the mean free path at any usual
  // density and Rd peaks as 1/r^3 inside one of them, so no sum over disks
  // gets the near field right (a receiver between surfels would miss the
  // peak, one on a surfel would count it with its neighbours' overlap). The
  // near field is instead E(x) AnnulusIntegral(0, near_m) with the receiver's
  // own irradiance, and the surfels carry only what lies beyond.
  // The exitance of a translucent receiver: its own irradiance E_here
  // through the near field (the disk of near_m about it, in closed form)
  // plus what the surfels beyond carried to it (`gathered`, from a splat or
  // an exact gather of SurfelKernel).
  float Exitance(float E_here, float near_m, float gathered) const {
    return E_here * static_cast<float>(AnnulusIntegral(0, near_m)) + gathered;
  }
  float SurfelKernel(float r_f, float area, float near_m = 0) const {
    const double r = r_f, rho = std::sqrt(area / kPi), lo = near_m;
    if (r + rho <= lo) return 0.0f;
    if (r <= 1e-9 * rho) return static_cast<float>(AnnulusIntegral(lo, std::max(lo, rho)));
    double sum = r < rho && rho - r > lo ? AnnulusIntegral(lo, rho - r) : 0.0;
    const double a = std::max(std::fabs(r - rho), lo), b = r + rho, mid = 0.5 * (a + b), half = 0.5 * (b - a);
    constexpr int kPoints = 12;
    for (int k = 0; k < kPoints; ++k) {
      const double t = kPi * (k + 0.5) / kPoints;
      const double u = mid - half * std::cos(t), du = half * std::sin(t) * kPi / kPoints;
      const double c = std::clamp((u * u + r * r - rho * rho) / (2 * u * r), -1.0, 1.0);
      sum += Rd(static_cast<float>(u)) * 2 * std::acos(c) * u * du;
    }
    return static_cast<float>(sum);
  }
  // The integral of Rd over the plane (Jensen et al. 2001, Eq. 6).
  double TotalReflectance() const {
    const double s = std::sqrt(3 * (1 - static_cast<double>(alpha_prime)));
    return alpha_prime / 2.0 * (1 + std::exp(-4.0 / 3.0 * A * s)) * std::exp(-s);
  }
  // The distance beyond which Rd(r) * area < epsilon (Rd falls with r).
  float MaxDistance(float area, float epsilon) const {
    if (!(Rd(0) * area >= epsilon)) return 0;
    float lo = 0, hi = z_v + 1e-6f;
    while (Rd(hi) * area >= epsilon && hi < 1e6f) lo = hi, hi *= 2;
    for (int i = 0; i < 40; ++i) {
      const float mid = 0.5f * (lo + hi);
      (Rd(mid) * area >= epsilon ? lo : hi) = mid;
    }
    return hi;
  }
};

}  // namespace phos::render
