// phos slurm against a real Slurm (docs/scale.md): a one-node cluster on this
// machine (munged, slurmctld, slurmd, with a slurm.conf written here, on
// ports of its own), stopped by PID afterwards, even when a check fails.
// Arrays for a render, a decay map and a fit batch give what one process
// gives; a render task requeued (killed) mid-run is redone whole and the
// frames are still the same. Skipped, saying why, only where the cluster
// cannot start (slurm-wlm or munge missing, not root, a daemon that dies).
// Also, without Slurm: the scripts --no-submit writes, and status.

#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <map>
#include <set>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "phos/render/renderer.h"
#include "test_util.h"

namespace phos::testing {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// Runs a shell command; its exit code and what it printed (both streams).
CommandResult Shell(const std::string& command) {
  CommandResult result;
  FILE* pipe = popen((command + " 2>&1 </dev/null").c_str(), "r");
  if (!pipe) return result;
  char buffer[1024];
  while (std::fgets(buffer, sizeof buffer, pipe)) result.out += buffer;
  const int status = pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

bool WaitFor(const std::function<bool()>& condition, double timeout_s, double poll_s = 0.05) {
  const auto end = Clock::now() + std::chrono::duration<double>(timeout_s);
  while (Clock::now() < end) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::duration<double>(poll_s));
  }
  return condition();
}

std::string Executable(const std::string& name) {
  for (const char* dir : {"/usr/sbin", "/usr/bin", "/sbin", "/bin", "/usr/local/sbin", "/usr/local/bin"})
    if (::access((std::string(dir) + "/" + name).c_str(), X_OK) == 0) return std::string(dir) + "/" + name;
  return "";
}

std::string Tail(const fs::path& log) {
  const std::string text = ReadText(log);
  return text.size() > 600 ? text.substr(text.size() - 600) : text;
}

// A job credential's lifetime (slurm.conf AuthInfo cred_expire; Slurm's
// default 120 s), which is also how long a requeued job waits before it may
// start again (slurm.conf(5)). A local node launches in well under a second;
// the default made the requeue two thirds of this test's time.
constexpr int kCredentialLifetimeS = 20;

// The script users start a one-node cluster with (docs/scale.md).
std::string OneNodeScript() {
  return (fs::path(PHOS_FIXTURES_DIR).parent_path() / "scripts" / "slurm-one-node.sh").string();
}

// munged, slurmctld and slurmd as a one-node cluster in a folder of its own,
// through scripts/slurm-one-node.sh.
class OneNodeSlurm {
 public:
  // "" when the cluster is up; otherwise why it cannot be.
  std::string Start() {
    if (::geteuid() != 0) return "the one-node cluster runs slurmd, which needs root";
    for (const char* tool :
         {"munged", "mungekey", "slurmctld", "slurmd", "sbatch", "scontrol", "squeue", "sinfo", "scancel"})
      if (Executable(tool).empty())
        return std::string(tool) + " is not installed (scripts/bootstrap.sh installs slurm-wlm and munge)";
    const fs::path d = dir_.path();
    started_ = true;
    const CommandResult start = Shell("PHOS_SLURM_CRED_EXPIRE_S=" + std::to_string(kCredentialLifetimeS) +
                                      " PHOS_SLURM_MEMORY_MB=2000 bash " + OneNodeScript() + " start " + d.string());
    if (start.exit_code != 0) return "scripts/slurm-one-node.sh start failed: " + start.out;
    // sbatch, squeue, scontrol (and phos slurm's sbatch) find it.
    ::setenv("SLURM_CONF", (d / "slurm.conf").c_str(), 1);
    return "";
  }

  // Cancels every job, then stops the daemons it started.
  void Stop() {
    if (!started_) return;
    Shell("bash " + OneNodeScript() + " stop " + dir_.path().string());
    started_ = false;
    ::unsetenv("SLURM_CONF");
  }

  ~OneNodeSlurm() { Stop(); }
  const fs::path& dir() const { return dir_.path(); }

 private:
  TempDir dir_;
  bool started_ = false;
};

std::map<std::string, LargeTable<float>> Images(const fs::path& dir, const std::string& extension) {
  std::map<std::string, LargeTable<float>> images;
  for (const auto& entry : fs::directory_iterator(dir))
    if (entry.path().extension() == extension)
      images[entry.path().filename().string()] = render::ReadImage(entry.path()).pixels;
  return images;
}

bool HasTemporaries(const fs::path& dir) {
  for (const auto& entry : fs::recursive_directory_iterator(dir))
    if (entry.path().filename().string().find(".tmp.") != std::string::npos) return true;
  return false;
}

// What the jobs of a chain printed (their logs), and Slurm's record of each, for a failure's message.
std::string Logs(const fs::path& job_dir) {
  std::string text;
  if (fs::exists(job_dir / "logs"))
    for (const auto& entry : fs::directory_iterator(job_dir / "logs"))
      text += "\n--- " + entry.path().string() + "\n" + Tail(entry.path());
  const std::string job = ReadText(job_dir / "job.json");
  for (std::size_t at = job.find("\"job_id\""); at != std::string::npos; at = job.find("\"job_id\"", at + 1)) {
    const std::size_t open = job.find('"', job.find(':', at)) + 1;
    text += "\n--- scontrol show job " + job.substr(open, job.find('"', open) - open) + "\n" +
            Shell("scontrol -o show job " + job.substr(open, job.find('"', open) - open)).out;
  }
  return text;
}

nlohmann::json Job(const fs::path& job_dir) { return nlohmann::json::parse(ReadText(job_dir / "job.json")); }
std::string JobId(const fs::path& job_dir, int stage) {
  return Job(job_dir)["stages"][stage]["job_id"].get<std::string>();
}
std::string JobState(const std::string& id) {
  const std::string out = Shell("scontrol -o show job " + id).out;
  const std::size_t at = out.find("JobState=");
  return at == std::string::npos ? "" : out.substr(at + 9, out.find(' ', at) - at - 9);
}

TEST(SlurmCluster, ArraysEqualOneProcessAndARequeuedTaskIsRedoneWhole) {
  OneNodeSlurm slurm;
  const std::string why = slurm.Start();
  if (!why.empty()) GTEST_SKIP() << "no one-node Slurm cluster here, the Slurm test is skipped: " << why;
  TempDir work;
  const std::string site = " --cpus-per-task 1 --mem-per-task 100M --time-per-task 00:10:00";

  // The render: 6 path-traced frames across the lights-out; task 0 has
  // frames 0-2 and is requeued once frame 0 is written and before frame 2 is.
  const std::string scene = Fixture("scenes/cornell-phosphor.json").string();
  const std::string render = scene + " --times 5,20,31,45,60,70 --width 80 --height 60 --transport path --spp 32";
  const fs::path render_job = work / "render-job";
  const CommandResult submitted = RunPhos("slurm render --tasks 2 --job-dir " + render_job.string() + site + " -- " +
                                          render + " --out " + (work / "frames").string());
  ASSERT_EQ(submitted.exit_code, 0) << submitted.out << submitted.err;
  const std::string render_tasks = JobId(render_job, 1);
  const bool mid_run = WaitFor(
      [&] { return fs::exists(work / "frames" / "frame-0000.exr") && !fs::exists(work / "frames" / "frame-0002.exr"); },
      120, 0.005);
  ASSERT_TRUE(mid_run) << "task 0 was never caught between its first and last frame";
  ASSERT_EQ(Shell("scontrol requeue " + render_tasks + "_0").exit_code, 0);
  // Slurm holds a requeued job before it may start again: slurmctld sets its
  // BeginTime past the expiry of the killed run's job credential
  // (kCredentialLifetimeS here; Slurm's default is 120 s), because the node
  // refuses to launch a job whose credential it has just revoked. Forcing
  // the start earlier (scontrol update StartTime=now) launched the rerun
  // into that refusal: it failed at once with exit code 1 and no output,
  // even once the killed run's process was gone and nothing was completing
  // (CI, 3 December, twice). So the test waits for Slurm's own restart.
  ASSERT_TRUE(WaitFor([&] { return JobState(render_tasks + "_0") == "PENDING"; }, 30, 0.05))
      << JobState(render_tasks + "_0");

  // The map (3 tiles) and the batch (2 shares of 2 items).
  const std::string session = (work / "session").string();
  ASSERT_EQ(RunPhos("capture decay --sim-material " + Fixture("materials/orange.json").string() + " --sim-inset " +
                    Fixture("materials/blue.json").string() + " --sim-size 40x30 --charge-s 1800 --out " + session)
                .exit_code,
            0);
  for (const char* name : {"orange", "blue"})
    ASSERT_EQ(RunPhos("capture all --sim-material " + Fixture(std::string("materials/") + name + ".json").string() +
                      " --sim-size 16x12 --out " + (work / "captures" / name).string())
                  .exit_code,
              0);
  const fs::path map_job = work / "map-job", batch_job = work / "batch-job";
  CommandResult r = RunPhos("slurm map --tasks 3 --job-dir " + map_job.string() + site + " -- " + session + " --out " +
                            (work / "map").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunPhos("slurm batch --tasks 2 --job-dir " + batch_job.string() + site + " -- " + (work / "captures").string() +
              " --out " + (work / "batch").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;

  // One process each, meanwhile.
  ASSERT_EQ(RunPhos("render " + render + " --out " + (work / "one-frames").string()).exit_code, 0);
  ASSERT_EQ(RunPhos("fit map " + session + " --out " + (work / "one-map").string()).exit_code, 0);
  ASSERT_EQ(RunPhos("fit batch " + (work / "captures").string() + " --out " + (work / "one-batch").string()).exit_code,
            0);

  // Every job of the three chains ends, and ends well.
  const bool ended =
      WaitFor([] { return Shell("squeue -h").out.empty(); }, 360, 0.25);  // the requeue's hold, and the rest
  ASSERT_TRUE(ended) << Shell("squeue").out << Tail(slurm.dir() / "slurmctld.log") << Logs(render_job) << Logs(map_job)
                     << Logs(batch_job);
  for (const fs::path& job : {render_job, map_job, batch_job}) {
    const nlohmann::json record = Job(job);  // kept: a loop over Job(job)["stages"] read a destroyed temporary
    for (const auto& stage : record["stages"]) {
      const std::string id = stage["job_id"].get<std::string>();
      // Every task's state (an array shows one line per task), as a sorted set.
      const std::string shown = Shell("scontrol -o show job " + id).out;
      std::set<std::string> states;
      for (std::size_t at = shown.find("JobState="); at != std::string::npos; at = shown.find("JobState=", at + 1))
        states.insert(shown.substr(at, shown.find(' ', at) - at));
      EXPECT_EQ(states, std::set<std::string>{"JobState=COMPLETED"})
          << job << " " << stage["name"] << " (job " << id << "): " << shown << Logs(job);
    }
    const CommandResult status = RunPhos("slurm status " + job.string() + " --json");
    ASSERT_EQ(status.exit_code, 0) << status.err;
    const nlohmann::json said = nlohmann::json::parse(status.out);
    EXPECT_TRUE(said["done"].get<bool>()) << status.out;
    // Slurm's own word beside the records: a job "COMPLETED", an array "N COMPLETED".
    for (const auto& stage : said["stages"]) {
      const std::string state = stage["slurm_state"].get<std::string>();
      EXPECT_TRUE(state == "COMPLETED" || (state.size() > 10 && state.substr(state.size() - 10) == " COMPLETED" &&
                                           state.find(',') == std::string::npos))
          << job << " " << stage["name"] << ": " << state;
    }
  }
  // The requeued task ran twice, its frames are whole and no temporary is left.
  EXPECT_NE(Shell("scontrol -o show job " + render_tasks + "_0").out.find("Restarts=1"), std::string::npos);
  EXPECT_FALSE(HasTemporaries(work / "frames"));

  const auto frames = Images(work / "frames", ".exr"), one_frames = Images(work / "one-frames", ".exr");
  ASSERT_EQ(frames.size(), 6u);
  for (const auto& [name, pixels] : one_frames) EXPECT_TRUE(frames.at(name) == pixels) << name;
  const render::Image map = render::ReadImage(work / "map" / "decay-map.exr"),
                      one_map = render::ReadImage(work / "one-map" / "decay-map.exr");
  ASSERT_EQ(map.pixels.size(), one_map.pixels.size());
  EXPECT_EQ(std::memcmp(map.pixels.data(), one_map.pixels.data(), map.pixels.size() * sizeof(float)), 0);
  EXPECT_EQ(ReadText(work / "map" / "kr.png"), ReadText(work / "one-map" / "kr.png"));
  for (const char* name : {"orange.json", "blue.json"})
    EXPECT_EQ(ReadText(work / "batch" / name), ReadText(work / "one-batch" / name)) << name;
  EXPECT_TRUE(fs::exists(work / "batch" / "summary.csv"));
  slurm.Stop();
}

// A small decay session (40 x 30) for the map's check.
std::string SmallSession(const TempDir& dir) {
  const std::string session = (dir / "s").string();
  const CommandResult r = RunPhos("capture decay --sim-material " + Fixture("materials/orange.json").string() +
                                  " --sim-size 40x30 --charge-s 600 --out " + session);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return session;
}

// A stand-in for sbatch that prints job ids 101, 102, ... and fails on call
// `fail_at` (0: never), with scancel beside it logging what it cancels: what
// phos slurm does around sbatch, without a cluster (SlurmCluster runs the real one).
std::string FakeSbatch(const TempDir& dir, int fail_at) {
  const fs::path bin = dir / "bin";
  fs::create_directories(bin);
  WriteText(bin / "sbatch", "#!/bin/bash\nn=$(( $(cat " + (bin / "count").string() +
                                " 2>/dev/null || echo 0) + 1 ))\n" + "echo $n > " + (bin / "count").string() + "\n" +
                                "echo \"$@\" >> " + (bin / "calls").string() + "\n" + "if [ $n -eq " +
                                std::to_string(fail_at) +
                                " ]; then echo 'sbatch: error: Batch job submission failed' >&2; exit 1; fi\n"
                                // A note on stderr, as many sites print, on a submission that succeeds.
                                "echo 'sbatch: info: Setting QOS to normal' >&2\n"
                                "echo $((100 + n))\n");
  WriteText(bin / "scancel", "#!/bin/bash\necho \"$@\" >> " + (bin / "cancelled").string() + "\n");
  fs::permissions(bin / "sbatch", fs::perms::owner_all);
  fs::permissions(bin / "scancel", fs::perms::owner_all);
  return (bin / "sbatch").string();
}

TEST(SlurmScripts, NoSubmitWritesTheChainAndStatusCountsRecords) {
  TempDir dir;
  const std::string session = SmallSession(dir);
  const CommandResult r = RunPhos("slurm map --tasks 4 --no-submit --job-dir " + (dir / "job").string() +
                                  " --partition short --account lab7 --sbatch-option qos=low -- " + session +
                                  " --out " + (dir / "out").string() + " --weights none");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string tasks = ReadText(dir / "job" / "tasks.sbatch");
  for (const char* line : {"#SBATCH --array=0-3\n", "#SBATCH --partition=short\n", "#SBATCH --account=lab7\n",
                           "#SBATCH --qos=low\n", "#SBATCH --mem=4G\n", "#SBATCH --time=01:00:00\n",
                           "#SBATCH --requeue\n", "'--tile' ${SLURM_ARRAY_TASK_ID}/4\n", "'--weights' 'none'"})
    EXPECT_NE(tasks.find(line), std::string::npos) << line << " not in\n" << tasks;
  EXPECT_NE(ReadText(dir / "job" / "merge.sbatch").find("'--merge'"), std::string::npos);
  // The tiles wait for nothing; the merge waits for every tile to end, however it ended, and checks the records.
  EXPECT_NE(r.out.find("  tasks sbatch --parsable "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("  merge sbatch --parsable --dependency=afterany:<previous job> "), std::string::npos) << r.out;
  // Nothing done yet; then two tiles' records: 2/4.
  CommandResult status = RunPhos("slurm status " + (dir / "job").string());
  ASSERT_EQ(status.exit_code, 0) << status.err;
  EXPECT_NE(status.out.find("tasks  0/4 done; not done: 0 1 2 3"), std::string::npos) << status.out;
  fs::create_directories(dir / "out" / "tiles");
  for (int i : {1, 3})
    WriteText(dir / "out" / "tiles" / ("tile-" + std::to_string(i) + "-of-4.json"),
              R"({"format":"phos.task-done/1","task":"t","inputs":"","outputs":[],"seconds":2,"host":"h"})");
  status = RunPhos("slurm status " + (dir / "job").string());
  EXPECT_NE(status.out.find("tasks  2/4 done; not done: 0 2; 2 s per task"), std::string::npos) << status.out;
  // --require-done (the render's last job) names what is missing, after the lines it sums up, in a log too.
  EXPECT_TRUE(IsOneLineUserError(RunPhos("slurm status " + (dir / "job").string() + " --require-done"),
                                 "not every task is done: tasks 0,2 of 4 not done; merge not done"));
  const std::string log =
      Shell(std::string(PHOS_BINARY) + " slurm status " + (dir / "job").string() + " --require-done").out;
  ASSERT_NE(log.find("not every task is done"), std::string::npos) << log;
  EXPECT_LT(log.find("tasks  2/4 done"), log.find("not every task is done")) << log;
  // Scripts written and never submitted do not block the folder: submitting replaces them.
  const std::string sbatch = FakeSbatch(dir, 0);
  const CommandResult submit = RunPhos("slurm map --tasks 4 --sbatch " + sbatch + " --job-dir " +
                                       (dir / "job").string() + " -- " + session + " --out " + (dir / "out").string());
  ASSERT_EQ(submit.exit_code, 0) << submit.err;
  EXPECT_NE(submit.out.find("  merge job 102 after 101"), std::string::npos) << submit.out;
  // A second submission from the same folder is refused.
  const CommandResult again = RunPhos("slurm map --tasks 4 --no-submit --job-dir " + (dir / "job").string() + " -- " +
                                      session + " --out " + (dir / "out").string());
  EXPECT_EQ(again.exit_code, 2);
  EXPECT_NE(again.err.find("a job was already submitted from this folder"), std::string::npos) << again.err;
}

TEST(SlurmScripts, EveryStageWaitsForTheOneBeforeToEndHoweverItEnded) {
  // A render's tasks after a solver pass that failed (say, killed) start from
  // the states there are, or fail with its line; with afterok they waited forever.
  TempDir dir;
  const std::string sbatch = FakeSbatch(dir, 0);
  const CommandResult r = RunPhos("slurm render --tasks 2 --sbatch " + sbatch + " --job-dir " + (dir / "job").string() +
                                  " -- " + Fixture("scenes/cornell-phosphor.json").string() + " --out " +
                                  (dir / "frames").string() + " --times 20,40");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string calls = ReadText(dir / "bin" / "calls");
  EXPECT_NE(calls.find("--dependency=afterany:101 "), std::string::npos) << calls;
  EXPECT_NE(calls.find("--dependency=afterany:102 "), std::string::npos) << calls;
  EXPECT_EQ(calls.find("afterok"), std::string::npos) << calls;
  // The render's last job only reads records: it asks for little, not a task's share.
  const std::string check = ReadText(dir / "job" / "merge.sbatch"), tasks = ReadText(dir / "job" / "tasks.sbatch");
  for (const char* line : {"#SBATCH --mem=256M\n", "#SBATCH --cpus-per-task=1\n", "#SBATCH --time=00:10:00\n"})
    EXPECT_NE(check.find(line), std::string::npos) << line << " not in\n" << check;
  EXPECT_NE(tasks.find("#SBATCH --mem=4G\n"), std::string::npos) << tasks;
  // status says what Slurm says of each job (here a stand-in scontrol: the
  // solver pass failed, its array pending), beside the records it counts.
  WriteText(
      dir / "bin" / "scontrol",
      "#!/bin/bash\ncase $4 in\n"
      "101) echo 'JobId=101 JobName=phos-render-solve JobState=FAILED Reason=NonZeroExitCode Dependency=(null)' ;;\n"
      // A pending array's tasks are one record (ArrayTaskId=0-1), as Slurm prints them.
      "102) echo 'JobId=102 ArrayJobId=102 ArrayTaskId=0-1 JobState=PENDING Reason=Dependency Dependency=afterany:101' "
      ";;\n"
      "*) exit 1 ;;\nesac\n");
  fs::permissions(dir / "bin" / "scontrol", fs::perms::owner_all);
  const CommandResult status = Shell("PATH=" + (dir / "bin").string() + ":$PATH " + std::string(PHOS_BINARY) +
                                     " slurm status " + (dir / "job").string());
  EXPECT_NE(status.out.find("  solve  not done  [job 101: FAILED]"), std::string::npos) << status.out;
  EXPECT_NE(status.out.find("  tasks  0/2 done; not done: 0 1  [job 102: 2 PENDING (Dependency)]"), std::string::npos)
      << status.out;
  EXPECT_NE(status.out.find("  merge  not done  [job 103]"), std::string::npos) << status.out;  // scontrol: unknown
  // A controller that does not answer (SLURM_CONF still set after the cluster
  // stopped): status asks once, gives up after scontrol's 5 s, and asks no more.
  WriteText(dir / "bin" / "scontrol",
            "#!/bin/bash\necho \"$@\" >> " + (dir / "bin" / "asked").string() + "\nexec sleep 30\n");
  const CommandResult silent = Shell("PATH=" + (dir / "bin").string() + ":$PATH " + std::string(PHOS_BINARY) +
                                     " slurm status " + (dir / "job").string());
  EXPECT_NE(silent.out.find("  solve  not done  [job 101]"), std::string::npos) << silent.out;
  EXPECT_EQ(ReadText(dir / "bin" / "asked"), "-o show job 101\n");
  // A task whose solver pass left no states folder at all (cancelled before
  // it made one) starts from the scene's start: the same frames, said.
  const std::string scene = Fixture("scenes/cornell-phosphor.json").string();
  const CommandResult task =
      RunPhos("render " + scene + " --out " + (dir / "task").string() +
              " --times 20,40 --width 32 --height 24 --task 1/2 --checkpoints " + (dir / "no-states").string());
  ASSERT_EQ(task.exit_code, 0) << task.err;
  EXPECT_NE(task.err.find("no-states: no such folder; the states start from the scene's start"), std::string::npos)
      << task.err;
  ASSERT_EQ(RunPhos("render " + scene + " --out " + (dir / "whole").string() + " --times 20,40 --width 32 --height 24")
                .exit_code,
            0);
  EXPECT_TRUE(render::ReadImage(dir / "task" / "frame-0001.exr").pixels ==
              render::ReadImage(dir / "whole" / "frame-0001.exr").pixels);
  // A word of the user's that starts with ${ is quoted like any other: only the array index is the shell's.
  const CommandResult dollar = RunPhos("slurm render --tasks 2 --no-submit --job-dir " + (dir / "job2").string() +
                                       " -- " + scene + " --times 20,40 --out '${HOME}/phos-test-out'");
  ASSERT_EQ(dollar.exit_code, 0) << dollar.err;
  const std::string script = ReadText(dir / "job2" / "tasks.sbatch");
  EXPECT_NE(script.find(" '${HOME}/phos-test-out' "), std::string::npos) << script;
  EXPECT_NE(script.find("'--task' ${SLURM_ARRAY_TASK_ID}/2 "), std::string::npos) << script;
}

TEST(SlurmScripts, ACommandItsTasksWouldRefuseIsRefusedBeforeAnythingIsWritten) {
  TempDir dir;
  const std::string sbatch = FakeSbatch(dir, 0), scene = Fixture("scenes/cornell-phosphor.json").string();
  const std::string job = (dir / "job").string(), out = " --out " + (dir / "frames").string();
  WriteText(dir / "afile", "");  // an --out that is a file
  auto refused = [&](const std::string& kind, const std::string& command, const std::string& why) {
    const CommandResult r =
        RunPhos("slurm " + kind + " --tasks 10 --sbatch " + sbatch + " --job-dir " + job + " -- " + command);
    EXPECT_TRUE(IsOneLineUserError(r, why)) << command << "\n" << r.err;
    EXPECT_FALSE(fs::exists(job)) << command;  // no folder, no script
  };
  refused("render", scene + out + " --no-such", "COMMAND: its tasks would fail (nothing submitted)");
  refused("render", scene + out + " --no-such", "--no-such");
  refused("render", scene + out + " --frames 0:4", "--frames excludes --task");
  refused("render", scene + out + " --times 20,40 --exposure auto", "\"auto\" meters every frame after dark");
  refused("render", (dir / "none.json").string() + out, "none.json");
  refused("map", (dir / "no-session").string() + out, "no-session");
  refused("batch", (dir / "no-captures").string() + out, "no-captures");
  // More tiles than the session's 30 rows: some tile would have none, and the merge could never run.
  const std::string session = SmallSession(dir);
  const CommandResult rows =
      RunPhos("slurm map --tasks 31 --sbatch " + sbatch + " --job-dir " + job + " -- " + session + out);
  EXPECT_TRUE(IsOneLineUserError(rows, "has no rows: more tiles than the frames' 30 rows")) << rows.err;
  EXPECT_FALSE(fs::exists(job));
  refused("map", session + out + " --weights bogus", "--weights");
  refused("map", session + " --out " + (dir / "afile").string(), "is a file, not a folder");
  // --check fits and writes nothing, and is not for a merge (which would write).
  EXPECT_TRUE(IsOneLineUserError(RunPhos("fit map " + session + out + " --merge --check"), "--check"));
  EXPECT_FALSE(fs::exists(dir / "bin" / "calls"));  // sbatch never ran
  // The command's options before or without the --: said so.
  // The options before the -- that are not phos slurm's are named, not the right words after it.
  for (const auto& [words, named] : std::vector<std::pair<std::string, std::string>>{
           {" " + scene + out, "--out: not an option of phos slurm render; The command's own arguments go after --"},
           {out + " -- " + scene, "--out: not an option of phos slurm render;"},
           {" --transport path -- " + scene + out, "--transport: not an option of phos slurm render;"},
           {" " + scene + " --times 20,40 -- " + out, "--times: not an option of phos slurm render;"}}) {
    const CommandResult r = RunPhos("slurm render --tasks 2 --job-dir " + job + words);
    EXPECT_TRUE(IsOneLineUserError(r, named)) << words;
    EXPECT_EQ(r.err.find(scene), std::string::npos) << r.err;  // the scene is not among the wrong words
  }
  EXPECT_FALSE(fs::exists(job));
  // What a task would refuse after its scene is loaded: checked too.
  refused("render", scene + " --out " + (dir / "afile").string(),
          "--out: '" + (dir / "afile").string() + "' is a file");
  refused("render", scene + out + " --indirect-visibility", "--indirect-visibility: is for --transport dss");
  // A time limit Slurm would refuse, refused before anything else.
  EXPECT_TRUE(IsOneLineUserError(
      RunPhos("slurm render --tasks 2 --time-per-task 90min --job-dir " + job + " -- " + scene + out),
      "--time-per-task: expected a Slurm time"));
  // The render's last job asks for 10 minutes, or the tasks' time if that is shorter.
  for (const auto& [time, check_time] : std::vector<std::pair<std::string, std::string>>{
           {"5", "5"}, {"9:30", "9:30"}, {"01:00:00", "00:10:00"}, {"UNLIMITED", "00:10:00"}}) {
    const fs::path folder = dir / ("light" + std::to_string(check_time.size()) + time.substr(0, 1));
    ASSERT_EQ(RunPhos("slurm render --tasks 2 --no-submit --time-per-task " + time + " --job-dir " + folder.string() +
                      " -- " + scene + out)
                  .exit_code,
              0)
        << time;
    EXPECT_NE(ReadText(folder / "merge.sbatch").find("#SBATCH --time=" + check_time + "\n"), std::string::npos) << time;
  }
  for (const char* time : {"90", "1:30:00", "2-12", "2-12:30:00", "UNLIMITED"})
    EXPECT_EQ(RunPhos("slurm render --tasks 2 --no-submit --time-per-task " + std::string(time) + " --job-dir " +
                      (dir / (std::string("t") + time)).string() + " -- " + scene + out)
                  .exit_code,
              0)
        << time;
  // Empty paths: one line each, not an internal error.
  EXPECT_TRUE(IsOneLineUserError(RunPhos("slurm render --tasks 2 --job-dir '' -- " + scene + out), "--job-dir"));
  EXPECT_TRUE(IsOneLineUserError(RunPhos("slurm render --tasks 2 --job-dir " + job + " -- " + scene + " --out ''"),
                                 "--out is empty"));
}

// A newline in --partition or --sbatch-option was written raw into the job
// script, and what followed it ran as a command of the job; --mem-per-task
// -4G, 4X and 0 and --time-per-task 99:99:99 were written unchecked. Each
// value the scripts hold outside the quoted command is one value of the form
// sbatch takes, or refused in one line before anything is written.
TEST(SlurmScripts, EveryValueOfAJobScriptIsOneValueOfTheFormSlurmTakes) {
  TempDir dir;
  const std::string scene = Fixture("scenes/cornell-phosphor.json").string(),
                    out = " --out " + (dir / "frames").string();
  const std::string job = (dir / "job").string(), ran = (dir / "ran").string();
  auto refused = [&](const std::string& options, const std::string& why) {
    const CommandResult r =
        RunPhos("slurm render --tasks 2 --no-submit --job-dir " + job + options + " -- " + scene + out);
    EXPECT_TRUE(IsOneLineUserError(r, why)) << options;
    EXPECT_FALSE(fs::exists(job)) << options;
  };
  refused(" --partition 'debug\ntouch " + ran + "'", "--partition: contains a control character (code 10)");
  refused(" --sbatch-option 'qos=short\ntouch " + ran + "'", "--sbatch-option: contains a control character (code 10)");
  refused(" --account 'lab\rtouch " + ran + "'", "--account: contains a control character (code 13)");
  refused(" --partition 'debug --mem=1'", "--partition: contains a space");
  EXPECT_TRUE(IsOneLineUserError(
      RunPhos("slurm render --tasks 2 --no-submit --job-dir '" + job + "\ntouch " + ran + "' -- " + scene + out),
      "--job-dir: contains a control character (code 10)"));
  for (const char* memory : {"-4G", "4X", "0", "00", "4 G", "G", "4.5G", ""})
    refused(std::string(" --mem-per-task='") + memory + "'", "--mem-per-task: expected a positive whole amount");
  for (const char* time : {"99:99:99", "5:75", "1-24", "1-2:60", "1-2:3:60", "2:60:00", "-5", "1:2:3:4"})
    refused(std::string(" --time-per-task='") + time + "'", "--time-per-task: expected a Slurm time");
  EXPECT_FALSE(fs::exists(ran));
  // The forms sbatch takes are written as given.
  for (const auto& [memory, time] : std::vector<std::pair<std::string, std::string>>{
           {"4096", "100:00:00"}, {"500M", "1-23:59:59"}, {"2t", "59:59"}, {"4G", "7-0"}}) {
    const fs::path folder = dir / ("ok" + memory);
    const CommandResult r =
        RunPhos("slurm render --tasks 2 --no-submit --job-dir " + folder.string() + " --mem-per-task " + memory +
                " --time-per-task " + time + " --sbatch-option 'comment=two words' -- " + scene + out);
    ASSERT_EQ(r.exit_code, 0) << memory << " " << time << ": " << r.err;
    const std::string script = ReadText(folder / "tasks.sbatch");
    EXPECT_NE(script.find("#SBATCH --mem=" + memory + "\n#"), std::string::npos) << script;
    EXPECT_NE(script.find("#SBATCH --time=" + time + "\n"), std::string::npos) << script;
  }
}

TEST(SlurmScripts, ALaterSbatchThatFailsCancelsTheJobsBeforeIt) {
  // The third sbatch (the merge) fails: the solver pass and the array were
  // queued already; they are cancelled, no job.json is written, and a retry
  // in the same folder submits the chain once.
  TempDir dir;
  const std::string sbatch = FakeSbatch(dir, 3), scene = Fixture("scenes/cornell-phosphor.json").string();
  const std::string submit = "slurm render --tasks 2 --sbatch " + sbatch + " --job-dir " + (dir / "job").string() +
                             " -- " + scene + " --out " + (dir / "frames").string() + " --times 20,40";
  const CommandResult r = RunPhos(submit);
  EXPECT_TRUE(IsOneLineUserError(r, "were cancelled: nothing of this chain runs")) << r.err;
  EXPECT_NE(r.err.find("merge.sbatch: sbatch: refused: Batch job submission failed;"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("(101 102)"), std::string::npos) << r.err;
  EXPECT_EQ(ReadText(dir / "bin" / "cancelled"), "101 102\n");
  EXPECT_FALSE(fs::exists(dir / "job" / "job.json"));
  const CommandResult retry = RunPhos(submit);
  ASSERT_EQ(retry.exit_code, 0) << retry.err;
  EXPECT_NE(retry.out.find("  merge job 106 after 105"), std::string::npos) << retry.out;
}

}  // namespace
}  // namespace phos::testing
