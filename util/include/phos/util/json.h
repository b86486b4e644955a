#pragma once
// Validated reading of JSON input files. A JsonField is a value together with
// the file it came from and its path inside it ("states[0].ke[3]"), so every
// complaint names both, in the one form of UserError.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <initializer_list>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "phos/util/atomic_file.h"  // WriteFileAtomically, for the writers of JSON

namespace phos {

// The largest input file phos reads (material, scene, constraints, lab
// config, curve CSV, mesh, glTF buffer): 256 MiB. Limits before allocation
// (docs/fuzzing.md, "Limits"): a file is sized before it is read.
inline constexpr std::uintmax_t kMaxInputFileBytes = std::uintmax_t{256} << 20;

// The whole content of a regular file of at most max_bytes. Anything else is
// a UserError naming the file: missing, a folder, a FIFO or a device (which
// would block or never end: /dev/zero), or larger than the limit.
std::string ReadFileText(const std::filesystem::path& path, std::uintmax_t max_bytes = kMaxInputFileBytes);

// The deepest nesting of arrays and objects phos reads in JSON text, its
// own files' or a glTF's: 64 levels. Parsers that recurse once per level
// (tinygltf turns a glTF's `extras` into its own values so) ran out of stack
// on 20,000 nested arrays in a 40 KB file; phos's formats nest under 10.
inline constexpr int kMaxJsonNesting = 64;

// Refuses JSON text whose arrays and objects nest deeper than
// kMaxJsonNesting: a UserError naming `source` and the byte where the limit is
// passed. A bracket-counting scan outside strings, without parsing, so it can
// run before a parser that recurses; a syntax error is left to the parser.
void CheckJsonNesting(std::string_view text, const std::string& source);

// Parses JSON text; a syntax error, nesting past kMaxJsonNesting or a key
// given twice in one object (the last would win in silence) is a UserError
// naming `source`.
nlohmann::json ParseJsonText(std::string_view text, const std::string& source);

// Reads (ReadFileText) and parses a JSON file; a missing file or a syntax
// error is a UserError.
nlohmann::json ReadJsonFile(const std::filesystem::path& path);

// The records of a JSON Lines file (frames.jsonl, events.jsonl) that parse as
// objects: a crash can tear the last line, and what parses is what was
// recorded. A missing file has no records.
std::vector<nlohmann::json> ReadJsonLines(const std::filesystem::path& path);

class JsonField {
 public:
  JsonField(const nlohmann::json& value, std::string source, std::string path = "");

  const nlohmann::json& value() const { return *value_; }
  const std::string& path() const { return path_; }
  const std::string& source() const { return source_; }

  bool Has(std::string_view key) const;
  JsonField operator[](std::string_view key) const;  // required member of an object
  std::optional<JsonField> Optional(std::string_view key) const;
  JsonField At(std::size_t index) const;  // element of an array
  std::size_t ArraySize() const;          // fails unless an array
  bool IsNull() const { return value_->is_null(); }

  double Number() const;  // finite number
  double NumberAtLeast(double lower) const;
  double NumberInRange(double lower, double upper) const;
  int Integer(int lower, int upper) const;
  bool Boolean() const;  // true or false
  std::string String() const;
  std::string NonEmptyString() const;
  // An array of finite numbers >= lower with exactly `size` elements (any size if 0).
  std::vector<double> NumberArray(std::size_t size = 0, double lower = -std::numeric_limits<double>::infinity()) const;

  // Fails on a member whose name is not in `known` (a typo must not pass silently).
  void RejectUnknownKeys(std::initializer_list<std::string_view> known) const;

  [[noreturn]] void Fail(std::string_view message) const;

 private:
  void RequireObject() const;
  const nlohmann::json* value_;
  std::string source_;
  std::string path_;
};

// A short description of a JSON value for error messages: -1, "abc", an array, null.
std::string DescribeJson(const nlohmann::json& value);

}  // namespace phos
