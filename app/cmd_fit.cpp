// phos fit session: a captured sample (phos capture all) into a material file
// and a report; phos fit map and batch. The curve fits (decay-curve,
// charge-curve) live in cmd_fit_curve.cpp.

#include <cmath>
#include <cstdio>
#include <memory>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <functional>
#include <regex>
#include <optional>
#include <set>
#include <thread>
#include <string>

#include <CLI/CLI.hpp>
#include <OpenImageIO/imageio.h>
#include <nlohmann/json.hpp>

#include "cli_finite.h"
#include "commands.h"
#include "phos/acquire/session.h"
#include "phos/acquire/session_records.h"
#include "phos/fit/decay_fit.h"
#include "phos/fit/decay_map.h"
#include "phos/fit/decay_map_file.h"
#include "phos/fit/captured_sample.h"
#include "phos/fit/session_fit.h"
#include "phos/model/material.h"
#include "phos/model/schedule.h"
#include "phos/model/state_reduction.h"
#include "phos/util/atomic_file.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/image_file.h"
#include "phos/util/json.h"
#include "phos/util/progress.h"
#include "phos/util/task_record.h"

namespace phos::app {
namespace {

struct SessionArgs {
  std::string dir, out, report, compare, weights = "poisson";
  int components = 0, max_components = 3, max_iterations = 0;
  bool json = false, sequential = false, joint = false;  // joint: the default, accepted for older scripts
  bool keep_unconverged = false;
  std::optional<double> span_s, tolerance;  // --span-s, --tolerance: only the states a scene of span_s needs
};

// Only the states a scene needs (model/state_reduction.h): the fitted
// material reduced to the fewest states whose radiance stays within
// --tolerance of it over --span-s, charged as the session's decay was (its
// charge light for its charge time, from dark), then dark.
std::optional<StateReduction> ReduceForSpan(const CapturedSample& sample, const Material& material,
                                            const SessionArgs& args) {
  if (!args.span_s) return std::nullopt;
  if (!sample.decay) ThrowUserError(args.dir, "--span-s", "the session has no decay part to take its charge from");
  const DecayCharge charge = ChargeBeforeDecay(*sample.decay);
  if (charge.band_irradiance.empty())
    ThrowUserError(args.dir, "--span-s",
                   "the decay part records no band irradiance of its charge light: the states cannot be charged");
  StateReductionOptions options;
  options.span_s = *args.span_s;
  options.tolerance = *args.tolerance;
  const IrradianceSchedule schedule =
      IrradianceSchedule::ChargeThenDecay(charge.band_irradiance, charge.charge_s, *args.span_s);
  return ReduceStates(material, schedule, options, args.out);
}

// A material whose fit stopped at its iteration limit is not written unless
// the user asked to keep it (then it is, and the output says so).
void RequireConverged(const SessionFit& fit, const std::string& dir, bool keep) {
  if (fit.unconverged.empty() || keep) return;
  ThrowUserError(dir, "",
                 JoinComma(fit.unconverged) +
                     " did not converge: nothing written (raise --max-iterations, or give --keep-unconverged to "
                     "write it anyway)");
}

nlohmann::json OptionalJson(const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); }

nlohmann::json OptionalArrayJson(const std::vector<std::optional<double>>& values) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& v : values) out.push_back(OptionalJson(v));
  return out;
}

// "0.1 +- 0.002, -, ..." per band.
std::string BandValuesText(const std::vector<std::optional<double>>& values,
                           const std::vector<std::optional<double>>& stderr_values) {
  std::string text;
  for (std::size_t b = 0; b < values.size(); ++b) {
    text.append(b ? ", " : "");
    if (!values[b]) {
      text.append("-");
      continue;
    }
    text.append(FormatShort(*values[b]));
    if (b < stderr_values.size() && stderr_values[b]) text.append(" +- ").append(FormatShort(*stderr_values[b], 2));
  }
  return text;
}

nlohmann::json JointJson(const JointFit& j, bool written) {
  nlohmann::json ke = nlohmann::json::array();
  for (const KeEstimate& k : j.ke)
    ke.push_back({{"ke", OptionalArrayJson(k.ke)}, {"ke_stderr", OptionalArrayJson(k.ke_stderr)}});
  return {{"kr", j.kr},
          {"kr_stderr", j.kr_stderr},
          {"a", j.a},
          {"ke", ke},
          {"converged", j.converged},
          {"weighted_ss_sequential", {{"decay", j.decay_sequential}, {"excitation", j.excitation_sequential}}},
          {"weighted_ss_joint", {{"decay", j.decay_joint}, {"excitation", j.excitation_joint}}},
          {"written", written}};
}

nlohmann::json ComparisonJson(const MaterialComparison& c) {
  nlohmann::json per_state = nlohmann::json::array();
  for (const auto& errors : c.ke_relative_error_per_state) per_state.push_back(OptionalArrayJson(errors));
  return {{"kr_relative_error", c.kr_relative_error},
          {"spectrum_l1", c.spectrum_l1},
          {"ke_relative_error", OptionalArrayJson(c.ke_relative_error)},
          {"ke_relative_error_per_state", per_state}};
}

void PrintSessionFit(const SessionArgs& args, const SessionFit& fit) {
  std::printf("phos fit session: %s -> %s (%s s)\n", args.dir.c_str(), args.out.c_str(),
              FormatShort(fit.seconds).c_str());
  std::printf("  nc = %d: %s\n", fit.decay->n_components, fit.decay->choice.c_str());
  for (std::size_t i = 0; i < fit.material.states.size(); ++i) {
    const ExcitedState& state = fit.material.states[i];
    std::printf("  state %zu: kr = %s +- %s /s\n", i + 1, FormatShort(state.kr).c_str(),
                FormatShort(state.kr_stderr.value_or(0.0), 2).c_str());
    std::printf("    ke per band (1/s per unit irradiance): %s\n", BandValuesText(state.ke, state.ke_stderr).c_str());
  }
  if (fit.state_excitation && !fit.state_excitation->converged)
    std::printf("  excitation fit did not converge: %s\n", fit.state_excitation->termination.c_str());
  for (const std::string& stage : fit.unconverged)
    std::printf("  warning: written although %s did not converge (--keep-unconverged)\n", stage.c_str());
  if (fit.joint) {
    const JointFit& j = *fit.joint;
    std::string kr;
    for (std::size_t i = 0; i < j.kr.size(); ++i) kr.append(i ? ", " : "").append(FormatShort(j.kr[i]));
    std::printf(
        "  joint refinement%s: kr = %s /s; weighted sum of squares (decay + excitation) %s + %s = %s, "
        "sequential %s + %s = %s%s\n",
        fit.joint_written ? " (written)" : "", kr.c_str(), FormatShort(j.decay_joint).c_str(),
        FormatShort(j.excitation_joint).c_str(), FormatShort(j.decay_joint + j.excitation_joint).c_str(),
        FormatShort(j.decay_sequential).c_str(), FormatShort(j.excitation_sequential).c_str(),
        FormatShort(j.decay_sequential + j.excitation_sequential).c_str(), j.converged ? "" : " (not converged)");
  }
  for (const std::string& note : fit.notes) std::printf("  note: %s\n", note.c_str());
  if (!args.report.empty()) std::printf("  report: %s\n", args.report.c_str());
}

void PrintComparison(const std::string& compare, const MaterialComparison& c) {
  const std::string kr_text = JoinComma(c.kr_relative_error, [](double e) { return FormatShort(100 * e) + "%"; });
  std::printf("  against %s: kr off by %s; emission spectrum L1 %s\n", compare.c_str(), kr_text.c_str(),
              FormatShort(c.spectrum_l1).c_str());
  for (std::size_t i = 0; i < c.ke_relative_error_per_state.size(); ++i) {
    const std::string ke_text = JoinComma(c.ke_relative_error_per_state[i],
                                          [](const auto& e) { return e ? FormatShort(100 * *e) + "%" : "-"; });
    std::printf("    state %zu: ke off by %s\n", i + 1, ke_text.c_str());
  }
}

void RunFitSession(const SessionArgs& args) {
  RequireOutputFile(args.out, "--out");
  RequireOutputFile(args.report, "--report");
  SessionFitOptions options;
  options.components = args.components;
  options.max_components = args.max_components;
  options.weighting = ParseWeightsOption(args.weights);
  options.joint = !args.sequential;
  options.max_iterations = args.max_iterations;
  std::optional<Material> truth;
  if (!args.compare.empty()) truth = LoadMaterial(args.compare);  // a bad file fails before any work
  const CapturedSample sample = LoadCapturedSample(args.dir);
  const SessionFit fit = FitSession(sample, options);
  RequireConverged(fit, args.dir, args.keep_unconverged);
  const std::optional<StateReduction> reduced = ReduceForSpan(sample, fit.material, args);
  std::optional<MaterialComparison> comparison;
  if (truth) comparison = CompareMaterials(fit.material, *truth);
  for (const std::string& file : {args.out, args.report}) {
    const std::filesystem::path parent = std::filesystem::path(file).parent_path();
    std::error_code ec;
    if (!file.empty() && !parent.empty())
      std::filesystem::create_directories(parent, ec);  // a failure is named by the write
  }
  SaveMaterial(reduced ? reduced->material : fit.material, args.out);
  if (!args.report.empty())
    WriteFileAtomically(args.report, SessionReportHtml(fit, "phos fit session " + args.dir, comparison));
  nlohmann::json json = {
      {"material", args.out}, {"seconds", fit.seconds}, {"notes", fit.notes}, {"unconverged", fit.unconverged}};
  json["n_components"] = fit.decay->n_components;
  json["choice"] = fit.decay->choice;
  json["bic"] = fit.decay->bic;
  nlohmann::json states = nlohmann::json::array();
  for (const ExcitedState& state : fit.material.states)
    states.push_back({{"kr", state.kr},
                      {"kr_stderr", OptionalJson(state.kr_stderr)},
                      {"ke", OptionalArrayJson(state.ke)},
                      {"ke_stderr", OptionalArrayJson(state.ke_stderr)}});
  json["states"] = states;
  if (fit.state_excitation)
    json["excitation"] = {{"converged", fit.state_excitation->converged},
                          {"condition_number", fit.state_excitation->condition_number},
                          {"frames", fit.state_excitation->frames},
                          {"S", fit.state_excitation->S},
                          {"background", fit.state_excitation->background},
                          {"weighted_rss", fit.state_excitation->weighted_rss},
                          {"a", fit.state_excitation->a},
                          {"a_stderr", fit.state_excitation->a_stderr}};
  if (fit.joint) json["joint"] = JointJson(*fit.joint, fit.joint_written);
  json["written"] = fit.joint_written ? "joint" : "sequential";
  if (reduced)
    json["reduced"] = {{"span_s", *args.span_s},
                       {"tolerance", *args.tolerance},
                       {"states_full", reduced->states_before},
                       {"states_kept", reduced->states_after},
                       {"max_radiance_error", reduced->max_error}};
  if (!args.json) PrintSessionFit(args, fit);
  if (reduced && !args.json)
    std::printf("  written with %d of its %d state(s): the fewest within %s over %s s (largest radiance error %s)\n",
                reduced->states_after, reduced->states_before, FormatShort(*args.tolerance).c_str(),
                FormatShort(*args.span_s).c_str(), FormatShort(reduced->max_error, 3).c_str());
  if (comparison) {
    json["comparison"] = ComparisonJson(*comparison);
    if (!args.json) PrintComparison(args.compare, *comparison);
  }
  if (args.json) std::printf("%s\n", json.dump().c_str());
}

// ---- phos fit map ------------------------------------------------------------

struct MapArgs {
  std::string session, out, weights = "poisson", tile;
  int states = 1;
  bool no_background = false, json = false, merge = false;
  bool check = false;  // --check: the session and --tile checked, nothing fitted or written
};

// What the map's pixels are made from: a tile's done record for other inputs is not this map's.
// (One state writes the record it always wrote, so older tiles stay done.)
std::string MapInputs(const MapArgs& args, int tiles) {
  return "session=" + args.session + " weights=" + args.weights + " background=" + std::to_string(!args.no_background) +
         " tiles=" + std::to_string(tiles) + (args.states == 1 ? "" : " states=" + std::to_string(args.states));
}

// How the session charged the sample before the decay (fit's
// ChargeBeforeDecay), for the map's header. None recorded (a lab config that
// gives no irradiance for the light): the renderer then takes the map as
// charged to r = 1, as docs/render.md says.
fit::DecayMapCharge MapChargeOf(const CapturedSample::Decay& decay) {
  const DecayCharge recorded = ChargeBeforeDecay(decay);
  fit::DecayMapCharge charge;
  if (recorded.band_irradiance.empty()) return charge;
  charge.charge_s = static_cast<float>(recorded.charge_s);
  for (double value : recorded.band_irradiance) charge.band_irradiance.push_back(static_cast<float>(value));
  return charge;
}

// The session's frames as a map's input, only the rows of tile `index` of
// `count` (rows [H index / count, H (index + 1) / count)): a tile holds only
// its rows in memory. The whole map is tile 0 of 1.
struct MapFrames {
  DecayMapInput input;
  fit::DecayMapCharge charge;
  std::vector<std::string> channel_names;
  int clipped = 0;
  int full_height = 0;
  std::size_t first_row = 0;
};

// Rows [first, last) of tile `index` of `count`, or a UserError if it has none.
std::pair<std::size_t, std::size_t> TileRows(const std::filesystem::path& dir, int height, int index, int count) {
  const auto [first, last] = TaskShare(static_cast<std::size_t>(height), index, count);
  if (first >= last)
    ThrowUserError(dir.string(), "--tile",
                   "has no rows: more tiles than the frames' " + std::to_string(height) + " rows");
  return {first, last};
}

MapFrames ReadMapFrames(const MapArgs& args, int index, int count) {
  namespace fs = std::filesystem;
  const fs::path dir = args.session;
  // Typed records, every frame checked against its size and checksum first:
  // a map is never built on a bad frame.
  std::vector<std::string> notes;
  const CapturedSample::Decay decay = LoadDecaySession(dir, &notes);
  for (const std::string& note : notes) std::printf("phos fit map: %s\n", note.c_str());
  MapFrames out;
  out.charge = MapChargeOf(decay);
  DecayMapInput& input = out.input;
  const std::vector<DecaySample> samples = DecaySamples(decay, &out.clipped);
  ProgressBar reading("reading frames", samples.size());
  for (const DecaySample& sample : samples) {
    reading.Advance();
    const FrameRecord& line = sample.frame->record;
    const Frame frame = ReadFrame(dir, line);
    if (input.frames.empty()) {
      out.full_height = frame.height;
      const auto [first, last] = TileRows(dir, frame.height, index, count);
      out.first_row = first;
      input.width = frame.width;
      input.height = static_cast<int>(last - first);
      input.channels = frame.channels;
      out.channel_names = frame.channel_names;
    } else if (frame.width != input.width || frame.height != out.full_height || frame.channels != input.channels) {
      ThrowUserError((dir / line.file).string(), "", "differs in size from the first frame");
    }
    const std::size_t row_values = static_cast<std::size_t>(frame.width) * frame.channels;
    std::vector<float> rate(static_cast<std::size_t>(input.height) * row_values);
    const std::size_t offset = out.first_row * row_values;
    for (std::size_t i = 0; i < rate.size(); ++i)
      rate[i] = static_cast<float>((frame.pixels[offset + i] - frame.black_level_dn) / frame.exposure_s);
    input.frames.push_back(std::move(rate));
    input.exposure_s.push_back(frame.exposure_s);
    input.t_s.push_back(sample.t_s);
  }
  return out;
}

// A fitted map packed as decay-map.exr holds it (fit/decay_map_file.h), with
// what its frames were.
fit::DecayMapImage MapImageOf(const DecayMap& map, const MapFrames& frames) {
  fit::DecayMapImage image = fit::PackDecayMap(map, frames.channel_names);
  image.frames = frames.input.frames.size();
  image.clipped = frames.clipped;
  image.charge = frames.charge;
  return image;
}

// decay-map.exr and kr.png of a whole map, and what the command says of it.
void WriteMapOutputs(const MapArgs& args, const fit::DecayMapImage& map, const std::string& where) {
  namespace fs = std::filesystem;
  const std::size_t pixels = static_cast<std::size_t>(map.width) * map.height, nch = map.names.size();
  std::vector<float> kr(pixels);
  for (std::size_t p = 0; p < pixels; ++p) kr[p] = map.pixels[p * nch];
  // A map with no finite rate anywhere is no result (a frame record's
  // exposure out of range, a session of dark frames): an error, not exit 0.
  if (std::none_of(kr.begin(), kr.end(), [](float k) { return std::isfinite(k); }))
    ThrowUserError(where, "", "no pixel has a finite decay rate: nothing written (are the frames dark or clipped?)");
  std::error_code ec;
  fs::create_directories(args.out, ec);
  if (ec) ThrowUserError(args.out, "", "cannot create the output folder: " + ec.message());
  const fs::path exr = fs::path(args.out) / "decay-map.exr";
  fit::WriteDecayMap(exr, map);
  // A look at kr: grey from the 1st to the 99th percentile.
  std::vector<float> finite;
  for (float k : kr)
    if (std::isfinite(k)) finite.push_back(k);
  std::sort(finite.begin(), finite.end());
  const float lo = finite.empty() ? 0 : finite[finite.size() / 100],
              hi = finite.empty() ? 1 : finite[finite.size() * 99 / 100];
  const float median = finite.empty() ? std::nanf("") : finite[finite.size() / 2];
  std::vector<float> grey(pixels);
  for (std::size_t p = 0; p < pixels; ++p)
    grey[p] = std::isfinite(kr[p]) ? std::clamp((kr[p] - lo) / std::max(hi - lo, 1e-12f), 0.0f, 1.0f) : 0.0f;
  OIIO::ImageSpec png(map.width, map.height, 1, OIIO::TypeDesc::UINT8);
  png.channelnames = {"Y"};
  WriteImageAtomically(fs::path(args.out) / "kr.png", png, OIIO::TypeDesc::FLOAT, grey.data());
  const bool two_states = map.two_states();
  if (args.json) {
    nlohmann::json json = nlohmann::json({{"width", map.width},
                                          {"height", map.height},
                                          {"frames", map.frames},
                                          {"clipped_frames", map.clipped},
                                          {"seconds", map.seconds},
                                          {"exr", exr.string()},
                                          {"channels", map.names},
                                          {"kr_median_per_s", median},
                                          {"kr_p01_per_s", lo},
                                          {"kr_p99_per_s", hi},
                                          {"pixels_without_decay", map.no_decay}});
    if (two_states) json["pixels_with_one_state"] = map.one_state;
    std::printf("%s\n", json.dump().c_str());
    return;
  }
  std::printf(
      "phos fit map: %dx%d pixels, %zu frames, fitted in %s s -> %s (kr, amplitude.*, background.*, rms%s), "
      "kr.png\n",
      map.width, map.height, map.frames, FormatShort(map.seconds).c_str(), exr.string().c_str(),
      two_states ? ", kr2, amplitude2.*" : "");
  std::printf("  kr: median %s /s, 1%%-99%% %s to %s /s; %zu pixel(s) without a decay\n", FormatShort(median).c_str(),
              FormatShort(lo).c_str(), FormatShort(hi).c_str(), map.no_decay);
  if (two_states) std::printf("  two states: %zu decaying pixel(s) kept one state (kr2 NaN there)\n", map.one_state);
}

DecayMap FitMapFrames(const MapArgs& args, const MapFrames& frames) {
  DecayMapOptions options;
  options.background = !args.no_background;
  options.weighting = ParseWeightsOption(args.weights);
  options.states = args.states;
  ProgressBar fitting("fitting pixels", static_cast<std::size_t>(frames.input.height));
  DecayMap map = FitDecayMap(frames.input, options, args.session, [&](std::size_t) { fitting.Advance(); });
  fitting.Finish();
  return map;
}

// Tiles (docs/scale.md): tile i of N is rows [H i / N, H (i + 1) / N) of
// the map, fitted exactly as the whole map fits them (the rows' blocks of
// pixels are the same), in <out>/tiles/tile-i-of-N.exr with what the merge
// needs in its header, then its done record tile-i-of-N.json.
std::filesystem::path TilePath(const std::string& out, int index, int count, const char* extension) {
  return std::filesystem::path(out) / "tiles" /
         ("tile-" + std::to_string(index) + "-of-" + std::to_string(count) + extension);
}

void RunFitMapTile(const MapArgs& args) {
  int index = 0, count = 0;
  if (!ParseTaskIndex(args.tile, &index, &count))
    ThrowUserError("", "--tile", "expected i/N with 0 <= i < N, got \"" + args.tile + "\"");
  const auto start = std::chrono::steady_clock::now();
  const std::filesystem::path done = TilePath(args.out, index, count, ".json");
  const std::string inputs = MapInputs(args, count);
  if (TaskIsDone(done, inputs)) {
    std::printf("phos fit map: tile %d/%d already fitted (%s): nothing to do\n", index, count, done.c_str());
    return;
  }
  RemoveTemporaries(done.parent_path(),
                    {done.filename().string(), TilePath(args.out, index, count, ".exr").filename().string()});
  const MapFrames frames = ReadMapFrames(args, index, count);
  const std::size_t first_row = frames.first_row, last_row = first_row + frames.input.height;
  const fit::DecayMapImage tile = MapImageOf(FitMapFrames(args, frames), frames);
  std::error_code ec;
  std::filesystem::create_directories(done.parent_path(), ec);
  if (ec) ThrowUserError(done.parent_path().string(), "", "cannot create the folder: " + ec.message());
  const std::filesystem::path exr = TilePath(args.out, index, count, ".exr");
  fit::WriteDecayMapTile(exr, tile, static_cast<int>(first_row), frames.full_height);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  WriteTaskDone(done, {"fit map tile " + args.tile, inputs, {exr.string()}, seconds, HostName()});
  std::printf("phos fit map: tile %d/%d, rows %zu-%zu of %d, %zu frames, fitted in %s s -> %s\n", index, count,
              first_row, last_row - 1, frames.full_height, tile.frames, FormatShort(tile.seconds).c_str(), exr.c_str());
}

// The tiles of <out>/tiles into one map: every tile of the one count found
// must be there with its done record for these inputs.
void RunFitMapMerge(const MapArgs& args) {
  namespace fs = std::filesystem;
  const fs::path tiles = fs::path(args.out) / "tiles";
  std::set<int> counts;
  std::error_code ec;
  static const std::regex form(R"(tile-(\d+)-of-(\d+)\.exr)");
  for (const auto& entry : fs::directory_iterator(tiles, ec)) {
    std::smatch m;
    const std::string name = entry.path().filename().string();
    if (std::regex_match(name, m, form)) counts.insert(std::stoi(m[2]));
  }
  if (ec || counts.empty()) ThrowUserError(tiles.string(), "", "holds no tiles (run 'phos fit map --tile i/N' first)");
  if (counts.size() > 1)
    ThrowUserError(tiles.string(), "", "holds tiles of more than one count N: remove the old ones");
  const int count = *counts.begin();
  const std::string inputs = MapInputs(args, count);
  std::string missing;
  for (int i = 0; i < count; ++i) {
    // With SESSION given, the tiles must be of it and these options; without, any whole tile does.
    const fs::path done = TilePath(args.out, i, count, ".json");
    if (args.session.empty() ? !ReadTaskDone(done) : !TaskIsDone(done, inputs))
      missing += (missing.empty() ? "" : ", ") + std::to_string(i);
  }
  if (!missing.empty())
    ThrowUserError(tiles.string(), "",
                   "tile(s) " + missing + " of " + std::to_string(count) +
                       " not done for these inputs (session, --weights, --no-background, --states): nothing merged");
  std::vector<fs::path> exrs;
  for (int i = 0; i < count; ++i) exrs.push_back(TilePath(args.out, i, count, ".exr"));
  const fit::DecayMapImage map = fit::MergeDecayMapTiles(exrs);
  WriteMapOutputs(args, map, tiles.string());
}

// --check: what a map or a tile would refuse before fitting, read from the
// session's records and its first frame only: a decay session with frames,
// and --tile i/N with no tile of N empty (so 'phos slurm map' refuses N
// above the rows before it submits an array whose merge could never run).
void CheckFitMap(const MapArgs& args) {
  int index = 0, count = 1;
  if (!args.tile.empty() && !ParseTaskIndex(args.tile, &index, &count))
    ThrowUserError("", "--tile", "expected i/N with 0 <= i < N, got \"" + args.tile + "\"");
  ParseWeightsOption(args.weights);
  RequireFolderOrNothing(args.out, "--out");
  const std::filesystem::path dir = args.session;
  std::vector<std::string> ignored;
  const CapturedSample::Decay decay = LoadDecaySession(dir, &ignored);
  if (decay.frames.empty()) ThrowUserError(dir.string(), "", "has no frames to fit");
  const Frame first = ReadFrame(dir, decay.frames.front().record);
  for (int i = 0; i < count; ++i) TileRows(dir, first.height, i, count);
  std::printf("phos fit map: %s: %zu frame(s) of %d x %d, %d tile(s) (--check: nothing fitted)\n", dir.c_str(),
              decay.frames.size(), first.width, first.height, count);
}

void RunFitMap(const MapArgs& args) {
  RequireFolderOrNothing(args.out, "--out");
  if (args.merge) return RunFitMapMerge(args);
  if (args.session.empty()) ThrowUserError("", "SESSION", "is required (except with --merge)");
  if (args.check) return CheckFitMap(args);
  if (!args.tile.empty()) return RunFitMapTile(args);
  const MapFrames frames = ReadMapFrames(args, 0, 1);
  if (frames.clipped > 0 && !args.json) std::printf("phos fit map: %d clipped frame(s) left out\n", frames.clipped);
  WriteMapOutputs(args, MapImageOf(FitMapFrames(args, frames), frames), args.session);
}

// ---- phos fit batch ----------------------------------------------------------

struct BatchArgs {
  std::vector<std::string> inputs;
  std::string out, weights = "poisson", task;
  int jobs = 0, components = 0, max_components = 3;
  bool reports = true, json = false, merge = false;
  bool check = false;  // --check: the items and --task checked, nothing fitted or written
  bool keep_unconverged = false;
};

// <item>.done.json: an item of a batch is done. Written last (after the
// material and the report), through a rename; a record that does not parse
// or lacks a field means "not done", so the item is fitted again, as does
// one made from other inputs (BatchItemInputs: the data or the options).
struct BatchDoneRecord {
  std::string item;
  int n_components = 0;
  double kr_per_s = 0, seconds = 0;       // kr: the first state's
  std::vector<double> kr_by_state_per_s;  // every state's (absent before it was recorded: just kr)
  std::vector<std::string> notes;
  std::string inputs;  // BatchItemInputs of the fit ("" in records from before it was recorded)

  nlohmann::json ToJson() const {
    return {{"item", item},       {"n_components", n_components},
            {"kr", kr_per_s},     {"kr_by_state", kr_by_state_per_s},
            {"seconds", seconds}, {"notes", notes},
            {"inputs", inputs}};
  }
  // nullopt (and why) when the record is not a whole one.
  static std::optional<BatchDoneRecord> FromJson(const nlohmann::json& j, std::string* why) {
    BatchDoneRecord r;
    if (!j.is_object()) return *why = "not a JSON object", std::nullopt;
    if (!j.contains("item") || !j["item"].is_string()) return *why = "no item", std::nullopt;
    if (!j.contains("n_components") || !j["n_components"].is_number_integer() || j["n_components"].get<int>() < 1 ||
        j["n_components"].get<int>() > 4)
      return *why = "no n_components of 1-4", std::nullopt;
    if (!j.contains("kr") || !j["kr"].is_number() || !(j["kr"].get<double>() > 0) ||
        !std::isfinite(j["kr"].get<double>()))
      return *why = "no finite kr > 0", std::nullopt;
    if (!j.contains("seconds") || !j["seconds"].is_number()) return *why = "no seconds", std::nullopt;
    r.item = j["item"].get<std::string>();
    r.n_components = j["n_components"].get<int>();
    r.kr_per_s = j["kr"].get<double>();
    r.seconds = j["seconds"].get<double>();
    if (j.contains("notes") && j["notes"].is_array())
      for (const nlohmann::json& note : j["notes"])
        if (note.is_string()) r.notes.push_back(note.get<std::string>());
    if (j.contains("kr_by_state") && j["kr_by_state"].is_array())
      for (const nlohmann::json& kr : j["kr_by_state"])
        if (kr.is_number()) r.kr_by_state_per_s.push_back(kr.get<double>());
    if (r.kr_by_state_per_s.empty()) r.kr_by_state_per_s = {r.kr_per_s};
    if (j.contains("inputs") && j["inputs"].is_string()) r.inputs = j["inputs"].get<std::string>();
    return r;
  }
};

// What an item's fit is made from, so that a rerun refits an item whose
// data or options changed and keeps only a fit of these inputs (a folder
// replaced by another capture, or --components or --max-components given, kept the old fit).
// The data: the XXH3 of every session.json and frames.jsonl of the folder
// and its parts (frames.jsonl holds each frame's own size and checksum).
std::string BatchItemInputs(const std::filesystem::path& item, const SessionFitOptions& options) {
  namespace fs = std::filesystem;
  nlohmann::json data = nlohmann::json::object();
  std::vector<fs::path> folders = {item};
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(item, ec))
    if (entry.is_directory() && fs::is_regular_file(entry.path() / "session.json")) folders.push_back(entry.path());
  std::sort(folders.begin() + 1, folders.end());
  for (const fs::path& folder : folders)
    for (const char* name : {"session.json", "frames.jsonl"})
      if (fs::is_regular_file(folder / name, ec))
        data[fs::relative(folder / name, item, ec).generic_string()] = DigestFile(folder / name).xxh3;
  return nlohmann::json({{"components", options.components},
                         {"max_components", options.max_components},
                         {"weights", WeightingName(options.weighting)},
                         {"joint", options.joint},
                         {"data", data}})
      .dump();
}

// The done record of an item, if whole ("why" says what is wrong otherwise).
std::optional<BatchDoneRecord> ReadBatchDone(const std::filesystem::path& path, std::string* why) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return *why = "", std::nullopt;
  try {
    return BatchDoneRecord::FromJson(ReadJsonFile(path), why);
  } catch (const UserError& e) {
    *why = "does not parse";
    return std::nullopt;
  }
}

// The capture folders named: each input is one, or holds them as subfolders.
std::vector<std::filesystem::path> BatchItems(const std::vector<std::string>& inputs) {
  namespace fs = std::filesystem;
  std::vector<fs::path> items;
  for (const std::string& input : inputs) {
    const fs::path path = input;
    std::error_code ec;
    if (fs::is_regular_file(path / "session.json", ec)) {
      items.push_back(path);
      continue;
    }
    if (!fs::is_directory(path, ec)) ThrowUserError(input, "", "is neither a capture folder nor a folder of them");
    std::vector<fs::path> found;
    for (const auto& entry : fs::directory_iterator(path, ec))
      if (entry.is_directory() && fs::is_regular_file(entry.path() / "session.json")) found.push_back(entry.path());
    if (found.empty()) ThrowUserError(input, "", "holds no capture folder (no */session.json)");
    std::sort(found.begin(), found.end());
    items.insert(items.end(), found.begin(), found.end());
  }
  std::set<std::string> names;
  for (const fs::path& item : items)
    if (!names.insert(item.filename().string()).second)
      ThrowUserError(item.string(), "",
                     "two items are named '" + item.filename().string() +
                         "': outputs are named after the folder, so names must differ");
  return items;
}

// One item of a batch and what became of it: kept (its done record is for
// these inputs), fitted now, or failed with why.
struct BatchRow {
  std::string name, status, detail, inputs;
  int nc = 0;
  double kr = 0, seconds = 0;
  std::vector<double> kr_by_state;
};

// The items this run (or --task share) has, each with its row, and those to fit.
struct BatchPlan {
  std::vector<std::filesystem::path> items;
  int task_index = 0, task_count = 0;
  std::vector<BatchRow> rows;
  std::vector<std::size_t> todo;
};

// --task i/N: this array task's share of the items, in order (the items'
// own done records make it idempotent; the summary is the merge's).
BatchPlan ShareOfItems(const BatchArgs& args) {
  BatchPlan plan;
  plan.items = BatchItems(args.inputs);
  if (!args.task.empty()) {
    if (!ParseTaskIndex(args.task, &plan.task_index, &plan.task_count))
      ThrowUserError("", "--task", "expected i/N with 0 <= i < N, got \"" + args.task + "\"");
    const auto [first, last] = TaskShare(plan.items.size(), plan.task_index, plan.task_count);
    plan.items = std::vector<std::filesystem::path>(plan.items.begin() + first, plan.items.begin() + last);
  }
  return plan;
}

// An item is done when its record (<name>.done.json, written last and
// atomically, after the material and the report) exists for the same
// inputs: a crash mid-batch leaves the unfinished items without one, and
// only they rerun.
void ReadDoneRecords(const BatchArgs& args, const SessionFitOptions& options, BatchPlan* plan) {
  namespace fs = std::filesystem;
  plan->rows.resize(plan->items.size());
  for (std::size_t i = 0; i < plan->items.size(); ++i) {
    BatchRow& row = plan->rows[i];
    row.name = plan->items[i].filename().string();
    row.inputs = BatchItemInputs(plan->items[i], options);
    std::string why;
    const std::optional<BatchDoneRecord> record = ReadBatchDone(fs::path(args.out) / (row.name + ".done.json"), &why);
    if (record && record->inputs == row.inputs) {
      row.status = "kept";
      row.nc = record->n_components;
      row.kr = record->kr_per_s;
      row.kr_by_state = record->kr_by_state_per_s;
      row.seconds = record->seconds;
      row.detail = args.merge ? "fitted before this merge (its task's record)" : "done in an earlier run";
    } else {
      if (record)
        row.detail = "its .done.json was made from other inputs (the data or the options): fitted again";
      else if (!why.empty())
        row.detail = "its .done.json " + why + ": fitted again";
      plan->todo.push_back(i);
    }
  }
}

// A task's leftovers of the items it fits again: the temporary of the file a
// killed run was writing, and an earlier run's failure (the merge reads
// .failed.txt as this chain's word, so a task killed before the item must
// leave it "not fitted yet", not failed for an old reason).
void ClearTaskLeftovers(const BatchArgs& args, const BatchPlan& plan) {
  std::vector<std::string> names;
  for (std::size_t i : plan.todo)
    for (const char* suffix : {".json", ".html", ".done.json", ".failed.txt"})
      names.push_back(plan.rows[i].name + suffix);
  RemoveTemporaries(args.out, names);
  std::error_code ec;
  for (std::size_t i : plan.todo)
    std::filesystem::remove(std::filesystem::path(args.out) / (plan.rows[i].name + ".failed.txt"), ec);
}

// --merge: an item its task could not fit (its .failed.txt, the task's own
// words) is a failed row of the summary, as in one process's batch; one no
// task has tried yet is refused, naming it. Nothing is fitted.
void MergeTaskFailures(const BatchArgs& args, BatchPlan* plan) {
  std::vector<std::size_t> untried;
  for (std::size_t i : plan->todo) {
    const std::filesystem::path failed = std::filesystem::path(args.out) / (plan->rows[i].name + ".failed.txt");
    std::error_code exists_error;
    const std::string why = std::filesystem::is_regular_file(failed, exists_error) ? ReadFileText(failed, 1 << 20) : "";
    if (why.empty()) {
      untried.push_back(i);
      continue;
    }
    plan->rows[i].status = "failed";
    plan->rows[i].detail = why.substr(0, why.find_last_not_of("\n") + 1);
  }
  if (!untried.empty()) {
    const std::string missing = JoinComma(untried, [&](std::size_t i) { return plan->rows[i].name; });
    ThrowUserError(args.out, "--merge", "item(s) not fitted yet: " + missing + " (nothing merged)");
  }
  plan->todo.clear();
}

// Fits one item into its row, writing its material, report and done record;
// one item's bad data is said in its row and .failed.txt, never thrown.
void FitBatchItem(const BatchArgs& args, const SessionFitOptions& options, const std::filesystem::path& item,
                  BatchRow* row) {
  const std::filesystem::path base = std::filesystem::path(args.out) / row->name;
  std::error_code ec;
  try {
    const SessionFit fit = FitSession(item, options);
    RequireConverged(fit, item.string(), args.keep_unconverged);
    SaveMaterial(fit.material, base.string() + ".json");
    if (args.reports)
      WriteFileAtomically(base.string() + ".html", SessionReportHtml(fit, "phos fit batch: " + row->name));
    row->status = "fitted";
    row->nc = fit.decay->n_components;
    row->kr = fit.material.states[0].kr;
    row->kr_by_state.clear();
    for (const ExcitedState& state : fit.material.states) row->kr_by_state.push_back(state.kr);
    row->seconds = fit.seconds;
    const std::string earlier = row->detail;
    row->detail = fit.notes.empty() ? "" : std::to_string(fit.notes.size()) + " note(s): " + fit.notes.front();
    if (!earlier.empty()) row->detail = earlier + (row->detail.empty() ? "" : "; " + row->detail);
    const BatchDoneRecord done{item.string(), row->nc, row->kr, row->seconds, row->kr_by_state, fit.notes, row->inputs};
    WriteFileAtomically(base.string() + ".done.json", done.ToJson().dump(2) + "\n");
    std::filesystem::remove(base.string() + ".failed.txt", ec);
  } catch (const std::exception& e) {
    row->status = "failed";
    row->detail = e.what();
    try {
      WriteFileAtomically(base.string() + ".failed.txt", std::string(e.what()) + "\n");
    } catch (...) {}
  }
}

// The items to fit, --jobs at a time.
void FitBatchItems(const BatchArgs& args, const SessionFitOptions& options, BatchPlan* plan) {
  const int jobs = args.jobs > 0 ? args.jobs : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  ProgressBar progress("fit batch", plan->todo.size());
  std::atomic<std::size_t> next{0};
  auto worker = [&] {
    for (std::size_t k = next++; k < plan->todo.size(); k = next++) {
      const std::size_t i = plan->todo[k];
      FitBatchItem(args, options, plan->items[i], &plan->rows[i]);
      progress.Advance();
    }
  };
  std::vector<std::thread> threads;
  for (int t = 0; t < std::min<int>(jobs, static_cast<int>(plan->todo.size())); ++t) threads.emplace_back(worker);
  for (std::thread& t : threads) t.join();
  progress.Finish();
}

struct BatchCounts {
  int failed = 0;
  std::size_t fitted_now = 0, kept = 0;
};

// One summary table, on screen (or as JSON) and as summary.csv (one process's
// or a merge's; a task writes none). kr_per_s is the first state's (as
// before); kr_by_state_per_s every state's, ';'-separated, last so that
// readers of the older columns go on.
BatchCounts SummarizeBatch(const BatchArgs& args, const std::vector<BatchRow>& rows) {
  std::string csv = "item,status,n_components,kr_per_s,seconds,detail,kr_by_state_per_s\n";
  if (!args.json) std::printf("%-24s %-7s %3s %16s %8s  %s\n", "item", "status", "nc", "kr (1/s)", "s", "detail");
  BatchCounts counts;
  nlohmann::json json_rows = nlohmann::json::array();
  for (const BatchRow& row : rows) {
    counts.failed += row.status == "failed";
    counts.fitted_now += row.status == "fitted";
    counts.kept += row.status == "kept";
    json_rows.push_back({{"item", row.name},
                         {"status", row.status},
                         {"n_components", row.nc},
                         {"kr_per_s", row.kr},
                         {"kr_by_state_per_s", row.kr_by_state},
                         {"seconds", row.seconds},
                         {"detail", row.detail}});
    const std::string kr_text = JoinComma(row.kr_by_state, [](double kr) { return FormatShort(kr); });
    if (!args.json)
      std::printf("%-24s %-7s %3d %16s %8s  %s\n", row.name.c_str(), row.status.c_str(), row.nc,
                  row.status == "failed" ? "-" : kr_text.c_str(), FormatShort(row.seconds).c_str(), row.detail.c_str());
    std::string detail = row.detail;
    std::replace(detail.begin(), detail.end(), '"', '\'');
    csv.append(row.name + "," + row.status + "," + std::to_string(row.nc) + "," + FormatDouble(row.kr) + "," +
               FormatDouble(row.seconds) + ",\"" + detail + "\"," + Join(row.kr_by_state, ";", FormatDouble) + "\n");
  }
  if (args.task.empty()) WriteFileAtomically(std::filesystem::path(args.out) / "summary.csv", csv);
  if (args.json)
    std::printf("%s\n", nlohmann::json({{"items", json_rows},
                                        {"fitted_now", counts.fitted_now},
                                        {"kept", counts.kept},
                                        {"failed", counts.failed},
                                        {"out", args.out}})
                            .dump()
                            .c_str());
  else
    std::printf("phos fit batch: %zu item(s)%s, %zu fitted now, %zu kept, %d failed -> %s%s\n", rows.size(),
                args.task.empty() ? "" : (" (task " + args.task + ")").c_str(), counts.fitted_now, counts.kept,
                counts.failed, args.out.c_str(), args.task.empty() ? " (summary.csv)" : "");
  return counts;
}

// The task's record (phos slurm status counts them), after its items' own.
void WriteBatchTaskRecord(const BatchArgs& args, const BatchPlan& plan, double seconds) {
  TaskDoneRecord record{"fit batch task " + args.task, "", {}, 0, HostName()};
  for (const std::filesystem::path& item : plan.items) {
    record.inputs += item.string() + ";";
    record.outputs.push_back((std::filesystem::path(args.out) / (item.filename().string() + ".json")).string());
  }
  record.seconds = seconds;
  WriteTaskDone(std::filesystem::path(args.out) / "tasks" /
                    ("task-" + std::to_string(plan.task_index) + "-of-" + std::to_string(plan.task_count) + ".json"),
                record);
}

void RunFitBatch(const BatchArgs& args) {
  RequireFolderOrNothing(args.out, "--out");
  SessionFitOptions options;
  options.components = args.components;
  options.max_components = args.max_components;
  options.weighting = ParseWeightsOption(args.weights);
  BatchPlan plan = ShareOfItems(args);
  if (args.check) {
    std::printf("phos fit batch: %zu item(s) to fit or keep (--check: nothing fitted)\n", plan.items.size());
    return;
  }
  const auto task_start = std::chrono::steady_clock::now();
  std::error_code ec;
  std::filesystem::create_directories(args.out, ec);
  if (ec) ThrowUserError(args.out, "", "cannot create the output folder: " + ec.message());
  ReadDoneRecords(args, options, &plan);
  if (!args.task.empty()) ClearTaskLeftovers(args, plan);
  if (args.merge) MergeTaskFailures(args, &plan);
  FitBatchItems(args, options, &plan);
  const BatchCounts counts = SummarizeBatch(args, plan.rows);
  if (counts.failed > 0)
    ThrowUserError("", "fit batch",
                   std::to_string(counts.failed) + " item(s) could not be fitted (see the table and " + args.out +
                       "/<item>.failed.txt)");
  if (!args.task.empty())
    WriteBatchTaskRecord(args, plan,
                         std::chrono::duration<double>(std::chrono::steady_clock::now() - task_start).count());
}

}  // namespace

void RegisterFit(CLI::App& app) {
  CLI::App* fit = app.add_subcommand("fit", "Fit model coefficients to measured curves (Ceres).");
  fit->require_subcommand(1);

  RegisterFitCurve(*fit);

  auto session = std::make_shared<SessionArgs>();
  CLI::App* f = fit->add_subcommand(
      "session",
      "Fit a captured sample (the folder of 'phos capture all') into a material file: the LVF calibration,\n"
      "the emission spectrum (non-negative reconstruction through the filter), the decay (kr, nc by BIC),\n"
      "the excitation per light (ke per band, the delay after light-off modelled) and Lambda (Sec.\n"
      "8.4.2-8.4.6). What cannot be fitted is noted; the report shows data against fit as plots.");
  f->add_option("DIR", session->dir, "the capture folder")->required();
  f->add_option("--out", session->out, "material file to write (phos.material/1)")->required();
  f->add_option("--report", session->report, "HTML report: data against fit, residuals, uncertainties, nc and why");
  auto fixed_nc = f->add_option("--components", session->components, "fix the number of states (1-4; default: BIC)")
                      ->check(CLI::Range(1, 4));
  auto chosen_nc =
      f->add_option("--max-components", session->max_components, "choose nc by BIC up to N, 1-4 (default 3)")
          ->check(CLI::Range(1, 4));
  fixed_nc->excludes(chosen_nc);
  f->add_option("--weights", session->weights,
                "poisson (the default here: a session's values are the camera's photon counts, in DN) or none");
  f->add_option("--compare", session->compare,
                "a material to compare with (the one a simulated sample was made of): kr, spectrum and ke errors");
  f->add_flag("--sequential", session->sequential,
              "write the sequential fit of the paper (kr from the decay, then the excitation with kr held)\n"
              "instead of the joint refinement (decay and excitation fitted at once, the default when it\n"
              "converges); both are always reported");
  f->add_flag("--joint", session->joint, "write the joint refinement (the default; kept for older scripts)")
      ->excludes("--sequential");
  f->add_flag("--json", session->json, "print one JSON object");
  f->add_option("--max-iterations", session->max_iterations,
                "the solvers' iteration limit for the decay and excitation fits (default: 100 and 200)")
      ->check(CLI::Range(1, 100000));
  auto span = f->add_option("--span-s", session->span_s,
                            "write only the states a scene of this many seconds needs: the fewest whose radiance\n"
                            "stays within --tolerance of the full fit's, charged as the session's decay was, then dark")
                  ->check(kFinite)
                  ->check(kPositive);
  auto tolerance = f->add_option("--tolerance", session->tolerance,
                                 "with --span-s: the largest radiance error allowed, relative to the total (e.g. 0.02)")
                       ->check(kFinite)
                       ->check(kPositive);
  span->needs(tolerance);
  tolerance->needs(span);
  f->add_flag("--keep-unconverged", session->keep_unconverged,
              "write the material even when a fit it holds stopped at its iteration limit (it is said);\n"
              "without it such a fit writes nothing and exits 2");
  f->callback([session] { RunFitSession(*session); });

  auto map_args = std::make_shared<MapArgs>();
  CLI::App* mp = fit->add_subcommand(
      "map",
      "Fit every pixel of a decay session (a spatially varying sample): one rate shared by the pixel's\n"
      "channels, an amplitude and a background per channel, by variable projection on a shared rate grid\n"
      "and Newton steps, in parallel. Writes decay-map.exr (float: kr, amplitude.*, background.*, rms;\n"
      "with --states 2 also kr2, amplitude2.*) and kr.png (kr in grey, 1st to 99th percentile) into --out.");
  mp->add_option("SESSION", map_args->session, "a decay session folder (required unless --merge)");
  mp->add_option("--out", map_args->out, "output folder")->required();
  mp->add_option("--tile", map_args->tile,
                 "i/N: fit only the i-th (0-based) of N bands of rows (a Slurm array task), into\n"
                 "<out>/tiles/tile-i-of-N.exr, then its done record tile-i-of-N.json; a rerun with the record\n"
                 "does nothing. The pixels equal the whole map's bit for bit (docs/scale.md)");
  mp->add_flag("--merge", map_args->merge,
               "assemble <out>/tiles into decay-map.exr and kr.png, the same as one run writes; every tile\n"
               "must be done for the same session and options")
      ->excludes("--tile");
  mp->add_option("--weights", map_args->weights, "poisson (the default: pixels are photon counts) or none");
  mp->add_flag("--no-background", map_args->no_background, "no background term (dark signal already removed)");
  mp->add_option("--states", map_args->states,
                 "1 (default) or 2: exponentials per pixel. With 2, kr is the slow state's rate and kr2 the\n"
                 "fast one's, where BIC keeps both; elsewhere kr2 is NaN (docs/two-state-map.md)")
      ->check(CLI::Range(1, 2));
  mp->add_flag("--json", map_args->json, "print one JSON object (size, frames, kr percentiles, outputs)");
  mp->add_flag("--check", map_args->check,
               "check the session (a decay session with frames) and --tile against its rows, then stop:\n"
               "nothing fitted or written ('phos slurm map' checks its tasks' command so)")
      ->excludes("--merge");
  mp->callback([map_args] { RunFitMap(*map_args); });

  auto batch = std::make_shared<BatchArgs>();
  CLI::App* b = fit->add_subcommand(
      "batch",
      "Fit many captured samples, in parallel (one per core): each input is a 'capture all' folder or a\n"
      "folder of them. Writes <item>.json (material), <item>.html (report) and <item>.done.json into --out;\n"
      "a rerun keeps the items that have their .done.json and fits only the rest, so a crash mid-batch\n"
      "redoes only what was unfinished. Ends with one summary table (also summary.csv). An item that\n"
      "fails is said and kept out; the others go on (exit code 2 if any failed).");
  b->add_option("INPUT", batch->inputs, "capture folders, or folders holding them")->required();
  b->add_option("--out", batch->out, "output folder")->required();
  b->add_option("--jobs", batch->jobs, "items fitted at once, 1 to 1024 (default: the number of cores)")
      ->check(CLI::Range(1, 1024));
  auto batch_fixed_nc = b->add_option("--components", batch->components, "fix the number of states (1-4; default: BIC)")
                            ->check(CLI::Range(1, 4));
  batch_fixed_nc->excludes(
      b->add_option("--max-components", batch->max_components, "choose nc by BIC up to N, 1-4 (default 3)")
          ->check(CLI::Range(1, 4)));
  b->add_option("--weights", batch->weights, "poisson (the default: as fit session) or none");
  b->add_flag("--json", batch->json, "print one JSON object (the rows of the summary table) instead of the table");
  b->add_flag("--keep-unconverged", batch->keep_unconverged,
              "write an item's material even when a fit it holds did not converge (else the item fails)");
  b->add_option("--task", batch->task,
                "i/N: fit only the i-th (0-based) of N near-equal consecutive shares of the items (a Slurm\n"
                "array task); no summary.csv (the merge writes it); then <out>/tasks/task-i-of-N.json");
  b->add_flag("--merge", batch->merge,
              "fit nothing: write summary.csv of items all fitted already (by the array tasks); an item\n"
              "without its .done.json is an error naming it")
      ->excludes("--task");
  b->add_flag("--check", batch->check,
              "find the items and check the options, then stop: nothing fitted or written\n"
              "('phos slurm batch' checks its tasks' command so)")
      ->excludes("--merge");
  b->callback([batch] { RunFitBatch(*batch); });
  RequireFiniteNumbers(*fit);
}

}  // namespace phos::app
