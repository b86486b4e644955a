// phos slurm: render, map and batch as Slurm job arrays (docs/scale.md).
//   phos slurm render|map|batch --tasks N --job-dir DIR [site options] -- <the command's own arguments>
//   phos slurm status DIR [--json]
// Writes the sbatch scripts into DIR and submits them: for a render, the
// solver pass (the states are sequential in time), then the array of frame
// ranges; for a map, the array of tiles; for a batch, the array of item
// shares; then a merge job. Before anything is written, the tasks' command
// is run with --check (its options, its inputs), so a mistake after `--` is
// one line at submission, not a log line after the queue. Each stage waits
// for the one before to end, however it ended (--dependency=afterany), and
// checks for itself what it needs: with afterok, a stage that failed (a
// requeued task whose rerun failed, in CI; a solver pass given a bad option)
// left the next PENDING forever (DependencyNeverSatisfied) with nothing said.
// With afterany, render tasks whose solver pass failed start from the latest
// state there is (the scene's start if none: slower, the same frames) or
// fail with the pass's own line, and the merge fails with one line naming
// the missing tasks, which `status` shows too. Every task is idempotent (its
// done record, util/task_record.h), so Slurm's requeue and a resubmission
// are safe; `status` counts the records.

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "phos/util/atomic_file.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/task_record.h"

namespace phos::app {
namespace {

namespace fs = std::filesystem;

// Where Slurm's defaults are not the site's, these pass through to every job.
struct SiteOptions {
  std::string partition, account;          // "": the cluster's default partition, the user's default account
  std::string time_per_task = "01:00:00";  // --time of each job: HH:MM:SS
  std::string mem_per_task = "4G";         // --mem of each job
  int cpus_per_task = 2;
  std::vector<std::string> extra;  // more sbatch options, without their dashes ("qos=short")
};

struct SubmitArgs {
  std::string kind;  // render, map, batch
  int tasks = 0;
  std::string job_dir, sbatch = "sbatch";
  bool no_submit = false, json = false;
  SiteOptions site;
  std::vector<std::string> command;  // the phos command's own arguments
};

// One job of the chain: its script, its Slurm id once submitted, and the done
// records that say it finished (a merge: the files it writes).
struct SlurmStage {
  std::string name;    // "solve", "tasks", "merge"
  std::string script;  // path
  std::string job_id;  // "" before submission
  std::vector<std::string> done;

  nlohmann::json ToJson() const { return {{"name", name}, {"script", script}, {"job_id", job_id}, {"done", done}}; }
  static SlurmStage FromJson(const JsonField& j) {
    j.RejectUnknownKeys({"name", "script", "job_id", "done"});
    SlurmStage s{j["name"].NonEmptyString(), j["script"].String(), j["job_id"].String(), {}};
    const JsonField done = j["done"];
    for (std::size_t i = 0; i < done.ArraySize(); ++i) s.done.push_back(done.At(i).String());
    return s;
  }
};

// <job-dir>/job.json: what was submitted (phos.slurm-job/1), read by `status`.
struct SlurmJob {
  static constexpr const char* kFormat = "phos.slurm-job/1";
  std::string kind;
  int tasks = 0;
  std::vector<std::string> command;
  std::vector<SlurmStage> stages;
  double submitted_s = 0;  // seconds sbatch took for the whole chain

  nlohmann::json ToJson() const {
    nlohmann::json stages_json = nlohmann::json::array();
    for (const SlurmStage& s : stages) stages_json.push_back(s.ToJson());
    return {{"format", kFormat},  {"kind", kind},          {"tasks", tasks},
            {"command", command}, {"stages", stages_json}, {"submitted_s", submitted_s}};
  }
  static SlurmJob FromJson(const JsonField& j) {
    j.RejectUnknownKeys({"format", "kind", "tasks", "command", "stages", "submitted_s"});
    if (j["format"].String() != kFormat) j["format"].Fail(std::string("expected \"") + kFormat + "\"");
    SlurmJob job;
    job.kind = j["kind"].NonEmptyString();
    job.tasks = j["tasks"].Integer(1, 1000000);
    const JsonField command = j["command"];
    for (std::size_t i = 0; i < command.ArraySize(); ++i) job.command.push_back(command.At(i).String());
    const JsonField stages = j["stages"];
    for (std::size_t i = 0; i < stages.ArraySize(); ++i) job.stages.push_back(SlurmStage::FromJson(stages.At(i)));
    job.submitted_s = j["submitted_s"].NumberAtLeast(0);
    return job;
  }
};

// 'text' for a shell, whatever it holds.
std::string ShellQuote(const std::string& text) {
  std::string quoted = "'";
  for (char c : text) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

// The phos beside this executable (the same bin folder): the jobs run this build.
std::string PhosExecutable() {
  char path[PATH_MAX];
  const ssize_t n = readlink("/proc/self/exe", path, sizeof path - 1);
  if (n <= 0) return "phos";
  return (fs::path(std::string(path, static_cast<std::size_t>(n))).parent_path() / "phos").string();
}

// The value of --out in the command's arguments, absolute ("" if absent).
std::string OutFolder(const std::vector<std::string>& command) {
  for (std::size_t i = 0; i < command.size(); ++i) {
    std::string value;
    if (command[i] == "--out" && i + 1 < command.size())
      value = command[i + 1];
    else if (command[i].rfind("--out=", 0) == 0)
      value = command[i].substr(6);
    else
      continue;
    if (value.empty()) ThrowUserError("", "COMMAND", "--out is empty: give the folder for the outputs");
    return fs::absolute(value).lexically_normal().string();
  }
  return "";
}

std::string TaskRecordName(const char* prefix, int i, int n) {
  return std::string(prefix) + std::to_string(i) + "-of-" + std::to_string(n) + ".json";
}

// Minutes of a Slurm time limit (sbatch(1): MM, MM:SS, HH:MM:SS, D-HH,
// D-HH:MM, D-HH:MM:SS); nullopt for UNLIMITED or anything else.
std::optional<double> SlurmMinutes(const std::string& time) {
  static const std::regex form(R"((?:(\d+)-)?(\d+)(?::(\d+))?(?::(\d+))?)");
  std::smatch m;
  if (!std::regex_match(time, m, form)) return std::nullopt;
  auto number = [&](int i) { return m[i].matched ? std::stod(m[i].str()) : 0.0; };
  const int fields = 1 + m[3].matched + m[4].matched;  // after the day
  if (m[1].matched) {                                  // D-HH[:MM[:SS]]
    return number(1) * 1440 + number(2) * 60 + number(3) + number(4) / 60;
  }
  if (fields == 1) return number(2);                   // MM
  if (fields == 2) return number(2) + number(3) / 60;  // MM:SS
  return number(2) * 60 + number(3) + number(4) / 60;  // HH:MM:SS
}

// Why `time` is not a time limit sbatch takes (sbatch(1), --time: MM, MM:SS,
// HH:MM:SS, D-HH, D-HH:MM, D-HH:MM:SS or UNLIMITED), "" if it is one. Slurm
// reads seconds past 59, minutes past 59 after hours and hours past 23 after
// days as nonsense or refuses them when the job is submitted: refused here.
std::string SlurmTimeError(const std::string& time) {
  if (time == "UNLIMITED" || time == "INFINITE" || time == "unlimited" || time == "infinite") return "";
  static const std::regex form(R"((?:(\d+)-)?(\d+)(?::(\d+))?(?::(\d+))?)");
  std::smatch m;
  const std::string expected = "expected a Slurm time (MM, MM:SS, HH:MM:SS, D-HH, D-HH:MM, D-HH:MM:SS or UNLIMITED)";
  if (time.size() > 32 || !std::regex_match(time, m, form)) return expected + ", got \"" + time + "\"";
  auto number = [&](int i) { return std::stod(m[i].str()); };
  const bool days = m[1].matched;
  const int fields = 1 + m[3].matched + m[4].matched;
  // Which field each number is: [hours, minutes, seconds] or a part of them.
  const bool has_hours = days || fields == 3;
  const int seconds_at = days ? 4 : fields == 1 ? 0 : fields == 2 ? 3 : 4;
  const int minutes_at = days ? 3 : fields == 3 ? 3 : 2;
  std::string why;
  if (days && number(2) >= 24) why = "hours after days must be under 24";
  if (has_hours && m[minutes_at].matched && number(minutes_at) >= 60) why = "minutes after hours must be under 60";
  if (seconds_at > 0 && m[seconds_at].matched && number(seconds_at) >= 60) why = "seconds must be under 60";
  return why.empty() ? "" : expected + ", got \"" + time + "\": " + why;
}

// Why `memory` is not a --mem sbatch takes (a positive whole number of
// megabytes, or with a K, M, G or T suffix), "" if it is one. 0 is Slurm's
// "all of a node's memory", not a task's share: refused.
std::string SlurmMemoryError(const std::string& memory) {
  static const std::regex form(R"(0*[1-9]\d{0,15}[KMGTkmgt]?)");
  if (std::regex_match(memory, form)) return "";
  return "expected a positive whole amount with an optional K, M, G or T suffix (sbatch --mem: 4G, 500M, 4096), "
         "got \"" +
         memory + "\"";
}

// Refuses a value written into a job script that would not stay one value
// there: a control character (a newline ends the #SBATCH line, and what follows
// runs as a command) anywhere, and a space where it would start another option.
void RequireScriptValue(const std::string& value, const std::string& field, bool spaces_allowed) {
  for (char c : value) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7f)
      ThrowUserError("", field,
                     "contains a control character (code " + std::to_string(u) + "), which the job script cannot hold");
    if (c == ' ' && !spaces_allowed)
      ThrowUserError("", field, "contains a space, which would start another sbatch option in the job script");
  }
}

// One sbatch script: the site's options, then `body`.
// `light`: a job that only reads done records (the render's last, `phos
// slurm status`, about 4 MB): one CPU, 256 MB and 10 minutes, not a task's
// share, so that it does not wait in the queue for a task's resources.
std::string Script(const SubmitArgs& args, const std::string& name, int array_tasks, const std::string& body,
                   bool light = false) {
  SiteOptions site = args.site;
  if (light) {
    site.cpus_per_task = 1;
    site.mem_per_task = "256M";
    // 10 minutes, or the tasks' time if shorter (a partition whose MaxTime
    // is below 10 minutes would refuse or never run it).
    const std::optional<double> task_minutes = SlurmMinutes(site.time_per_task);
    if (!task_minutes || *task_minutes >= 10) site.time_per_task = "00:10:00";
  }
  const fs::path logs = fs::path(args.job_dir) / "logs";
  std::string s = "#!/bin/bash\n# Written by phos slurm " + args.kind + " (docs/scale.md).\n";
  s += "#SBATCH --job-name=phos-" + args.kind + "-" + name + "\n";
  if (array_tasks > 0) s += "#SBATCH --array=0-" + std::to_string(array_tasks - 1) + "\n";
  s += "#SBATCH --output=" + (logs / (array_tasks > 0 ? name + "-%A_%a.out" : name + "-%j.out")).string() + "\n";
  s += "#SBATCH --chdir=" + fs::current_path().string() + "\n";
  s += "#SBATCH --ntasks=1\n#SBATCH --cpus-per-task=" + std::to_string(site.cpus_per_task) + "\n";
  s += "#SBATCH --time=" + site.time_per_task + "\n#SBATCH --mem=" + site.mem_per_task + "\n";
  // A task lost with its node (or preempted) runs again: it redoes its share whole.
  s += "#SBATCH --requeue\n";
  if (!site.partition.empty()) s += "#SBATCH --partition=" + site.partition + "\n";
  if (!site.account.empty()) s += "#SBATCH --account=" + site.account + "\n";
  for (const std::string& option : site.extra)
    s += std::string("#SBATCH ") + (option.rfind('-', 0) == 0 ? "" : "--") + option + "\n";
  s += "set -euo pipefail\n" + body + "\n";
  return s;
}

std::string Command(const std::vector<std::string>& words) {
  std::string s;
  // Every word quoted but the array task's index this file writes ("${SLURM_ARRAY_TASK_ID}/N"), which the
  // job's shell must expand: a user's word that starts with ${ is theirs, not the shell's.
  for (const std::string& w : words)
    s += (s.empty() ? "" : " ") + (w.rfind("${SLURM_ARRAY_TASK_ID}/", 0) == 0 ? w : ShellQuote(w));
  return s;
}

// How a stage waits for the one before: once it has ended, however it ended
// (see the top).
constexpr const char* kDependency = "afterany";

// A child's exit code from pclose's wait status (128 + the signal if one ended it).
int ExitCode(int status) { return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status); }

// A shell command's stdout and exit code (-1: it could not be started).
struct ShellRun {
  std::string out;
  int exit_code = -1;
};
ShellRun RunShell(const std::string& command) {
  ShellRun run;
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return run;
  char buffer[4096];
  while (std::fgets(buffer, sizeof buffer, pipe)) run.out += buffer;
  run.exit_code = ExitCode(pclose(pipe));
  return run;
}

// The last line of `text` with something on it ("" if none).
std::string LastLine(const std::string& text) {
  std::string last, line;
  std::istringstream lines(text);
  while (std::getline(lines, line))
    if (line.find_first_not_of(" \t\r") != std::string::npos) last = line;
  return last;
}

// Runs sbatch --parsable on a script; the job id, or a UserError with sbatch's words.
std::string Submit(const std::string& sbatch, const std::string& script, const std::string& dependency,
                   const std::string& after) {
  // The id from stdout alone: many sites print notes on stderr ("sbatch:
  // info: Setting QOS ...") and submit all the same (exit status 0).
  // Its stderr goes to the job folder's logs (made before any submission,
  // ours): <script name>.sbatch-stderr, kept.
  const fs::path errors =
      fs::path(script).parent_path() / "logs" / (fs::path(script).stem().string() + ".sbatch-stderr");
  const std::string command = ShellQuote(sbatch) + " --parsable" +
                              (after.empty() ? "" : " --dependency=" + dependency + ":" + after) + " " +
                              ShellQuote(script) + " 2>" + ShellQuote(errors.string());
  const ShellRun run = RunShell(command);
  if (run.exit_code < 0) ThrowUserError("", "--sbatch", "cannot run '" + sbatch + "'");
  std::error_code ec;
  const std::string stderr_text = fs::exists(errors, ec) ? ReadFileText(errors, 1 << 20) : "";
  const std::string last = LastLine(run.out), id = last.substr(0, last.find(';'));  // "id;cluster" on federations
  const bool numeric = !id.empty() && id.find_first_not_of("0123456789") == std::string::npos;
  if (run.exit_code == 0 && numeric) return id;
  // sbatch's lines ("sbatch: error: ..."), each without its prefix, on one line.
  std::string said, line;
  std::istringstream lines(stderr_text + "\n" + run.out);
  while (std::getline(lines, line)) {
    for (const char* prefix : {"sbatch: error: ", "sbatch: "})
      if (line.rfind(prefix, 0) == 0) line.erase(0, std::strlen(prefix));
    if (line.find_first_not_of(" \t\r") != std::string::npos) said += (said.empty() ? "" : "; ") + line;
  }
  ThrowUserError(script, "sbatch",
                 "refused: " + (said.empty() ? "exit status " + std::to_string(run.exit_code) : said));
}

// Runs the tasks' command with --check (render, fit map, fit batch: every
// refusal a task would make before its work); its one line, if it refuses.
void CheckCommand(const std::vector<std::string>& words) {
  std::vector<std::string> check = words;
  check.push_back("--check");
  const ShellRun run = RunShell(Command(check) + " 2>&1");
  if (run.exit_code < 0) ThrowUserError("", "COMMAND", "cannot run '" + words.front() + "' to check it");
  if (run.exit_code == 0) return;
  // Its last line that says something: the refusal (warnings come before it).
  const std::string last = LastLine(run.out);
  ThrowUserError("", "COMMAND",
                 "its tasks would fail (nothing submitted): " +
                     (last.empty() ? "exit status " + std::to_string(run.exit_code) : last));
}

// Cancels jobs already submitted when a later sbatch failed, so that nothing
// runs that job.json does not record; scancel beside --sbatch if that is a
// path, else on PATH. False if it could not.
bool CancelJobs(const std::string& sbatch, const std::vector<std::string>& ids) {
  const fs::path beside = fs::path(sbatch).parent_path() / "scancel";
  const std::string scancel = sbatch.find('/') != std::string::npos && fs::exists(beside) ? beside.string() : "scancel";
  std::string command = ShellQuote(scancel);
  for (const std::string& id : ids) command += " " + ShellQuote(id);
  return std::system((command + " >/dev/null 2>&1").c_str()) == 0;
}

// The job.json of a folder: an earlier submission's (refused: a second chain
// would write to the same logs), or scripts written by --no-submit and never
// submitted (replaced).
void RequireNoJobSubmitted(const fs::path& dir) {
  const fs::path file = dir / "job.json";
  if (!fs::exists(file)) return;
  const nlohmann::json json = ReadJsonFile(file);
  const SlurmJob job = SlurmJob::FromJson(JsonField(json, file.string()));
  const bool submitted =
      std::any_of(job.stages.begin(), job.stages.end(), [](const SlurmStage& s) { return !s.job_id.empty(); });
  if (submitted)
    ThrowUserError(file.string(), "",
                   "a job was already submitted from this folder ('phos slurm status " + dir.string() +
                       "'); give another --job-dir");
}

void RunSubmit(const SubmitArgs& args) {
  if (args.command.empty())
    ThrowUserError("", "COMMAND", "give the phos " + args.kind + " arguments after --, e.g. -- SCENE --out OUT");
  const std::string out = OutFolder(args.command);
  if (out.empty()) ThrowUserError("", "COMMAND", "needs --out OUT (the tasks' outputs and done records go there)");
  if (args.job_dir.empty()) ThrowUserError("", "--job-dir", "is empty: give the folder for the scripts and logs");
  const fs::path dir = fs::absolute(args.job_dir).lexically_normal();
  // Every value the scripts hold outside the quoted command (Script).
  RequireScriptValue(dir.string(), "--job-dir", true);
  RequireScriptValue(fs::current_path().string(), "the working folder", true);
  RequireScriptValue(args.site.partition, "--partition", false);
  RequireScriptValue(args.site.account, "--account", false);
  for (const std::string& option : args.site.extra) RequireScriptValue(option, "--sbatch-option", true);
  RequireNoJobSubmitted(dir);
  const std::string phos = PhosExecutable(), n = std::to_string(args.tasks), task = "${SLURM_ARRAY_TASK_ID}/" + n;
  std::vector<std::string> base = {phos};
  if (args.kind == "map" || args.kind == "batch") base.push_back("fit");
  base.push_back(args.kind);
  base.insert(base.end(), args.command.begin(), args.command.end());
  const std::string states = (dir / "states").string();
  // The first task's command as it will run (a map's check covers every tile).
  std::vector<std::string> first_task = base;
  if (args.kind == "render")
    first_task.insert(first_task.end(), {"--task", "0/" + n, "--checkpoints", states});
  else
    first_task.insert(first_task.end(), {args.kind == "map" ? "--tile" : "--task", "0/" + n});
  CheckCommand(first_task);
  std::error_code ec;
  fs::create_directories(dir / "logs", ec);
  if (ec) ThrowUserError(dir.string(), "--job-dir", "cannot create: " + ec.message());
  SubmitArgs a = args;
  a.job_dir = dir.string();

  SlurmJob job{args.kind, args.tasks, args.command, {}, 0};
  auto stage = [&](const std::string& name, int array, const std::vector<std::string>& extra,
                   std::vector<std::string> done) {
    std::vector<std::string> words = base;
    words.insert(words.end(), extra.begin(), extra.end());
    const fs::path script = dir / (name + ".sbatch");
    WriteFileAtomically(script, Script(a, name, array, Command(words)));
    job.stages.push_back({name, script.string(), "", std::move(done)});
  };
  std::vector<std::string> task_done;
  if (args.kind == "render") {
    stage("solve", 0, {"--solve-only", "--checkpoints", states, "--tasks", n},
          {(dir / "states" / "done.json").string()});
    for (int i = 0; i < args.tasks; ++i)
      task_done.push_back((fs::path(out) / "done" / TaskRecordName("task-", i, args.tasks)).string());
    stage("tasks", args.tasks, {"--task", task, "--checkpoints", states}, task_done);
    // Nothing to assemble: the frames are the outputs. The last job checks that every range is done.
    const fs::path script = dir / "merge.sbatch";
    WriteFileAtomically(
        script, Script(a, "merge", 0, Command({phos, "slurm", "status", dir.string(), "--require-done"}), true));
    job.stages.push_back({"merge", script.string(), "", {}});
  } else if (args.kind == "map") {
    for (int i = 0; i < args.tasks; ++i)
      task_done.push_back((fs::path(out) / "tiles" / TaskRecordName("tile-", i, args.tasks)).string());
    stage("tasks", args.tasks, {"--tile", task}, task_done);
    stage("merge", 0, {"--merge"}, {(fs::path(out) / "decay-map.exr").string(), (fs::path(out) / "kr.png").string()});
  } else {
    for (int i = 0; i < args.tasks; ++i)
      task_done.push_back((fs::path(out) / "tasks" / TaskRecordName("task-", i, args.tasks)).string());
    stage("tasks", args.tasks, {"--task", task}, task_done);
    stage("merge", 0, {"--merge"}, {(fs::path(out) / "summary.csv").string()});
  }
  if (!args.no_submit) {
    const auto start = std::chrono::steady_clock::now();
    std::vector<std::string> submitted;
    try {
      for (SlurmStage& s : job.stages)
        submitted.push_back(s.job_id =
                                Submit(args.sbatch, s.script, kDependency, submitted.empty() ? "" : submitted.back()));
    } catch (const UserError& e) {
      // The stages before it are queued already: cancelled, so that a retry
      // in this folder (no job.json) does not run the chain twice.
      if (submitted.empty()) throw;
      std::string ids;
      for (const std::string& id : submitted) ids += (ids.empty() ? "" : " ") + id;
      if (CancelJobs(args.sbatch, submitted))
        throw UserError(std::string(e.what()) + "; the job(s) submitted before it (" + ids +
                        ") were cancelled: nothing of this chain runs");
      throw UserError(std::string(e.what()) + "; job(s) " + ids +
                      " were submitted before it and could not be cancelled: 'scancel " + ids + "'");
    }
    job.submitted_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  WriteFileAtomically(dir / "job.json", job.ToJson().dump(2) + "\n");
  if (args.json) {
    std::printf("%s\n", job.ToJson().dump().c_str());
    return;
  }
  // Paths as the user gave the folder (job.json has them absolute).
  const fs::path shown = args.job_dir;
  std::printf("phos slurm %s: %d task(s), %s -> %s\n", args.kind.c_str(), args.tasks,
              args.no_submit ? "scripts written (not submitted)" : "submitted", shown.c_str());
  std::string after;
  for (const SlurmStage& s : job.stages) {
    const std::string script = (shown / fs::path(s.script).filename()).string();
    if (args.no_submit)
      std::printf("  %-5s sbatch --parsable%s %s\n", s.name.c_str(),
                  after.empty() ? "" : (std::string(" --dependency=") + kDependency + ":<previous job>").c_str(),
                  script.c_str());
    else
      std::printf("  %-5s job %s%s  %s\n", s.name.c_str(), s.job_id.c_str(),
                  after.empty() ? "" : (" after " + after).c_str(), script.c_str());
    after = args.no_submit ? "x" : s.job_id;
  }
  std::printf("  progress: phos slurm status %s\n", shown.c_str());
}

// ---- phos slurm status ------------------------------------------------------

// How many array tasks an scontrol record stands for: its ArrayTaskId, "3",
// or the pending rest of an array as one record, "0-1" or "2,4-7%2" (1 for
// a job that is not an array).
int ArrayTasksOf(const std::string& array_task_id) {
  if (array_task_id.empty()) return 1;
  const std::string ids = array_task_id.substr(0, array_task_id.find('%'));  // "%2": at most 2 at once
  int tasks = 0;
  std::istringstream parts(ids);
  std::string part;
  while (std::getline(parts, part, ',')) {
    const std::size_t dash = part.find('-');
    if (dash == std::string::npos) {
      ++tasks;
      continue;
    }
    char* end = nullptr;
    const long first = std::strtol(part.c_str(), nullptr, 10), last = std::strtol(part.c_str() + dash + 1, &end, 10);
    const long step = end && *end == ':' ? std::max(1L, std::strtol(end + 1, nullptr, 10)) : 1;  // "4-7:2"
    tasks += last >= first ? static_cast<int>((last - first) / step + 1) : 1;
  }
  return std::max(tasks, 1);
}

// Slurm's own word on a job, for status beside the done records: "FAILED",
// "PENDING (DependencyNeverSatisfied)", an array's "2 COMPLETED, 1 RUNNING";
// "" when scontrol cannot say (not installed, no cluster, or a job older than
// the controller keeps: slurm.conf's MinJobAge, 300 s by default). A
// controller that does not answer within 5 s (scontrol would wait about 18 s
// a call) is asked nothing more: *answering turns false.
std::string SlurmState(const std::string& job_id, bool* answering) {
  if (!*answering) return "";
  const ShellRun run = RunShell("timeout 5 scontrol -o show job " + ShellQuote(job_id) + " 2>/dev/null");
  if (run.exit_code == 124) *answering = false;  // timeout(1)'s code
  std::map<std::string, int> counts;             // array tasks by state (with its reason while pending)
  int tasks = 0;
  std::string line;
  std::istringstream records(run.out);
  while (std::getline(records, line)) {  // one record per line
    line += '\n';
    auto field = [&](const std::string& key) {
      const std::size_t at = line.find(" " + key + "=");
      if (at == std::string::npos) return std::string();
      const std::size_t begin = at + key.size() + 2;
      return line.substr(begin, line.find_first_of(" \n", begin) - begin);
    };
    std::string state = field("JobState");
    const std::string reason = field("Reason");
    if (!state.empty()) {
      if (state == "PENDING" && !reason.empty() && reason != "None") state += " (" + reason + ")";
      const int n = ArrayTasksOf(field("ArrayTaskId"));
      counts[state] += n;
      tasks += n;
    }
  }
  if (tasks == 0) return "";
  if (tasks == 1 && !counts.empty()) return counts.begin()->first;
  std::string said;
  for (const auto& [state, n] : counts) said += (said.empty() ? "" : ", ") + std::to_string(n) + " " + state;
  return said;
}

struct StatusArgs {
  std::string dir;
  bool json = false, require_done = false;
};

void RunStatus(const StatusArgs& args) {
  const fs::path file = fs::path(args.dir) / "job.json";
  const nlohmann::json json = ReadJsonFile(file);
  const SlurmJob job = SlurmJob::FromJson(JsonField(json, file.string()));
  nlohmann::json stages = nlohmann::json::array();
  bool all = true;
  std::string text, not_done;  // not_done: the stages and tasks not done, for --require-done's one line
  bool slurm_answering = true;
  for (const SlurmStage& s : job.stages) {
    std::vector<int> missing;
    double seconds = 0;
    for (std::size_t i = 0; i < s.done.size(); ++i) {
      // A task's record, or a merge's output file.
      const bool record = fs::path(s.done[i]).extension() == ".json";
      if (record) {
        const std::optional<TaskDoneRecord> r = ReadTaskDone(s.done[i]);
        if (r)
          seconds += r->seconds;
        else
          missing.push_back(static_cast<int>(i));
      } else if (!fs::exists(s.done[i])) {
        missing.push_back(static_cast<int>(i));
      }
    }
    const std::size_t done = s.done.size() - missing.size();
    const bool whole = missing.empty() && (!s.done.empty() || all);  // a check stage is done when all before it are
    if (!whole && !s.done.empty()) {
      std::string which = s.name;
      if (s.name == "tasks") {
        which += " ";
        const std::size_t shown = std::min<std::size_t>(missing.size(), 20);  // one line, even of 100,000 tasks
        for (std::size_t k = 0; k < shown; ++k) which += (k ? "," : "") + std::to_string(missing[k]);
        if (shown < missing.size()) which += " and " + std::to_string(missing.size() - shown) + " more";
        which += " of " + std::to_string(s.done.size());
      }
      not_done += (not_done.empty() ? "" : "; ") + which + " not done";
    }
    all = all && whole;
    const std::string slurm_state = s.job_id.empty() ? "" : SlurmState(s.job_id, &slurm_answering);
    stages.push_back({{"name", s.name},
                      {"job_id", s.job_id},
                      {"slurm_state", slurm_state},
                      {"done", done},
                      {"of", s.done.size()},
                      {"missing", missing},
                      {"task_seconds", seconds}});
    std::string line = "  " + s.name + std::string(s.name.size() < 7 ? 7 - s.name.size() : 1, ' ');
    if (s.name == "tasks") {
      line += std::to_string(done) + "/" + std::to_string(s.done.size()) + " done";
      if (!missing.empty()) {
        line += "; not done:";
        for (int i : missing) line += " " + std::to_string(i);
      }
      if (done > 0) line += "; " + FormatShort(seconds / done, 3) + " s per task";
    } else {
      line += whole ? "done" : "not done";
      if (seconds > 0) line += " (" + FormatShort(seconds, 3) + " s)";
    }
    text += line +
            (s.job_id.empty() ? "" : "  [job " + s.job_id + (slurm_state.empty() ? "" : ": " + slurm_state) + "]") +
            "\n";
  }
  if (args.json) {
    std::printf(
        "%s\n",
        nlohmann::json({{"kind", job.kind}, {"tasks", job.tasks}, {"done", all}, {"stages", stages}}).dump().c_str());
  } else {
    std::printf("phos slurm status: %s, %d task(s): %s\n%s", job.kind.c_str(), job.tasks, all ? "done" : "not done",
                text.c_str());
  }
  if (args.require_done && !all)
    ThrowUserError(args.dir, "",
                   "not every task is done: " + (not_done.empty() ? std::string("see the lines above") : not_done));
}

void AddSubmit(CLI::App& slurm, const std::string& kind, const std::string& what) {
  auto args = std::make_shared<SubmitArgs>();
  args->kind = kind;
  CLI::App* cmd = slurm.add_subcommand(kind, what);
  cmd->add_option("--tasks", args->tasks, "Array tasks (the work is split in N near-equal shares)")
      ->required()
      ->check(CLI::Range(1, 100000));
  cmd->add_option("--job-dir", args->job_dir,
                  "Folder for the scripts, job.json and the logs (on the shared filesystem)")
      ->required();
  cmd->add_option("--partition", args->site.partition, "sbatch --partition (default: the cluster's default)");
  cmd->add_option("--account", args->site.account, "sbatch --account (default: your default account)");
  cmd->add_option("--time-per-task", args->site.time_per_task,
                  "sbatch --time of each job: MM, MM:SS, HH:MM:SS, D-HH, D-HH:MM, D-HH:MM:SS or UNLIMITED")
      ->default_str("01:00:00")
      // Slurm's forms of a time limit; anything else sbatch refuses after the check.
      ->check(CLI::Validator([](std::string& value) { return SlurmTimeError(value); }, "", "slurm time"));
  cmd->add_option("--mem-per-task", args->site.mem_per_task,
                  "sbatch --mem of each job: a positive amount with an optional K, M, G or T suffix\n"
                  "(docs/scale.md says what each kind needs)")
      ->default_str("4G")
      ->check(CLI::Validator([](std::string& value) { return SlurmMemoryError(value); }, "", "slurm memory"));
  cmd->add_option("--cpus-per-task", args->site.cpus_per_task, "sbatch --cpus-per-task")
      ->default_str("2")
      ->check(CLI::Range(1, 1024));
  cmd->add_option("--sbatch-option", args->site.extra,
                  "Another sbatch option for every job, without its dashes, e.g. --sbatch-option qos=short\n"
                  "(#SBATCH --qos=short; repeatable)")
      ->allow_extra_args(false);  // one value each time: a -- after it still starts COMMAND
  cmd->add_option("--sbatch", args->sbatch, "The sbatch to run")->default_str("sbatch");
  cmd->add_flag("--no-submit", args->no_submit, "Write the scripts and job.json only; print the sbatch commands");
  cmd->add_flag("--json", args->json, "Print job.json (the stages, their scripts and job ids)");
  cmd->add_option("COMMAND", args->command,
                  "After --: the arguments of 'phos " + std::string(kind == "render" ? "render" : "fit " + kind) +
                      "', --out included")
      ->required();
  // An option that is not phos slurm's is most often the command's, given
  // before or without the --: RunCommand adds this footer to CLI11's "not
  // expected" (and --help shows it).
  cmd->footer("The command's own arguments go after --, e.g. phos slurm " + kind + " --tasks 2 --job-dir J -- " +
              (kind == "render" ? "SCENE"
               : kind == "map"  ? "SESSION"
                                : "CAPTURES") +
              " --out OUT");
  cmd->callback([args] { RunSubmit(*args); });
}

}  // namespace

void RegisterSlurm(CLI::App& app) {
  CLI::App* slurm = app.add_subcommand("slurm", Summary("slurm"));
  slurm->require_subcommand(1);
  AddSubmit(*slurm, "render",
            "Render a scene's frames as a job array: the solver pass (one job: the states are sequential in\n"
            "time), then N ranges of frames (phos render --task i/N), then a check that every range is done.\n"
            "Example: phos slurm render --tasks 8 --job-dir jobs/box -- scene.json --out frames --transport path");
  AddSubmit(*slurm, "map",
            "Fit a decay map as a job array: N bands of rows (phos fit map --tile i/N), then the merge\n"
            "(--merge: decay-map.exr and kr.png). Example: phos slurm map --tasks 4 --job-dir jobs/m -- S --out M");
  AddSubmit(*slurm, "batch",
            "Fit a batch as a job array: N shares of the items (phos fit batch --task i/N), then the merge\n"
            "(summary.csv). Example: phos slurm batch --tasks 16 --job-dir jobs/b -- captures --out materials");
  auto status = std::make_shared<StatusArgs>();
  CLI::App* s = slurm->add_subcommand("status", "Progress of a submitted job from its tasks' done records");
  s->add_option("DIR", status->dir, "The --job-dir of the submission")->required();
  s->add_flag("--json", status->json, "Print one JSON object");
  s->add_flag("--require-done", status->require_done, "Exit 2 unless every stage is done (the render's last job)");
  s->callback([status] { RunStatus(*status); });
}

}  // namespace phos::app
