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

// A FIFO as a material path hung, and /dev/zero exhausted memory.
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

// Parsers that recurse once per level (tinygltf) overflowed the stack on
// 20,000 nested arrays: the nesting is counted before any parser runs, and
// brackets inside strings (escaped quotes included) are not nesting.
TEST(CheckJsonNesting, RefusesNestingPastTheLimitOutsideStrings) {
  auto error = [](const std::string& text) {
    return testing::ErrorOfType<UserError>([&] { ParseJsonText(text, "f.json"); });
  };
  const int limit = kMaxJsonNesting;
  EXPECT_EQ(error(std::string(limit, '[') + std::string(limit, ']')), "(no error)");
  EXPECT_EQ(error(std::string(limit + 1, '[') + std::string(limit + 1, ']')),
            "f.json: arrays and objects nested more than the limit of 64 levels deep (at byte 64)");
  EXPECT_EQ(error(std::string(20000, '[') + std::string(20000, ']')).rfind("f.json: arrays and objects nested", 0), 0u);
  EXPECT_EQ(error(R"({"a": [{"b": ")" + std::string(1000, '[') + R"(\"[[["}]})"), "(no error)");
  EXPECT_EQ(error("{\"a\": {\"b\": " + std::string(limit, '[') + std::string(limit, ']') + "}}")
                .rfind("f.json: arrays and objects nested more than the limit of 64 levels deep", 0),
            0u);
}

// A key given twice in one object: nlohmann keeps the last in silence, so a
// scene's second "phosphor" or a material's second "kr" won unseen.
TEST(ParseJsonText, AKeyGivenTwiceInOneObjectIsRefusedNamingIt) {
  auto error = [](const std::string& text) {
    return testing::ErrorOfType<UserError>([&] { ParseJsonText(text, "f.json"); });
  };
  EXPECT_EQ(error(R"({"kr": 1, "kr": 2})"), "f.json: kr: the key is given twice");
  EXPECT_EQ(error(R"({"states": [{"kr": 1}, {"ke": [1], "kr": 2, "ke": [3]}]})"),
            "f.json: states[1].ke: the key is given twice");
  EXPECT_EQ(error(R"({"a": {"b": [[1], [2, {"c": 1, "d": {}, "c": 2}]]}})"),
            "f.json: a.b[1][1].c: the key is given twice");
  // The same key in different objects, or at different depths, is no duplicate.
  EXPECT_EQ(error(R"({"a": {"a": 1}, "b": [{"a": 1}, {"a": 2}], "c": {"b": {"a": 3}}})"), "(no error)");
  EXPECT_EQ(ParseJsonText(R"({"x": [1, {"y": 2}], "z": 3})", "f.json")["x"][1]["y"], 2);
}

}  // namespace
}  // namespace phos
