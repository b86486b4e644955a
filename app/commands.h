#pragma once
// Every `phos` command registers its options and its action here.

#include <string>

#include <CLI/CLI.hpp>

#include "phos/fit/curve.h"

namespace phos::app {

void RegisterSimulate(CLI::App& app);
void RegisterPlot(CLI::App& app);
void RegisterFit(CLI::App& app);
// The curve fits under `phos fit` (decay-curve, charge-curve): app/cmd_fit_curve.cpp.
void RegisterFitCurve(CLI::App& fit);
void RegisterCapture(CLI::App& app);
void RegisterRender(CLI::App& app);
void RegisterEdit(CLI::App& app);
void RegisterEditor(CLI::App& app);

// --weights of every fit command: none or poisson, else a UserError naming the option.
Weighting ParseWeightsOption(const std::string& text);

}  // namespace phos::app
