#pragma once
// The tasks a cluster runs (phos slurm, docs/scale.md): a range of frames, a
// tile of a decay map, a share of a batch. Each writes its done record last,
// atomically, after all its outputs (each itself written whole). So a rerun of
// a finished task finds the record and does nothing, a killed task has none
// and is redone whole, and Slurm's requeue is safe; `phos slurm status`
// counts the records.

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace phos {

struct TaskDoneRecord {
  static constexpr const char* kFormat = "phos.task-done/1";
  std::string task;    // what was done: "render frames 0:4", "fit map tile 1/4"
  std::string inputs;  // what it was made from (the options that shape the outputs): a
                       // record for other inputs is not this task's, and the task runs
  std::vector<std::string> outputs;
  double seconds = 0;  // the task's own run time
  std::string host;    // where it ran

  nlohmann::json ToJson() const;
  // nullopt (and why) when the record is not a whole one.
  static std::optional<TaskDoneRecord> FromJson(const nlohmann::json& json, std::string* why);
};

// Atomic (atomic_file.h).
void WriteTaskDone(const std::filesystem::path& path, const TaskDoneRecord& record);
// The record at `path` if it is whole; nullopt if it is missing (why = "") or
// not whole (why says what is wrong).
std::optional<TaskDoneRecord> ReadTaskDone(const std::filesystem::path& path, std::string* why = nullptr);
// True when `path` holds a whole record of a task made from `inputs`: the
// task is done and a rerun does nothing.
bool TaskIsDone(const std::filesystem::path& path, const std::string& inputs);

// A killed task leaves, besides the files it finished, the temporary of the
// one it was writing (atomic_file.h: "<name>.tmp.<pid><ext>"). Its rerun
// removes those of its outputs (`names`, in folder `dir`) first, so no
// partial output outlives it. Returns how many were removed.
std::size_t RemoveTemporaries(const std::filesystem::path& dir, const std::vector<std::string>& names);

// "i/N" (0 <= i < N, N >= 1): task i of N. False if the text is not that.
bool ParseTaskIndex(const std::string& text, int* index, int* count);
// Task i of N's share of `items` in order: [first, last), the shares differing by at most one.
std::pair<std::size_t, std::size_t> TaskShare(std::size_t items, int index, int count);

// This machine's name (the record's host).
std::string HostName();

}  // namespace phos
