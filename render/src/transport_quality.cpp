#include "phos/render/transport_quality.h"

#include <cmath>

#include "phos/util/error.h"

namespace phos::render {

// The text of render/data/transport-quality.json, compiled in by
// cmake/EmbedText.cmake (transport_quality_data.cpp in the build folder).
extern const char kTransportQualityJson[];

double TransportQuality::PathSsim(int spp) const {
  PHOS_CHECK(!path_ssim.empty());
  if (spp <= path_ssim.front().first) return path_ssim.front().second;
  for (std::size_t i = 0; i < path_ssim.size(); ++i)
    if (path_ssim[i].first == spp) return path_ssim[i].second;
  const auto& [last_spp, last_ssim] = path_ssim.back();
  if (spp > last_spp) return 1.0 - (1.0 - last_ssim) * std::pow(0.5, std::log(double(spp) / last_spp) / std::log(4.0));
  // Between two measured counts: linear in log spp.
  for (std::size_t i = 1; i < path_ssim.size(); ++i)
    if (spp < path_ssim[i].first) {
      const auto& [s0, q0] = path_ssim[i - 1];
      const auto& [s1, q1] = path_ssim[i];
      const double w = std::log(double(spp) / s0) / std::log(double(s1) / s0);
      return q0 + w * (q1 - q0);
    }
  return last_ssim;
}

nlohmann::json TransportQuality::ToJson() const {
  nlohmann::json path = nlohmann::json::array();
  for (const auto& [spp, ssim] : path_ssim) path.push_back({{"spp", spp}, {"ssim", ssim}});
  return {{"format", kFormat}, {"source", source},         {"scene", scene},
          {"view", view},      {"reference", reference},   {"direct_ssim", direct_ssim},
          {"dss_ssim", dss_ssim}, {"path", path}};
}

TransportQuality TransportQuality::FromJson(const JsonField& j) {
  j.RejectUnknownKeys({"format", "source", "scene", "view", "reference", "direct_ssim", "dss_ssim", "path"});
  if (j["format"].String() != kFormat) j["format"].Fail(std::string("expected \"") + kFormat + "\"");
  TransportQuality q;
  q.source = j["source"].NonEmptyString();
  q.scene = j["scene"].NonEmptyString();
  q.view = j["view"].NonEmptyString();
  q.reference = j["reference"].NonEmptyString();
  q.direct_ssim = j["direct_ssim"].NumberInRange(-1, 1);
  q.dss_ssim = j["dss_ssim"].NumberInRange(-1, 1);
  const JsonField path = j["path"];
  if (path.ArraySize() == 0) path.Fail("needs at least one sample count");
  for (std::size_t i = 0; i < path.ArraySize(); ++i) {
    const JsonField e = path.At(i);
    e.RejectUnknownKeys({"spp", "ssim"});
    const int spp = e["spp"].Integer(1, 1 << 20);
    if (!q.path_ssim.empty() && spp <= q.path_ssim.back().first) e["spp"].Fail("sample counts must increase");
    q.path_ssim.emplace_back(spp, e["ssim"].NumberInRange(-1, 1));
  }
  return q;
}

const TransportQuality& MeasuredTransportQuality() {
  static const TransportQuality table = TransportQuality::FromJson(
      JsonField(ParseJsonText(kTransportQualityJson, "transport-quality.json (built in)"),
                "transport-quality.json (built in)"));
  return table;
}

}  // namespace phos::render
