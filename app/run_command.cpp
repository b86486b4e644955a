// The error policy of every phos-<command> executable (commands.h):
// a mistake in the input (file, option, field) prints one line naming it and
// exits with code 2; nothing already written is lost, because every output
// file is written whole through a rename. An internal error exits with 1.

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "cli_finite.h"
#include "commands.h"
#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos::app {
namespace {

// The long and short names of a command's options, with their dashes.
std::vector<std::string> OptionNames(const CLI::App& level) {
  std::vector<std::string> names;
  for (const CLI::Option* option : level.get_options()) {
    for (const std::string& name : option->get_lnames()) names.push_back("--" + name);
    for (const std::string& name : option->get_snames()) names.push_back("-" + name);
  }
  return names;
}

// A mistyped word of the command line, one line naming the nearest valid one
// ("phos simulate: --materal: unknown option; did you mean --material?"), or
// "" if every word is known. CLI11 reports the first of its own checks that
// fails, often a consequence of the mistake rather than the mistake: "--material
// is required" for --materal, "The following arguments were not expected: 1
// --charg-s", "A subcommand is required" for `phos fit schedule-curv`. So the
// words are walked here as CLI11 reads them, command by subcommand, up to a
// --, and the first option or subcommand its level does not know is named.
// *suggested says whether a nearest word was found.
std::string Mistyped(const CLI::App& app, const std::vector<char*>& args, bool* suggested) {
  const CLI::App* level = &app;
  std::string name = "phos";
  for (std::size_t i = 1; i < args.size(); ++i) {
    const std::string word = args[i];
    if (word == "--") break;  // the words after it are another command's (phos slurm)
    double number = 0;
    if (word.size() > 1 && word[0] == '-' && !ParseDouble(word, &number)) {
      const std::string option = word.substr(0, word.find('='));
      const CLI::Option* known = level->get_option_no_throw(option);
      if (known == nullptr) {
        const std::string nearest = Closest(option, OptionNames(*level));
        *suggested = !nearest.empty();
        return name + ": " + option + ": unknown option" +
               (nearest.empty() ? " (see '" + name + " --help')" : "; did you mean " + nearest + "?");
      }
      if (word.find('=') == std::string::npos && known->get_type_size_max() > 0) ++i;  // its value
      continue;
    }
    const std::vector<const CLI::App*> subcommands = level->get_subcommands([](const CLI::App*) { return true; });
    const auto sub =
        std::find_if(subcommands.begin(), subcommands.end(), [&](const CLI::App* s) { return s->check_name(word); });
    if (sub != subcommands.end()) {
      level = *sub;
      name += " " + word;
      continue;
    }
    // A word that is no subcommand where only subcommands are taken.
    const bool takes_words = !level->get_options([](const CLI::Option* o) { return o->get_positional(); }).empty();
    if (!subcommands.empty() && !takes_words) {
      std::vector<std::string> names;
      for (const CLI::App* s : subcommands) names.push_back(s->get_name());
      const std::string nearest = Closest(word, names);
      *suggested = !nearest.empty();
      return name + ": " + word + ": unknown subcommand" +
             (nearest.empty() ? " (one of " + JoinComma(names) + ")" : "; did you mean " + nearest + "?");
    }
  }
  return "";
}

}  // namespace

std::string DataFolder() {
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const std::filesystem::path installed = self.parent_path() / PHOS_DATA_DIR_FROM_BIN;
    if (std::filesystem::is_directory(installed / "materials", ec)) return installed.lexically_normal().string();
  }
  return PHOS_FIXTURES_DIR;
}

int RunCommand(int argc, char** argv, const char* command, void (*register_command)(CLI::App&)) {
  CLI::App app{kAbout, "phos"};
  app.require_subcommand(1);
  app.failure_message(CLI::FailureMessage::simple);
  register_command(app);
  RequireFiniteNumbers(app);  // NaN and infinity refused in every floating-point option of every command
  // The summary `phos --help` shows, whichever file registered the command.
  for (CLI::App* sub : app.get_subcommands({}))
    if (sub->get_name() == command) sub->description(Summary(command));

  // phos execs us as `phos <command> ...`; run by hand, the command's name may be left out.
  std::vector<char*> args(argv, argv + argc);
  if (argc < 2 || std::strcmp(argv[1], command) != 0) args.insert(args.begin() + 1, const_cast<char*>(command));
  try {
    app.parse(static_cast<int>(args.size()), args.data());
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // Name the (possibly nested) command the mistake was made in: "phos fit decay-curve".
    std::string name;
    const CLI::App* level = &app;
    while (!level->get_subcommands().empty()) {
      level = level->get_subcommands().front();
      name += " " + level->get_name();
    }
    std::fflush(stdout);  // what was printed before comes before the error, in a log too
    bool suggested = false;
    const std::string mistyped = Mistyped(app, args, &suggested);
    if (suggested || (!mistyped.empty() && level->get_footer().empty())) {
      std::fprintf(stderr, "%s\n", mistyped.c_str());
      return 2;
    }
    // Words a command with a footer (phos slurm's: the command's own
    // arguments go after --) does not take: CLI11 lists the words it could
    // not place, often the right ones after the --; name the options before
    // the -- that are not its own instead, and say where they go.
    if (dynamic_cast<const CLI::ExtrasError*>(&e) && !level->get_footer().empty()) {
      std::string misplaced;
      bool dashes = false;
      for (std::size_t i = 1; i < args.size(); ++i) {
        const std::string word = args[i];
        if (word == "--") {
          dashes = true;
          break;
        }
        if (word.rfind("--", 0) != 0) continue;
        const std::string option = word.substr(0, word.find('='));
        if (!level->get_option_no_throw(option)) misplaced += (misplaced.empty() ? "" : " ") + option;
      }
      const std::string what = !misplaced.empty() ? misplaced + ": not an option of phos" + name
                               : dashes         ? "words before -- that are not its own"
                                                : "no -- before the command's arguments";
      std::fprintf(stderr, "phos%s: %s; %s\n", name.c_str(), what.c_str(), level->get_footer().c_str());
      return 2;
    }
    std::fprintf(stderr, "phos%s: %s (see 'phos%s --help')\n", name.c_str(), e.what(), name.c_str());
    return 2;
  } catch (const phos::UserError& e) {
    // A job's log holds both streams: the lines an error refers to ("see the
    // lines above") were still in stdout's buffer when it was written.
    std::fflush(stdout);
    std::fprintf(stderr, "phos: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fflush(stdout);
    std::fprintf(stderr, "phos: internal error: %s\n", e.what());
    return 1;
  }
  return 0;
}

}  // namespace phos::app
