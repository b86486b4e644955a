// phos: capture, fit and render phosphorescent materials.
//
// Error policy (DESIGN.md): a mistake in the input (file, option, field)
// prints one line naming it and exits with code 2; nothing already written
// is lost, because every output file is written whole through a rename.

#include <cstdio>
#include <exception>
#include <string>

#include <CLI/CLI.hpp>

#include "commands.h"
#include "phos/util/error.h"

int main(int argc, char** argv) {
  CLI::App app{
      "phos: capture, fit and render phosphorescent materials.\n"
      "Materials follow the rate-equation model dr/dt = (1 - r) sum_b ke[b] E[b] - kr r,\n"
      "Lp[b] = sum_i Lambda_i[b] kr_i r_i (files: phos.material/1, see docs/).\n"
      "Run 'phos <command> --help' for the options of a command.",
      "phos"};
  app.require_subcommand(1);
  app.failure_message(CLI::FailureMessage::simple);
  phos::app::RegisterSimulate(app);
  phos::app::RegisterPlot(app);
  phos::app::RegisterFit(app);
  phos::app::RegisterCapture(app);
  phos::app::RegisterRender(app);
  phos::app::RegisterEdit(app);
  phos::app::RegisterEditor(app);

  // Name an unknown command rather than CLI11's "A subcommand is required".
  if (argc > 1 && argv[1][0] != '-') {
    bool known = false;
    std::string names;
    for (const CLI::App* sub : app.get_subcommands({})) {
      known = known || sub->get_name() == argv[1];
      names += (names.empty() ? "" : ", ") + sub->get_name();
    }
    if (!known) {
      std::fprintf(stderr, "phos: unknown command '%s' (commands: %s; see 'phos --help')\n", argv[1], names.c_str());
      return 2;
    }
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // Name the (possibly nested) command the mistake was made in: "phos fit decay-curve".
    std::string command;
    for (const CLI::App* level = &app; !level->get_subcommands().empty();) {
      level = level->get_subcommands().front();
      command += " " + level->get_name();
    }
    std::fprintf(stderr, "phos%s: %s (see 'phos%s --help')\n", command.c_str(), e.what(), command.c_str());
    return 2;
  } catch (const phos::UserError& e) {
    std::fprintf(stderr, "phos: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "phos: internal error: %s\n", e.what());
    return 1;
  }
  return 0;
}
