#include "phos/util/task_record.h"

#include <unistd.h>

#include <climits>
#include <cstdlib>
#include <set>

#include "phos/util/atomic_file.h"
#include "phos/util/error.h"
#include "phos/util/json.h"

namespace phos {

nlohmann::json TaskDoneRecord::ToJson() const {
  return {{"format", kFormat}, {"task", task},       {"inputs", inputs},
          {"outputs", outputs}, {"seconds", seconds}, {"host", host}};
}

std::optional<TaskDoneRecord> TaskDoneRecord::FromJson(const nlohmann::json& j, std::string* why) {
  auto fail = [&](const char* what) {
    if (why) *why = what;
    return std::nullopt;
  };
  if (!j.is_object()) return fail("not a JSON object");
  if (!j.contains("format") || j["format"] != kFormat) return fail("not a phos.task-done/1 record");
  for (const char* key : {"task", "inputs", "host"})
    if (!j.contains(key) || !j[key].is_string()) return fail("a string field is missing");
  if (!j.contains("seconds") || !j["seconds"].is_number()) return fail("no seconds");
  if (!j.contains("outputs") || !j["outputs"].is_array()) return fail("no outputs");
  TaskDoneRecord r;
  r.task = j["task"].get<std::string>();
  r.inputs = j["inputs"].get<std::string>();
  r.host = j["host"].get<std::string>();
  r.seconds = j["seconds"].get<double>();
  for (const nlohmann::json& o : j["outputs"]) {
    if (!o.is_string()) return fail("an output is not a string");
    r.outputs.push_back(o.get<std::string>());
  }
  return r;
}

void WriteTaskDone(const std::filesystem::path& path, const TaskDoneRecord& record) {
  std::error_code ec;
  std::filesystem::create_directories(path.parent_path(), ec);
  if (ec) ThrowUserError(path.parent_path().string(), "", "cannot create the folder: " + ec.message());
  WriteFileAtomically(path, record.ToJson().dump(2) + "\n");
}

std::optional<TaskDoneRecord> ReadTaskDone(const std::filesystem::path& path, std::string* why) {
  if (why) why->clear();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return std::nullopt;
  try {
    return TaskDoneRecord::FromJson(ReadJsonFile(path), why);
  } catch (const UserError&) {
    if (why) *why = "does not parse";
    return std::nullopt;
  }
}

bool TaskIsDone(const std::filesystem::path& path, const std::string& inputs) {
  const std::optional<TaskDoneRecord> record = ReadTaskDone(path);
  return record && record->inputs == inputs;
}

std::size_t RemoveTemporaries(const std::filesystem::path& dir, const std::vector<std::string>& names) {
  const std::set<std::string> wanted(names.begin(), names.end());
  std::vector<std::filesystem::path> stale;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir.empty() ? "." : dir, ec)) {
    const std::string name = entry.path().filename().string();
    const std::size_t tmp = name.find(".tmp.");
    if (tmp != std::string::npos && wanted.count(name.substr(0, tmp))) stale.push_back(entry.path());
  }
  for (const auto& path : stale) std::filesystem::remove(path, ec);
  return stale.size();
}

bool ParseTaskIndex(const std::string& text, int* index, int* count) {
  const std::size_t slash = text.find('/');
  if (slash == std::string::npos || slash == 0 || slash + 1 == text.size()) return false;
  char* end = nullptr;
  const std::string a = text.substr(0, slash), b = text.substr(slash + 1);
  const long i = std::strtol(a.c_str(), &end, 10);
  if (*end != '\0' || a.find_first_not_of("0123456789") != std::string::npos) return false;
  const long n = std::strtol(b.c_str(), &end, 10);
  if (*end != '\0' || b.find_first_not_of("0123456789") != std::string::npos) return false;
  if (n < 1 || n > 1000000 || i < 0 || i >= n) return false;
  *index = static_cast<int>(i);
  *count = static_cast<int>(n);
  return true;
}

std::pair<std::size_t, std::size_t> TaskShare(std::size_t items, int index, int count) {
  const auto at = [&](int k) { return static_cast<std::size_t>((static_cast<unsigned long long>(items) * k) / count); };
  return {at(index), at(index + 1)};
}

std::string HostName() {
  char name[HOST_NAME_MAX + 1] = {};
  if (gethostname(name, sizeof name - 1) != 0) return "unknown";
  return name;
}

}  // namespace phos
