// phos slurm against a real Slurm (issue 15): a one-node cluster on this
// machine (munged, slurmctld, slurmd, with a slurm.conf written here, on
// ports of its own), stopped by PID afterwards, even when a check fails.
// Arrays for a render, a decay map and a fit batch give what one process
// gives; a render task requeued (killed) mid-run is redone whole and the
// frames are still the same. Skipped, saying why, only where the cluster
// cannot start (slurm-wlm or munge missing, not root, a daemon that dies).
// Also, without Slurm: the scripts --no-submit writes, and status.

#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
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

// A TCP port free now (the kernel's pick).
int FreePort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t size = sizeof address;
  int port = 0;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0 &&
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &size) == 0)
    port = ntohs(address.sin_port);
  ::close(fd);
  return port;
}

// Running (a zombie, which init reaps later, counts as gone).
bool Alive(pid_t pid) {
  if (::kill(pid, 0) != 0) return false;
  const std::string stat = ReadText("/proc/" + std::to_string(pid) + "/stat");
  const std::size_t paren = stat.rfind(')');
  return paren == std::string::npos || paren + 2 >= stat.size() || stat[paren + 2] != 'Z';
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

// munged, slurmctld and slurmd as a one-node cluster in a folder of its own.
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
    ::chmod(d.c_str(), 0755);  // slurmd and the jobs read the config
    const CommandResult key = Shell(Executable("mungekey") + " -c -f -k " + (d / "munge.key").string());
    if (key.exit_code != 0) return "mungekey failed: " + key.out;
    ::chmod((d / "munge.key").c_str(), 0600);
    const CommandResult munged =
        Shell(Executable("munged") + " --socket=" + (d / "munge.sock").string() +
              " --key-file=" + (d / "munge.key").string() + " --pid-file=" + (d / "munged.pid").string() +
              " --log-file=" + (d / "munged.log").string() + " --seed-file=" + (d / "munged.seed").string());
    pid_files_.push_back(d / "munged.pid");
    if (munged.exit_code != 0) return "munged did not start: " + munged.out;
    char host[256] = {};
    ::gethostname(host, sizeof host - 1);
    const std::string hostname = std::string(host).substr(0, std::string(host).find('.'));
    fs::create_directories(d / "state");
    fs::create_directories(d / "spool");
    const std::string conf = (d / "slurm.conf").string();
    WriteText(
        conf,
        "ClusterName=phos" + std::to_string(::getpid()) + "\nSlurmctldHost=" + hostname +
            "\nSlurmctldPort=" + std::to_string(FreePort()) + "\nSlurmdPort=" + std::to_string(FreePort()) +
            "\nSlurmUser=root\nSlurmdUser=root\nAuthType=auth/munge\nAuthInfo=socket=" + (d / "munge.sock").string() +
            ",cred_expire=" + std::to_string(kCredentialLifetimeS) +
            "\nStateSaveLocation=" + (d / "state").string() + "\nSlurmdSpoolDir=" + (d / "spool").string() +
            "\nSlurmctldPidFile=" + (d / "slurmctld.pid").string() + "\nSlurmdPidFile=" + (d / "slurmd.pid").string() +
            "\nSlurmctldLogFile=" + (d / "slurmctld.log").string() + "\nSlurmdLogFile=" + (d / "slurmd.log").string() +
            "\nProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\nSelectType=select/cons_tres\n"
            "SelectTypeParameters=CR_Core\nSchedulerType=sched/backfill\nMpiDefault=none\n"
            "ReturnToService=2\nJobCompType=jobcomp/none\nJobAcctGatherType=jobacct_gather/none\n"
            "AccountingStorageType=accounting_storage/none\nSwitchType=switch/none\nMinJobAge=3600\n"
            "KillWait=5\nNodeName=" +
            hostname + " CPUs=2 RealMemory=2000 State=UNKNOWN\nPartitionName=test Nodes=" + hostname +
            " Default=YES MaxTime=INFINITE State=UP\n");
    ::setenv("SLURM_CONF", conf.c_str(), 1);  // sbatch, squeue, scontrol (and phos slurm's sbatch) find it
    const CommandResult ctld = Shell(Executable("slurmctld") + " -i -f " + conf);
    pid_files_.push_back(d / "slurmctld.pid");
    if (ctld.exit_code != 0) return "slurmctld did not start: " + ctld.out + Tail(d / "slurmctld.log");
    const CommandResult slurmd = Shell(Executable("slurmd") + " -f " + conf);
    pid_files_.push_back(d / "slurmd.pid");
    if (slurmd.exit_code != 0) return "slurmd did not start: " + slurmd.out + Tail(d / "slurmd.log");
    if (!WaitFor([] { return Shell("sinfo -h -o %T").out.find("idle") != std::string::npos; }, 30, 0.2))
      return "the node did not come up in 30 s: " + Tail(d / "slurmctld.log") + Tail(d / "slurmd.log");
    return "";
  }

  // Cancels every job, then stops the daemons it started, by their PIDs (last started first).
  void Stop() {
    if (pid_files_.empty()) return;
    Shell("scancel --full --user=root");
    WaitFor([] { return Shell("squeue -h -t running,completing").out.empty(); }, 15, 0.2);
    for (auto it = pid_files_.rbegin(); it != pid_files_.rend(); ++it) {
      const std::string text = ReadText(*it);
      const pid_t pid = static_cast<pid_t>(std::atol(text.c_str()));
      if (pid <= 1) continue;
      ::kill(pid, SIGTERM);
      if (!WaitFor([pid] { return !Alive(pid); }, 10, 0.05)) ::kill(pid, SIGKILL);
    }
    pid_files_.clear();
    ::unsetenv("SLURM_CONF");
  }

  ~OneNodeSlurm() { Stop(); }
  const fs::path& dir() const { return dir_.path(); }

 private:
  TempDir dir_;
  std::vector<fs::path> pid_files_;
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
  const bool ended = WaitFor([] { return Shell("squeue -h").out.empty(); }, 360, 0.25);  // the requeue's hold, and the rest
  ASSERT_TRUE(ended) << Shell("squeue").out << Tail(slurm.dir() / "slurmctld.log") << Logs(render_job) << Logs(map_job) << Logs(batch_job);
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
    EXPECT_TRUE(nlohmann::json::parse(status.out)["done"].get<bool>()) << status.out;
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

TEST(SlurmScripts, NoSubmitWritesTheChainAndStatusCountsRecords) {
  TempDir dir;
  const CommandResult r = RunPhos("slurm map --tasks 4 --no-submit --job-dir " + (dir / "job").string() +
                                  " --partition short --account lab7 --sbatch-option qos=low -- S --out " +
                                  (dir / "out").string() + " --weights none");
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
  EXPECT_EQ(RunPhos("slurm status " + (dir / "job").string() + " --require-done").exit_code, 2);
  // A second submission from the same folder is refused.
  const CommandResult again = RunPhos("slurm map --tasks 4 --no-submit --job-dir " + (dir / "job").string() +
                                      " -- S --out " + (dir / "out").string());
  EXPECT_EQ(again.exit_code, 2);
  EXPECT_NE(again.err.find("a job was already submitted from this folder"), std::string::npos) << again.err;
}

}  // namespace
}  // namespace phos::testing
