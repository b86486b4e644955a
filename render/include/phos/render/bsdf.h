#pragma once
// Glossy surfaces (glTF 2.0 metallic-roughness, docs/render.md): a GGX
// microfacet lobe over the diffuse base, energy-conserving, for the direct
// and path transports. The glow stays isotropic (Sec. 8.3.4): only the
// reflection of light changes.
//
// The model is glTF's (Appendix B of the glTF 2.0 spec): base colour c per
// band, metallic m, roughness r (alpha = r^2):
//   f = (1 - m) [f_spec(F0 = 0.04) + f_base(c)] + m f_spec(F0 = c)
// where f_spec is the GGX lobe (Trowbridge-Reitz D, Smith height-correlated
// G2, Schlick's Fresnel) plus Kulla and Conty 2017's multiple-scattering
// lobe, so a white metal reflects all it receives at every roughness, and
// f_base is the diffuse base under the dielectric coating, scaled by the
// energy the coating leaves, (1 - E_spec(mu_o)) (1 - E_spec(mu_i)) /
// (pi (1 - E_spec_avg)), so a white dielectric reflects all it receives too
// (the white furnace test, tests/render/bsdf_test.cpp). The directional
// albedos E are tabulated once per process by quadrature.

#include "phos/render/geometry.h"

namespace phos::render {

// Gloss (scene.h): metallic in [0, 1], roughness in [kMinRoughness, 1]
// (below it the lobe is a mirror this renderer does not trace).

// The BSDF at one hit: the object's gloss and the hit's albedo (its base
// colour per band), with the shading normal n on the side the ray arrived.
class GlossyBsdf {
 public:
  GlossyBsdf(const Gloss& gloss, const float* albedo, int band_count);
  // f(wo, wi) per band into f[0, band count); wo, wi unit, pointing away.
  void Eval(const Vec3f& n, const Vec3f& wo, const Vec3f& wi, float* f) const;
  // The solid-angle pdf with which Sample draws wi.
  float Pdf(const Vec3f& n, const Vec3f& wo, const Vec3f& wi) const;
  // Draws wi: the specular lobe by Heitz 2018's visible-normal sampling, or
  // the cosine lobe (the base and the multiple-scattering lobe), chosen by
  // u0. False when it falls below the surface.
  bool Sample(const Vec3f& n, const Vec3f& wo, float u0, float u1, float u2, Vec3f* wi, float* pdf) const;
  // The share of light from direction wo's hemisphere reflected toward wo,
  // per band (the directional albedo): what a uniform sky's reflection is.
  void DirectionalAlbedo(float cos_o, float* rho) const;

 private:
  const float* albedo_;
  int band_count_;
  float metallic_, alpha_;
  float specular_probability_;
};

// The tabulated directional albedos (for tests): GGX with F = 1, single
// scattering, at cos theta_o = mu and roughness r; and its average
// 2 int E mu dmu.
float GgxDirectionalAlbedo(float mu, float roughness);
float GgxAverageAlbedo(float roughness);

}  // namespace phos::render
