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
