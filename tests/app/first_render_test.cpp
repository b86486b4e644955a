// A first render shows the glow: at a number for the exposure (the default
// 1), a run whose glow after dark would show nearly black says so in one
// line, with the exposure "auto" would choose; nothing is said when the glow
// shows, when nothing glows, or when no frame is after dark.

#include <filesystem>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "phos/util/format.h"
#include "test_util.h"

namespace phos {
namespace {

using testing::RunPhos;

TEST(FirstRender, ANearlyBlackGlowAfterDarkIsSaidWithWhatToPass) {
  testing::TempDir dir;
  // The Cornell box: its LED is on until 30 s; 40 and 90 s are after dark.
  const std::string render = "render " + testing::Fixture("scenes/cornell-phosphor.json").string() + " --out " +
                             (dir / "out").string() + " --width 48 --height 48";
  const auto metered = RunPhos(render + " --times 20,40,90 --exposure auto --json");
  ASSERT_EQ(metered.exit_code, 0) << metered.err;
  EXPECT_EQ(metered.err, "");
  const nlohmann::json chosen = nlohmann::json::parse(metered.out);
  const double automatic = chosen["exposure"].get<double>();
  const double luminance = chosen["exposure_auto"]["metered_luminance"].get<double>();
  ASSERT_GT(luminance, 0);

  const auto first = RunPhos(render + " --times 20,40,90");
  ASSERT_EQ(first.exit_code, 0) << first.err;
  const double shown = luminance / (1 + luminance);  // Reinhard at exposure 1
  ASSERT_LT(shown, 0.02);
  EXPECT_EQ(first.err,
            "phos render: warning: exposure 1: the glow after dark is nearly black (the brightest frame's "
            "median glowing pixel shows at " +
                FormatShort(100 * shown, 2) + "% of white); pass --exposure auto, or --exposure " +
                FormatShort(automatic, 3) + "\n");
  // Under the path tracer its frames after dark are metered as auto meters
  // them (their direct-transport frames, at the same --spp): the same number.
  const std::string path = render + " --times 40 --transport path --spp 2";
  const auto path_auto = RunPhos(path + " --exposure auto --json");
  ASSERT_EQ(path_auto.exit_code, 0) << path_auto.err;
  const auto path_first = RunPhos(path);
  ASSERT_EQ(path_first.exit_code, 0) << path_first.err;
  EXPECT_NE(path_first.err.find("--exposure " +
                                FormatShort(nlohmann::json::parse(path_auto.out)["exposure"].get<double>(), 3) + "\n"),
            std::string::npos)
      << path_first.err;

  // Nothing said: at auto's exposure, at one that shows the glow at 2% or
  // more, with no frame after dark, or when nothing glows.
  for (const std::string& quiet :
       std::vector<std::string>{" --times 20,40,90 --exposure " + FormatDouble(automatic),
                                " --times 40 --exposure " + FormatDouble(1.01 * 0.02 / 0.98 / luminance),
                                " --times 10,20", " --times 40 --no-phosphorescence"}) {
    const auto run = RunPhos(render + quiet);
    ASSERT_EQ(run.exit_code, 0) << quiet << ": " << run.err;
    EXPECT_EQ(run.err, "") << quiet;
  }
  const auto dim = RunPhos(render + " --times 40 --exposure " + FormatDouble(0.99 * 0.02 / 0.98 / luminance));
  EXPECT_NE(dim.err.find("nearly black"), std::string::npos) << dim.err;
}

}  // namespace
}  // namespace phos
