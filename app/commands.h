#pragma once
// Every `phos` command registers its options and its action here.

#include <CLI/CLI.hpp>

namespace phos::app {

void RegisterSimulate(CLI::App& app);
void RegisterPlot(CLI::App& app);
void RegisterFit(CLI::App& app);
void RegisterCapture(CLI::App& app);
void RegisterRender(CLI::App& app);
void RegisterEdit(CLI::App& app);
void RegisterEditor(CLI::App& app);

}  // namespace phos::app
