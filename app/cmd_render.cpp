// phos render: a scene's frames with the coupled solver (DESIGN.md contract):
//   phos render SCENE.json --out DIR [--times t1,t2,...] [--transport direct|path|dss]
//       [--no-phosphorescence] [--json]
//   JSON: {"frames":[{"t":..,"exr":path,"png":path,"seconds":..}], ...}

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "cli_finite.h"
#include "commands.h"
#include "phos/model/material.h"
#include "phos/render/night_vision.h"
#include "phos/render/renderer.h"
#include "phos/render/scene.h"
#include "phos/render/solver.h"
#include "phos/render/volume.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/progress.h"

namespace phos::app {
namespace {

struct RenderArgs {
  std::string scene, out, times, transport = "direct";
  bool no_phosphorescence = false, json = false;
  int spp = 0, width = 0, height = 0;
  double exposure = 0;
  double night_vision_cd = 0;
  double budget_s = 0, quality = 0;
  bool transport_given = false, indirect_visibility = false;
  std::string contact_sheet;
  std::vector<std::string> materials;
};

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

void Run(const RenderArgs& args) {
  using namespace phos::render;
  Transport transport = ParseTransport(args.transport);
  const bool choose = args.budget_s > 0 || args.quality > 0;
  if (args.budget_s > 0 && args.quality > 0)
    ThrowUserError("", "--budget-s", "give a time budget or a quality (--quality), not both");
  if (choose && (args.transport_given || args.spp > 0))
    ThrowUserError("", args.budget_s > 0 ? "--budget-s" : "--quality",
                   "picks the transport and its samples itself: leave out --transport and --spp");
  Scene scene = LoadScene(args.scene);
  if (args.width > 0) scene.camera.width = args.width;
  if (args.height > 0) scene.camera.height = args.height;
  if (args.exposure > 0) scene.camera.exposure = args.exposure;
  // --material OBJECT=FILE: try another (say, a freshly fitted) material in the scene.
  for (const std::string& assignment : args.materials) {
    const auto equals = assignment.find('=');
    if (equals == std::string::npos || equals == 0 || equals + 1 == assignment.size())
      ThrowUserError("", "--material", "expected OBJECT=FILE, got \"" + assignment + "\"");
    const std::string name = assignment.substr(0, equals), file = assignment.substr(equals + 1);
    auto object =
        std::find_if(scene.objects.begin(), scene.objects.end(), [&](const Object& o) { return o.name == name; });
    if (object == scene.objects.end()) ThrowUserError("", "--material", "the scene has no object '" + name + "'");
    auto material = std::make_shared<Material>(LoadMaterial(file));
    if (!(material->bands == scene.bands))
      ThrowUserError(file, "bands_nm", "differ from the scene's; the renderer needs one band grid");
    object->phosphor = material;
    object->phosphor_path = file;
  }

  std::vector<double> times = scene.FrameTimes();
  if (!args.times.empty()) {
    std::string bad;
    if (!ParseDoubleList(args.times, &times, &bad))
      ThrowUserError("", "--times", "expected a comma-separated list of seconds, got \"" + bad + "\"");
    // Frames are numbered in the order given and the states only advance:
    // times out of order are refused rather than silently re-sorted.
    for (std::size_t i = 0; i < times.size(); ++i) {
      if (times[i] < scene.start_s)
        ThrowUserError("", "--times",
                       FormatDouble(times[i]) + " s is before the scene's start (" + FormatDouble(scene.start_s) +
                           " s): states are only known from there on");
      if (i > 0 && times[i] < times[i - 1])
        ThrowUserError("", "--times",
                       "expected times in increasing order, got " + FormatDouble(times[i]) + " after " +
                           FormatDouble(times[i - 1]));
    }
    // Past the scene's end is allowed (the frame an hour after lights-out), and said.
    if (!times.empty() && times.back() > scene.end_s)
      std::fprintf(stderr,
                   "phos render: warning: --times: %s s is past the scene's end (%s s); rendered all the same\n",
                   FormatDouble(times.back()).c_str(), FormatDouble(scene.end_s).c_str());
  }
  std::error_code ec;
  std::filesystem::create_directories(args.out, ec);
  if (ec) ThrowUserError("", "--out", "cannot create '" + args.out + "': " + ec.message());

  SceneGeometry geometry(scene);
  std::unique_ptr<CoupledSolver> solver;
  if (!args.no_phosphorescence && scene.HasPhosphors()) solver = std::make_unique<CoupledSolver>(scene, geometry);
  FrameOptions options = DefaultFrameOptions(scene, transport);
  if (args.spp > 0) options.spp = options.direct_spp = args.spp;
  if (args.indirect_visibility && transport != Transport::kDss)
    ThrowUserError("", "--indirect-visibility", "is for --transport dss");
  options.indirect_visibility = args.indirect_visibility;
  nlohmann::json choice_json;
  std::string choice_line;
  if (choose) {
    // Measure each transport's cost on this scene at the first frame, then pick.
    if (solver)
      solver->AdvanceTo(times.front());
    else
      geometry.SetTime(times.front());
    const TransportChoice choice =
        ChooseTransport(MeasureTransportCandidates(geometry, solver.get(), options), args.budget_s, args.quality);
    options = choice.chosen.options;
    transport = options.transport;
    nlohmann::json candidates = nlohmann::json::array();
    std::string costs;
    for (const TransportCandidate& c : choice.candidates) {
      candidates.push_back(
          {{"transport", c.label}, {"estimated_s", c.estimated_s}, {"expected_ssim", c.expected_ssim}});
      if (c.label != "path 16 spp" && c.label != "path 256 spp" && c.label != "path 1024 spp")
        costs += (costs.empty() ? "" : ", ") + c.label + " " + FormatShort(c.estimated_s, 2) + " s";
    }
    choice_json = {{"chosen", choice.chosen.label},
                   {"estimated_s", choice.chosen.estimated_s},
                   {"expected_ssim", choice.chosen.expected_ssim},
                   {"fits", choice.fits},
                   {"candidates", candidates}};
    if (args.budget_s > 0)
      choice_json["budget_s"] = args.budget_s;
    else
      choice_json["quality"] = args.quality;
    choice_line = std::string(args.budget_s > 0 ? "budget " + FormatShort(args.budget_s) + " s per frame"
                                                : "quality (SSIM) " + FormatShort(args.quality)) +
                  ": " + choice.chosen.label + " (estimated " + FormatShort(choice.chosen.estimated_s, 2) +
                  " s, expected SSIM " + FormatShort(choice.chosen.expected_ssim, 3) + ")" +
                  (choice.fits         ? ""
                   : args.budget_s > 0 ? " - nothing fits, the fastest"
                                       : " - nothing reaches it, the best") +
                  "; measured: " + costs;
  }

  nlohmann::json frames = nlohmann::json::array();
  std::vector<Image> sheet_frames;
  std::vector<std::string> sheet_labels;
  ProgressBar progress("render " + scene.name, times.size());
  for (std::size_t f = 0; f < times.size(); ++f) {
    const double t = times[f];
    const auto start = std::chrono::steady_clock::now();
    if (solver)
      solver->AdvanceTo(t);
    else
      geometry.SetTime(t);
    const double solver_s = Seconds(start);
    const auto render_start = std::chrono::steady_clock::now();
    FrameStats stats;
    const Image bands = RenderBands(geometry, solver.get(), options, &stats);
    const Image rgb = BandsToLinearSrgb(bands, scene.bands);
    const double render_s = Seconds(render_start);
    const double seconds = Seconds(start);

    char name[64];
    std::snprintf(name, sizeof name, "frame-%04zu", f);
    const std::filesystem::path exr = std::filesystem::path(args.out) / (std::string(name) + ".exr");
    const std::filesystem::path png = std::filesystem::path(args.out) / (std::string(name) + ".png");
    WriteExr(exr, rgb, bands, scene.bands);
    WritePng(png, rgb, scene.camera.exposure);
    if (!args.contact_sheet.empty()) {
      sheet_frames.push_back(ToneMap(rgb, scene.camera.exposure));
      sheet_labels.push_back("t = " + FormatShort(t, 4) + " s");
    }
    nlohmann::json entry = {{"t", t},
                            {"exr", exr.string()},
                            {"png", png.string()},
                            {"seconds", seconds},
                            {"solver_seconds", solver_s},
                            {"render_seconds", render_s},
                            {"rays", stats.rays}};
    if (args.night_vision_cd > 0) {
      NightVisionOptions night;
      night.cd_per_unit = args.night_vision_cd;
      night.exposure = scene.camera.exposure;
      night.seed = scene.settings.seed * 1000003ull + f;  // fresh grain every frame
      const std::filesystem::path night_png = std::filesystem::path(args.out) / (std::string(name) + "-night.png");
      WritePng(night_png, NightVision(bands, rgb, scene.bands, night), 1.0);
      entry["night_png"] = night_png.string();
    }
    frames.push_back(entry);
    progress.Advance();
  }
  progress.Finish();
  if (!args.contact_sheet.empty()) WriteContactSheet(args.contact_sheet, sheet_frames, sheet_labels, 4);

  nlohmann::json result = {
      {"scene", args.scene},         {"transport", TransportName(transport)}, {"phosphorescence", solver != nullptr},
      {"width", scene.camera.width}, {"height", scene.camera.height},         {"frames", frames}};
  if (choose) result["transport_choice"] = choice_json;
  if (solver) {
    const SolverStats& s = solver->stats();
    result["solver"] = {{"texels", s.texels},
                        {"lit_steps", s.steps},
                        {"dark_jumps", s.dark_jumps},
                        {"irradiance_updates", s.irradiance_updates},
                        {"shadow_rays", s.shadow_rays}};
    if (const VolumeMedia* media = solver->media()) {
      const VolumeStats& v = media->stats();
      result["solver"]["volumes"] = {{"voxels", v.voxels},         {"phosphor_voxels", v.phosphor_voxels},
                                     {"lit_voxels", v.lit_voxels}, {"lit_steps", v.steps},
                                     {"dark_jumps", v.dark_jumps}, {"light_updates", v.light_updates}};
    }
  }
  if (args.json) {
    std::cout << result.dump() << "\n";
    return;
  }
  std::string states = "no phosphorescence";
  if (solver) {
    states = std::to_string(solver->stats().texels) + " phosphor texels";
    if (solver->media()) states += ", " + std::to_string(solver->media()->stats().phosphor_voxels) + " phosphor voxels";
  }
  std::printf("%s: %zu frame(s), %dx%d, transport %s, %s\n", scene.name.c_str(), times.size(), scene.camera.width,
              scene.camera.height, TransportName(transport), states.c_str());
  if (choose) std::printf("  transport for the %s\n", choice_line.c_str());
  for (const auto& frame : frames)
    std::printf("  t = %8s s  %7.3f s  %s\n", FormatDouble(frame["t"].get<double>()).c_str(),
                frame["seconds"].get<double>(), frame["png"].get<std::string>().c_str());
}

}  // namespace

void RegisterRender(CLI::App& app) {
  auto args = std::make_shared<RenderArgs>();
  CLI::App* cmd = app.add_subcommand("render", Summary("render"));
  cmd->add_option("scene", args->scene, "Scene file (phos.scene/1)")->required();
  cmd->add_option("--out", args->out, "Folder for frame-NNNN.exr and frame-NNNN.png")->required();
  cmd->add_option("--times", args->times,
                  "Comma-separated frame times in seconds, in increasing order (default: the scene's time range\n"
                  "at its fps); times past the scene's end are rendered with a warning");
  cmd->add_option("--transport", args->transport,
                  "direct (fast, no interreflection), path (the reference: a spectral path tracer) or dss\n"
                  "(direct plus one diffuse bounce through deep screen space; docs/render.md)")
      ->default_str("direct")
      ->each([args](const std::string&) { args->transport_given = true; });
  cmd->add_flag("--indirect-visibility", args->indirect_visibility,
                "dss: keep the nearest surfel per direction (the bounced z-buffer) instead of blending them:\n"
                "no light leaks through occluders and nothing occludes twice; slower (docs/dss-trade.md)");
  cmd->add_option("--budget-s", args->budget_s,
                  "Pick the transport for a time budget per frame: each is timed on this scene, and the best\n"
                  "expected quality that fits is used (direct, dss, path 4 to 1024 spp; the qualities are the\n"
                  "trade study's SSIM against the path tracer, docs/dss-trade.md)")
      ->check(kFinite)
      ->check(CLI::PositiveNumber);
  cmd->add_option("--quality", args->quality,
                  "Pick the cheapest transport whose expected SSIM reaches this (0 to 1; e.g. 0.9)")
      ->check(CLI::Range(1e-9, 1.0));
  cmd->add_flag("--no-phosphorescence", args->no_phosphorescence,
                "Render phosphors as plain diffuse surfaces (no states, no glow)");
  cmd->add_option("--spp", args->spp, "Samples per pixel (default: the scene's render.spp or direct_spp)")
      ->check(CLI::Range(1, 1 << 20));
  cmd->add_option("--width", args->width, "Override the camera's width in pixels")->check(CLI::Range(1, 16384));
  cmd->add_option("--height", args->height, "Override the camera's height in pixels")->check(CLI::Range(1, 16384));
  cmd->add_option("--exposure", args->exposure, "PNG exposure (default: the camera's); EXR files are never scaled")
      ->check(kFinite)
      ->check(CLI::PositiveNumber);
  cmd->add_option("--night-vision", args->night_vision_cd,
                  "Also write frame-NNNN-night.png as a dark-adapted eye sees it (Thompson et al. 2002:\n"
                  "blue shift, loss of acuity, grain); the value is the luminance in cd/m^2 of radiance 1")
      ->check(kFinite)
      ->check(CLI::PositiveNumber);
  cmd->add_option("--contact-sheet", args->contact_sheet,
                  "Also write every frame side by side, labelled with its time, to this PNG");
  cmd->add_option("--material", args->materials,
                  "OBJECT=FILE: give the object of that name this phosphor material (repeatable),\n"
                  "e.g. one just fitted by 'phos fit', without editing the scene");
  cmd->add_flag("--json", args->json, "Print one JSON object: frames with t, exr, png and seconds");
  cmd->callback([args] { Run(*args); });
}

}  // namespace phos::app
