// phos: capture, fit and render phosphorescent materials.
//
// This is only the dispatcher, after git: `phos <command> ...` runs the
// executable phos-<command> found next to this one (the same bin folder, from
// /proc/self/exe), with the same arguments. Each of those links only the parts
// its command needs, so `phos simulate` or `phos fit decay-curve` start in a
// few milliseconds without loading OpenImageIO, Embree, Aravis or OpenCV
// (bench/startup.sh measures it). `phos --help` lists every command
// from kCommands (commands.h) without linking any of them.
//
// Conventions: `phos --version` prints the project version (phos::kVersion).
// A bare `phos` prints the usage on standard error and exits with 2, like git
// (which prints its usage and exits non-zero): no command is a usage mistake,
// and phos's code for those is 2, its text on stderr as for every other. An
// unknown command is one line naming the nearest command, exit 2.

#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>

#include "commands.h"
#include "phos/util/format.h"
#include "phos/util/version.h"

namespace {

// The executable that runs `phos ARGS`: phos-<command>, except that the curve
// fits, which need no session reader (nor OpenImageIO), are phos-fit-curve.
std::string ExecutableFor(int argc, char** argv) {
  const std::string_view command = argv[1];
  if (command == "fit" && argc > 2) {
    const std::string_view sub = argv[2];
    if (sub == "decay-curve" || sub == "charge-curve" || sub == "schedule-curve") return "phos-fit-curve";
  }
  return "phos-" + std::string(command);
}

// The folder this executable was run from, with its trailing '/' ("" if unknown).
std::string OwnFolder(const char* argv0) {
  char path[PATH_MAX];
  const ssize_t n = readlink("/proc/self/exe", path, sizeof path - 1);
  std::string self = n > 0 ? std::string(path, static_cast<std::size_t>(n)) : std::string(argv0);
  const std::size_t slash = self.rfind('/');
  return slash == std::string::npos ? "" : self.substr(0, slash + 1);
}

}  // namespace

int main(int argc, char** argv) {
  // A command: run its executable at once (before building any help).
  if (argc > 1 && argv[1][0] != '-' && phos::app::Summary(argv[1])[0] != '\0') {
    const std::string folder = OwnFolder(argv[0]);
    const std::string executable = ExecutableFor(argc, argv);
    if (!folder.empty()) {
      execv((folder + executable).c_str(), argv);
    } else {
      execvp(executable.c_str(), argv);
    }
    std::fprintf(stderr, "phos: internal error: cannot run %s%s: %s (it is built and installed beside phos)\n",
                 folder.c_str(), executable.c_str(), std::strerror(errno));
    return 1;
  }

  CLI::App app{phos::app::kAbout, "phos"};
  app.require_subcommand(1);
  app.failure_message(CLI::FailureMessage::simple);
  app.set_version_flag("--version", std::string("phos ") + phos::kVersion, "Print the version and exit");
  for (const phos::app::CommandSummary& c : phos::app::kCommands) app.add_subcommand(c.name, c.summary);
  if (argc < 2) {
    std::fputs(app.help().c_str(), stderr);
    return 2;
  }
  if (argv[1][0] != '-') {
    std::vector<std::string> names;
    for (const phos::app::CommandSummary& c : phos::app::kCommands) names.push_back(c.name);
    const std::string nearest = phos::Closest(argv[1], names);
    if (!nearest.empty())
      std::fprintf(stderr, "phos: %s: unknown command; did you mean %s?\n", argv[1], nearest.c_str());
    else
      std::fprintf(stderr, "phos: %s: unknown command (one of %s; see 'phos --help')\n", argv[1],
                   phos::JoinComma(names).c_str());
    return 2;
  }

  // Options before any command: --help, --version, or a mistake.
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);  // --help, --version
    const std::string option = std::string(argv[1]).substr(0, std::string(argv[1]).find('='));
    const std::string nearest = app.get_option_no_throw(option) ? "" : phos::Closest(option, {"--help", "--version"});
    if (!nearest.empty())
      std::fprintf(stderr, "phos: %s: unknown option; did you mean %s?\n", option.c_str(), nearest.c_str());
    else
      std::fprintf(stderr, "phos: %s (see 'phos --help')\n", e.what());
    return 2;
  }
  return 0;
}
