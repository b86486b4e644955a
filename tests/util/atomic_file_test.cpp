// util/atomic_file.h, the one way phos replaces a file, and util/random.h,
// the one generator of the renderer.

#include "phos/util/atomic_file.h"

#include <gtest/gtest.h>

#include <cmath>
#include <unistd.h>

#include <stdexcept>

#include "phos/util/error.h"
#include "phos/util/random.h"
#include "test_util.h"

namespace phos {
namespace {

std::size_t EntryCount(const std::filesystem::path& dir) {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir)) ++n;
  return n;
}

TEST(WriteAtomically, ReplacesTheFileWholeAndLeavesNoTemporary) {
  testing::TempDir dir;
  testing::WriteText(dir / "a.json", "old");
  WriteFileAtomically(dir / "a.json", "new contents");
  EXPECT_EQ(testing::ReadText(dir / "a.json"), "new contents");
  WriteFileAtomically(dir / "a.json", "synced", {.sync = true});
  EXPECT_EQ(testing::ReadText(dir / "a.json"), "synced");
  EXPECT_EQ(EntryCount(dir.path()), 1u);
}

TEST(WriteAtomically, AWriterThatFailsLeavesTheOldFileAndNoTemporary) {
  testing::TempDir dir;
  testing::WriteText(dir / "frame.tif", "old frame");
  EXPECT_THROW(WriteAtomically(dir / "frame.tif",
                               [](const std::filesystem::path& temporary) {
                                 testing::WriteText(temporary, "half a fr");
                                 throw std::runtime_error("disk full");
                               }),
               std::runtime_error);
  EXPECT_EQ(testing::ReadText(dir / "frame.tif"), "old frame");
  EXPECT_EQ(EntryCount(dir.path()), 1u);
}

TEST(WriteAtomically, TheTemporaryKeepsTheExtensionAndIsMadeAfreshNeverThroughALink) {
  testing::TempDir dir;
  const std::filesystem::path temporary = AtomicTemporaryPath(dir / "out.exr");
  EXPECT_EQ(temporary.extension(), ".exr");                                   // OpenImageIO chooses the format by it
  EXPECT_NE(temporary.filename().string().find(".tmp."), std::string::npos);  // how a resume finds leftovers
  // A link planted at the temporary's name is removed, and what it points at is untouched.
  testing::WriteText(dir / "victim", "keep me");
  std::filesystem::create_symlink(dir / "victim", temporary);
  WriteAtomically(dir / "out.exr", [](const std::filesystem::path& t) {
    EXPECT_FALSE(std::filesystem::is_symlink(t));
    EXPECT_EQ(std::filesystem::file_size(t), 0u);
    testing::WriteText(t, "image");
  });
  EXPECT_EQ(testing::ReadText(dir / "victim"), "keep me");
  EXPECT_EQ(testing::ReadText(dir / "out.exr"), "image");
  EXPECT_FALSE(std::filesystem::exists(std::filesystem::symlink_status(temporary)));
}

TEST(WriteAtomically, AFolderThatCannotBeWrittenIsOneUserErrorNamingTheFile) {
  if (::geteuid() == 0) GTEST_SKIP() << "root writes into read-only folders";
  testing::TempDir dir;
  std::filesystem::create_directory(dir / "ro");
  std::filesystem::permissions(dir / "ro", std::filesystem::perms::owner_read | std::filesystem::perms::owner_exec);
  const std::string error = testing::ErrorOfType<UserError>([&] { WriteFileAtomically(dir / "ro" / "a.json", "x"); });
  std::filesystem::permissions(dir / "ro", std::filesystem::perms::owner_all);
  EXPECT_NE(error.find("a.json"), std::string::npos) << error;
}

TEST(WriteAtomically, MakesTheFoldersOfThePath) {
  testing::TempDir dir;
  WriteFileAtomically(dir / "results" / "fitted" / "m.json", "{}");
  EXPECT_EQ(testing::ReadText(dir / "results" / "fitted" / "m.json"), "{}");
}

TEST(RequireOutputFile, RefusesWhatCannotBeWrittenThereBeforeAnyWork) {
  testing::TempDir dir;
  std::filesystem::create_directory(dir / "adir");
  testing::WriteText(dir / "afile", "x");
  const auto error = [&](const std::filesystem::path& path, std::span<const std::string_view> extensions = {}) {
    return testing::ErrorOfType<UserError>([&] { RequireOutputFile(path, "--report", extensions); });
  };
  // Files that can be written: new, old, in folders still to be made, any case of an extension.
  for (const char* name : {"new.json", "afile", "adir/new.html", "made/later/m.json"})
    EXPECT_EQ(error(dir / name), "(no error)") << name;
  EXPECT_EQ(error(dir / "sheet.PNG", kImageExtensions), "(no error)");
  EXPECT_EQ(error("", kImageExtensions), "(no error)");  // not given
  EXPECT_EQ(error("m.json"), "(no error)");              // in the working folder
  // A folder where a file is expected, said as such.
  EXPECT_EQ(error(dir / "adir"), "--report: '" + (dir / "adir").string() + "' is a folder, not a file");
  EXPECT_EQ(error((dir / "new").string() + "/"), "--report: '" + (dir / "new").string() + "/' is a folder, not a file");
  // No extension, or one the writer does not know.
  EXPECT_EQ(
      error(dir / "sheet", kImageExtensions),
      "--report: '" + (dir / "sheet").string() + "': expected a file name ending in .png, .jpg, .jpeg, .tif or .tiff");
  EXPECT_NE(error(dir / "plot.png", kSvgExtension).find("ending in .svg"), std::string::npos);
  // Under a file.
  EXPECT_EQ(error(dir / "afile" / "sub" / "m.json"), "--report: '" + (dir / "afile" / "sub" / "m.json").string() +
                                                         "' cannot be written: '" + (dir / "afile").string() +
                                                         "' is a file, not a folder");
  // The output folders' own check: a file is not a folder, a folder under a file cannot be made.
  EXPECT_EQ(testing::ErrorOfType<UserError>([&] { RequireFolderOrNothing(dir / "afile", "--out"); }),
            "--out: '" + (dir / "afile").string() + "' is a file, not a folder");
  EXPECT_NE(testing::ErrorOfType<UserError>([&] {
              RequireFolderOrNothing(dir / "afile" / "frames", "--out");
            }).find("is a file, not a folder"),
            std::string::npos);
  EXPECT_EQ(testing::ErrorOfType<UserError>([&] { RequireFolderOrNothing(dir / "adir" / "frames", "--out"); }),
            "(no error)");
  // A folder this process may not write into (root may write anywhere).
  if (::geteuid() != 0) {
    std::filesystem::permissions(dir / "adir", std::filesystem::perms::owner_read | std::filesystem::perms::owner_exec);
    const std::string refused = error(dir / "adir" / "m.json");
    std::filesystem::permissions(dir / "adir", std::filesystem::perms::owner_all);
    EXPECT_NE(refused.find("cannot be written: folder"), std::string::npos) << refused;
  }
}

TEST(SplitMix64, IsTheReferenceGenerator) {
  // The first outputs of Vigna's splitmix64.c from state 0.
  SplitMix64 random(0);
  EXPECT_EQ(random.Next(), 0xE220A8397B1DCDAFull);
  EXPECT_EQ(random.Next(), 0x6E789E6AA1B965F4ull);
  EXPECT_EQ(random.Next(), 0x06C45D188009454Full);
  SplitMix64 a(7), b(7);
  for (int i = 0; i < 1000; ++i) {
    const float u = a.UniformFloat();
    const double v = b.UniformDouble();
    EXPECT_GE(u, 0.0f);
    EXPECT_LT(u, 1.0f);
    EXPECT_GE(v, 0.0);
    EXPECT_LT(v, 1.0);
  }
}

TEST(InterleavedGradientNoise, IsInTheUnitIntervalAndDiffersBetweenNeighbours) {
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const float v = InterleavedGradientNoise(x, y);
      EXPECT_GE(v, 0.0f);
      EXPECT_LT(v, 1.0f);
      EXPECT_NE(v, InterleavedGradientNoise(x + 1, y));
    }
}

// Jimenez's formula with its fmod, bit for bit, over a 16k x 16k frame's corners and a sample between.
TEST(InterleavedGradientNoise, IsJimenezsFormulaBitForBit) {
  auto jimenez = [](int x, int y) {
    const float v =
        52.9829189f * std::fmod(0.06711056f * static_cast<float>(x) + 0.00583715f * static_cast<float>(y), 1.0f);
    return v - std::floor(v);
  };
  for (int y = 0; y < 16384; y += 7)
    for (int x : {0, 1, 2, 639, 640, 8191, 16383, y / 3}) ASSERT_EQ(InterleavedGradientNoise(x, y), jimenez(x, y)) << x << "," << y;
}

}  // namespace
}  // namespace phos
