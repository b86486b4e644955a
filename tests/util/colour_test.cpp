#include "phos/util/colour.h"

#include <cmath>
#include <gtest/gtest.h>
#include <random>
#include <stdexcept>

namespace phos {
namespace {

// Sharma, Wu and Dalal (2005), Table 1: the 34 test pairs (L*a*b* of each
// sample, and the CIEDE2000 difference to four decimals). Pairs 7-16 probe
// the hue angle's discontinuities (a' = 0, mean hue across 0/360 degrees),
// 17-24 large and unit differences, 25-34 the BFD, RIT-DuPont and Leeds data.
struct SharmaPair {
  Lab lab1, lab2;
  double dE00;
};
const SharmaPair kSharma2005[] = {
    {{50.0000, 2.6772, -79.7751}, {50.0000, 0.0000, -82.7485}, 2.0425},
    {{50.0000, 3.1571, -77.2803}, {50.0000, 0.0000, -82.7485}, 2.8615},
    {{50.0000, 2.8361, -74.0200}, {50.0000, 0.0000, -82.7485}, 3.4412},
    {{50.0000, -1.3802, -84.2814}, {50.0000, 0.0000, -82.7485}, 1.0000},
    {{50.0000, -1.1848, -84.8006}, {50.0000, 0.0000, -82.7485}, 1.0000},
    {{50.0000, -0.9009, -85.5211}, {50.0000, 0.0000, -82.7485}, 1.0000},
    {{50.0000, 0.0000, 0.0000}, {50.0000, -1.0000, 2.0000}, 2.3669},
    {{50.0000, -1.0000, 2.0000}, {50.0000, 0.0000, 0.0000}, 2.3669},
    {{50.0000, 2.4900, -0.0010}, {50.0000, -2.4900, 0.0009}, 7.1792},
    {{50.0000, 2.4900, -0.0010}, {50.0000, -2.4900, 0.0010}, 7.1792},
    {{50.0000, 2.4900, -0.0010}, {50.0000, -2.4900, 0.0011}, 7.2195},
    {{50.0000, 2.4900, -0.0010}, {50.0000, -2.4900, 0.0012}, 7.2195},
    {{50.0000, -0.0010, 2.4900}, {50.0000, 0.0009, -2.4900}, 4.8045},
    {{50.0000, -0.0010, 2.4900}, {50.0000, 0.0010, -2.4900}, 4.8045},
    {{50.0000, -0.0010, 2.4900}, {50.0000, 0.0011, -2.4900}, 4.7461},
    {{50.0000, 2.5000, 0.0000}, {50.0000, 0.0000, -2.5000}, 4.3065},
    {{50.0000, 2.5000, 0.0000}, {73.0000, 25.0000, -18.0000}, 27.1492},
    {{50.0000, 2.5000, 0.0000}, {61.0000, -5.0000, 29.0000}, 22.8977},
    {{50.0000, 2.5000, 0.0000}, {56.0000, -27.0000, -3.0000}, 31.9030},
    {{50.0000, 2.5000, 0.0000}, {58.0000, 24.0000, 15.0000}, 19.4535},
    {{50.0000, 2.5000, 0.0000}, {50.0000, 3.1736, 0.5854}, 1.0000},
    {{50.0000, 2.5000, 0.0000}, {50.0000, 3.2972, 0.0000}, 1.0000},
    {{50.0000, 2.5000, 0.0000}, {50.0000, 1.8634, 0.5757}, 1.0000},
    {{50.0000, 2.5000, 0.0000}, {50.0000, 3.2592, 0.3350}, 1.0000},
    {{60.2574, -34.0099, 36.2677}, {60.4626, -34.1751, 39.4387}, 1.2644},
    {{63.0109, -31.0961, -5.8663}, {62.8187, -29.7946, -4.0864}, 1.2630},
    {{61.2901, 3.7196, -5.3901}, {61.4292, 2.2480, -4.9620}, 1.8731},
    {{35.0831, -44.1164, 3.7933}, {35.0232, -40.0716, 1.5901}, 1.8645},
    {{22.7233, 20.0904, -46.6940}, {23.0331, 14.9730, -42.5619}, 2.0373},
    {{36.4612, 47.8580, 18.3852}, {36.2715, 50.5065, 21.2231}, 1.4146},
    {{90.8027, -2.0831, 1.4410}, {91.1528, -1.6435, 0.0447}, 1.4441},
    {{90.9257, -0.5406, -0.9208}, {88.6381, -0.8985, -0.7239}, 1.5381},
    {{6.7747, -0.2908, -2.4247}, {5.8714, -0.0985, -2.2286}, 0.6377},
    {{2.0776, 0.0795, -1.1350}, {0.9033, -0.0636, -0.5514}, 0.9082},
};

TEST(Ciede2000, MatchesSharmaWuDalalTestData) {
  int pair = 1;
  for (const SharmaPair& p : kSharma2005) {
    // The table rounds to four decimals.
    EXPECT_NEAR(Ciede2000(p.lab1, p.lab2), p.dE00, 0.5e-4 + 1e-12) << "pair " << pair;
    ++pair;
  }
}

TEST(Ciede2000, IsSymmetricAndZeroOnIdenticalColours) {
  for (const SharmaPair& p : kSharma2005) {
    EXPECT_NEAR(Ciede2000(p.lab2, p.lab1), Ciede2000(p.lab1, p.lab2), 1e-12);
    EXPECT_EQ(Ciede2000(p.lab1, p.lab1), 0.0);
  }
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> L(0, 100), ab(-100, 100);
  for (int i = 0; i < 10000; ++i) {
    const Lab x{L(rng), ab(rng), ab(rng)}, y{L(rng), ab(rng), ab(rng)};
    const double d = Ciede2000(x, y);
    ASSERT_TRUE(std::isfinite(d));
    EXPECT_GE(d, 0.0);
    EXPECT_NEAR(Ciede2000(y, x), d, 1e-9 * (1 + d));
  }
}

TEST(XyzToLab, WhiteIsL100AndNeutral) {
  const Tristimulus white = D65WhiteXyz();
  const Lab lab = XyzToLab(white, white);
  EXPECT_NEAR(lab.L, 100, 1e-12);
  EXPECT_NEAR(lab.a, 0, 1e-12);
  EXPECT_NEAR(lab.b, 0, 1e-12);
  // Middle grey (Y = 0.18 of the white) has L* = 49.5, still neutral.
  const Lab grey = XyzToLab({0.18 * white[0], 0.18 * white[1], 0.18 * white[2]}, white);
  EXPECT_NEAR(grey.L, 116 * std::cbrt(0.18) - 16, 1e-12);
  EXPECT_NEAR(grey.L, 49.4961, 1e-4);
  EXPECT_NEAR(grey.a, 0, 1e-12);
  EXPECT_NEAR(grey.b, 0, 1e-12);
  // Black is L* = 0; the linear segment meets the cube root at (6/29)^3.
  EXPECT_NEAR(XyzToLab({0, 0, 0}, white).L, 0, 1e-12);
  const double t = std::pow(6.0 / 29.0, 3);
  EXPECT_NEAR(XyzToLab({t * white[0], t * (1 - 1e-12), t * white[2]}, white).L,
              XyzToLab({t * white[0], t * (1 + 1e-12), t * white[2]}, white).L, 1e-9);
}

TEST(XyzToLab, SrgbRedHasItsKnownLab) {
  // sRGB (1, 0, 0) is XYZ (0.4124, 0.2126, 0.0193): L*a*b* (53.24, 80.09, 67.20)
  // against D65 (the usual published value).
  const Lab red = XyzToLab({0.412456, 0.212673, 0.019334}, D65WhiteXyz());
  EXPECT_NEAR(red.L, 53.24, 0.01);
  EXPECT_NEAR(red.a, 80.09, 0.02);
  EXPECT_NEAR(red.b, 67.20, 0.02);
}

TEST(D65White, IsWhiteInLinearSrgb) {
  const Tristimulus rgb = XyzToLinearSrgb(D65WhiteXyz());
  for (double v : rgb) EXPECT_NEAR(v, 1.0, 1e-4);
}

TEST(FitColourMatrix, RecoversAKnownMatrixAndRefusesAPlane) {
  const ColourMatrix M = {{{0.5, 0.3, 0.1}, {0.2, 0.9, -0.1}, {0.0, 0.1, 1.2}}};
  std::vector<Tristimulus> from, to;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  for (int k = 0; k < 20; ++k) {
    from.push_back({u(rng), u(rng), u(rng)});
    to.push_back(Apply(M, from.back()));
  }
  const ColourMatrix fitted = FitColourMatrix(from, to);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(fitted[i][j], M[i][j], 1e-12);
  // Samples in a plane (the third coordinate always 0) cannot fix M.
  for (Tristimulus& v : from) v[2] = 0;
  EXPECT_THROW(FitColourMatrix(from, to), std::invalid_argument);
  EXPECT_THROW(FitColourMatrix({{1, 0, 0}}, {}), std::invalid_argument);
}

TEST(Cie1931Cmf, PeaksWhereTheTablesDo) {
  // CIE 1931 tables: ybar peaks at 555 nm with 1.0 (the fit: within 1%),
  // xbar has its main lobe near 600 nm and zbar near 445 nm.
  EXPECT_NEAR(Cie1931Cmf(555)[1], 1.0, 0.01);
  EXPECT_NEAR(Cie1931Cmf(600)[0], 1.0622, 0.03);
  EXPECT_NEAR(Cie1931Cmf(445)[2], 1.7826, 0.05);
  // A band mean of a constant-width band lies between the function's extremes on it.
  const Tristimulus mean = Cie1931CmfBandMean(550, 560);
  EXPECT_GT(mean[1], Cie1931Cmf(550)[1] - 0.01);
  EXPECT_LT(mean[1], 1.01);
}

}  // namespace
}  // namespace phos
