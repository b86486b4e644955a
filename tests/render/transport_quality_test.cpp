// The expected quality behind --budget-s and --quality (transport_quality.h):
// the table built into the renderer is the DSS trade study's output, the
// same numbers as its CSV (docs/dss-trade.csv), and its reader refuses what
// is not such a table.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "phos/render/transport_quality.h"
#include "phos/util/error.h"
#include "test_util.h"

namespace phos::render {
namespace {

// SSIM per (method, parameters) of the study's glow's-bounce rows.
std::map<std::string, double> StudyGlowSsim() {
  std::ifstream csv(std::filesystem::path(PHOS_FIXTURES_DIR) / ".." / "docs" / "dss-trade.csv");
  std::map<std::string, double> ssim;
  std::string line;
  while (std::getline(csv, line)) {
    std::vector<std::string> f;
    std::stringstream cells(line);
    for (std::string cell; std::getline(cells, cell, ',');) f.push_back(cell);
    if (f.size() == 6 && f[0].rfind("cornell-phosphor t=40 s", 0) == 0) ssim[f[1] + " " + f[2]] = std::stod(f[5]);
  }
  return ssim;
}

TEST(TransportQuality, TheBuiltInTableIsTheStudysMeasurement) {
  const TransportQuality& q = MeasuredTransportQuality();
  const std::map<std::string, double> study = StudyGlowSsim();
  ASSERT_FALSE(study.empty()) << "docs/dss-trade.csv has no glow's-bounce rows";
  EXPECT_DOUBLE_EQ(q.direct_ssim, study.at("direct (no bounce) -"));
  EXPECT_DOUBLE_EQ(q.dss_ssim, study.at("deep screen space (direct + one bounce) defaults"));
  ASSERT_FALSE(q.path_ssim.empty());
  for (const auto& [spp, ssim] : q.path_ssim)
    EXPECT_DOUBLE_EQ(ssim, study.at("path tracer spp=" + std::to_string(spp))) << spp << " spp";
  EXPECT_EQ(q.scene, "fixtures/scenes/cornell-phosphor.json");
  EXPECT_NE(q.source.find("phos-dss-study"), std::string::npos);
}

TEST(TransportQuality, PathSsimIsMeasuredThenNoiseHalvesPer4xSamples) {
  TransportQuality q;
  q.path_ssim = {{4, 0.6}, {16, 0.8}, {64, 0.92}};
  EXPECT_DOUBLE_EQ(q.PathSsim(16), 0.8);
  EXPECT_DOUBLE_EQ(q.PathSsim(1), 0.6);  // below the first: the first
  EXPECT_NEAR(q.PathSsim(8), 0.7, 1e-12);  // halfway in log spp
  EXPECT_NEAR(q.PathSsim(256), 1 - 0.08 / 2, 1e-12);
  EXPECT_NEAR(q.PathSsim(1024), 1 - 0.08 / 4, 1e-12);
  EXPECT_NEAR(q.PathSsim(128), 1 - 0.08 / std::sqrt(2.0), 1e-12);
  // Written and read back, it is the same table.
  q.source = "s";
  q.scene = "x.json";
  q.view = "v";
  q.reference = "r";
  q.direct_ssim = 0.4;
  q.dss_ssim = 0.9;
  const nlohmann::json j = q.ToJson();
  const TransportQuality back = TransportQuality::FromJson(JsonField(j, "t.json"));
  EXPECT_EQ(back.ToJson(), j);
}

TEST(TransportQuality, ATableThatIsNotOneIsOneLineNamingTheField) {
  const nlohmann::json good = MeasuredTransportQuality().ToJson();
  auto refusal = [](const nlohmann::json& j) {
    try {
      TransportQuality::FromJson(JsonField(j, "t.json"));
    } catch (const UserError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  nlohmann::json j = good;
  j["dss_ssim"] = 2;
  EXPECT_NE(refusal(j).find("dss_ssim"), std::string::npos) << refusal(j);
  j = good;
  j["path"] = nlohmann::json::array({{{"spp", 16}, {"ssim", 0.8}}, {{"spp", 4}, {"ssim", 0.6}}});
  EXPECT_NE(refusal(j).find("must increase"), std::string::npos) << refusal(j);
  j = good;
  j["path"] = nlohmann::json::array();
  EXPECT_NE(refusal(j).find("path"), std::string::npos) << refusal(j);
  j = good;
  j["ssim_of_magic"] = 1;
  EXPECT_NE(refusal(j).find("ssim_of_magic"), std::string::npos) << refusal(j);
  j = good;
  j.erase("scene");
  EXPECT_NE(refusal(j).find("scene"), std::string::npos) << refusal(j);
  EXPECT_EQ(refusal(good), "accepted");
}

}  // namespace
}  // namespace phos::render
