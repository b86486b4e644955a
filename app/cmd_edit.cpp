// phos edit solve: the material that meets an artist's space-time constraints
// at one point (Sec. 8.6; its output: docs/formats.md, "What the commands write"):
//   phos edit solve CONSTRAINTS.json --json
//   JSON: {"material": {...}, "cost":.., "residuals":[..], "seconds":..,
//          "baseline": {"cost":.., "seconds":..}}

#include <cstdio>
#include <iostream>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>
#include <CLI/CLI.hpp>

#include "commands.h"
#include "phos/editor/solve.h"
#include "phos/model/material.h"
#include "phos/util/atomic_file.h"
#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos::app {
namespace {

struct EditSolveArgs {
  std::string constraints, out;
  int states = 0;
  bool json = false, no_baseline = false;
};

void Run(const EditSolveArgs& args) {
  RequireOutputFile(args.out, "--out");
  editor::Problem problem = editor::LoadProblem(args.constraints);
  if (args.states > 0) problem.states = args.states;
  const editor::Solution solution = editor::Solve(problem);
  std::string why;
  const std::optional<editor::Solution> baseline =
      args.no_baseline ? std::nullopt : editor::SolveGridBaseline(problem, &why);
  if (args.no_baseline) why = "not asked for (--no-baseline)";
  if (!args.out.empty()) SaveMaterial(solution.material, args.out);

  nlohmann::json result = editor::SolutionToJson(solution);
  if (baseline) {
    result["baseline"] = {{"cost", baseline->cost},
                          {"seconds", baseline->seconds},
                          {"evaluations", baseline->evaluations},
                          {"method", "Table 8.2 grid, 10 values per parameter, nc = 1"}};
  } else {
    result["baseline"] = {{"cost", nullptr}, {"seconds", nullptr}, {"why", why}};
  }
  if (args.json) {
    std::cout << result.dump() << "\n";
    return;
  }
  std::printf("%d state(s), cost %s, solved in %s ms\n", problem.states, FormatShort(solution.cost, 4).c_str(),
              FormatShort(solution.seconds * 1e3, 3).c_str());
  for (const ExcitedState& s : solution.material.states) {
    // Unknown where no light reaches the point (the look says nothing of it), as in the file: null.
    const std::string ke = JoinComma(s.ke, [](const auto& k) { return k ? FormatShort(*k, 3) : std::string("unknown"); });
    const std::string Lambda = JoinComma(s.Lambda, [](double l) { return FormatShort(l, 3); });
    // With their units (docs/formats.md, the material file): ke per unit of
    // band irradiance, Lambda the radiance per unit of kr r.
    std::printf("  kr %s /s  ke [%s] /s per unit irradiance  Lambda [%s] radiance per unit kr r\n",
                FormatShort(s.kr, 4).c_str(), ke.c_str(), Lambda.c_str());
  }
  for (const editor::ConstraintResult& c : solution.constraints)
    std::printf("  %-24s residual %s\n", Printable(c.label).c_str(), FormatShort(c.residual, 3).c_str());
  for (const std::string& note : solution.feedback) std::printf("  note: %s\n", note.c_str());
  if (baseline)
    std::printf("baseline (the paper's grid search): cost %s in %s ms\n", FormatShort(baseline->cost, 4).c_str(),
                FormatShort(baseline->seconds * 1e3, 3).c_str());
  else
    std::printf("baseline: %s\n", why.c_str());
  if (!args.out.empty()) std::printf("material written to %s\n", args.out.c_str());
}

}  // namespace

void RegisterEdit(CLI::App& app) {
  CLI::App* edit = app.add_subcommand("edit", "Design a material by saying how it should look over time (Sec. 8.6)");
  edit->require_subcommand(1);
  auto args = std::make_shared<EditSolveArgs>();
  CLI::App* solve =
      edit->add_subcommand("solve",
                           "Find the phosphor that meets space-time constraints at one point: targets ('this\n"
                           "radiance at t') and bounds ('at least this bright until t'), given the irradiance\n"
                           "there over time (phos.constraints/1, see docs/editor.md: a row per frame, or phases\n"
                           "such as [{\"duration_s\": 10, \"irradiance\": [1, 0.6, 0.2]}, {\"duration_s\": 90}]).\n"
                           "Lambda is solved in closed form for every (kr, ke) of a log-grid curve library,\n"
                           "then Ceres refines the best.\n"
                           "Also runs the paper's grid search (Table 8.2) on the same input, for comparison.");
  solve->add_option("constraints", args->constraints, "Constraints file (phos.constraints/1)")->required();
  solve->add_option("--states", args->states, "Excited states to solve for (default: the file's 'states')")
      ->check(CLI::Range(1, 3));
  solve->add_option("--out", args->out, "Also write the material (phos.material/1) here");
  solve->add_flag("--no-baseline", args->no_baseline, "Skip the paper's grid search");
  solve->add_flag("--json", args->json, "Print one JSON object (material, cost, residuals, seconds, baseline)");
  solve->callback([args] { Run(*args); });
}

}  // namespace phos::app
