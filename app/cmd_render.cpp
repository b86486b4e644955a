// phos render: a scene's frames with the coupled solver (DESIGN.md contract):
//   phos render SCENE.json --out DIR [--times t1,t2,...] [--transport direct|path|dss]
//       [--no-phosphorescence] [--json]
//   JSON: {"frames":[{"t":..,"exr":path,"png":path,"seconds":..}], ...}
// On a cluster (docs/scale.md) the states, which are sequential in time, are
// solved once (--solve-only --checkpoints DIR --tasks N: a state file at the
// start of each of N frame ranges), then the ranges render independently
// (--task i/N or --frames A:B, from the latest state at or before A), each
// writing a done record last (util/task_record.h).

#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <numeric>
#include <optional>
#include <regex>
#include <set>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "cli_finite.h"
#include "commands.h"
#include "phos/model/material.h"
#include "phos/model/photometry.h"
#include "phos/render/exposure.h"
#include "phos/render/night_vision.h"
#include "phos/render/phosphor_map.h"
#include "phos/render/renderer.h"
#include "phos/render/scene.h"
#include "phos/render/solver.h"
#include "phos/render/volume.h"
#include "phos/util/atomic_file.h"
#include "phos/util/digest.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/progress.h"
#include "phos/util/task_record.h"

namespace phos::app {
namespace {

struct RenderArgs {
  std::string scene, out, times, transport = "direct";
  bool no_phosphorescence = false, json = false;
  bool check = false;  // --check: every refusal a run would make up to here, then nothing written
  std::string exr_compression = "zip";
  int spp = 0, width = 0, height = 0;
  std::string exposure_text;  // --exposure as given: a number or "auto"
  bool exposure_given = false;
  double exposure = 0;          // --exposure's number (0: not given or "auto")
  bool exposure_auto = false;   // --exposure auto
  std::optional<double> ev100;  // --exposure ev100:N (a physical scene's camera)
  double night_vision_cd = 0;
  double budget_s = 0, quality = 0;
  bool transport_given = false, indirect_visibility = false;
  std::string contact_sheet;
  std::vector<std::string> materials;
  std::string unknown_ke;  // --unknown-ke: "zero", or "" (refuse, unless the scene's object says zero)
  // Shards (docs/scale.md): a range of frames, or the solver pass.
  std::string frames, task, checkpoints;
  bool solve_only = false;
  int solve_tasks = 1;
};

// The frames [first, last) of the run's frame list this process renders.
struct FrameRange {
  std::size_t first = 0, last = 0;
  bool whole = true;      // every frame (no --frames, no --task)
  std::string done_name;  // the done record's file name under <out>/done/ (ranges only)
};

FrameRange SelectFrames(const RenderArgs& args, std::size_t frame_count) {
  FrameRange range{0, frame_count, true, ""};
  if (!args.frames.empty()) {
    static const std::regex form(R"((\d{1,9}):(\d{1,9}))");
    std::smatch m;
    if (!std::regex_match(args.frames, m, form))
      ThrowUserError("", "--frames", "expected FIRST:END (frame indices, END excluded), got \"" + args.frames + "\"");
    range.first = std::stoul(m[1]);
    range.last = std::stoul(m[2]);
    if (range.first >= range.last || range.last > frame_count)
      ThrowUserError("", "--frames",
                     "expected 0 <= FIRST < END <= " + std::to_string(frame_count) + " (the run has " +
                         std::to_string(frame_count) + " frames), got " + args.frames);
    range.whole = false;
    range.done_name = "frames-" + std::to_string(range.first) + "-" + std::to_string(range.last) + ".json";
  } else if (!args.task.empty()) {
    int index = 0, count = 0;
    if (!ParseTaskIndex(args.task, &index, &count))
      ThrowUserError("", "--task", "expected i/N with 0 <= i < N, got \"" + args.task + "\"");
    const auto [first, last] = TaskShare(frame_count, index, count);
    range = {first, last, false, "task-" + std::to_string(index) + "-of-" + std::to_string(count) + ".json"};
  }
  return range;
}

// The files a scene was read from, by content: the scene file, its meshes,
// phosphor materials, masks, maps and texture files, the files the meshes
// name (an OBJ's .mtl, a glTF's buffers), and --material's
// files, each with its XXH3 (util/digest.h). A path may name a file that is
// not there any more (an embedded image's name): it counts as absent.
nlohmann::json SceneFileDigests(const RenderArgs& a, const render::Scene& scene) {
  std::set<std::string> files = {a.scene};
  auto add = [&](const std::filesystem::path& file) {
    if (!file.empty()) files.insert(file.string());
  };
  for (const render::Object& object : scene.objects) {
    if (object.mesh) {
      add(object.mesh->file);  // not its source: "cornell.obj#left" names no file
      for (const std::filesystem::path& file : object.mesh->also_read) add(file);  // its .mtl, its .bin
    }
    add(object.phosphor_path);
    if (object.phosphor_mask) add(*object.phosphor_mask);
    if (object.phosphor_map) add(object.phosphor_map->file);
    if (object.albedo_texture && !object.albedo_texture->embedded) add(object.albedo_texture->texture);
    if (object.gloss_texture && !object.gloss_texture->embedded) add(object.gloss_texture->texture);
  }
  for (const render::Volume& volume : scene.volumes) add(volume.phosphor_path);
  nlohmann::json digests = nlohmann::json::object();
  for (const std::string& file : files) {
    std::error_code ec;
    digests[file] = std::filesystem::is_regular_file(file, ec) ? DigestFile(file).xxh3 : "absent";
  }
  return digests;
}

// What a range's frames are made from: the options and the content of every
// file the scene reads (an artist's edit to the scene or a material between
// runs makes them another range's inputs). A done record for other inputs
// is not this range's.
std::string RangeInputs(const RenderArgs& a, const render::Scene& scene, const FrameRange& range) {
  std::string materials;
  for (const std::string& m : a.materials) materials += m + ";";
  return "files=" + SceneFileDigests(a, scene).dump() + " scene=" + a.scene + " times=" + a.times +
         " transport=" + a.transport + " spp=" + std::to_string(a.spp) + " size=" + std::to_string(a.width) + "x" +
         std::to_string(a.height) + " exposure=" + FormatDouble(a.exposure) +
         " night=" + FormatDouble(a.night_vision_cd) + " no_phosphorescence=" + std::to_string(a.no_phosphorescence) +
         " indirect_visibility=" + std::to_string(a.indirect_visibility) + " materials=" + materials +
         " frames=" + std::to_string(range.first) + ":" + std::to_string(range.last) +
         // Only when not the default, so that ranges rendered before the option stay done.
         (a.exr_compression == "zip" ? "" : " exr=" + a.exr_compression) +
         (a.unknown_ke.empty() ? "" : " unknown_ke=" + a.unknown_ke);
}

// Where the solver pass writes the state at frame f.
std::filesystem::path CheckpointPath(const std::string& dir, std::size_t frame) {
  char name[32];
  std::snprintf(name, sizeof name, "state-%06zu.bin", frame);
  return std::filesystem::path(dir) / name;
}

// The latest state at or before `frame` in the folder (SIZE_MAX: none).
std::size_t LatestCheckpoint(const std::string& dir, std::size_t frame) {
  std::size_t best = SIZE_MAX;
  std::error_code ec;
  if (!std::filesystem::exists(dir, ec)) {
    // A solver pass that failed or was cancelled before it made the folder
    // (phos slurm's tasks run after it however it ended): the states start
    // from the scene's start, the same frames, later.
    std::fprintf(stderr,
                 "phos render: warning: --checkpoints %s: no such folder; the states start from the scene's start\n",
                 dir.c_str());
    return best;
  }
  static const std::regex form(R"(state-(\d{6,9})\.bin)");
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    std::smatch m;
    const std::string name = entry.path().filename().string();
    if (!std::regex_match(name, m, form)) continue;
    const std::size_t f = std::stoul(m[1]);
    if (f <= frame && (best == SIZE_MAX || f > best)) best = f;
  }
  if (ec) ThrowUserError(dir, "--checkpoints", "cannot read the folder: " + ec.message());
  return best;
}

// The summary's first line (and the transport chosen for a budget or a
// quality, if any): what is rendered, how, and with what states.
std::string SummaryHead(const render::Scene& scene, const render::CoupledSolver* solver, std::size_t frames,
                        render::Transport transport, const std::string& choice_line) {
  std::string states = "no phosphorescence";
  if (solver) {
    states = std::to_string(solver->stats().texels) + " phosphor texels";
    if (solver->media()) states += ", " + std::to_string(solver->media()->stats().phosphor_voxels) + " phosphor voxels";
  }
  char line[512];
  std::snprintf(line, sizeof line, "%s: %zu frame(s), %dx%d, transport %s, %s", scene.name.c_str(), frames,
                scene.camera.width, scene.camera.height, render::TransportName(transport), states.c_str());
  std::string head = line;  // appended piece by piece: GCC 12's -Wrestrict misreads a chain of +
  if (!choice_line.empty()) {
    head += "\n  transport for the ";
    head += choice_line;
  }
  return head;
}
// A frame's line of the summary: its time, its seconds and its PNG.
std::string FrameLine(const nlohmann::json& frame) {
  char line[128];
  std::snprintf(line, sizeof line, "  t = %8s s  %7.3f s  ", FormatDouble(frame["t"].get<double>()).c_str(),
                frame["seconds"].get<double>());
  std::string text = line;
  text += frame["png"].get<std::string>();
  return text;
}

// Once per object, on stderr: a phosphor that lights were on for but that
// never received their irradiance (a winding facing away, or a shadow), so
// it will not glow; and the names, for --json.
nlohmann::json WarnNeverCharged(const render::Scene& scene, const render::CoupledSolver& solver) {
  nlohmann::json names = nlohmann::json::array();
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    const int slot = solver.atlas().SlotOf(static_cast<int>(o));
    if (slot < 0 || !solver.charge_report(slot).NeverCharged()) continue;
    names.push_back(scene.objects[o].name);
    std::fprintf(stderr, "phos render: warning: '%s' receives no irradiance in a lit scene, so it never glows: %s\n",
                 scene.objects[o].name.c_str(),
                 solver.charge_report(slot).lit_from_behind
                     ? "the light reaches its back (a phosphor charges on its front only, the side its triangles' "
                       "counter-clockwise winding faces; reverse the winding, or make it \"two_sided\": true)"
                     : "no light reaches its front (in shadow, or facing away from every light)");
  }
  return names;
}

// Once per object, on stderr: the parts of its glTF material that phos does
// not draw (render::Mesh::unread_material: a normal map, emission, alpha),
// so that a surface drawn without them is no surprise; and the same by
// object name, for --json.
nlohmann::json WarnUnreadMaterial(const render::Scene& scene) {
  nlohmann::json unread = nlohmann::json::object();
  for (const render::Object& object : scene.objects) {
    if (!object.mesh || object.mesh->unread_material.empty()) continue;
    const std::vector<std::string>& parts = object.mesh->unread_material;
    unread[object.name] = parts;
    const std::string list = JoinComma(parts);
    std::fprintf(stderr,
                 "phos render: warning: '%s' (%s): not drawn: %s (phos draws a glTF material's base colour and "
                 "metallic-roughness)\n",
                 object.name.c_str(), object.mesh->source.c_str(), list.c_str());
  }
  return unread;
}

// On stderr: lights that put nothing in the scene's bands (a spectrum
// outside them lights nothing), and a scene with no light and no sky whose
// phosphors all start uncharged: its frames are black, which it rendered
// without a word.
void WarnDarkLights(const render::Scene& scene) {
  const std::string bands =
      FormatDouble(scene.bands.edges_nm.front()) + "-" + FormatDouble(scene.bands.edges_nm.back()) + " nm";
  for (const render::Light& light : scene.lights)
    if (std::all_of(light.E_per_band.begin(), light.E_per_band.end(), [](double e) { return e == 0; }))
      std::fprintf(stderr,
                   "phos render: warning: light '%s' puts nothing in the scene's bands (%s): its spectrum lies "
                   "outside them, so it lights nothing\n",
                   light.name.c_str(), bands.c_str());
  if (!scene.lights.empty() || scene.environment) return;
  const auto charged = [](const render::InitialState& s) { return s.kind != render::InitialState::Kind::kZero; };
  const bool any_charged = std::any_of(scene.objects.begin(), scene.objects.end(),
                                       [&](const render::Object& o) { return o.phosphor && charged(o.initial); }) ||
                           std::any_of(scene.volumes.begin(), scene.volumes.end(),
                                       [&](const render::Volume& v) { return v.phosphor && charged(v.initial); });
  if (!any_charged)
    std::fprintf(stderr,
                 "phos render: warning: the scene has no light and no sky, and no phosphor starts charged "
                 "(\"initial\"): every frame is black\n");
}

// --unknown-ke zero: every phosphor takes a ke not measured as 0 (not
// charging), as "unknown_ke": "zero" on each object and volume would say in
// writing; said in one line on stderr, naming each material and the bands
// something lights (ChargingSources) where it zeroes a ke. Those the scene
// already takes as zero are its own statement, and not repeated.
void ZeroUnknownKeEverywhere(render::Scene* scene) {
  std::vector<std::string> zeroed;
  const auto take = [&](bool* as_zero, const Material& material, const std::string& path) {
    if (*as_zero) return;
    *as_zero = true;
    std::vector<std::string> bands;
    for (int b = 0; b < material.band_count(); ++b) {
      const bool unknown = std::any_of(material.states.begin(), material.states.end(),
                                       [&](const ExcitedState& state) { return !state.ke_known(b); });
      if (unknown && !render::ChargingSources(*scene, b).empty()) bands.push_back(material.bands.BandName(b));
    }
    const std::string item = "'" + material.name + "' (" + path + ") in " + JoinComma(bands);
    if (!bands.empty() && std::find(zeroed.begin(), zeroed.end(), item) == zeroed.end()) zeroed.push_back(item);
  };
  for (render::Object& object : scene->objects)
    if (object.phosphor) take(&object.unknown_ke_as_zero, *object.phosphor, object.phosphor_path);
  for (render::Volume& volume : scene->volumes)
    if (volume.phosphor) take(&volume.unknown_ke_as_zero, *volume.phosphor, volume.phosphor_path);
  if (!zeroed.empty())
    std::fprintf(stderr, "phos render: warning: --unknown-ke zero: ke not measured taken as 0 (not charging): %s\n",
                 Join(zeroed, "; ").c_str());
}

// --exposure: "auto", "ev100:N" or a positive number, into exposure_auto,
// ev100 and exposure.
void ParseExposureOption(RenderArgs* args) {
  if (!args->exposure_given) return;
  if (args->exposure_text == "auto") {
    args->exposure_auto = true;
    return;
  }
  const std::string_view text = args->exposure_text;
  if (text.starts_with("ev100:")) {
    double ev100 = 0;
    if (!ParseDouble(std::string(text.substr(6)), &ev100) || !(std::abs(ev100) <= 64))
      ThrowUserError("", "--exposure",
                     "expected ev100:N with N a number in [-64, 64], got \"" + args->exposure_text + "\"");
    args->ev100 = ev100;
    return;
  }
  if (!ParseDouble(args->exposure_text, &args->exposure) || !(args->exposure > 0))
    ThrowUserError("", "--exposure",
                   "expected \"auto\", ev100:N or a positive number, got \"" + args->exposure_text + "\"");
}

// --exposure ev100:N of a physical scene: the scale before the tone map
// that shows a luminance of 1.2 x 2^EV100 cd/m² (the luminance that
// saturates the sensor at that EV100: L_max = 78 / (q S) x 2^EV100 at
// S = 100 and lens attenuation q = 0.65, ISO 12232's saturation-based
// speed, as Filament's physically based camera defines it (Filament
// documentation, "Physically based camera": exposure = 1 / (1.2 x 2^EV100),
// after Lagarde and de Rousiers 2014, "Moving Frostbite to PBR") as 1. pbrt-v4 (src/pbrt/film.cpp,
// PixelSensor) scales by imagingRatio = exposure time x ISO / 100 instead,
// with no saturation point. The PNG's linear RGB has Y = 1 for band radiance 1
// in every band (BandsToLinearSrgb), which is K = sum_b w_b cd/m²
// (PhotopicBandEfficacy), so the scale is K / (1.2 x 2^EV100).
double Ev100Exposure(const render::Scene& scene, double ev100) {
  const std::vector<double> efficacy = PhotopicBandEfficacy(scene.bands);
  const double luminance_of_rgb_one = std::accumulate(efficacy.begin(), efficacy.end(), 0.0);
  return luminance_of_rgb_one / (1.2 * std::exp2(ev100));
}

// The frames "exposure": "auto" meters: those after dark, or every frame when
// none is (a scene lit throughout).
struct MeteredFrames {
  std::vector<bool> metered;  // per frame of the run
  bool after_dark = true;     // false: no frame is after dark, all are metered
  std::size_t count = 0;
};
MeteredFrames FramesToMeter(const render::Scene& scene, const std::vector<double>& times) {
  MeteredFrames frames{std::vector<bool>(times.size()), true, 0};
  for (std::size_t f = 0; f < times.size(); ++f) frames.metered[f] = !scene.AnyLightOnAt(times[f]);
  frames.count = static_cast<std::size_t>(std::count(frames.metered.begin(), frames.metered.end(), true));
  if (frames.count == 0) frames = {std::vector<bool>(times.size(), true), false, times.size()};
  return frames;
}

// What "exposure": "auto" meters of a frame: under path or dss transport,
// the direct transport's frame of the same moment, whose pixels after dark
// are the glow itself, of the surfaces and media the camera sees, and not
// the light it throws on the rest. Metering the path tracer's own frame let
// the dim, noisy indirect light of every other surface set the median: the
// glow-sign's glowing letters came out white and the rest as noise. So every
// transport chooses the same exposure, and its frames compare at one.
render::Image MeteredFrame(const render::SceneGeometry& geometry, const render::CoupledSolver* solver,
                           render::FrameOptions options, const render::Image& rgb) {
  if (options.transport == render::Transport::kDirect) return rgb;
  options.transport = render::Transport::kDirect;
  options.progress_rows = nullptr;
  return render::BandsToLinearSrgb(render::RenderBands(geometry, solver, options), geometry.scene().bands);
}

// A number for the exposure at which the glow after dark shows nearly black:
// its brightest frame's median glowing pixel under 2% of white on the PNGs
// (auto shows it at 18%), said in one line with what to pass instead.
void WarnNearlyBlack(double exposure, const render::AutoExposure& dark) {
  constexpr double kNearlyBlackDisplayLuminance = 0.02;
  if (dark.glowing_pixels == 0) return;  // nothing glows: black is right
  const double shown = exposure * dark.metered_luminance / (1 + exposure * dark.metered_luminance);
  if (shown >= kNearlyBlackDisplayLuminance) return;
  std::fprintf(stderr,
               "phos render: warning: exposure %s: the glow after dark is nearly black (the brightest frame's median "
               "glowing pixel shows at %s%% of white); pass --exposure auto, or --exposure %s\n",
               FormatShort(exposure).c_str(), FormatShort(100 * shown, 2).c_str(),
               FormatShort(dark.exposure, 3).c_str());
}

std::string FrameStem(std::size_t frame) {
  char name[32];
  std::snprintf(name, sizeof name, "frame-%04zu", frame);
  return name;
}

// The frames laid out by --contact-sheet, tone-mapped, with their labels.
struct ContactSheet {
  std::vector<render::Image> frames;
  std::vector<std::string> labels;
};

// What a frame shows at `exposure`: frame-NNNN.png, with --night-vision
// frame-NNNN-night.png (its path goes into `entry`), and its cell of the
// contact sheet (with --contact-sheet).
void WriteFrameViews(const RenderArgs& args, const render::Scene& scene, std::size_t frame, double t, double exposure,
                     const render::Image& rgb, const render::Image& bands, nlohmann::json* entry, ContactSheet* sheet) {
  using namespace phos::render;
  const std::filesystem::path out = args.out;
  WritePng(out / (FrameStem(frame) + ".png"), rgb, exposure);
  if (!args.contact_sheet.empty()) {
    sheet->frames.push_back(ToneMap(rgb, exposure));
    sheet->labels.push_back("t = " + FormatShort(t, 4) + " s");
  }
  if (args.night_vision_cd > 0) {
    NightVisionOptions night;
    night.cd_per_unit = args.night_vision_cd;
    night.exposure = exposure;
    night.seed = scene.settings.seed * 1000003ull + frame;  // fresh grain every frame
    const std::filesystem::path night_png = out / (FrameStem(frame) + "-night.png");
    WritePng(night_png, NightVision(bands, rgb, scene.bands, night), 1.0);
    (*entry)["night_png"] = night_png.string();
  }
}

// A frame's linear sRGB and bands back from its EXR (32-bit float, as
// WriteExr wrote them: the values rendered, bit for bit), by channel name:
// the file keeps them sorted, a physical frame's "Y" before "band0" (and
// "band10" before "band2").
void ReadFrameExr(const std::filesystem::path& path, int band_count, render::Image* rgb, render::Image* bands) {
  std::vector<std::string> names = {"R", "G", "B"};
  for (int b = 0; b < band_count; ++b) names.push_back("band" + std::to_string(b));
  const render::Image exr = render::ReadImageChannels(path, names);
  *rgb = render::Image(exr.width, exr.height, 3);
  *bands = render::Image(exr.width, exr.height, band_count);
  for (std::size_t p = 0; p < static_cast<std::size_t>(exr.width) * exr.height; ++p) {
    std::copy_n(&exr.pixels[p * exr.channels], 3, &rgb->pixels[3 * p]);
    std::copy_n(&exr.pixels[p * exr.channels + 3], band_count, &bands->pixels[p * band_count]);
  }
}

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// The solver pass: every state from the start through the last frame,
// advanced frame by frame exactly as one sequential run does (the same steps
// at the same break points: the floats come out the same), writing the state
// at the first frame of each of `tasks` ranges. Idempotent: its done record
// (<dir>/done.json) makes a rerun do nothing.
void SolveOnly(const RenderArgs& args, const render::Scene& scene, render::CoupledSolver* solver,
               const std::vector<double>& times) {
  using namespace phos::render;
  const auto start = std::chrono::steady_clock::now();
  const std::filesystem::path dir = args.checkpoints, done = dir / "done.json";
  const std::string inputs =
      RangeInputs(args, scene, {0, times.size(), true, ""}) + " tasks=" + std::to_string(args.solve_tasks);
  nlohmann::json result = {{"scene", args.scene}, {"frames", times.size()}, {"tasks", args.solve_tasks}};
  if (TaskIsDone(done, inputs)) {
    result["done_before"] = true;
    if (args.json)
      std::cout << result.dump() << "\n";
    else
      std::printf("%s: solver states already written (%s): nothing to do\n", scene.name.c_str(), done.c_str());
    return;
  }
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) ThrowUserError("", "--checkpoints", "cannot create '" + dir.string() + "': " + ec.message());
  std::vector<std::size_t> starts;
  for (int i = 0; i < args.solve_tasks; ++i) {
    const std::size_t first = TaskShare(times.size(), i, args.solve_tasks).first;
    if (starts.empty() || starts.back() != first) starts.push_back(first);
  }
  TaskDoneRecord record{"render solve " + std::to_string(args.solve_tasks) + " ranges", inputs, {}, 0, HostName()};
  nlohmann::json written = nlohmann::json::array();
  if (solver) {
    std::size_t next = 0;
    for (std::size_t f = 0; f < times.size() && next < starts.size(); ++f) {
      solver->AdvanceTo(times[f]);
      if (f != starts[next]) continue;
      const std::filesystem::path path = CheckpointPath(dir.string(), f);
      WriteSolverCheckpoint(path, solver->Checkpoint(static_cast<int>(f)));
      record.outputs.push_back(path.string());
      written.push_back({{"frame", f}, {"t", times[f]}, {"file", path.string()}});
      ++next;
    }
  }
  record.seconds = Seconds(start);
  WriteTaskDone(done, record);
  result["checkpoints"] = written;
  if (solver) result["never_charged"] = WarnNeverCharged(scene, *solver);
  result["seconds"] = record.seconds;
  if (args.json) {
    std::cout << result.dump() << "\n";
    return;
  }
  if (!solver)
    std::printf("%s: no phosphorescence, no states: ranges render without checkpoints\n", scene.name.c_str());
  else
    std::printf("%s: %zu frame(s) solved (%.3f s); the state at the start of %zu range(s) -> %s\n", scene.name.c_str(),
                times.size(), record.seconds, written.size(), dir.c_str());
}

// Brings the solver to the frame before `first`, so that the range's first
// AdvanceTo takes the very steps of one sequential run: from the latest
// checkpoint at or before it (if any), then frame by frame.
void PositionSolver(render::CoupledSolver* solver, const std::string& checkpoints, const std::vector<double>& times,
                    std::size_t first) {
  if (!solver || first == 0) return;
  std::size_t from = 0;
  if (!checkpoints.empty()) {
    const std::size_t k = LatestCheckpoint(checkpoints, first);
    if (k != SIZE_MAX) {
      const std::filesystem::path path = CheckpointPath(checkpoints, k);
      const render::SolverCheckpoint c = render::ReadSolverCheckpoint(path);
      if (c.frame != static_cast<int>(k) || c.time_s != times[k])
        ThrowUserError(path.string(), "time_s",
                       "is the state at " + FormatDouble(c.time_s) + " s, but frame " + std::to_string(k) +
                           " of this run is at " + FormatDouble(times[k]) + " s (solved with other --times?)");
      solver->Restore(c, path.string());
      from = k;
    }
  }
  for (std::size_t f = from; f < first; ++f) solver->AdvanceTo(times[f]);
}

// SIGINT and SIGTERM (Ctrl-C, a Slurm cancel or time limit) ended a render
// with exit 130 or 143 and no word. One line, written with write(2) (all a
// signal handler may do), says what is left; then the usual exit code.
extern "C" void SayInterruptedAndExit(int signal_number) {
  const char* line = signal_number == SIGINT
                         ? "phos render: interrupted (SIGINT): every frame written is whole; the temporary of the one "
                           "being written is removed by the next run\n"
                         : "phos render: terminated (SIGTERM): every frame written is whole; the temporary of the one "
                           "being written is removed by the next run\n";
  const ssize_t ignored = ::write(STDERR_FILENO, line, std::strlen(line));
  (void)ignored;
  std::_Exit(128 + signal_number);
}
void SayWhenInterrupted() {
  struct sigaction action {};
  action.sa_handler = SayInterruptedAndExit;
  sigemptyset(&action.sa_mask);
  for (int signal_number : {SIGINT, SIGTERM}) sigaction(signal_number, &action, nullptr);
}

// What one render run works on, filled stage by stage (Run).
struct RenderRun {
  render::Scene scene;
  render::Transport transport = render::Transport::kDirect;
  bool choose = false;  // --budget-s or --quality: the transport is measured and picked
  std::vector<double> times;
  FrameRange range;
  std::filesystem::path done;  // a range's done record (none for a whole run)
  std::string inputs;          // what a range is made from
  std::chrono::steady_clock::time_point started;
  std::unique_ptr<render::SceneGeometry> geometry;
  std::unique_ptr<render::CoupledSolver> solver;
  render::FrameOptions options;
  nlohmann::json choice_json;  // --budget-s / --quality: what was measured and chosen
  std::string choice_line;
};

// Every output before any work (a refusal after the frames would lose them),
// and the transport options that go together.
void CheckOutputsAndTransport(const RenderArgs& args, RenderRun& r) {
  using namespace phos::render;
  if (!args.solve_only) RequireFolderOrNothing(args.out, "--out");
  RequireOutputFile(args.contact_sheet, "--contact-sheet", kImageExtensions);
  if (args.solve_only) RequireFolderOrNothing(args.checkpoints, "--checkpoints");
  r.transport = ParseTransport(args.transport);
  r.choose = args.budget_s > 0 || args.quality > 0;
  if (args.budget_s > 0 && args.quality > 0)
    ThrowUserError("", "--budget-s", "give a time budget or a quality (--quality), not both");
  if (r.choose && (args.transport_given || args.spp > 0))
    ThrowUserError("", args.budget_s > 0 ? "--budget-s" : "--quality",
                   "picks the transport and its samples itself: leave out --transport and --spp");
}

// The scene with the options that change it: size, exposure, --material, --unknown-ke.
void PrepareScene(const RenderArgs& args, RenderRun& r) {
  using namespace phos::render;
  r.scene = LoadScene(args.scene);
  if (args.width > 0) r.scene.camera.width = args.width;
  if (args.height > 0) r.scene.camera.height = args.height;
  // The scene file's limit holds for the options too: 16384 x 16384 passed
  // each option's own range and took 12.7 GB before its first frame.
  if (static_cast<double>(r.scene.camera.width) * r.scene.camera.height > render::kMaxPixels)
    ThrowUserError("", args.width > 0 ? "--width" : "--height",
                   std::to_string(r.scene.camera.width) + " x " + std::to_string(r.scene.camera.height) +
                       " pixels is more than the limit of " + std::to_string(render::kMaxPixels) +
                       " pixels per frame (8192 x 8192)");
  if (args.exposure > 0) {
    r.scene.camera.exposure = args.exposure;
    r.scene.camera.exposure_auto = false;
  }
  if (args.exposure_auto) r.scene.camera.exposure_auto = true;
  if (args.ev100) {
    if (r.scene.units != Units::kPhysical)
      ThrowUserError("", "--exposure",
                     "ev100 is a camera's exposure in physical units; the scene '" + args.scene +
                         "' is relative (its radiances have no unit): give a number or auto");
    r.scene.camera.exposure = Ev100Exposure(r.scene, *args.ev100);
    r.scene.camera.exposure_auto = false;
  }
  // --material OBJECT=FILE: try another (say, a freshly fitted) material in the scene.
  for (const std::string& assignment : args.materials) {
    const auto equals = assignment.find('=');
    if (equals == std::string::npos || equals == 0 || equals + 1 == assignment.size())
      ThrowUserError("", "--material", "expected OBJECT=FILE, got \"" + assignment + "\"");
    const std::string name = assignment.substr(0, equals), file = assignment.substr(equals + 1);
    auto object =
        std::find_if(r.scene.objects.begin(), r.scene.objects.end(), [&](const Object& o) { return o.name == name; });
    if (object == r.scene.objects.end()) ThrowUserError("", "--material", "the scene has no object '" + name + "'");
    // One object: a scene's names are its objects' own (LoadScene refuses two alike).
    auto material = std::make_shared<Material>(LoadMaterial(file));
    if (const std::string mismatch = render::BandGridMismatch(material->bands, r.scene.bands); !mismatch.empty())
      ThrowUserError(file, "bands_nm", mismatch);
    if (const std::string mismatch = render::UnitsMismatch(*material, file, r.scene.units); !mismatch.empty())
      ThrowUserError("", "--material", "'" + name + "': " + mismatch);
    object->phosphor = material;
    object->phosphor_path = file;
  }
  // An object --material makes a phosphor gets texels: counted as the loader
  // counts them, so --check refuses what the run would.
  if (!args.materials.empty()) CheckTexelLimits(r.scene);
  if (args.unknown_ke == "zero") ZeroUnknownKeEverywhere(&r.scene);
}

// The frames' times: the scene's, or --times (increasing, from the scene's start).
void FrameTimesOf(const RenderArgs& args, RenderRun& r) {
  r.times = r.scene.FrameTimes();
  if (!args.times.empty()) {
    std::string bad;
    if (!ParseDoubleList(args.times, &r.times, &bad))
      ThrowUserError("", "--times", "expected a comma-separated list of seconds, got \"" + bad + "\"");
    // Frames are numbered in the order given and the states only advance:
    // times out of order are refused rather than silently re-sorted.
    for (std::size_t i = 0; i < r.times.size(); ++i) {
      if (r.times[i] < r.scene.start_s)
        ThrowUserError("", "--times",
                       FormatDouble(r.times[i]) + " s is before the scene's start (" + FormatDouble(r.scene.start_s) +
                           " s): states are only known from there on");
      if (i > 0 && r.times[i] < r.times[i - 1])
        ThrowUserError("", "--times",
                       "expected times in increasing order, got " + FormatDouble(r.times[i]) + " after " +
                           FormatDouble(r.times[i - 1]));
    }
    // Past the scene's end is allowed (the frame an hour after lights-out), and said.
    if (!r.times.empty() && r.times.back() > r.scene.end_s)
      std::fprintf(stderr,
                   "phos render: warning: --times: %s s is past the scene's end (%s s); rendered all the same\n",
                   FormatDouble(r.times.back()).c_str(), FormatDouble(r.scene.end_s).c_str());
  }
}

// The frames this process renders, and the options a range refuses.
void SelectRange(const RenderArgs& args, RenderRun& r) {
  r.range = SelectFrames(args, r.times.size());
  if (!r.range.whole && r.choose)
    ThrowUserError("", args.budget_s > 0 ? "--budget-s" : "--quality",
                   "is timed on each machine, so ranges could choose differently: give --transport");
  if (!r.range.whole && !args.contact_sheet.empty())
    ThrowUserError("", "--contact-sheet", "needs every frame: not with --frames or --task");
  if (!r.range.whole && !args.solve_only && r.scene.camera.exposure_auto) {
    const std::string why = "\"auto\" meters every frame after dark: not with --frames or --task; give a number";
    if (args.exposure_auto) ThrowUserError("", "--exposure", why);
    ThrowUserError(args.scene, "camera.exposure", why + " with --exposure");
  }
  if (args.solve_only && args.checkpoints.empty())
    ThrowUserError("", "--solve-only", "writes the states to --checkpoints DIR: give it");
  if (!args.solve_only && args.out.empty()) ThrowUserError("", "--out", "is required (except with --solve-only)");
  if (args.indirect_visibility && r.transport != render::Transport::kDss)
    ThrowUserError("", "--indirect-visibility", "is for --transport dss");
}

// A range already rendered from these very inputs: said, and true.
bool RangeDoneBefore(const RenderArgs& args, RenderRun& r) {
  r.done = r.range.whole ? std::filesystem::path() : std::filesystem::path(args.out) / "done" / r.range.done_name;
  r.inputs = r.range.whole ? "" : RangeInputs(args, r.scene, r.range);
  if (!r.range.whole && !args.solve_only && TaskIsDone(r.done, r.inputs)) {
    // A rerun of a finished range (Slurm's requeue, a resubmitted array) does nothing.
    if (args.json)
      std::cout << nlohmann::json({{"scene", args.scene}, {"done_before", true}, {"done", r.done.string()}}).dump()
                << "\n";
    else
      std::printf("%s: frames %zu:%zu already rendered (%s): nothing to do\n", r.scene.name.c_str(), r.range.first,
                  r.range.last, r.done.c_str());
    return true;
  }
  return false;
}

// A killed run of these frames (a range, or the whole run: an 82 MB
// frame-0000.exr.tmp.<pid>.exr outlived a timeout) left the temporary of the
// frame it was writing: gone first.
void RemoveFrameTemporaries(const RenderArgs& args, const FrameRange& range) {
  std::vector<std::string> names;
  for (std::size_t f = range.first; f < range.last; ++f) {
    char name[32];
    for (const char* suffix : {".exr", ".png", "-night.png"}) {
      std::snprintf(name, sizeof name, "frame-%04zu%s", f, suffix);
      names.push_back(name);
    }
  }
  RemoveTemporaries(args.out, names);
}

// The frame options of the transport asked for, or (--budget-s, --quality)
// of the one measured and picked on this scene at the first frame.
void ChooseFrameOptions(const RenderArgs& args, RenderRun& r) {
  using namespace phos::render;
  r.options = DefaultFrameOptions(r.scene, r.transport);
  if (args.spp > 0) r.options.spp = r.options.direct_spp = args.spp;
  r.options.indirect_visibility = args.indirect_visibility;
  if (r.choose) {
    // Measure each transport's cost on this scene at the first frame, then pick.
    if (r.solver)
      r.solver->AdvanceTo(r.times.front());
    else
      r.geometry->SetTime(r.times.front());
    const TransportChoice choice = ChooseTransport(MeasureTransportCandidates(*r.geometry, r.solver.get(), r.options),
                                                   args.budget_s, args.quality);
    r.options = choice.chosen.options;
    r.transport = r.options.transport;
    nlohmann::json candidates = nlohmann::json::array();
    std::string costs;
    for (const TransportCandidate& c : choice.candidates) {
      candidates.push_back(
          {{"transport", c.label}, {"estimated_s", c.estimated_s}, {"expected_ssim", c.expected_ssim}});
      if (c.label != "path 16 spp" && c.label != "path 256 spp" && c.label != "path 1024 spp")
        costs += (costs.empty() ? "" : ", ") + c.label + " " + FormatShort(c.estimated_s, 2) + " s";
    }
    r.choice_json = {{"chosen", choice.chosen.label},
                     {"estimated_s", choice.chosen.estimated_s},
                     {"expected_ssim", choice.chosen.expected_ssim},
                     {"fits", choice.fits},
                     {"candidates", candidates}};
    if (args.budget_s > 0)
      r.choice_json["budget_s"] = args.budget_s;
    else
      r.choice_json["quality"] = args.quality;
    r.choice_line = std::string(args.budget_s > 0 ? "budget " + FormatShort(args.budget_s) + " s per frame"
                                                  : "quality (SSIM) " + FormatShort(args.quality)) +
                    ": " + choice.chosen.label + " (estimated " + FormatShort(choice.chosen.estimated_s, 2) +
                    " s, expected SSIM " + FormatShort(choice.chosen.expected_ssim, 3) + ")" +
                    (choice.fits         ? ""
                     : args.budget_s > 0 ? " - nothing fits, the fastest"
                                         : " - nothing reaches it, the best") +
                    "; measured: " + costs;
  }
}

// The frames rendered: each one's JSON entry (its files, times and rays), and
// what "auto" exposure meters of them.
struct RenderedFrames {
  nlohmann::json frames = nlohmann::json::array();
  nlohmann::json unread_material;
  ContactSheet sheet;
  MeteredFrames metered;
  // "auto" chooses from this meter; a number is checked by it: the glow
  // after dark at the default exposure 1 is all but black (the Cornell box's
  // median glowing pixel shows at 0.3% of white), and a first render should
  // say so and what to pass rather than show black frames.
  render::ExposureMeter meter;
  // With a fixed exposure each frame's line is known as soon as its files
  // are written, and printed then (flushed): a cluster job's log, or a run
  // killed half-way, shows the frames done. With "auto" the views wait for
  // every metered frame, so the lines come at the end.
  bool line_per_frame = false;
};

// One frame: the states advanced to t, the bands rendered, the EXR written
// and, at a fixed exposure, its views; its JSON entry.
nlohmann::json RenderFrame(const RenderArgs& args, RenderRun& r, std::size_t f, RenderedFrames* out) {
  using namespace phos::render;
  const double t = r.times[f];
  r.options.frame = f;  // the path tracer's seed: pixel, frame and sample
  const auto start = std::chrono::steady_clock::now();
  if (r.solver)
    r.solver->AdvanceTo(t);
  else
    r.geometry->SetTime(t);
  const double solver_s = Seconds(start);
  const auto render_start = std::chrono::steady_clock::now();
  FrameStats stats;
  const Image bands = RenderBands(*r.geometry, r.solver.get(), r.options, &stats);
  const Image rgb = BandsToLinearSrgb(bands, r.scene.bands);
  const double render_s = Seconds(render_start);
  const double seconds = Seconds(start);

  const std::filesystem::path exr = std::filesystem::path(args.out) / (FrameStem(f) + ".exr");
  const std::filesystem::path png = std::filesystem::path(args.out) / (FrameStem(f) + ".png");
  WriteExr(exr, rgb, bands, r.scene.bands, args.exr_compression, r.scene.units);
  nlohmann::json entry = {{"t", t},
                          {"exr", exr.string()},
                          {"png", png.string()},
                          {"seconds", seconds},
                          {"solver_seconds", solver_s},
                          {"render_seconds", render_s},
                          {"setup_seconds", stats.setup_s},
                          {"rays", stats.rays}};
  if (!r.scene.camera.exposure_auto)
    WriteFrameViews(args, r.scene, f, t, r.scene.camera.exposure, rgb, bands, &entry, &out->sheet);
  if (out->metered.metered[f] && (r.scene.camera.exposure_auto || out->metered.after_dark))
    out->meter.Add(MeteredFrame(*r.geometry, r.solver.get(), r.options, rgb));
  return entry;
}

// The range's frames, one after the other, with a progress bar.
void RenderFrames(const RenderArgs& args, RenderRun& r, RenderedFrames* out) {
  out->unread_material = WarnUnreadMaterial(r.scene);
  WarnDarkLights(r.scene);
  // "auto": the views wait for the exposure, which needs every metered frame.
  out->metered = FramesToMeter(r.scene, r.times);
  // Counted in rows of pixels, so the bar moves inside a long (path-traced) frame.
  ProgressBar progress("render " + r.scene.name,
                       (r.range.last - r.range.first) * static_cast<std::size_t>(r.scene.camera.height));
  r.options.progress_rows = &progress;
  SayWhenInterrupted();
  out->line_per_frame = !args.json && !r.scene.camera.exposure_auto;
  if (out->line_per_frame)
    progress.Print(stdout,
                   SummaryHead(r.scene, r.solver.get(), r.range.last - r.range.first, r.transport, r.choice_line));
  for (std::size_t f = r.range.first; f < r.range.last; ++f) {
    nlohmann::json entry = RenderFrame(args, r, f, out);
    if (out->line_per_frame) progress.Print(stdout, FrameLine(entry));
    out->frames.push_back(entry);
  }
  progress.Finish();
  r.options.progress_rows = nullptr;
}

// The exposure the views are shown at: the fixed one (said when the glow
// after dark is nearly black at it), or "auto"'s from the meter, with the
// views written now from the EXRs (the frames need not all stay in memory).
struct ShownExposure {
  double exposure = 1;
  render::AutoExposure chosen;
};
ShownExposure WriteViews(const RenderArgs& args, const RenderRun& r, RenderedFrames* rendered) {
  ShownExposure shown{r.scene.camera.exposure, {}};
  if (!r.scene.camera.exposure_auto && rendered->metered.after_dark)
    WarnNearlyBlack(shown.exposure, rendered->meter.Choose());
  if (r.scene.camera.exposure_auto) {
    shown.chosen = rendered->meter.Choose();
    shown.exposure = shown.chosen.exposure;
    if (shown.chosen.glowing_pixels == 0)
      std::fprintf(stderr, "phos render: warning: exposure auto: the %zu %s are black (no pixel glows): exposure 1\n",
                   shown.chosen.metered_frames,
                   rendered->metered.after_dark ? "frame(s) after dark" : "frame(s) (none is after dark)");
    for (std::size_t f = r.range.first; f < r.range.last; ++f) {
      render::Image rgb, bands;
      nlohmann::json& entry = rendered->frames[f - r.range.first];
      ReadFrameExr(entry["exr"].get<std::string>(), r.scene.bands.band_count(), &rgb, &bands);
      WriteFrameViews(args, r.scene, f, r.times[f], shown.exposure, rgb, bands, &entry, &rendered->sheet);
    }
  }
  if (!args.contact_sheet.empty())
    render::WriteContactSheet(args.contact_sheet, rendered->sheet.frames, rendered->sheet.labels, 4);
  return shown;
}

// Last, after every frame is whole on disk: the range is done.
void WriteRangeDone(const RenderRun& r, const nlohmann::json& frames) {
  TaskDoneRecord record{"render frames " + std::to_string(r.range.first) + ":" + std::to_string(r.range.last),
                        r.inputs,
                        {},
                        Seconds(r.started),
                        HostName()};
  for (const auto& frame : frames) record.outputs.push_back(frame["exr"].get<std::string>());
  WriteTaskDone(r.done, record);
}

// What the command says: the JSON object, or the summary and a line per frame
// (unless each was said as it was written).
void ReportRun(const RenderArgs& args, const RenderRun& r, const RenderedFrames& rendered, const ShownExposure& shown) {
  using namespace phos::render;
  const nlohmann::json& frames = rendered.frames;
  const MeteredFrames& metered = rendered.metered;
  const AutoExposure& chosen = shown.chosen;
  const double exposure = shown.exposure;
  nlohmann::json result = {{"scene", args.scene},
                           {"transport", TransportName(r.transport)},
                           {"phosphorescence", r.solver != nullptr},
                           {"width", r.scene.camera.width},
                           {"height", r.scene.camera.height},
                           {"frames", frames}};
  if (r.choose) result["transport_choice"] = r.choice_json;
  result["unread_material"] = rendered.unread_material;
  result["exposure"] = exposure;
  // A physical scene's EXRs are in W/(sr m²) per band with Y in cd/m²
  // (WriteExr); a relative scene's JSON stays as it was.
  if (r.scene.units == Units::kPhysical)
    result["units"] = {{"scene", "physical"}, {"bands", "W/(sr m2)"}, {"Y", "cd/m2"}};
  if (args.ev100) result["exposure_ev100"] = *args.ev100;
  if (r.scene.camera.exposure_auto)
    result["exposure_auto"] = {{"metered", metered.after_dark ? "after dark" : "all frames"},
                               {"metered_frames", chosen.metered_frames},
                               {"metered_transport", "direct"},
                               {"glowing_pixels", chosen.glowing_pixels},
                               {"metered_luminance", chosen.metered_luminance},
                               {"percentile", kMeteredPercentile * 100},
                               {"frame", "brightest"},
                               {"display_luminance", kMeteredDisplayLuminance}};
  if (r.solver) {
    const SolverStats& s = r.solver->stats();
    result["solver"] = {{"texels", s.texels},           {"lit_steps", s.steps},
                        {"dark_jumps", s.dark_jumps},   {"irradiance_updates", s.irradiance_updates},
                        {"shadow_rays", s.shadow_rays}, {"never_charged", WarnNeverCharged(r.scene, *r.solver)}};
    if (const VolumeMedia* media = r.solver->media()) {
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
  if (rendered.line_per_frame) return;  // said frame by frame
  std::printf("%s\n", SummaryHead(r.scene, r.solver.get(), frames.size(), r.transport, r.choice_line).c_str());
  if (r.scene.camera.exposure_auto)
    std::printf(
        "  exposure auto: %s, metered on %zu %s%s: the brightest frame's median glowing pixel "
        "(luminance %s) shown as mid-grey (%s)\n",
        FormatShort(exposure, 4).c_str(), chosen.metered_frames,
        metered.after_dark ? "frame(s) after dark" : "frame(s) (none is after dark)",
        r.transport == Transport::kDirect ? "" : " (their direct-transport frames)",
        FormatShort(chosen.metered_luminance, 4).c_str(), FormatShort(kMeteredDisplayLuminance).c_str());
  for (const auto& frame : frames) std::printf("%s\n", FrameLine(frame).c_str());
}

void Run(const RenderArgs& args) {
  using namespace phos::render;
  RenderRun r;
  CheckOutputsAndTransport(args, r);
  PrepareScene(args, r);
  FrameTimesOf(args, r);
  SelectRange(args, r);
  if (args.check) {
    std::printf("%s: the command would render %zu frame(s) (--check: nothing written)\n", r.scene.name.c_str(),
                args.solve_only ? std::size_t{0} : r.range.last - r.range.first);
    return;
  }
  if (RangeDoneBefore(args, r)) return;
  r.started = std::chrono::steady_clock::now();
  r.geometry = std::make_unique<SceneGeometry>(r.scene);
  if (!args.no_phosphorescence && r.scene.HasPhosphors())
    r.solver = std::make_unique<CoupledSolver>(r.scene, *r.geometry);
  if (args.solve_only) {
    // Said at the solve too: on a cluster it is the first task to run, and
    // its log the first a user reads.
    WarnUnreadMaterial(r.scene);
    WarnDarkLights(r.scene);
    SolveOnly(args, r.scene, r.solver.get(), r.times);
    return;
  }
  // After the solver's refusals (a ke not measured in a lit band): they leave no folder behind.
  std::error_code ec;
  std::filesystem::create_directories(args.out, ec);
  if (ec) ThrowUserError("", "--out", "cannot create '" + args.out + "': " + ec.message());
  PositionSolver(r.solver.get(), args.checkpoints, r.times, r.range.first);
  RemoveFrameTemporaries(args, r.range);
  ChooseFrameOptions(args, r);
  RenderedFrames rendered;
  RenderFrames(args, r, &rendered);
  const ShownExposure shown = WriteViews(args, r, &rendered);
  if (!r.range.whole) WriteRangeDone(r, rendered.frames);
  ReportRun(args, r, rendered, shown);
}

}  // namespace

void RegisterRender(CLI::App& app) {
  auto args = std::make_shared<RenderArgs>();
  CLI::App* cmd = app.add_subcommand("render", Summary("render"));
  cmd->add_option("scene", args->scene, "Scene file (phos.scene/1)")->required();
  cmd->add_option("--out", args->out, "Folder for frame-NNNN.exr and frame-NNNN.png (required unless --solve-only)");
  cmd->add_option("--times", args->times,
                  "Comma-separated frame times in seconds, in increasing order (default: the scene's time range\n"
                  "at its fps); times past the scene's end are rendered with a warning")
      // Given empty (a script's unset variable), it meant every frame of the scene, silently.
      ->check(CLI::Validator(
          [](const std::string& text) {
            return text.empty() ? std::string("expected a comma-separated list of seconds, got nothing")
                                : std::string();
          },
          "", "non-empty"));
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
      ->check(kPositive);
  cmd->add_option("--quality", args->quality,
                  "Pick the cheapest transport whose expected SSIM reaches this (0 to 1; e.g. 0.9)")
      ->check(kFraction);
  cmd->add_flag("--no-phosphorescence", args->no_phosphorescence,
                "Render phosphors as plain diffuse surfaces (no states, no glow)");
  cmd->add_option("--spp", args->spp, "Samples per pixel (default: the scene's render.spp or direct_spp)")
      ->check(CLI::Range(1, 1 << 20));
  cmd->add_option("--width", args->width,
                  "Override the camera's width in pixels (width x height at most 67108864, 8192 x 8192)")
      ->check(CLI::Range(1, 16384));
  cmd->add_option("--height", args->height, "Override the camera's height in pixels")->check(CLI::Range(1, 16384));
  cmd->add_option("--exposure", args->exposure_text,
                  "PNG exposure: a positive number, or auto: one exposure for the sequence that shows the median\n"
                  "glowing pixel of the brightest frame after dark (no light on; of all frames if none is) as\n"
                  "mid-grey, metered on their direct-transport frames under any transport (docs/render.md);\n"
                  "or, for a physical scene, ev100:N: a camera at EV100 N, 1.2 x 2^N cd/m^2 shown as 1 before\n"
                  "the tone map (Filament's exposure = 1 / (1.2 x 2^EV100));\n"
                  "default: the camera's \"exposure\" (1 if not given). EXR files are never scaled")
      ->each([args](const std::string&) { args->exposure_given = true; });
  cmd->add_option("--night-vision", args->night_vision_cd,
                  "Also write frame-NNNN-night.png as a dark-adapted eye sees it (Thompson et al. 2002:\n"
                  "blue shift, loss of acuity, grain); the value is the luminance in cd/m^2 of radiance 1")
      ->check(kFinite)
      ->check(kPositive);
  cmd->add_option("--contact-sheet", args->contact_sheet,
                  "Also write every frame side by side, labelled with its time, to this PNG");
  cmd->add_option("--material", args->materials,
                  "OBJECT=FILE: give the object of that name this phosphor material (repeatable),\n"
                  "e.g. one just fitted by 'phos fit', without editing the scene");
  cmd->add_option("--unknown-ke", args->unknown_ke,
                  "zero: take every phosphor's ke where it was not measured (Table 8.1's presets, a fit's bands\n"
                  "no LED reached) as 0, not charging, as \"unknown_ke\": \"zero\" on each object would; one\n"
                  "line on stderr names each material and band. Default: such a band lit is refused")
      ->check(CLI::IsMember({"zero"}));
  cmd->add_flag("--json", args->json, "Print one JSON object: frames with t, exr, png and seconds");
  cmd->add_option("--exr-compression", args->exr_compression,
                  "How the EXR frames are compressed: zip, zips, piz, rle or none keep every float (none writes\n"
                  "fastest and largest; zip or piz smallest); pxr24 rounds floats to 24 bits; dwaa and dwab\n"
                  "are lossy on R, G, B, for viewing (docs/render.md, 'EXR compression', measures the trade)")
      ->default_str("zip")
      ->check(CLI::IsMember({"zip", "zips", "piz", "rle", "none", "pxr24", "dwaa", "dwab"}));
  cmd->add_flag("--check", args->check,
                "Load the scene and check every option as a run would, then stop before the solver: write\n"
                "nothing (exit 0: the run would start; 'phos slurm render' checks its tasks' command so)");
  cmd->add_option("--frames", args->frames,
                  "FIRST:END: render only frames FIRST to END-1 of the run (0-based, numbered as in the whole\n"
                  "run); equal bit for bit to the same frames of one run. The states start from the latest\n"
                  "--checkpoints state at or before FIRST (or from the scene's start). Writes a done record\n"
                  "<out>/done/frames-FIRST-END.json last; a rerun with one does nothing (docs/scale.md)");
  cmd->add_option("--task", args->task,
                  "i/N: render the i-th (0-based) of N near-equal consecutive ranges of frames, as --frames\n"
                  "(a Slurm array task: --task $SLURM_ARRAY_TASK_ID/N); done record <out>/done/task-i-of-N.json")
      ->excludes("--frames");
  cmd->add_flag("--solve-only", args->solve_only,
                "Render nothing: advance the states frame by frame (as a full run does: lights, dark jumps in\n"
                "closed form, the glow patches with phosphor_irradiance) and write the state at the first\n"
                "frame of each of --tasks ranges into --checkpoints, then <checkpoints>/done.json");
  cmd->add_option("--checkpoints", args->checkpoints,
                  "Folder of solver states (state-NNNNNN.bin, phos.solver-state/1, docs/formats.md): written by\n"
                  "--solve-only, read by --frames and --task");
  cmd->add_option("--tasks", args->solve_tasks, "With --solve-only: the number of frame ranges (default 1)")
      ->check(CLI::Range(1, 1000000))
      ->needs("--solve-only");
  cmd->callback([args] {
    ParseExposureOption(args.get());
    Run(*args);
  });
  // Each frame's line out as it is printed, into a pipe or a log too: a
  // killed render left an empty log, its lines still in the stdio buffer.
  cmd->preparse_callback([](std::size_t) { std::setvbuf(stdout, nullptr, _IOLBF, 0); });
}

}  // namespace phos::app
