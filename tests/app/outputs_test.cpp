// Every output path of every command is checked before any work (util's
// RequireOutputFile and RequireFolderOrNothing): a folder where a file is
// expected, a file where a folder is, an image without an image extension,
// a path under a file. One line, exit 2, and nothing written, not even the
// outputs that come first (fit session's material before its report, the
// frames before the contact sheet).

#include <algorithm>
#include <filesystem>
#include <gtest/gtest.h>
#include <string>
#include <vector>

#include "test_util.h"

namespace phos {
namespace {

using testing::RunPhos;

std::string Fixture(const std::string& name) { return testing::Fixture(name).string(); }

// The names in a folder, sorted.
std::vector<std::string> Entries(const std::filesystem::path& dir) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(dir))
    names.push_back(entry.path().lexically_relative(dir).string());
  std::sort(names.begin(), names.end());
  return names;
}

TEST(OutputPaths, AreRefusedBeforeAnyWorkAndNothingIsWritten) {
  testing::TempDir dir;
  std::filesystem::create_directory(dir / "adir");
  testing::WriteText(dir / "afile", "keep");
  const std::string d = dir.path().string() + "/";
  const std::string simulate =
      "simulate --material " + Fixture("materials/green.json") + " --charge-s 1 --irradiance 1,1,1,0,0,0,0,0 --dt 1";
  const std::string render = "render " + Fixture("scenes/still-life.json") + " --times 0,30 --width 32 --height 24";
  struct Case {
    std::string arguments, expected;
  };
  const std::vector<Case> cases = {
      {simulate + " --out " + d + "adir", "--out: '" + d + "adir' is a folder, not a file"},
      {simulate + " --out " + d + "g.csv --plot " + d + "g.png",
       "--plot: '" + d + "g.png': expected a file name ending in .svg"},
      {simulate + " --plot " + d + "afile/g.svg",
       "--plot: '" + d + "afile/g.svg' cannot be written: '" + d + "afile' is a file, not a folder"},
      {"plot " + d + "g.csv --out " + d + "adir/", "--out: '" + d + "adir/' is a folder, not a file"},
      {"fit decay-curve " + Fixture("curves/decay-two-components.csv") + " --plot " + d + "fit",
       "--plot: '" + d + "fit': expected a file name ending in .svg"},
      {"fit charge-curve " + Fixture("curves/charge.csv") + " --plot " + d + "adir",
       "--plot: '" + d + "adir' is a folder"},
      {"edit solve " + Fixture("constraints/glow-sign.json") + " --out " + d + "adir",
       "--out: '" + d + "adir' is a folder"},
      // The material would be written first, then the report refused, after the whole fit.
      {"fit session " + d + "no-session --out " + d + "f.json --report " + d + "adir",
       "--report: '" + d + "adir' is a folder"},
      {"fit session " + d + "no-session --out " + d + "adir --report " + d + "r.html",
       "--out: '" + d + "adir' is a folder"},
      {"fit map " + d + "no-session --out " + d + "afile", "--out: '" + d + "afile' is a file, not a folder"},
      {"fit batch " + d + "no-session --out " + d + "afile", "--out: '" + d + "afile' is a file, not a folder"},
      // Every frame would be rendered, then the sheet refused.
      {render + " --out " + d + "frames --contact-sheet " + d + "sheet",
       "--contact-sheet: '" + d + "sheet': expected a file name ending in .png, .jpg, .jpeg, .tif or .tiff"},
      {render + " --out " + d + "frames --contact-sheet " + d + "adir", "--contact-sheet: '" + d + "adir' is a folder"},
      {render + " --out " + d + "afile", "--out: '" + d + "afile' is a file, not a folder"},
      {render + " --out " + d + "afile/frames",
       "--out: '" + d + "afile/frames' cannot be written: '" + d + "afile' is a file"},
      {render + " --solve-only --checkpoints " + d + "afile",
       "--checkpoints: '" + d + "afile' is a file, not a folder"},
  };
  for (const Case& c : cases) {
    const auto result = RunPhos(c.arguments);
    EXPECT_TRUE(testing::IsOneLineUserError(result, c.expected)) << c.arguments;
    EXPECT_EQ(Entries(dir.path()), (std::vector<std::string>{"adir", "afile"})) << c.arguments;
    EXPECT_EQ(testing::ReadText(dir / "afile"), "keep");
  }
}

TEST(OutputPaths, FoldersStillToBeMadeAreMade) {
  // A file's folders need not exist: they are made, as --out folders are.
  testing::TempDir dir;
  const auto result = RunPhos("simulate --material " + Fixture("materials/green.json") +
                              " --charge-s 1 --irradiance 1,1,1,0,0,0,0,0 --dt 1 --out " +
                              (dir / "results/green/g.csv").string() + " --plot " + (dir / "plots/g.SVG").string());
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_TRUE(std::filesystem::is_regular_file(dir / "results/green/g.csv"));
  EXPECT_TRUE(std::filesystem::is_regular_file(dir / "plots/g.SVG"));
}

}  // namespace
}  // namespace phos
