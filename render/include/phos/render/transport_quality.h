#pragma once
// The expected quality of each transport, behind `phos render --budget-s`
// and `--quality` (ChooseTransport): mean SSIM of the glow's light against
// the path tracer at many samples, as the DSS trade study measured it
// (docs/dss-trade.md, "The glow's bounce"). It is data, not code: the study
// writes render/data/transport-quality.json (`phos-dss-study --quality-table`,
// run by `make study`), and the build compiles that file into the renderer.
// The record says which scene, view and reference it was measured on.

#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "phos/util/json.h"

namespace phos::render {

struct TransportQuality {
  static constexpr const char* kFormat = "phos.transport-quality/1";
  std::string source;     // the command that measured it
  std::string scene;      // the scene, as a path in the repository
  std::string view;       // the time and image it was measured on
  std::string reference;  // what the SSIM is against
  double direct_ssim = 0, dss_ssim = 0;
  std::vector<std::pair<int, double>> path_ssim;  // (spp, SSIM), spp increasing

  // Measured, or past the last spp measured extrapolated as noise falls:
  // 1 - SSIM halves per 4x samples. Below the first spp measured, the first.
  double PathSsim(int spp) const;

  nlohmann::json ToJson() const;
  static TransportQuality FromJson(const JsonField& j);
};

// The table built into this binary (render/data/transport-quality.json).
const TransportQuality& MeasuredTransportQuality();

}  // namespace phos::render
