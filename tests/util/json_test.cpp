#include "phos/util/json.h"

#include <functional>
#include <gtest/gtest.h>

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

TEST(WriteFileAtomically, ReplacesWholeAndLeavesNoTemporary) {
  testing::TempDir dir;
  WriteFileAtomically(dir / "a.txt", "one");
  WriteFileAtomically(dir / "a.txt", "two");
  EXPECT_EQ(testing::ReadText(dir / "a.txt"), "two");
  int files = 0;
  for ([[maybe_unused]] auto& entry : std::filesystem::directory_iterator(dir.path())) ++files;
  EXPECT_EQ(files, 1);
  EXPECT_THROW(WriteFileAtomically(dir / "no-such-dir" / "a.txt", "x"), UserError);
}

}  // namespace
}  // namespace phos
