#pragma once
// Helpers shared by the tests: fixtures, temporary folders, running the
// `phos` command and capturing what it prints.

#include <sys/wait.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace phos::testing {

inline std::filesystem::path Fixture(const std::string& relative) {
  return std::filesystem::path(PHOS_FIXTURES_DIR) / relative;
}

// A fresh folder under the system temp dir, removed when the test ends.
class TempDir {
 public:
  TempDir() {
    std::string pattern = (std::filesystem::temp_directory_path() / "phos-test-XXXXXX").string();
    path_ = ::mkdtemp(pattern.data());
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

inline std::string ReadText(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The lines of a JSONL file (frames.jsonl, events.jsonl), parsed.
inline std::vector<nlohmann::json> ReadJsonLines(const std::filesystem::path& path) {
  std::vector<nlohmann::json> lines;
  std::istringstream in(ReadText(path));
  for (std::string line; std::getline(in, line);) lines.push_back(nlohmann::json::parse(line));
  return lines;
}

// An excitation session's measurements: per charge (its run, a light and
// its light-off time on that run's clock) the charge time and how many
// frames (first and tail) it recorded, in frames.jsonl's order.
struct ExcitationCharge {
  std::string light;
  double light_off_s = 0, charge_s = 0;
  int frames = 0;
  int run = 0;
};
inline std::vector<ExcitationCharge> ExcitationCharges(const std::filesystem::path& frames_jsonl) {
  std::vector<ExcitationCharge> charges;
  for (const nlohmann::json& line : ReadJsonLines(frames_jsonl)) {
    const std::string light = line["light"].get<std::string>();
    const double off = line["light_off_s"].get<double>();
    const int run = line.value("run", 0);
    auto it = std::find_if(charges.begin(), charges.end(), [&](const ExcitationCharge& c) {
      return c.run == run && c.light == light && c.light_off_s == off;
    });
    if (it == charges.end()) it = charges.insert(charges.end(), {light, off, line["charge_s"].get<double>(), 0, run});
    ++it->frames;
  }
  return charges;
}

inline void WriteText(const std::filesystem::path& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

struct CommandResult {
  int exit_code = -1;
  std::string out, err;
};

// Runs `phos <arguments>` (arguments are passed to the shell as written).
inline CommandResult RunPhos(const std::string& arguments) {
  TempDir dir;
  std::string command = std::string(PHOS_BINARY) + " " + arguments + " >" + (dir / "out").string() + " 2>" +
                        (dir / "err").string() + " </dev/null";
  int status = std::system(command.c_str());
  CommandResult result;
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  result.out = ReadText(dir / "out");
  result.err = ReadText(dir / "err");
  return result;
}

// What a UserError thrown by f says, or "(no error)".
template <typename UserErrorType>
std::string ErrorOfType(const std::function<void()>& f) {
  try {
    f();
  } catch (const UserErrorType& e) {
    return e.what();
  }
  return "(no error)";
}

// A bad-input run of the command: exit code 2 and one line on stderr that
// contains `expected`.
inline ::testing::AssertionResult IsOneLineUserError(const CommandResult& result, const std::string& expected) {
  int lines = 0;
  for (char c : result.err) lines += c == '\n';
  if (result.exit_code == 2 && lines == 1 && result.err.find(expected) != std::string::npos)
    return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "exit " << result.exit_code << ", stderr: " << result.err
                                       << "(expected one line containing: " << expected << ")";
}

inline int LineCount(const std::string& text) {
  int lines = 0;
  for (char c : text) lines += c == '\n';
  return lines;
}

}  // namespace phos::testing
