#include "phos/model/spectral.h"

#include <gtest/gtest.h>

namespace phos {
namespace {

TEST(SpectralGrid, PaperGridIsEightBandsOf37_5nm) {
  SpectralGrid g = SpectralGrid::Paper();
  ASSERT_EQ(g.band_count(), 8);
  EXPECT_DOUBLE_EQ(g.lower_nm(0), 400);
  EXPECT_DOUBLE_EQ(g.width_nm(3), 37.5);
  EXPECT_DOUBLE_EQ(g.upper_nm(7), 700);
  EXPECT_EQ(g.BandName(3), "512.5-550 nm");
}

TEST(SampledSpectrum, IntegralOfALinearFunctionIsExact) {
  SampledSpectrum s{{300, 500, 800}, {0, 2, 2}};
  EXPECT_DOUBLE_EQ(s.Evaluate(400), 1);
  EXPECT_DOUBLE_EQ(s.Evaluate(299), 0);
  EXPECT_DOUBLE_EQ(s.Integrate(300, 500), 200);  // triangle
  EXPECT_DOUBLE_EQ(s.Integrate(350, 450), 100);  // mean 1 over 100 nm
  EXPECT_DOUBLE_EQ(s.Integrate(0, 1000), 200 + 600);
  std::vector<double> bands = IntegrateOverBands(s, SpectralGrid::Uniform(300, 800, 5));
  double total = 0;
  for (double b : bands) total += b;
  EXPECT_NEAR(total, 800, 1e-9);
  EXPECT_NEAR(AverageOverBands(s, SpectralGrid::Uniform(500, 800, 3))[1], 2, 1e-12);
}

TEST(RebinIntegrated, ConservesWhatBothGridsCover) {
  SpectralGrid from = SpectralGrid::Paper();
  SpectralGrid to{{380, 490, 580, 720}};  // RGB-like, wider than the source
  std::vector<double> values = {1, 2, 3, 4, 5, 6, 7, 8};
  std::vector<double> out = RebinIntegrated(values, from, to);
  double in_total = 36, out_total = out[0] + out[1] + out[2];
  EXPECT_NEAR(out_total, in_total, 1e-12);
  // 400-490 nm: bands 1, 2 and 40% of band 3.
  EXPECT_NEAR(out[0], 1 + 2 + 3 * (490 - 475) / 37.5, 1e-12);
}

}  // namespace
}  // namespace phos
