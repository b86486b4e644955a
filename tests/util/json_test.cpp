#include "phos/util/json.h"

#include <functional>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

std::string ErrorOf(const std::function<void()>& f) { return testing::ErrorOfType<UserError>(f); }

TEST(JsonField, ErrorsNameTheSourceAndThePath) {
  nlohmann::json j = nlohmann::json::parse(R"({"a": {"b": [1, -2, "x"]}, "s": 3})");
  JsonField root(j, "f.json");
  EXPECT_EQ(root["a"]["b"].At(0).Number(), 1);
  EXPECT_EQ(ErrorOf([&] { root["a"]["b"].At(1).NumberAtLeast(0); }), "f.json: a.b[1]: expected a number >= 0, got -2");
  EXPECT_EQ(ErrorOf([&] { root["a"]["b"].At(2).Number(); }), "f.json: a.b[2]: expected a number, got \"x\"");
  EXPECT_EQ(ErrorOf([&] { root["a"]["c"]; }), "f.json: a.c: missing (required)");
  EXPECT_EQ(ErrorOf([&] { root["s"].String(); }), "f.json: s: expected a string, got 3");
  EXPECT_EQ(ErrorOf([&] { root["a"]["b"].NumberArray(2); }), "f.json: a.b: expected 2 values (one per band), got 3");
  EXPECT_EQ(ErrorOf([&] { root.RejectUnknownKeys({"a"}); }), "f.json: s: unknown field (expected one of: a)");
}

TEST(ReadJsonFile, MissingAndMalformedFilesAreUserErrors) {
  testing::TempDir dir;
  EXPECT_NE(ErrorOf([&] { ReadJsonFile(dir / "none.json"); }).find("none.json: cannot open"), std::string::npos);
  testing::WriteText(dir / "bad.json", "{\"a\": 1,,}");
  std::string message = ErrorOf([&] { ReadJsonFile(dir / "bad.json"); });
  EXPECT_NE(message.find("bad.json: not valid JSON: parse error at line 1"), std::string::npos) << message;
}

// Issue 16: a FIFO as a material path hung, and /dev/zero exhausted memory.
TEST(ReadFileText, ReadsOnlyRegularFilesWithinTheLimit) {
  testing::TempDir dir;
  testing::WriteText(dir / "a.json", "{\"a\": 1}");
  EXPECT_EQ(ReadFileText(dir / "a.json"), "{\"a\": 1}");
  EXPECT_EQ(ReadJsonFile(dir / "a.json")["a"], 1);
  ASSERT_EQ(::mkfifo((dir / "fifo.json").c_str(), 0600), 0);
  EXPECT_EQ(
      ErrorOf([&] { ReadJsonFile(dir / "fifo.json"); }),
      (dir / "fifo.json").string() + ": not a regular file (a FIFO, socket or device); phos reads only regular files");
  EXPECT_NE(ErrorOf([&] { ReadJsonFile("/dev/zero"); }).find("/dev/zero: not a regular file"), std::string::npos);
  EXPECT_EQ(ErrorOf([&] { ReadJsonFile(dir.path()); }), dir.path().string() + ": is a folder, not a file");
  EXPECT_EQ(ErrorOf([&] { ReadFileText(dir / "a.json", 4); }),
            (dir / "a.json").string() + ": the file has 8 bytes, more than the limit of 4 bytes");
  EXPECT_EQ(ReadFileText(dir / "a.json", 8).size(), 8u);
  testing::WriteText(dir / "empty.json", "");
  EXPECT_EQ(ReadFileText(dir / "empty.json"), "");
}

TEST(WriteFileAtomically, ReplacesWholeAndLeavesNoTemporary) {
  testing::TempDir dir;
  WriteFileAtomically(dir / "a.txt", "one");
  WriteFileAtomically(dir / "a.txt", "two");
  EXPECT_EQ(testing::ReadText(dir / "a.txt"), "two");
  int files = 0;
  for ([[maybe_unused]] auto& entry : std::filesystem::directory_iterator(dir.path())) ++files;
  EXPECT_EQ(files, 1);
  // A folder of the path that cannot be made (a file is in the way); missing ones are made.
  testing::WriteText(dir / "in-the-way", "");
  EXPECT_THROW(WriteFileAtomically(dir / "in-the-way" / "a.txt", "x"), UserError);
}

}  // namespace
}  // namespace phos
