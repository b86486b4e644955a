#include "phos/render/bsdf.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "phos/util/math.h"
#include "sampling.h"

namespace phos::render {
namespace {

constexpr int kMuSteps = 32, kRoughnessSteps = 32, kSamplesPerSide = 32;
constexpr float kDielectricF0 = 0.04f;  // glTF's: a dielectric's reflectance at normal incidence

// GGX (Trowbridge-Reitz) in the local frame, z along the normal.
float D(float cos_h, float alpha) {
  const float a2 = alpha * alpha, d = cos_h * cos_h * (a2 - 1) + 1;
  return a2 / (kPiF * d * d);
}
// Smith's Lambda for GGX at cos theta = mu.
float Lambda(float mu, float alpha) {
  const float mu2 = std::max(mu * mu, 1e-12f);
  return 0.5f * (-1 + std::sqrt(1 + alpha * alpha * (1 - mu2) / mu2));
}

// Heitz 2018, "Sampling the GGX Distribution of Visible Normals": a
// microfacet normal seen from wo (local, z up) at (u1, u2).
Vec3f SampleVisibleNormal(const Vec3f& wo, float alpha, float u1, float u2) {
  const Vec3f vh = Vec3f(alpha * wo.x(), alpha * wo.y(), wo.z()).normalized();
  const float lensq = vh.x() * vh.x() + vh.y() * vh.y();
  const Vec3f t1 = lensq > 0 ? Vec3f(Vec3f(-vh.y(), vh.x(), 0) / std::sqrt(lensq)) : Vec3f(1, 0, 0);
  const Vec3f t2 = vh.cross(t1);
  const float r = std::sqrt(u1), phi = 2 * kPiF * u2;
  const float p1 = r * std::cos(phi);
  const float s = 0.5f * (1 + vh.z());
  const float p2 = (1 - s) * std::sqrt(std::max(0.0f, 1 - p1 * p1)) + s * r * std::sin(phi);
  const Vec3f nh = p1 * t1 + p2 * t2 + std::sqrt(std::max(0.0f, 1 - p1 * p1 - p2 * p2)) * vh;
  return Vec3f(alpha * nh.x(), alpha * nh.y(), std::max(1e-6f, nh.z())).normalized();
}

float RoughnessAt(int j) { return kMinRoughness + (1 - kMinRoughness) * static_cast<float>(j) / (kRoughnessSteps - 1); }
float MuAt(int i) { return (static_cast<float>(i) + 0.5f) / kMuSteps; }

// E(mu, r) and E5(mu, r): the single-scattering directional albedo of GGX
// with F = 1 and with F = (1 - wo.h)^5 (Schlick's term), by stratified
// visible-normal sampling (weight G2 / G1(wo)); their averages 2 int E mu dmu.
struct Tables {
  std::array<float, kMuSteps * kRoughnessSteps> E{}, E5{};
  std::array<float, kRoughnessSteps> E_avg{}, E5_avg{};
  Tables() {
    for (int j = 0; j < kRoughnessSteps; ++j) {
      const float alpha = RoughnessAt(j) * RoughnessAt(j);
      for (int i = 0; i < kMuSteps; ++i) {
        const float mu = MuAt(i);
        const Vec3f wo(std::sqrt(1 - mu * mu), 0, mu);
        double sum = 0, sum5 = 0;
        for (int a = 0; a < kSamplesPerSide; ++a)
          for (int b = 0; b < kSamplesPerSide; ++b) {
            const Vec3f h = SampleVisibleNormal(wo, alpha, (a + 0.5f) / kSamplesPerSide, (b + 0.5f) / kSamplesPerSide);
            const float cos_oh = wo.dot(h);
            const Vec3f wi = 2 * cos_oh * h - wo;
            if (!(wi.z() > 0)) continue;
            const float weight = (1 + Lambda(mu, alpha)) / (1 + Lambda(mu, alpha) + Lambda(wi.z(), alpha));
            sum += weight;
            sum5 += weight * std::pow(1 - std::max(0.0f, cos_oh), 5.0f);
          }
        const double n = double(kSamplesPerSide) * kSamplesPerSide;
        E[j * kMuSteps + i] = static_cast<float>(sum / n);
        E5[j * kMuSteps + i] = static_cast<float>(sum5 / n);
        E_avg[j] += 2 * E[j * kMuSteps + i] * mu / kMuSteps;
        E5_avg[j] += 2 * E5[j * kMuSteps + i] * mu / kMuSteps;
      }
    }
  }
};
const Tables& GetTables() {
  static const Tables tables;
  return tables;
}

// Bilinear in (mu, roughness) between the table's nodes, clamped at its edges.
float Lookup(const std::array<float, kMuSteps * kRoughnessSteps>& table, float mu, float roughness) {
  const float x = std::clamp(mu * kMuSteps - 0.5f, 0.0f, kMuSteps - 1.0f);
  const float y = std::clamp((roughness - kMinRoughness) / (1 - kMinRoughness) * (kRoughnessSteps - 1), 0.0f,
                             kRoughnessSteps - 1.0f);
  const int i = std::min(static_cast<int>(x), kMuSteps - 2), j = std::min(static_cast<int>(y), kRoughnessSteps - 2);
  const float fx = x - i, fy = y - j;
  auto at = [&](int ii, int jj) { return table[jj * kMuSteps + ii]; };
  return (1 - fy) * ((1 - fx) * at(i, j) + fx * at(i + 1, j)) + fy * ((1 - fx) * at(i, j + 1) + fx * at(i + 1, j + 1));
}
float LookupAverage(const std::array<float, kRoughnessSteps>& table, float roughness) {
  const float y = std::clamp((roughness - kMinRoughness) / (1 - kMinRoughness) * (kRoughnessSteps - 1), 0.0f,
                             kRoughnessSteps - 1.0f);
  const int j = std::min(static_cast<int>(y), kRoughnessSteps - 2);
  const float fy = y - j;
  return (1 - fy) * table[j] + fy * table[j + 1];
}

// Kulla and Conty 2017: the multiple-scattering lobe's Fresnel factor for a
// Schlick F0, F_avg^2 E_avg / (1 - F_avg (1 - E_avg)), F_avg = F0 + (1 - F0) / 21.
float MultipleScatteringFresnel(float F0, float E_avg) {
  const float F_avg = F0 + (1 - F0) / 21;
  return F_avg * F_avg * E_avg / (1 - F_avg * (1 - E_avg));
}

// What a surface does at one (mu_o, mu_i): the quantities every band shares.
struct Terms {
  float E_o, E_i, E_avg;      // GGX with F = 1
  float E5_o;                 // its Schlick part at wo
  float Espec_o, Espec_i;     // the dielectric coating's whole reflection (single + multiple)
  float Espec_avg;
  float ms_dielectric;        // F_ms(0.04)
};
Terms TermsAt(float mu_o, float mu_i, float roughness) {
  const Tables& t = GetTables();
  Terms terms;
  terms.E_o = Lookup(t.E, mu_o, roughness);
  terms.E_i = Lookup(t.E, mu_i, roughness);
  terms.E5_o = Lookup(t.E5, mu_o, roughness);
  terms.E_avg = LookupAverage(t.E_avg, roughness);
  terms.ms_dielectric = MultipleScatteringFresnel(kDielectricF0, terms.E_avg);
  auto coating = [&](float E, float E5) { return kDielectricF0 * E + (1 - kDielectricF0) * E5 + (1 - E) * terms.ms_dielectric; };
  terms.Espec_o = coating(terms.E_o, terms.E5_o);
  terms.Espec_i = coating(terms.E_i, Lookup(t.E5, mu_i, roughness));
  terms.Espec_avg = coating(terms.E_avg, LookupAverage(t.E5_avg, roughness));
  return terms;
}

}  // namespace

float GgxDirectionalAlbedo(float mu, float roughness) { return Lookup(GetTables().E, mu, roughness); }
float GgxAverageAlbedo(float roughness) { return LookupAverage(GetTables().E_avg, roughness); }

GlossyBsdf::GlossyBsdf(const Gloss& gloss, const float* albedo, int band_count)
    : albedo_(albedo),
      band_count_(band_count),
      metallic_(std::clamp(gloss.metallic, 0.0f, 1.0f)),
      alpha_(std::max(gloss.roughness, kMinRoughness) * std::max(gloss.roughness, kMinRoughness)),
      // Half the directions from the specular lobe on a dielectric, all on a
      // metal (whose base is black): the cosine lobe covers the rest.
      specular_probability_(0.5f + 0.5f * std::clamp(gloss.metallic, 0.0f, 1.0f)) {}

void GlossyBsdf::Eval(const Vec3f& n, const Vec3f& wo, const Vec3f& wi, float* f) const {
  const float mu_o = n.dot(wo), mu_i = n.dot(wi);
  if (!(mu_o > 0 && mu_i > 0)) {
    std::fill(f, f + band_count_, 0.0f);
    return;
  }
  const float roughness = std::sqrt(alpha_);
  const Vec3f h = (wo + wi).normalized();
  const float cos_oh = std::max(0.0f, wo.dot(h));
  const float specular = D(n.dot(h), alpha_) / (1 + Lambda(mu_o, alpha_) + Lambda(mu_i, alpha_)) / (4 * mu_o * mu_i);
  const float schlick = std::pow(1 - cos_oh, 5.0f);
  const Terms t = TermsAt(mu_o, mu_i, roughness);
  const float ms = (1 - t.E_o) * (1 - t.E_i) / (kPiF * (1 - t.E_avg));
  const float base = (1 - t.Espec_o) * (1 - t.Espec_i) / (kPiF * (1 - t.Espec_avg));
  const float m = metallic_;
  for (int b = 0; b < band_count_; ++b) {
    const float c = albedo_[b];
    const float F0 = (1 - m) * kDielectricF0 + m * c;
    const float F = F0 + (1 - F0) * schlick;
    const float ms_fresnel = (1 - m) * t.ms_dielectric + m * MultipleScatteringFresnel(c, t.E_avg);
    f[b] = specular * F + ms * ms_fresnel + (1 - m) * c * base;
  }
}

float GlossyBsdf::Pdf(const Vec3f& n, const Vec3f& wo, const Vec3f& wi) const {
  const float mu_o = n.dot(wo), mu_i = n.dot(wi);
  if (!(mu_o > 0 && mu_i > 0)) return 0.0f;
  const Vec3f h = (wo + wi).normalized();
  // Visible normals: G1(wo) D(h) max(0, wo.h) / mu_o, over 4 wo.h for the reflection.
  const float specular = D(n.dot(h), alpha_) / (1 + Lambda(mu_o, alpha_)) / (4 * mu_o);
  return specular_probability_ * specular + (1 - specular_probability_) * mu_i * kInvPiF;
}

bool GlossyBsdf::Sample(const Vec3f& n, const Vec3f& wo, float u0, float u1, float u2, Vec3f* wi,
                        float* pdf) const {
  const TangentFrame frame(n);
  if (u0 < specular_probability_) {
    const Vec3f wo_local = frame.ToLocal(wo);
    if (!(wo_local.z() > 0)) return false;
    const Vec3f h_local = SampleVisibleNormal(wo_local, alpha_, u1, u2);
    const Vec3f h = frame.ToWorld(h_local.x(), h_local.y(), h_local.z());
    *wi = 2 * wo.dot(h) * h - wo;
  } else {
    *wi = SampleCosineHemisphere(frame, u1, u2);
  }
  if (!(n.dot(*wi) > 0)) return false;
  *pdf = Pdf(n, wo, *wi);
  return *pdf > 0;
}

void GlossyBsdf::DirectionalAlbedo(float cos_o, float* rho) const {
  const float roughness = std::sqrt(alpha_);
  const Terms t = TermsAt(std::max(cos_o, 1e-4f), 1.0f, roughness);
  const float m = metallic_;
  for (int b = 0; b < band_count_; ++b) {
    const float c = albedo_[b];
    const float metal = c * t.E_o + (1 - c) * t.E5_o + (1 - t.E_o) * MultipleScatteringFresnel(c, t.E_avg);
    rho[b] = (1 - m) * (t.Espec_o + c * (1 - t.Espec_o)) + m * metal;
  }
}

}  // namespace phos::render
