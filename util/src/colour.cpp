#include "phos/util/colour.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace phos {

namespace {

// One lobe of Wyman, Sloan and Shirley's fit: a Gaussian with a different
// width on each side of its peak.
double Lobe(double nm, double mu, double sigma_low, double sigma_high) {
  const double s = (nm - mu) / (nm < mu ? sigma_low : sigma_high);
  return std::exp(-0.5 * s * s);
}

}  // namespace

Tristimulus Cie1931Cmf(double nm) {
  return {
      1.056 * Lobe(nm, 599.8, 37.9, 31.0) + 0.362 * Lobe(nm, 442.0, 16.0, 26.7) - 0.065 * Lobe(nm, 501.1, 20.4, 26.2),
      0.821 * Lobe(nm, 568.8, 46.9, 40.5) + 0.286 * Lobe(nm, 530.9, 16.3, 31.1),
      1.217 * Lobe(nm, 437.0, 11.8, 36.0) + 0.681 * Lobe(nm, 459.0, 26.0, 13.8)};
}

Tristimulus Cie1931CmfBandMean(double lower_nm, double upper_nm) {
  const double width_nm = upper_nm - lower_nm;
  const int steps = std::max(8, static_cast<int>(width_nm));
  Tristimulus mean = {0, 0, 0};
  for (int k = 0; k < steps; ++k) {
    const Tristimulus cmf = Cie1931Cmf(lower_nm + (k + 0.5) * width_nm / steps);
    for (int c = 0; c < 3; ++c) mean[c] += cmf[c] / steps;
  }
  return mean;
}

Tristimulus Apply(const ColourMatrix& m, const Tristimulus& v) {
  Tristimulus out = {0, 0, 0};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) out[i] += m[i][j] * v[j];
  return out;
}

ColourMatrix FitColourMatrix(const std::vector<Tristimulus>& from, const std::vector<Tristimulus>& to) {
  if (from.size() != to.size()) throw std::invalid_argument("FitColourMatrix: as many targets as samples are needed");
  // M = (sum to from^T) (sum from from^T)^-1.
  ColourMatrix A{}, B{};  // A = sum from from^T, B = sum to from^T
  for (std::size_t k = 0; k < from.size(); ++k)
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        A[i][j] += from[k][i] * from[k][j];
        B[i][j] += to[k][i] * from[k][j];
      }
  // The inverse of the symmetric A by its adjugate.
  const double det = A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) -
                     A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0]) +
                     A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]);
  double scale = 0;
  for (const auto& row : A)
    for (double v : row) scale = std::max(scale, std::fabs(v));
  if (!(std::fabs(det) > 1e-12 * scale * scale * scale))
    throw std::invalid_argument("FitColourMatrix: the samples do not span three dimensions");
  ColourMatrix inverse;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const int r0 = (j + 1) % 3, r1 = (j + 2) % 3, c0 = (i + 1) % 3, c1 = (i + 2) % 3;
      inverse[i][j] = (A[r0][c0] * A[r1][c1] - A[r0][c1] * A[r1][c0]) / det;
    }
  ColourMatrix M{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) M[i][j] += B[i][k] * inverse[k][j];
  return M;
}

Tristimulus D65WhiteXyz() { return {0.95047, 1.0, 1.08883}; }

Lab XyzToLab(const Tristimulus& xyz, const Tristimulus& white) {
  // CIE 15:2004 Eq. 8.2-8.4: f(t) = t^(1/3) above (6/29)^3, else the tangent
  // line t / (3 (6/29)^2) + 4/29.
  constexpr double delta = 6.0 / 29.0;
  auto f = [](double t) { return t > delta * delta * delta ? std::cbrt(t) : t / (3 * delta * delta) + 4.0 / 29.0; };
  const double fx = f(xyz[0] / white[0]), fy = f(xyz[1] / white[1]), fz = f(xyz[2] / white[2]);
  return {116 * fy - 16, 500 * (fx - fy), 200 * (fy - fz)};
}

double Ciede2000(const Lab& lab1, const Lab& lab2) {
  // Sharma, Wu and Dalal (2005), Eqs. 2-25, kL = kC = kH = 1. Angles in degrees
  // as the paper states them, converted at each trigonometric call.
  constexpr double kDeg = std::numbers::pi / 180;
  constexpr double kPow25To7 = 6103515625.0;  // 25^7
  // Eqs. 2-7: a' stretches a* near the neutral axis; C' and h' from it.
  const double C1 = std::hypot(lab1.a, lab1.b), C2 = std::hypot(lab2.a, lab2.b);
  const double C_mean = 0.5 * (C1 + C2);
  const double C_mean7 = std::pow(C_mean, 7);
  const double G = 0.5 * (1 - std::sqrt(C_mean7 / (C_mean7 + kPow25To7)));
  const double a1 = (1 + G) * lab1.a, a2 = (1 + G) * lab2.a;
  const double Cp1 = std::hypot(a1, lab1.b), Cp2 = std::hypot(a2, lab2.b);
  // h' = 0 where a' = b = 0 (Eq. 7), else atan2 in [0, 360).
  auto hue = [](double b, double a) {
    if (a == 0 && b == 0) return 0.0;
    const double h = std::atan2(b, a) / kDeg;
    return h < 0 ? h + 360 : h;
  };
  const double hp1 = hue(lab1.b, a1), hp2 = hue(lab2.b, a2);
  // Eqs. 8-12: differences; the hue difference takes the shorter way round
  // and is 0 when either chroma is 0.
  const double dLp = lab2.L - lab1.L;
  const double dCp = Cp2 - Cp1;
  double dhp = 0;
  if (Cp1 * Cp2 != 0) {
    dhp = hp2 - hp1;
    if (dhp > 180)
      dhp -= 360;
    else if (dhp < -180)
      dhp += 360;
  }
  const double dHp = 2 * std::sqrt(Cp1 * Cp2) * std::sin(0.5 * dhp * kDeg);
  // Eqs. 13-22: means and the weighting functions.
  const double Lp_mean = 0.5 * (lab1.L + lab2.L);
  const double Cp_mean = 0.5 * (Cp1 + Cp2);
  double hp_mean = hp1 + hp2;  // Eq. 14: the mean hue, again the shorter way round
  if (Cp1 * Cp2 != 0) {
    if (std::fabs(hp1 - hp2) <= 180)
      hp_mean *= 0.5;
    else if (hp1 + hp2 < 360)
      hp_mean = 0.5 * (hp1 + hp2 + 360);
    else
      hp_mean = 0.5 * (hp1 + hp2 - 360);
  }
  const double T = 1 - 0.17 * std::cos((hp_mean - 30) * kDeg) + 0.24 * std::cos(2 * hp_mean * kDeg) +
                   0.32 * std::cos((3 * hp_mean + 6) * kDeg) - 0.20 * std::cos((4 * hp_mean - 63) * kDeg);
  const double d_theta = 30 * std::exp(-std::pow((hp_mean - 275) / 25, 2));
  const double Cp_mean7 = std::pow(Cp_mean, 7);
  const double R_C = 2 * std::sqrt(Cp_mean7 / (Cp_mean7 + kPow25To7));
  const double L50 = (Lp_mean - 50) * (Lp_mean - 50);
  const double S_L = 1 + 0.015 * L50 / std::sqrt(20 + L50);
  const double S_C = 1 + 0.045 * Cp_mean;
  const double S_H = 1 + 0.015 * Cp_mean * T;
  const double R_T = -std::sin(2 * d_theta * kDeg) * R_C;
  // Eq. 25.
  const double l = dLp / S_L, c = dCp / S_C, h = dHp / S_H;
  return std::sqrt(l * l + c * c + h * h + R_T * c * h);
}

}  // namespace phos
