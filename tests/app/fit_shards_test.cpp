// phos fit map --tile i/N and --merge, phos fit batch --task i/N and --merge
// (array tasks, docs/scale.md): the merged outputs equal one run's, a
// finished task is not run again, a merge with a task missing names it.

#include <gtest/gtest.h>

#include <cstring>

#include <nlohmann/json.hpp>

#include "phos/render/renderer.h"
#include "test_util.h"

namespace phos::testing {
namespace {

TEST(FitShards, MapTilesMergeIntoTheWholeMap) {
  TempDir dir;
  const std::string session = (dir / "s").string();
  ASSERT_EQ(RunPhos("capture decay --sim-material " + Fixture("materials/orange.json").string() + " --sim-inset " +
                    Fixture("materials/blue.json").string() + " --sim-size 40x30 --charge-s 1800 --out " + session)
                .exit_code,
            0);
  const CommandResult whole = RunPhos("fit map " + session + " --out " + (dir / "whole").string());
  ASSERT_EQ(whole.exit_code, 0) << whole.err;
  const std::string tiled = (dir / "tiled").string();
  for (int i : {2, 0})
    ASSERT_EQ(RunPhos("fit map " + session + " --out " + tiled + " --tile " + std::to_string(i) + "/3").exit_code, 0);
  // A tile missing: the merge names it and writes nothing.
  CommandResult merge = RunPhos("fit map " + session + " --out " + tiled + " --merge");
  EXPECT_EQ(merge.exit_code, 2);
  EXPECT_NE(merge.err.find("tile(s) 1 of 3 not done"), std::string::npos) << merge.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "tiled" / "decay-map.exr"));
  ASSERT_EQ(RunPhos("fit map " + session + " --out " + tiled + " --tile 1/3").exit_code, 0);
  // A rerun of a finished tile does nothing.
  const auto tile = dir / "tiled" / "tiles" / "tile-1-of-3.exr";
  const auto written = std::filesystem::last_write_time(tile);
  const CommandResult again = RunPhos("fit map " + session + " --out " + tiled + " --tile 1/3");
  EXPECT_NE(again.out.find("nothing to do"), std::string::npos) << again.out;
  EXPECT_EQ(std::filesystem::last_write_time(tile), written);
  merge = RunPhos("fit map " + session + " --out " + tiled + " --merge");
  ASSERT_EQ(merge.exit_code, 0) << merge.err;
  const render::Image a = render::ReadImage(dir / "whole" / "decay-map.exr"),
                      b = render::ReadImage(dir / "tiled" / "decay-map.exr");
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  ASSERT_EQ(a.pixels.size(), b.pixels.size());
  // Bit for bit, NaN (no decay) where NaN.
  EXPECT_EQ(std::memcmp(a.pixels.data(), b.pixels.data(), a.pixels.size() * sizeof(float)), 0);
  EXPECT_EQ(ReadText(dir / "whole" / "kr.png"), ReadText(dir / "tiled" / "kr.png"));
  // The merge says what one run says (the fitting time aside).
  EXPECT_EQ(whole.out.substr(whole.out.find("  kr:")), merge.out.substr(merge.out.find("  kr:")));
  // Tiles of other options are not this map's.
  merge = RunPhos("fit map " + session + " --out " + tiled + " --merge --weights none");
  EXPECT_EQ(merge.exit_code, 2);
}

TEST(FitShards, TwoStateMapTilesMergeIntoTheWholeMap) {
  TempDir dir;
  const std::string session = (dir / "s").string();
  ASSERT_EQ(RunPhos("capture decay --sim-material " + Fixture("materials/two-state-ratio20.json").string() +
                    " --sim-inset " + Fixture("materials/blue.json").string() +
                    " --sim-size 24x18 --charge-s 1800 --out " + session)
                .exit_code,
            0);
  const CommandResult whole = RunPhos("fit map " + session + " --out " + (dir / "whole").string() + " --states 2");
  ASSERT_EQ(whole.exit_code, 0) << whole.err;
  const std::string tiled = (dir / "tiled").string();
  for (int i : {0, 1})
    ASSERT_EQ(RunPhos("fit map " + session + " --out " + tiled + " --states 2 --tile " + std::to_string(i) + "/2")
                  .exit_code,
              0);
  // Tiles of one state are not this map's: the merge with --states 1 refuses them.
  CommandResult merge = RunPhos("fit map " + session + " --out " + tiled + " --merge");
  EXPECT_EQ(merge.exit_code, 2);
  merge = RunPhos("fit map " + session + " --out " + tiled + " --merge --states 2");
  ASSERT_EQ(merge.exit_code, 0) << merge.err;
  const render::Image a = render::ReadImage(dir / "whole" / "decay-map.exr"),
                      b = render::ReadImage(dir / "tiled" / "decay-map.exr");
  EXPECT_EQ(a.channels, 12);
  ASSERT_EQ(a.pixels.size(), b.pixels.size());
  EXPECT_EQ(std::memcmp(a.pixels.data(), b.pixels.data(), a.pixels.size() * sizeof(float)), 0);
  // The merge says what one run says, the count of one-state pixels too.
  EXPECT_EQ(whole.out.substr(whole.out.find("  kr:")), merge.out.substr(merge.out.find("  kr:")));
}

TEST(FitShards, BatchTasksThenMergeEqualOneBatch) {
  TempDir dir;
  for (const char* name : {"orange", "blue"})
    ASSERT_EQ(RunPhos("capture all --sim-material " + Fixture(std::string("materials/") + name + ".json").string() +
                      " --sim-size 16x12 --out " + (dir / "captures" / name).string())
                  .exit_code,
              0);
  const std::string captures = (dir / "captures").string();
  ASSERT_EQ(RunPhos("fit batch " + captures + " --out " + (dir / "whole").string()).exit_code, 0);
  const std::string out = (dir / "tasks").string();
  ASSERT_EQ(RunPhos("fit batch " + captures + " --out " + out + " --task 1/2").exit_code, 0);
  EXPECT_TRUE(std::filesystem::exists(dir / "tasks" / "tasks" / "task-1-of-2.json"));
  EXPECT_FALSE(std::filesystem::exists(dir / "tasks" / "summary.csv"));  // the merge's
  CommandResult merge = RunPhos("fit batch " + captures + " --out " + out + " --merge");
  EXPECT_EQ(merge.exit_code, 2);
  EXPECT_NE(merge.err.find("item(s) not fitted yet: blue"), std::string::npos) << merge.err;
  ASSERT_EQ(RunPhos("fit batch " + captures + " --out " + out + " --task 0/2").exit_code, 0);
  merge = RunPhos("fit batch " + captures + " --out " + out + " --merge --json");
  ASSERT_EQ(merge.exit_code, 0) << merge.err;
  EXPECT_EQ(nlohmann::json::parse(merge.out)["kept"].get<int>(), 2);
  // The summary says where the fits came from: the tasks, not "an earlier run".
  const std::string summary = ReadText(dir / "tasks" / "summary.csv");
  EXPECT_NE(summary.find("fitted before this merge"), std::string::npos) << summary;
  EXPECT_EQ(summary.find("earlier run"), std::string::npos) << summary;
  for (const char* name : {"orange", "blue"})
    EXPECT_EQ(ReadText(dir / "whole" / (std::string(name) + ".json")),
              ReadText(dir / "tasks" / (std::string(name) + ".json")))
        << name;
}

TEST(FitShards, AMergeListsAnItemItsTaskCouldNotFitAsOneBatchDoes) {
  // A capture folder whose session.json is not a session: one process's
  // batch lists it as failed in summary.csv and exits 2; the tasks' merge
  // must write the same row (it wrote no summary at all before).
  TempDir dir;
  ASSERT_EQ(RunPhos("capture all --sim-material " + Fixture("materials/orange.json").string() +
                    " --sim-size 16x12 --out " + (dir / "captures" / "orange").string())
                .exit_code,
            0);
  std::filesystem::create_directories(dir / "captures" / "broken");
  WriteText(dir / "captures" / "broken" / "session.json", "{}");
  const std::string captures = (dir / "captures").string(), out = (dir / "tasks").string();
  EXPECT_EQ(RunPhos("fit batch " + captures + " --out " + (dir / "whole").string()).exit_code, 2);
  EXPECT_EQ(RunPhos("fit batch " + captures + " --out " + out + " --task 0/2").exit_code, 2);  // broken
  EXPECT_EQ(RunPhos("fit batch " + captures + " --out " + out + " --task 1/2").exit_code, 0);  // orange
  const CommandResult merge = RunPhos("fit batch " + captures + " --out " + out + " --merge");
  EXPECT_TRUE(IsOneLineUserError(merge, "1 item(s) could not be fitted")) << merge.err;
  auto row = [](const std::string& csv, const std::string& item) {
    const std::size_t at = csv.find("\n" + item + ",");
    return at == std::string::npos ? std::string() : csv.substr(at + 1, csv.find('\n', at + 1) - at - 1);
  };
  const std::string whole = ReadText(dir / "whole" / "summary.csv"), merged = ReadText(dir / "tasks" / "summary.csv");
  ASSERT_NE(row(whole, "broken"), "") << whole;
  EXPECT_EQ(row(merged, "broken"), row(whole, "broken")) << merged;
  EXPECT_EQ(row(merged, "orange").rfind("orange,kept,", 0), 0u) << merged;
  EXPECT_NE(merge.out.find("0 fitted now, 1 kept, 1 failed"), std::string::npos) << merge.out;
}

}  // namespace
}  // namespace phos::testing
