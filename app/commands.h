#pragma once
// Every `phos` command registers its options and its action here, and is
// built into an executable of its own, phos-<command> (app/CMakeLists.txt),
// which links only the parts it needs; `phos` itself (main.cpp) only
// dispatches to them, as git does, so a command that needs no renderer or
// camera never loads them, and starts in milliseconds (bench/startup.sh).

#include <string>
#include <string_view>

// Declared, not included: CLI11 is header-only and heavy (7 s of each of the
// nine command_main.cpp compiles under the sanitizers), and the mains need
// only the name. Each command's source includes <CLI/CLI.hpp> itself.
namespace CLI {
class App;
}  // namespace CLI

namespace phos {
enum class Weighting;  // phos/fit/curve.h; declared here so commands without fits need no fit headers
}  // namespace phos

namespace phos::app {

// What `phos --help` says of each command: the one place the summaries are
// written, shared by the dispatcher and by the command's own help.
struct CommandSummary {
  const char* name;
  const char* summary;
};
inline constexpr CommandSummary kCommands[] = {
    {"simulate",
     "Simulate one point of a material: charge under constant irradiance, then dark.\n"
     "Starts from r = 0 (or --r0); t is measured from the start of the charge; one sample\n"
     "every --dt seconds from 0 to charge + decay, and at the end. Steps never straddle the light switch.\n"
     "Output: CSV t,r_1..r_nc,L_1..L_n (L = emitted radiance per band, Eq. 8.2), or --json\n"
     "{\"t\":[..],\"r\":[[..]],\"L\":[[..]],\"integrator\",\"steps\",\"warnings\"}. A physical material\n"
     "(\"units\": \"physical\") gives L in W/(sr m²) and adds its luminance, column or key luminance_cd_m2."},
    {"plot",
     "Plot the total emitted radiance (sum of the L_ columns) of 'phos simulate'\n"
     "CSV files over time, one line per file in the colour of the light it emits, into an SVG."},
    {"fit", "Fit model coefficients to measured curves (Ceres)."},
    {"capture",
     "Run a capture protocol (Sec. 8.4) on the simulated lab (--device sim --sim-material M.json) or a real\n"
     "one (--lab LAB.json) and write its session folder as it goes: session.json, frames.jsonl,\n"
     "events.jsonl, frames/*.tif (16-bit), stop.json. Lights go off on every way out."},
    {"render",
     "Render a scene's frames: the coupled solver charges and drains every phosphorescent\n"
     "texel through the scene's light schedule, then each frame is rendered per band and\n"
     "written as linear EXR (R,G,B and one channel per band) and tone-mapped PNG.\n"
     "Transports: direct (lights + glow, fast), path (spectral path tracer, the reference:\n"
     "glowing surfaces light the others) or dss (direct + one bounce through deep screen space);\n"
     "--budget-s or --quality picks one. Media (volumes) are ray marched in every transport.\n"
     "Scenes: phos.scene/1, see docs/render.md."},
    {"edit", "Design a material by saying how it should look over time (Sec. 8.6)"},
    {"editor",
     "Serve the material editor page: the scene at any time, a timeline, and constraints placed\n"
     "by clicking the image; every edit re-solves the material (Sec. 8.6). Listens on 127.0.0.1."},
    {"slurm",
     "Run a render, a decay map or a fit batch on a Slurm cluster as a job array, then a merge job\n"
     "that checks every task's done record; 'phos slurm status DIR' counts them. See docs/scale.md."},
    {"afterglow",
     "The standard test of a glow product, simulated (DIN 67510-1 style): a physical material, charged\n"
     "from dark by a source at an illuminance, then read in the dark: luminance in mcd/m² at given minutes,\n"
     "the time to a threshold, and the marking L10/L60 - t. See docs/afterglow.md."},
};
// The summary of a command of kCommands ("" for another name).
constexpr const char* Summary(std::string_view command) {
  for (const CommandSummary& c : kCommands)
    if (command == c.name) return c.summary;
  return "";
}

// What `phos --help` prints above the commands.
inline constexpr const char* kAbout =
    "phos: capture, fit and render phosphorescent materials.\n"
    "Materials follow the rate-equation model dr/dt = (1 - r) sum_b ke[b] E[b] - kr r,\n"
    "Lp[b] = sum_i Lambda_i[b] kr_i r_i (files: phos.material/1, see docs/).\n"
    "Run 'phos <command> --help' for the options of a command.";

// The main of every phos-<command> executable: registers the command, parses
// argv (with or without the command's name first: `phos-simulate --dt 1` and
// `phos simulate --dt 1` are the same) and applies the one error policy: a
// user error prints one line and returns 2, an internal error returns 1.
int RunCommand(int argc, char** argv, const char* command, void (*register_command)(CLI::App&));

void RegisterSimulate(CLI::App& app);
void RegisterPlot(CLI::App& app);
void RegisterAfterglow(CLI::App& app);
void RegisterFit(CLI::App& app);
// The curve fits under `phos fit` (decay-curve, charge-curve): app/cmd_fit_curve.cpp.
void RegisterFitCurve(CLI::App& fit);
// `phos fit schedule-curve` (app/cmd_fit_schedule.cpp); RegisterFitCurve registers it.
void RegisterFitSchedule(CLI::App& fit);
// `phos fit` holding only the curve fits: the executable phos-fit-curve, which needs no session reader.
void RegisterFitCurvesOnly(CLI::App& app);
void RegisterCapture(CLI::App& app);
void RegisterRender(CLI::App& app);
void RegisterEdit(CLI::App& app);
void RegisterEditor(CLI::App& app);
void RegisterSlurm(CLI::App& app);

// The folder of phos's data (the presets in materials/, the example scenes
// in scenes/): <prefix>/share/phos beside an installed phos (cmake
// --install), found from the executable's own folder; else, in a build
// tree, the source tree's fixtures/.
std::string DataFolder();

// --weights of every fit command: none or poisson, else a UserError naming the option.
Weighting ParseWeightsOption(const std::string& text);

}  // namespace phos::app
