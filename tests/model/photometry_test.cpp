// Photometry against analytic truths and independent copies of the CIE
// tables (model/include/phos/model/photometry.h).

#include "phos/model/photometry.h"

#include <cmath>
#include <functional>
#include <random>
#include <gtest/gtest.h>

#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

std::string ErrorOf(const std::function<void()>& f) { return testing::ErrorOfType<UserError>(f); }

SampledSpectrum Flat(double lower_nm, double upper_nm, double value) { return {{lower_nm, upper_nm}, {value, value}}; }

// pbrt-v4's CIE_Y_integral (src/pbrt/util/spectrum.h), the integral of its
// own copy of the 1 nm ybar table: an independent check of the 471 values.
constexpr double kPbrtCieYIntegral = 106.856895;

TEST(Photometry, TheTablesAreTheCieOnes) {
  const SampledSpectrum& v = PhotopicEfficiency();
  EXPECT_NEAR(IntegrateAll(v), kPbrtCieYIntegral, 1e-6 * kPbrtCieYIntegral);
  EXPECT_EQ(v.Evaluate(555), 1.0);  // the photopic peak
  for (double nm = 360; nm <= 830; nm += 1) EXPECT_LE(v.Evaluate(nm), 1.0) << nm;
  const SampledSpectrum& vs = ScotopicEfficiency();
  EXPECT_EQ(vs.Evaluate(507), 1.0);  // the scotopic peak
  EXPECT_EQ(vs.Evaluate(555), 0.402);
  for (double nm = 380; nm <= 780; nm += 1) EXPECT_LE(vs.Evaluate(nm), 1.0) << nm;
  EXPECT_EQ(IlluminantD65().Evaluate(560), 100.0);
  EXPECT_EQ(IlluminantD65().Evaluate(460), 117.812);
  EXPECT_EQ(IlluminantD65().Evaluate(830), 60.3125);
  EXPECT_EQ(IlluminantF11().Evaluate(545), 72.84);
  // Illuminant A's formula against its table in CIE 15:2004, to the table's 6 digits.
  const SampledSpectrum a = IlluminantA();
  const std::pair<double, double> table_a[] = {{300, 0.930483}, {380, 9.7951},  {460, 37.8121},
                                               {560, 100.0},    {700, 198.261}, {780, 241.675}};
  for (auto [nm, value] : table_a)
    EXPECT_NEAR(a.Evaluate(nm), value, 0.5 * std::pow(10.0, std::floor(std::log10(value)) - 5)) << nm;
}

TEST(Photometry, IntegrateProductIsExactForPiecewiseLinearSpectra) {
  // x on [0, 10] times (10 - x) sampled elsewhere: the integral of x (10 - x) is 500/3.
  const SampledSpectrum up{{0, 10}, {0, 10}}, down{{0, 3, 10}, {10, 7, 0}};
  EXPECT_NEAR(IntegrateProduct(up, down), 500.0 / 3.0, 1e-12);
  EXPECT_NEAR(IntegrateProduct(down, up), 500.0 / 3.0, 1e-12);
  // Outside each other's range: 0.
  EXPECT_EQ(IntegrateProduct(up, SampledSpectrum{{20, 30}, {1, 1}}), 0.0);
}

// A flat spectral radiance of 1 W/(sr m² nm) over all of V is K_m times the
// integral of V, by the spectrum and by one band covering it alike.
TEST(Photometry, AFlatSpectrumOverAllOfVIsKmTimesTheIntegralOfV) {
  const double truth = 683.0 * IntegrateAll(PhotopicEfficiency());
  EXPECT_NEAR(PhotopicIntegral(Flat(360, 830, 1.0)), truth, 1e-12 * truth);
  const SpectralGrid one_band{{360, 830}};
  EXPECT_NEAR(Luminance({470.0}, one_band), truth, 1e-12 * truth);
  const double scotopic = 1700.0 * IntegrateAll(ScotopicEfficiency());
  EXPECT_NEAR(ScotopicIntegral(Flat(380, 780, 1.0)), scotopic, 1e-12 * scotopic);
  EXPECT_NEAR(ScotopicLuminance({400.0}, SpectralGrid{{380, 780}}), scotopic, 1e-12 * scotopic);
}

// 1 W/(sr m²) in a narrow band at 555 nm is 683 cd/m²; at 507 nm, 1700 scotopic cd/m².
TEST(Photometry, ANarrowBandAtThePeakIsTheEfficacy) {
  EXPECT_NEAR(Luminance({1.0}, SpectralGrid{{554.9, 555.1}}), 683.0, 683.0 * 1e-4);
  EXPECT_NEAR(ScotopicLuminance({1.0}, SpectralGrid{{506.9, 507.1}}), 1700.0, 1700.0 * 1e-4);
  EXPECT_NEAR(PhotopicBandEfficacy(SpectralGrid{{554.9, 555.1}})[0], 683.0, 683.0 * 1e-4);
  // Band radiances add: the luminance is linear in them.
  const SpectralGrid paper = SpectralGrid::Paper();
  const std::vector<double> w = PhotopicBandEfficacy(paper);
  std::vector<double> L(8, 0.0);
  double sum = 0;
  for (int b = 0; b < 8; ++b) {
    L[b] = 0.1 * (b + 1);
    sum += w[b] * L[b];
  }
  EXPECT_NEAR(Luminance(L, paper), sum, 1e-12 * sum);
}

// A source scaled to E lux has E lux, by the spectrum exactly, and by its
// band irradiances on a fine grid to the band approximation.
TEST(Photometry, ASourceScaledToAnIlluminanceGivesItBack) {
  std::mt19937_64 rng(45);
  auto uniform = [&](double lower, double upper) { return std::uniform_real_distribution<double>(lower, upper)(rng); };
  for (const char* name : {"d65", "a", "fluorescent", "led405"}) {
    const SampledSpectrum s = *StandardSource(name);
    const double lux = std::exp(uniform(std::log(1e-3), std::log(1e5)));
    const double k = ScaleForPhotometric(s, lux, name);
    SampledSpectrum scaled = s;
    for (double& v : scaled.value) v *= k;
    EXPECT_NEAR(PhotopicIntegral(scaled), lux, 1e-12 * lux) << name;
    const SpectralGrid fine = SpectralGrid::Uniform(300, 830, 530);
    const std::vector<double> E = BandsForPhotometric(s, lux, fine, name);
    // Lux of W/m² as cd/m² of W/(sr m²); V is not flat inside a 1 nm band
    // (at 405 nm it changes by 13% per nm), so the bands agree to 2e-3.
    EXPECT_NEAR(Luminance(E, fine), lux, 2e-3 * lux) << name;
    // Irradiance: the bands over the whole spectrum hold all of it.
    const double w_m2 = uniform(0.1, 100);
    double total = 0;
    for (double e : BandsForRadiometric(s, w_m2, SpectralGrid{{250, 900}}, name)) total += e;
    EXPECT_NEAR(total, w_m2, 1e-12 * w_m2) << name;
  }
}

// What the band approximation costs on the paper's grid (8 bands over
// 400-700 nm): a source converted exactly at 1000 lx reads back through band
// means of V (the renderer's Y) to 0.2% for the smooth D65 and A, to 3% for
// F11's mercury lines, and not at all for a narrow line on V's steep flank
// (led405 reads 5x). docs/formats.md quotes these.
TEST(Photometry, TheBandApproximationOnThePapersGrid) {
  const SpectralGrid paper = SpectralGrid::Paper();
  auto read_back = [&](const char* name) {
    return Luminance(BandsForPhotometric(*StandardSource(name), 1000, paper, name), paper);
  };
  EXPECT_NEAR(read_back("d65"), 1000, 2);
  EXPECT_NEAR(read_back("a"), 1000, 2);
  EXPECT_NEAR(read_back("fluorescent"), 1000, 30);
  EXPECT_GT(read_back("led405"), 4000);
}

TEST(Photometry, BadSpectraAreRefused) {
  const SampledSpectrum infrared = LedSpectrum(1200, 10);
  EXPECT_EQ(ErrorOf([&] { BandsForPhotometric(infrared, 1000, SpectralGrid::Paper(), "ir.csv"); }),
            "ir.csv: its spectrum has no light V(lambda) sees (360-830 nm): no photometric value scales it");
  EXPECT_FALSE(StandardSource("xenon"));
  testing::TempDir dir;
  const auto write = [&](const std::string& text) {
    testing::WriteText(dir / "s.csv", text);
    return (dir / "s.csv").string();
  };
  const std::string path = write("wavelength_nm,irradiance\n400,1\n500,2\n");
  EXPECT_EQ(LoadSpectrumCsv(path).value, (std::vector<double>{1, 2}));
  EXPECT_EQ(ErrorOf([&] { LoadSpectrumCsv(write("nm,value\n400,1\n500,2\n")); }),
            path + ": a spectrum needs the columns wavelength_nm and irradiance");
  EXPECT_EQ(ErrorOf([&] { LoadSpectrumCsv(write("wavelength_nm,irradiance\n400,1\n")); }),
            path + ": a spectrum needs at least 2 rows");
  EXPECT_EQ(ErrorOf([&] { LoadSpectrumCsv(write("wavelength_nm,irradiance\n400,1\n500,-2\n")); }),
            path + ": irradiance: expected values >= 0, got -2");
  EXPECT_EQ(ErrorOf([&] { LoadSpectrumCsv(write("wavelength_nm,irradiance\n400,1\n400,2\n")); }),
            path + ": wavelength_nm: must increase (400 follows 400)");
}

}  // namespace
}  // namespace phos
