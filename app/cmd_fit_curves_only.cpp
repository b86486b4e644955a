// `phos fit` with only the curve fits (decay-curve, charge-curve), for the
// executable phos-fit-curve: it links Ceres and the curve fits, not the
// session reader and OpenImageIO that fit session, map and batch need
// (those are phos-fit, with cmd_fit.cpp).

#include <CLI/CLI.hpp>

#include "commands.h"

namespace phos::app {

void RegisterFitCurvesOnly(CLI::App& app) {
  CLI::App* fit = app.add_subcommand("fit", Summary("fit"));
  fit->require_subcommand(1);
  RegisterFitCurve(*fit);
}

}  // namespace phos::app
