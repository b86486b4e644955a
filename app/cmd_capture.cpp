// phos capture <protocol>: run a capture protocol against the simulated lab
// (--device sim --sim-material M.json) or a real one (--lab LAB.json: an
// Aravis camera and GPIO lights), writing the session folder as it goes.
// `all` runs the four protocols in order into one folder; `resume` goes on
// with an interrupted session where that makes sense.

#include <algorithm>
#include <cstdarg>
#include <cstdio>
#include <map>
#include <optional>
#include <sstream>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>
#include <CLI/CLI.hpp>

#include "cli_finite.h"
#include "commands.h"
#include "phos/acquire/lab.h"
#include "phos/acquire/protocol_records.h"
#include "phos/acquire/protocols.h"
#include "phos/acquire/session_records.h"
#include "phos/acquire/sim_lab.h"
#include "phos/model/material.h"
#include "phos/render/renderer.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/svg_plot.h"
#include "phos/util/version.h"

namespace phos::app {
namespace {

namespace fs = std::filesystem;

struct CaptureArgs {
  std::string device, lab, sim_material, sim_camera, sim_size, sim_inset, out;
  double sim_inset_radius = 0.5;
  double sim_albedo = 0.8;
  unsigned seed = 1;
  bool json = false;
};

// The devices a protocol runs on: the simulated lab or a real one, behind
// the same interfaces, with the description that goes into session.json.
struct Devices {
  // Simulated.
  VirtualClock virtual_clock;
  std::unique_ptr<SimulatedLab> sim;
  Material material;
  std::vector<double> albedo;
  // Real.
  std::unique_ptr<OpenedLab> real;
  LabConfig lab_config;
  // After `real`, so it stands down before the lights close.
  std::unique_ptr<LightsGuardian> guardian;

  Camera* camera = nullptr;
  Lights* lights = nullptr;
  Clock* clock = nullptr;
  RigChange rig;
  DevicesRecord description;
  SampleRecord sample;

  bool simulated() const { return sim != nullptr; }

  void OpenSim(Material m, std::vector<double> a, unsigned seed, const std::string& material_file,
               const std::string& camera_csv, int width, int height, const std::optional<Material>& inset,
               double inset_radius) {
    material = std::move(m);
    albedo = std::move(a);
    CameraModel camera_model = camera_csv.empty() ? DefaultCameraModel() : CameraModelFromCsv(camera_csv);
    camera_model.seed = seed;
    if (width > 0) camera_model.width = width;
    if (height > 0) camera_model.height = height;
    sim = std::make_unique<SimulatedLab>(material, albedo, DefaultLights(), camera_model, virtual_clock);
    if (inset) sim->SetInset(*inset, inset_radius);
    camera = sim.get();
    lights = &sim->lights();
    clock = &virtual_clock;
    SimulatedLab* lab = sim.get();
    rig = [lab](const std::string& what, bool in_place) {
      if (what == "lvf") lab->SetLvfInPath(in_place);
      if (what == "white_reference") lab->SetWhiteReferenceInView(in_place);
    };
    description.device = "sim";
    description.camera = sim->description();
    description.lights = sim->lights().channels();
    description.clock = "virtual";
    description.seed = seed;
    description.camera_csv = camera_csv;
    // What each light puts on the sample per band: the fit needs it for ke.
    for (const std::string& light : sim->lights().channels())
      description.light_band_irradiance[light] = sim->SourceBandIrradiance(light);
    description.bands_nm = material.bands.edges_nm;
    description.width = camera_model.width;
    description.height = camera_model.height;
    sample.material_file = material_file;
    sample.material = MaterialToJson(material);
    sample.albedo = albedo;
    if (inset) {
      sample.inset_material = MaterialToJson(*inset);
      sample.inset_radius_fraction = inset_radius;
    }
  }

  void OpenLabConfig(const fs::path& path) {
    lab_config = LoadLabConfig(path);
    real = OpenLab(lab_config);
    // Real lights stay off even if capture dies by kill -9 (LightsGuardian).
    guardian = std::make_unique<LightsGuardian>(*real->lights);
    camera = real->camera.get();
    lights = real->lights.get();
    clock = &real->clock;
    rig = real->rig;
    description = real->description;
    sample.note = "a real sample";
  }

  explicit Devices(const CaptureArgs& args) {
    std::string device = args.device.empty() ? (args.lab.empty() ? "sim" : "lab") : args.device;
    if (device == "sim") {
      if (args.sim_material.empty())
        ThrowUserError("", "--sim-material", "is required with --device sim (the simulated sample's material file)");
      if (!(args.sim_albedo >= 0 && args.sim_albedo <= 1))
        ThrowUserError("", "--sim-albedo", "expected a reflectance in [0, 1], got " + FormatDouble(args.sim_albedo));
      Material m = LoadMaterial(args.sim_material);
      std::vector<double> a =
          m.albedo ? *m.albedo : std::vector<double>(static_cast<std::size_t>(m.band_count()), args.sim_albedo);
      int width = 0, height = 0;
      if (!args.sim_size.empty()) {
        char x = 0;
        std::istringstream in(args.sim_size);
        if (!(in >> width >> x >> height) || x != 'x' || width < 8 || height < 8 || width > 8192 || height > 8192 ||
            !in.eof())
          ThrowUserError("", "--sim-size", "expected WxH with 8 to 8192 pixels a side, got '" + args.sim_size + "'");
      }
      std::optional<Material> inset;
      if (!args.sim_inset.empty()) inset = LoadMaterial(args.sim_inset);
      OpenSim(std::move(m), std::move(a), args.seed, args.sim_material, args.sim_camera, width, height, inset,
              args.sim_inset_radius);
    } else if (device == "lab") {
      if (args.lab.empty()) ThrowUserError("", "--device lab", "needs --lab LAB.json (the lab config; docs/lab.md)");
      OpenLabConfig(args.lab);
    } else {
      ThrowUserError("", "--device",
                     "expected 'sim' (the simulated lab) or 'lab' (real devices from --lab), got '" + device + "'");
    }
  }

  // Reopens the devices a session was recorded with (for resume).
  Devices(const SessionRecord& start, const fs::path& session_dir, int resume_count) {
    const std::string where = (session_dir / "session.json").string();
    const DevicesRecord devices = DevicesRecord::FromJson(start.devices, where + ": devices");
    if (!devices.simulated()) {
      OpenLabConfig(devices.lab_config);
      return;
    }
    const SampleRecord recorded = SampleRecord::FromJson(start.sample, where + ": sample");
    if (!recorded.material) ThrowUserError(where, "sample", "has no material: cannot rebuild the simulated lab");
    Material m = MaterialFromJson(*recorded.material, where);
    std::optional<Material> inset;
    if (recorded.inset_material) inset = MaterialFromJson(*recorded.inset_material, where);
    // New noise on each resume: a resumed camera is not the same exposure again.
    OpenSim(std::move(m), recorded.albedo, devices.seed + 1000u * resume_count, recorded.material_file,
            devices.camera_csv, devices.width, devices.height, inset, recorded.inset_radius_fraction);
  }
};

SessionRecord StartRecord(const std::string& protocol, const Devices& devices, nlohmann::json settings) {
  SessionRecord record;
  record.protocol = protocol;
  record.sample = devices.sample.ToJson();
  record.devices = devices.description.ToJson();
  record.settings = std::move(settings);
  record.phos_version = kVersion;
  return record;
}

// The calibration sources of this lab: the config's, or the simulated lab's.
std::vector<CalibrationLine> CalibrationLinesOf(const Devices& devices) {
  if (!devices.simulated()) return devices.lab_config.calibration_lines;
  std::vector<CalibrationLine> lines;
  for (const KnownLine& line : DefaultCalibrationLines()) lines.push_back({line.light, line.wavelength_nm});
  return lines;
}

// ---- previews: what a session captured, to look at ----------------------

// A decay's or a spectrum's frames, each with its delay after light-off.
std::vector<std::pair<FrameRecord, double>> FramesWithDelays(const fs::path& dir) {
  std::vector<std::pair<FrameRecord, double>> frames;
  if (ReadSessionRecord(dir).protocol == SpectrumFrameFields::kProtocol) {
    for (const auto& frame : ReadProtocolFrames<SpectrumFrameFields>(dir))
      frames.push_back({frame.record, frame.fields.delay_after_light_off_s});
  } else {
    for (const auto& frame : ReadProtocolFrames<DecayFrameFields>(dir))
      frames.push_back({frame.record, frame.fields.delay_after_light_off_s});
  }
  return frames;
}

// A contact sheet of a decay's or a spectrum's frames, each scaled by its
// exposure so the fading shows (one brightness scale for all), labelled with
// the delay.
void WriteFramesContactSheet(const fs::path& session_dir, const fs::path& out, int max_frames) {
  const std::vector<std::pair<FrameRecord, double>> listed = FramesWithDelays(session_dir);
  if (listed.empty()) return;
  const std::size_t step = std::max<std::size_t>(1, (listed.size() + max_frames - 1) / max_frames);
  std::vector<Frame> frames;
  std::vector<std::string> labels;
  double brightest = 0;
  for (std::size_t i = 0; i < listed.size(); i += step) {
    frames.push_back(ReadFrame(session_dir, listed[i].first));
    const Frame& f = frames.back();
    for (int c = 0; c < f.channels; ++c) brightest = std::max(brightest, f.MeanSignal(c) / f.exposure_s);
    labels.push_back("t+" + FormatShort(listed[i].second) + " s, " + FormatShort(f.exposure_s) + " s exp");
  }
  std::vector<render::Image> images;
  for (const Frame& f : frames) {
    // Upscale small sensors so the sheet is legible: nearest neighbour, 4x.
    const int scale = f.width < 200 ? 4 : 1;
    render::Image image(f.width * scale, f.height * scale, 3);
    for (int y = 0; y < image.height; ++y)
      for (int x = 0; x < image.width; ++x) {
        const std::size_t p = (static_cast<std::size_t>(y / scale) * f.width + x / scale) * f.channels;
        for (int c = 0; c < 3; ++c) {
          const int source_channel = f.channels == 3 ? c : 0;
          const double signal = (f.pixels[p + source_channel] - f.black_level_dn) / f.exposure_s;
          // Linear in signal per second, the brightest frame's mean at 0.8.
          image.at(x, y)[c] = static_cast<float>(std::clamp(0.8 * signal / std::max(brightest, 1e-12), 0.0, 1.0));
        }
      }
    images.push_back(std::move(image));
  }
  render::WriteContactSheet(out, images, labels, 6);
}

// The measured curves as a plot: signal per second of exposure (decay: over
// time after light-off; excitation: over charge time, one series per light).
// One point of a curves plot: a frame's mean signal per channel, its
// exposure, its x (delay after light-off, or charge time) and its light.
struct CurvePoint {
  std::string light;
  double x = 0, exposure_s = 1;
  std::vector<double> means;
};

std::vector<CurvePoint> CurvePoints(const fs::path& session_dir, const std::string& protocol) {
  std::vector<CurvePoint> points;
  if (protocol == ExcitationFrameFields::kProtocol) {
    for (const auto& [frame, line, fields] : ReadProtocolFrames<ExcitationFrameFields>(session_dir))
      points.push_back({fields.light, fields.charge_s, frame.exposure_s, fields.signal.mean_signal_dn});
  } else {
    for (const auto& [frame, line, fields] : ReadProtocolFrames<DecayFrameFields>(session_dir))
      points.push_back({"", fields.delay_after_light_off_s, frame.exposure_s, fields.signal.mean_signal_dn});
  }
  return points;
}

void WriteCurvesPlot(const fs::path& session_dir, const std::string& protocol, const fs::path& out) {
  std::map<std::string, PlotSeries> series;
  std::map<std::string, std::size_t> light_order;
  for (const CurvePoint& point : CurvePoints(session_dir, protocol)) {
    const std::vector<double>& means = point.means;
    const double exposure = point.exposure_s;
    const std::vector<std::string> names =
        means.size() == 3 ? std::vector<std::string>{"R", "G", "B"} : std::vector<std::string>{"Y"};
    for (std::size_t c = 0; c < means.size() && c < names.size(); ++c) {
      const std::string key = protocol == "excitation" ? point.light + " " + names[c] : names[c];
      PlotSeries& s = series.try_emplace(key, PlotSeries(key)).first->second;
      s.markers = true;
      s.x.push_back(point.x);
      s.y.push_back(means[c] / exposure);
      // Channels are red, green and blue in every plot; in the excitation
      // plot each light has its own line style (solid, dashed, dots).
      s.color = ChannelOrPaletteColor(names[c], static_cast<int>(c));
      if (protocol == "excitation") {
        const int light_index =
            static_cast<int>(light_order.try_emplace(point.light, light_order.size()).first->second);
        s.dashed = light_index % 3 == 1;
        s.line = light_index % 3 != 2;
      }
    }
  }
  std::vector<PlotSeries> all;
  for (auto& [key, s] : series) {
    if (protocol == "excitation") {  // sort by charge time; the midpoints came last
      std::vector<std::size_t> order(s.x.size());
      for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
      std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return s.x[a] < s.x[b]; });
      PlotSeries sorted = s;
      for (std::size_t i = 0; i < order.size(); ++i) sorted.x[i] = s.x[order[i]], sorted.y[i] = s.y[order[i]];
      all.push_back(sorted);
    } else {
      all.push_back(s);
    }
  }
  if (all.empty()) return;
  PlotOptions options;
  options.title = protocol == "excitation" ? "Excitation: response after charging for t (per light, per channel)"
                                           : "Decay after saturation, as captured";
  options.x_label = protocol == "excitation" ? "charge time t (s)" : "time after light-off (s)";
  options.y_label = "mean signal / exposure (DN/s)";
  options.log_y = protocol != "excitation";
  options.log_x = protocol == "excitation";
  WriteFileAtomically(out, PlotSvg(all, options));
}

// ---- what the user sees ----------------------------------------------------

// With --json the progress lines are left out and the command ends with one
// JSON object (JsonSummary). File-local: each phos-capture run is one command.
bool g_json_output = false;

void Say(const char* format, ...) __attribute__((format(printf, 1, 2)));
void Say(const char* format, ...) {
  if (g_json_output) return;
  va_list args;
  va_start(args, format);
  std::vfprintf(stdout, format, args);
  va_end(args);
}

// The folder and, for `all`, each part: protocol, frames listed, how it ended.
void PrintJsonSummary(const fs::path& dir) {
  auto part = [](const fs::path& path) {
    const SessionCheck check = CheckSession(path, false);
    return nlohmann::json{{"dir", path.string()},
                          {"protocol", check.protocol},
                          {"frames", check.frames},
                          {"state", check.stop ? check.stop->how : "interrupted"},
                          {"problems", check.problems}};
  };
  nlohmann::json summary = part(dir);
  if (summary["protocol"] == "all") {
    summary["parts"] = nlohmann::json::array();
    for (const std::string& name : kAllOrder)
      if (fs::exists(dir / name / "session.json")) summary["parts"].push_back(part(dir / name));
  }
  std::printf("%s\n", summary.dump().c_str());
}

// ---- running protocols into a session -----------------------------------

// Protocol settings (from options) and the code that runs them on devices,
// for one session folder, new or reopened.
struct Plan {
  std::string protocol;
  nlohmann::json settings;
};

void RunProtocol(const Plan& plan, Devices& devices, SessionWriter& session, bool resuming) {
  Camera& camera = *devices.camera;
  Lights& lights = *devices.lights;
  Clock& clock = *devices.clock;
  const std::string where = (session.dir() / "session.json").string() + ": settings";
  if (plan.protocol == DecayFrameFields::kProtocol) {
    RunDecayProtocol(camera, lights, clock, session, DecayProtocolOptions::FromJson(plan.settings, where));
  } else if (plan.protocol == ExcitationFrameFields::kProtocol) {
    RunExcitationProtocol(camera, lights, clock, session, ExcitationProtocolOptions::FromJson(plan.settings, where),
                          resuming ? ReadExcitationDone(session.dir()) : ExcitationDone{});
  } else if (plan.protocol == SpectrumFrameFields::kProtocol) {
    RunSpectrumProtocol(camera, lights, clock, session, devices.rig,
                        SpectrumProtocolOptions::FromJson(plan.settings, where));
  } else if (plan.protocol == LvfCalibrationFrameFields::kProtocol) {
    RunLvfCalibrationProtocol(camera, lights, clock, session, devices.rig,
                              LvfCalibrationOptions::FromJson(plan.settings, where),
                              resuming ? ReadLvfCalibrationDone(session.dir()) : std::vector<std::string>{});
  } else {
    ThrowUserError("", "protocol", "unknown protocol '" + plan.protocol + "'");
  }
}

bool Resumable(const std::string& protocol) { return protocol == "excitation" || protocol == "lvf-calibration"; }

// What the user sees at the end of a session: where it is and what it holds.
// A decay whose frames hold no glow: a charge light the sample does not take
// up (led365 on a paint charged in the blue), or no sample. The capture is
// complete, and its fit would fit the noise; one warning line on stderr says
// so. "No glow": no frame's brightest channel above 1% of the ADC's range,
// where the exposure control keeps a glowing sample's frames at 15-70%.
void WarnIfNoGlow(const std::string& protocol, const fs::path& dir) {
  if (protocol != "decay") return;
  double best_fraction = -1, brightest = 0, range = 0;  // of the range; the frame's mean and range, DN
  for (const auto& [frame, line, fields] : ReadProtocolFrames<DecayFrameFields>(dir)) {
    const double frame_range = std::ldexp(1.0, frame.adc_bits) - 1 - frame.black_level_dn;
    for (double mean : fields.signal.mean_signal_dn)
      if (mean / frame_range > best_fraction) {
        best_fraction = mean / frame_range;
        brightest = mean;
        range = frame_range;
      }
  }
  if (best_fraction < 0 || best_fraction >= 0.01) return;
  const SessionRecord start = ReadSessionRecord(dir);
  const DecayProtocolOptions settings =
      DecayProtocolOptions::FromJson(start.settings, (dir / "session.json").string() + ": settings");
  std::fprintf(stderr,
               "phos capture: warning: %s: no decay frame rose above 1%% of the camera's range (the brightest: %s "
               "of %s DN): the sample hardly glows; does '%s' charge it?\n",
               dir.string().c_str(), FormatShort(brightest, 3).c_str(), FormatShort(range, 5).c_str(),
               settings.charge_light.c_str());
}

// A decay over a span whose glow went below the well-exposed range at the
// longest exposure (the camera's floor for this protocol): its last frames
// are kept, fainter than the rest, and one warning line on stderr says from
// which delay, so a longer --max-exposure-s can lift them next time.
void WarnIfBelowTheRange(const std::string& protocol, const fs::path& dir) {
  if (protocol != "decay") return;
  const DecayProtocolOptions settings =
      DecayProtocolOptions::FromJson(ReadSessionRecord(dir).settings, (dir / "session.json").string() + ": settings");
  if (!(settings.span_s > 0)) return;
  int below = 0;
  double from_s = 0;
  for (const auto& [frame, line, fields] : ReadProtocolFrames<DecayFrameFields>(dir)) {
    const double range = std::ldexp(1.0, frame.adc_bits) - 1 - frame.black_level_dn;
    double brightest = 0;
    for (double mean : fields.signal.mean_signal_dn) brightest = std::max(brightest, mean / range);
    if (frame.exposure_s < settings.max_exposure_s * (1 - 1e-9) || brightest >= settings.low_fraction) continue;
    if (below++ == 0) from_s = fields.delay_after_light_off_s;
  }
  if (below == 0) return;
  std::fprintf(stderr,
               "phos capture: warning: %s: from %s s after light-off the glow stayed under %s%% of the camera's "
               "range at the longest exposure (%s s): %d frames below the well-exposed range\n",
               dir.string().c_str(), FormatShort(from_s, 4).c_str(),
               FormatShort(100 * settings.low_fraction, 3).c_str(), FormatShort(settings.max_exposure_s, 3).c_str(),
               below);
}

void PrintSession(const std::string& protocol, const fs::path& dir) {
  Say("phos capture %s: %zu frames -> %s\n", protocol.c_str(), ReadFrameRecords(dir).frames.size(),
      dir.string().c_str());
  WarnIfNoGlow(protocol, dir);
  WarnIfBelowTheRange(protocol, dir);
}

void Previews(const std::string& protocol, const fs::path& session_dir, const fs::path& into) {
  if (protocol == "decay") {
    WriteFramesContactSheet(session_dir, into / "decay-frames.png", 12);
    WriteCurvesPlot(session_dir, "decay", into / "decay-curve.svg");
  } else if (protocol == "excitation") {
    WriteCurvesPlot(session_dir, "excitation", into / "excitation-curves.svg");
  }
}

// The light channels a protocol's settings name, each with the option that named it.
std::vector<std::pair<std::string, std::string>> LightsNamed(const Plan& plan) {
  std::vector<std::pair<std::string, std::string>> named;  // option, channel
  const std::string where = "settings";
  if (plan.protocol == DecayFrameFields::kProtocol)
    named.push_back({"--light", DecayProtocolOptions::FromJson(plan.settings, where).charge_light});
  if (plan.protocol == SpectrumFrameFields::kProtocol)
    named.push_back({"--light", SpectrumProtocolOptions::FromJson(plan.settings, where).charge_light});
  if (plan.protocol == ExcitationFrameFields::kProtocol)
    for (const std::string& light : ExcitationProtocolOptions::FromJson(plan.settings, where).lights)
      named.push_back({"--excite", light});
  if (plan.protocol == LvfCalibrationFrameFields::kProtocol) {
    const LvfCalibrationOptions o = LvfCalibrationOptions::FromJson(plan.settings, where);
    for (const CalibrationLine& line : o.lines) named.push_back({"calibration_lines", line.light});
    named.push_back({"flat_light", o.flat_light});
  }
  return named;
}

// Every channel a plan names exists on the devices: checked before the
// session folder is created, so a typo leaves nothing behind to block the rerun.
void CheckLightsExist(const Plan& plan, const Devices& devices) {
  const std::vector<std::string> channels = devices.lights->channels();
  for (const auto& [option, channel] : LightsNamed(plan))
    if (std::find(channels.begin(), channels.end(), channel) == channels.end())
      ThrowUserError("", option, "unknown channel '" + channel + "' (this lab has: " + JoinComma(channels) + ")");
}

void RunNewSession(const Plan& plan, CaptureArgs& args) {
  g_json_output = args.json;
  Devices devices(args);
  // Bad settings are refused before the folder exists.
  CheckLightsExist(plan, devices);
  SessionWriter session(args.out, StartRecord(plan.protocol, devices, plan.settings).ToJson());
  RunProtocol(plan, devices, session, false);
  PrintSession(plan.protocol, args.out);
  Previews(plan.protocol, args.out, args.out);
  if (g_json_output) PrintJsonSummary(args.out);
}

// ---- all -----------------------------------------------------------------

struct AllArgs : CaptureArgs {
  std::string light;  // charge light (default: the lab's)
  std::vector<std::string> excite;
  double charge_s = 5400, duration_s = 180, interval_s = 5, reset_s = 900;
  double decay_span_s = 0;  // 0: the decay's schedule of --interval-s and --duration-s
  int tail_frames = ExcitationProtocolOptions{}.tail_frames;
};

void PrintNotes(const std::string& protocol, const std::vector<std::string>& notes) {
  for (const std::string& note : notes) Say("  %-16s %s\n", protocol.c_str(), note.c_str());
}

// Moves an interrupted (or bad) part aside whole, to start it over.
void MovePartAside(const fs::path& dir, const std::string& protocol, const std::string& why) {
  const fs::path part = dir / protocol;
  std::error_code ec;
  fs::path aside;
  for (int n = 1; fs::exists(aside = dir / (protocol + ".interrupted-" + std::to_string(n)), ec); ++n) {}
  fs::rename(part, aside, ec);
  if (ec) ThrowUserError(part.string(), "", "cannot move the part aside: " + ec.message());
  Say("  %-16s %s; kept as %s, starting over\n", protocol.c_str(), why.c_str(), aside.filename().string().c_str());
}

// The first problem of a check that resume cannot repair (a malformed record
// in the middle of a file, a stop.json that does not parse): "" if none.
// Torn last lines, stale temporaries and bad frames it can.
std::string UnrepairableProblem(const SessionCheck& check) {
  return check.unrepairable.empty() ? "" : check.unrepairable.front();
}

// Runs (or, resuming, finishes) every part of an `all` folder in order. A
// part that says it is complete is checked first: kept only if its records
// and frames are whole.
void RunAllParts(const fs::path& dir, const AllSettings& parts, Devices& devices, int resume_count) {
  for (const std::string& protocol : kAllOrder) {
    const fs::path part = dir / protocol;
    const Plan plan{protocol, parts.PartToJson(protocol)};
    std::error_code ec;
    if (fs::exists(part / "session.json", ec)) {
      const SessionCheck check = CheckSession(part);
      if (const std::string problem = UnrepairableProblem(check); !problem.empty())
        ThrowUserError(problem, "", "cannot be repaired by resume; see 'phos capture verify'");
      if (check.complete() && check.clean()) {
        Say("  %-16s complete already: kept\n", protocol.c_str());
        continue;
      }
      if (protocol == "decay" && !check.bad_frames.empty()) {
        const SessionCheck::BadFrame& bad = check.bad_frames.front();
        ThrowUserError(
            (part / bad.frame.file).string(), "",
            bad.problem +
                ": a decay frame cannot be measured again (the glow it saw is gone); "
                "the folder stays incomplete: restore the frame, or move the decay part aside to capture it anew");
      }
      if (Resumable(protocol)) {
        Say("  %-16s %s: resuming where it stopped\n", protocol.c_str(),
            check.complete() ? "complete but not whole" : "interrupted");
        std::vector<std::string> notes;
        std::unique_ptr<SessionWriter> session = SessionWriter::Reopen(part, true, &notes);
        PrintNotes(protocol, notes);
        RunProtocol(plan, devices, *session, true);
        continue;
      }
      // A decay or spectrum cannot go on: the glow kept fading unobserved.
      // Its frames are kept aside and the part starts over.
      MovePartAside(dir, protocol,
                    check.complete() ? "complete but not whole (" + check.problems.front() + ")"
                                     : "interrupted: a " + protocol + " cannot continue (the glow faded unobserved)");
    }
    SessionRecord start = StartRecord(protocol, devices, plan.settings);
    start.part_of = dir.filename().string();
    start.resume = resume_count;
    SessionWriter session(part, start.ToJson());
    RunProtocol(plan, devices, session, false);
    Say("  %-16s %d frames\n", protocol.c_str(), static_cast<int>(ReadFrameRecords(part).frames.size()));
    WarnIfNoGlow(protocol, part);
    WarnIfBelowTheRange(protocol, part);
  }
}

void FinishAll(const fs::path& dir) {
  Previews("decay", dir / "decay", dir);
  Previews("excitation", dir / "excitation", dir);
  WriteFramesContactSheet(dir / "spectrum", dir / "spectrum-frames.png", 6);
}

void RunCaptureAll(AllArgs args) {
  g_json_output = args.json;
  Devices devices(args);
  const std::string charge_light = !args.light.empty()   ? args.light
                                   : devices.simulated() ? "led405"
                                                         : devices.lab_config.charge_light;
  std::vector<std::string> excite = args.excite;
  if (excite.empty())
    excite = devices.simulated() ? std::vector<std::string>{"led420", "led456", "led494"}
                                 : std::vector<std::string>{charge_light};
  LvfCalibrationOptions calibration;
  calibration.lines = CalibrationLinesOf(devices);
  if (!devices.simulated()) {
    calibration.flat_light = devices.lab_config.flat_light;
    calibration.flat_temperature_k = devices.lab_config.flat_temperature_k;
    calibration.flat_irradiance = devices.lab_config.flat_irradiance;
  }
  SpectrumProtocolOptions spectrum;
  spectrum.charge_light = charge_light;
  DecayProtocolOptions decay;
  decay.charge_light = charge_light;
  decay.charge_s = args.charge_s;
  decay.duration_s = args.duration_s;
  decay.interval_s = args.interval_s;
  decay.span_s = args.decay_span_s;
  ExcitationProtocolOptions excitation;
  excitation.lights = excite;
  excitation.reset_s = args.reset_s;
  excitation.tail_frames = args.tail_frames;
  excitation.exposure_s = 0.2;
  // Check every part's settings before anything is created.
  std::string error;
  if (!calibration.IsValid(&error))
    ThrowUserError("", "lvf-calibration", error + " (calibration_lines in the lab config)");
  if (!spectrum.IsValid(&error)) ThrowUserError("", "spectrum", error);
  if (!decay.IsValid(&error)) ThrowUserError("", "decay", error);
  if (!excitation.IsValid(&error)) ThrowUserError("", "excitation", error);
  const AllSettings parts{calibration, spectrum, decay, excitation};
  for (const std::string& protocol : kAllOrder) CheckLightsExist({protocol, parts.PartToJson(protocol)}, devices);

  // The folder's own record: the plan of all parts, and how it ended.
  SessionWriter top(args.out, StartRecord("all", devices, parts.ToJson()).ToJson());
  Say("phos capture all -> %s\n", args.out.c_str());
  try {
    RunAllParts(args.out, parts, devices, 0);
  } catch (const std::exception& e) {
    top.StopQuietly("failed", e.what());  // the error to report is the first one
    throw;
  }
  top.Stop("complete");
  FinishAll(args.out);
  Say("  previews: decay-frames.png, decay-curve.svg, excitation-curves.svg, spectrum-frames.png\n");
  if (g_json_output) PrintJsonSummary(args.out);
}

// ---- resume ----------------------------------------------------------------

void RunCaptureResume(const std::string& dir_text, bool json) {
  g_json_output = json;
  const fs::path dir = dir_text;
  const SessionRecord start = ReadSessionRecord(dir);
  const std::string& protocol = start.protocol;
  if (protocol == "all") {
    std::optional<StopRecord> stop = ReadStopRecord(dir);
    bool parts_whole = true;
    for (const std::string& part : kAllOrder) {
      const SessionCheck check = CheckSession(dir / part);
      parts_whole = parts_whole && check.complete() && check.clean();
    }
    if (stop && stop->how == "complete" && parts_whole) {
      Say("phos capture resume: %s completed already, and every part is whole; nothing to do\n", dir.string().c_str());
      if (g_json_output) PrintJsonSummary(dir);
      return;
    }
    std::vector<std::string> notes;
    std::unique_ptr<SessionWriter> top = SessionWriter::Reopen(dir, true, &notes);
    const int resumes = CountResumes(dir);
    Devices devices(start, dir, resumes);
    Say("phos capture resume: %s (all)\n", dir.string().c_str());
    PrintNotes("all", notes);
    try {
      RunAllParts(dir, AllSettings::FromJson(start.settings, (dir / "session.json").string() + ": settings"), devices,
                  resumes);
    } catch (const std::exception& e) {
      top->StopQuietly("failed", e.what());
      throw;
    }
    top->Stop("complete");
    FinishAll(dir);
    if (g_json_output) PrintJsonSummary(dir);
    return;
  }
  const SessionCheck check = CheckSession(dir);
  if (check.complete() && check.clean()) {
    Say("phos capture resume: %s completed already; nothing to do\n", dir.string().c_str());
    if (g_json_output) PrintJsonSummary(dir);
    return;
  }
  if (const std::string problem = UnrepairableProblem(check); !problem.empty())
    ThrowUserError(problem, "", "cannot be repaired by resume; see 'phos capture verify'");
  if (!Resumable(protocol)) {
    if (!check.bad_frames.empty()) {
      const SessionCheck::BadFrame& bad = check.bad_frames.front();
      ThrowUserError((dir / bad.frame.file).string(), "",
                     bad.problem + ": a " + protocol +
                         " frame cannot be measured again (the glow it saw is gone); "
                         "the session stays incomplete: capture it anew into a new folder");
    }
    // Stopped before its first frame (a light the sample cannot take, a
    // camera that never delivered): no glow was watched fading; say why it stopped.
    if (check.frames == 0)
      ThrowUserError(dir.string(), "resume",
                     "a " + protocol + " cannot be continued, and this one stopped before its first frame" +
                         (check.stop && !check.stop->why.empty() ? " (" + check.stop->why + ")" : std::string()) +
                         ": run 'phos capture " + protocol + "' again into a new folder");
    ThrowUserError(dir.string(), "resume",
                   "a " + protocol +
                       " cannot be continued: the glow kept fading while nothing watched; its frames are "
                       "kept here, run 'phos capture " +
                       protocol + "' again into a new folder");
  }
  std::vector<std::string> notes;
  std::unique_ptr<SessionWriter> session = SessionWriter::Reopen(dir, true, &notes);
  for (const std::string& note : notes) Say("phos capture resume: %s\n", note.c_str());
  Devices devices(start, dir, session->run());  // new noise on every resume, not the first one's again
  RunProtocol({protocol, start.settings}, devices, *session, true);
  PrintSession(protocol, dir);
  Previews(protocol, dir, dir);
  if (g_json_output) PrintJsonSummary(dir);
}

// ---- verify ----------------------------------------------------------------

struct VerifyArgs {
  std::string dir;
  bool json = false;
};

// Checks a session (and every part of an `all` folder): one line per
// problem; returns how many.
std::size_t RunCaptureVerify(const VerifyArgs& args) {
  const fs::path dir = args.dir;
  const SessionRecord start = ReadSessionRecord(dir);
  std::vector<std::pair<fs::path, SessionCheck>> checks;
  checks.push_back({dir, CheckSession(dir)});
  if (start.protocol == "all")
    for (const std::string& part : kAllOrder) {
      std::error_code ec;
      if (fs::exists(dir / part / "session.json", ec))
        checks.push_back({dir / part, CheckSession(dir / part)});
      else if (checks.front().second.complete())
        checks.front().second.problems.push_back((dir / part).string() +
                                                 ": missing, in a folder whose stop.json says complete");
    }
  std::size_t problems = 0;
  nlohmann::json report = nlohmann::json::array();
  for (const auto& [path, check] : checks) {
    problems += check.problems.size();
    const std::string state = check.complete() ? "complete"
                              : check.stop     ? check.stop->how
                                               : "interrupted (no stop.json)";
    if (args.json) {
      report.push_back({{"session", path.string()},
                        {"protocol", check.protocol},
                        {"frames", check.frames},
                        {"state", state},
                        {"problems", check.problems},
                        {"bad_frames",
                         [&] {
                           nlohmann::json bad = nlohmann::json::array();
                           for (const SessionCheck::BadFrame& b : check.bad_frames)
                             bad.push_back({{"file", b.frame.file}, {"problem", b.problem}});
                           return bad;
                         }()},
                        {"stale_temporaries", check.stale_temporaries.size()}});
      continue;
    }
    for (const std::string& problem : check.problems) std::printf("%s\n", problem.c_str());
    if (check.problems.empty())
      std::printf(
          "ok: %s (%s, %d frames, %s%s)\n", path.string().c_str(), check.protocol.c_str(), check.frames, state.c_str(),
          check.stale_temporaries.empty()
              ? ""
              : (", " + std::to_string(check.stale_temporaries.size()) + " stale temporaries that resume removes")
                    .c_str());
  }
  if (args.json) std::printf("%s\n", nlohmann::json{{"clean", problems == 0}, {"sessions", report}}.dump(2).c_str());
  return problems;
}

// ---- options ---------------------------------------------------------------

void AddDeviceOptions(CLI::App* cmd, CaptureArgs& args) {
  cmd->add_option("--device", args.device, "sim (the simulated lab; the default) or lab (real devices from --lab)");
  cmd->add_option("--lab", args.lab, "lab config (phos.lab/1: camera, GPIO light channels; docs/lab.md)");
  cmd->add_option("--sim-material", args.sim_material, "material file of the simulated sample (--device sim)");
  cmd->add_option("--sim-albedo", args.sim_albedo, "sample reflectance when the material has none (default 0.8)");
  cmd->add_option("--sim-camera", args.sim_camera,
                  "CSV of the simulated camera's spectral sensitivities: wavelength_nm, then one column per\n"
                  "channel (R,G,B or Y); default: Gaussians at 600, 540, 460 nm, 90 nm wide (docs/capture.md)");
  cmd->add_option("--sim-size", args.sim_size, "simulated sensor size, WxH (default 64x48)");
  cmd->add_option("--sim-inset", args.sim_inset,
                  "a second material filling a centred disk of the sample (a spatially varying sample)");
  cmd->add_option("--sim-inset-radius", args.sim_inset_radius,
                  "the disk's radius, a fraction of the half-height (default 0.5)");
  cmd->add_option("--out", args.out, "session folder to create (new or empty)")->required();
  cmd->add_option("--seed", args.seed, "noise seed of the simulated camera (default 1)");
  cmd->add_flag("--json", args.json,
                "print one JSON object at the end (the session, its parts, frames, how each ended)\n"
                "instead of the progress lines");
}

constexpr const char* kDecaySpanHelp =
    "decay: seconds of decay to record over hours (e.g. 3600, 36000): frames log-spaced in delay, 10 per\n"
    "decade from 0.1 s, each exposed for the glow predicted at its slot; replaces --interval-s,\n"
    "--duration-s and --early-frames";

struct DecayArgs : CaptureArgs {
  std::string light;
  DecayProtocolOptions decay;
};

struct ExcitationArgs : CaptureArgs {
  ExcitationProtocolOptions excitation;
};

struct SpectrumArgs : CaptureArgs {
  std::string light;
  SpectrumProtocolOptions spectrum;
};

// phos capture decay.
void RegisterCaptureDecay(CLI::App* capture) {
  auto decay_args = std::make_shared<DecayArgs>();
  CLI::App* decay = capture->add_subcommand(
      "decay",
      "Decay after saturation (Sec. 8.4.4): charge with one light, switch it off, then take frames on a\n"
      "schedule starting a few ms after light-off, the exposure growing as the glow fades. Also writes\n"
      "decay-frames.png (contact sheet) and decay-curve.svg into --out.");
  AddDeviceOptions(decay, *decay_args);
  decay->add_option("--light", decay_args->light,
                    "light channel to charge with (default led405, or the lab's charge_light). It must only reach\n"
                    "bands whose ke the material knows");
  decay->add_option("--charge-s", decay_args->decay.charge_s, "seconds of charging (default 5400, 90 min)")
      ->check(kNonNegative);
  decay->add_option("--interval-s", decay_args->decay.interval_s, "seconds between frames (default 5)")
      ->check(kPositive);
  decay->add_option("--duration-s", decay_args->decay.duration_s, "seconds of decay to record (default 180)")
      ->check(kPositive);
  decay
      ->add_option("--first-delay-s", decay_args->decay.first_delay_s,
                   "light-off to the first exposure (default 0.005)")
      ->check(kNonNegative);
  decay->add_option("--early-frames", decay_args->decay.early_frames,
                    "frames between the first two slots, at delays halving from --interval-s / 2, so a state\n"
                    "that decays in under a second is seen by several frames (default 6; 0: none)");
  decay->add_option("--decay-span-s", decay_args->decay.span_s, kDecaySpanHelp)->check(kPositive);
  decay->add_option("--initial-exposure-s", decay_args->decay.initial_exposure_s, "first exposure (default 0.05)")
      ->check(kPositive);
  decay->add_option("--max-exposure-s", decay_args->decay.max_exposure_s, "longest exposure (default 4)")
      ->check(kPositive);
  decay->callback([decay_args] {
    DecayArgs args = *decay_args;
    args.decay.charge_light = args.light.empty() ? "led405" : args.light;
    if (args.light.empty() && !args.lab.empty()) args.decay.charge_light = LoadLabConfig(args.lab).charge_light;
    std::string error;
    if (!args.decay.IsValid(&error)) ThrowUserError("", "decay protocol", error);
    RunNewSession({DecayFrameFields::kProtocol, args.decay.ToJson()}, args);
  });
}

// phos capture excitation.
void RegisterCaptureExcitation(CLI::App* capture) {
  auto excitation_args = std::make_shared<ExcitationArgs>();
  CLI::App* excitation = capture->add_subcommand(
      "excitation",
      "Excitation per light (Sec. 8.4.6): for each light, reset in darkness, charge for t, switch off,\n"
      "wait a fixed short delay and expose; t doubles from --first-charge-s until a doubling adds less\n"
      "than 3%, then the midpoints of the rising part are measured too. Resumable.");
  AddDeviceOptions(excitation, *excitation_args);
  // --excite, as in `capture all`; --light, its first name, still works.
  excitation->add_option("--excite,--light", excitation_args->excitation.lights,
                         "light channel(s) to measure, one after the other (default led405; --light is the old name)");
  excitation->add_option("--reset-s", excitation_args->excitation.reset_s, "darkness before each charge (default 900)")
      ->check(kNonNegative);
  excitation
      ->add_option("--first-charge-s", excitation_args->excitation.first_charge_s, "first charge time (default 1)")
      ->check(kPositive);
  excitation->add_option("--max-charge-s", excitation_args->excitation.max_charge_s, "longest charge (default 4096)")
      ->check(kPositive);
  excitation->add_option("--delay-s", excitation_args->excitation.delay_s, "light-off to the exposure (default 0.05)")
      ->check(kNonNegative);
  excitation->add_option("--exposure-s", excitation_args->excitation.exposure_s, "exposure (default 1)")
      ->check(kPositive);
  excitation->add_option("--tail-frames", excitation_args->excitation.tail_frames,
                         "frames of decay tail after each charge's first frame, each --tail-growth times longer;\n"
                         "they split the response into the excited states (default 6; 0: one frame per charge)");
  excitation->add_option("--tail-growth", excitation_args->excitation.tail_growth,
                         "exposure ratio between successive tail frames (default 2)");
  excitation->callback([excitation_args] {
    ExcitationArgs args = *excitation_args;
    if (args.excitation.lights.empty()) args.excitation.lights = {"led405"};
    std::string error;
    if (!args.excitation.IsValid(&error)) ThrowUserError("", "excitation protocol", error);
    RunNewSession({ExcitationFrameFields::kProtocol, args.excitation.ToJson()}, args);
  });
}

// phos capture spectrum.
void RegisterCaptureSpectrum(CLI::App* capture) {
  auto spectrum_args = std::make_shared<SpectrumArgs>();
  CLI::App* spectrum = capture->add_subcommand(
      "spectrum",
      "Emission spectrum through the linear variable filter (Sec. 8.4.2): the filter goes in; then, per\n"
      "frame, the sample charges under a strong light, the light goes off and the camera exposes 5 ms\n"
      "later, the exposure stepping between cycles until --frames are well exposed. The LVF calibration\n"
      "turns columns into wavelengths.");
  AddDeviceOptions(spectrum, *spectrum_args);
  spectrum->add_option("--light", spectrum_args->light, "light channel to charge with (default led405)");
  spectrum->add_option("--charge-s", spectrum_args->spectrum.charge_s, "seconds of the first charge (default 600)")
      ->check(kNonNegative);
  spectrum->add_option("--recharge-s", spectrum_args->spectrum.recharge_s, "seconds of each later charge (default 300)")
      ->check(kNonNegative);
  spectrum->add_option("--frames", spectrum_args->spectrum.frames, "well-exposed frames to average (default 4)");
  spectrum->callback([spectrum_args] {
    SpectrumArgs args = *spectrum_args;
    args.spectrum.charge_light = args.light.empty() ? "led405" : args.light;
    if (args.light.empty() && !args.lab.empty()) args.spectrum.charge_light = LoadLabConfig(args.lab).charge_light;
    std::string error;
    if (!args.spectrum.IsValid(&error)) ThrowUserError("", "spectrum protocol", error);
    RunNewSession({SpectrumFrameFields::kProtocol, args.spectrum.ToJson()}, args);
  });
}

// phos capture lvf-calibration.
void RegisterCaptureLvfCalibration(CLI::App* capture) {
  auto calibration_args = std::make_shared<CaptureArgs>();
  CLI::App* calibration = capture->add_subcommand(
      "lvf-calibration",
      "LVF calibration (Sec. 8.4.2): with the white reference in view and the filter in, a dark frame, one\n"
      "well-exposed frame per source of known wavelength (the simulated lab: Hg 435.8 and 546.1 nm, HeNe\n"
      "632.8 nm; a real lab: calibration_lines of its config), and a flat field under the 3000 K lamp. Resumable.");
  AddDeviceOptions(calibration, *calibration_args);
  calibration->callback([calibration_args] {
    CaptureArgs args = *calibration_args;
    LvfCalibrationOptions options;
    if (!args.lab.empty()) {
      LabConfig config = LoadLabConfig(args.lab);
      options.lines = config.calibration_lines;
      options.flat_light = config.flat_light;
      options.flat_temperature_k = config.flat_temperature_k;
      options.flat_irradiance = config.flat_irradiance;
    } else {
      for (const KnownLine& line : DefaultCalibrationLines()) options.lines.push_back({line.light, line.wavelength_nm});
    }
    std::string error;
    if (!options.IsValid(&error)) ThrowUserError("", "lvf-calibration protocol", error);
    RunNewSession({LvfCalibrationFrameFields::kProtocol, options.ToJson()}, args);
  });
}

// phos capture all.
void RegisterCaptureAll(CLI::App* capture) {
  auto all_args = std::make_shared<AllArgs>();
  CLI::App* all = capture->add_subcommand(
      "all",
      "Everything for one sample, in order, each part a session in its own subfolder of --out:\n"
      "lvf-calibration, spectrum, decay, excitation. Ends with previews in --out: decay-frames.png,\n"
      "decay-curve.svg, excitation-curves.svg, spectrum-frames.png. Resumable part by part.");
  AddDeviceOptions(all, *all_args);
  all->add_option("--light", all_args->light, "charge light of the spectrum and decay (default led405 / the lab's)");
  all->add_option("--excite", all_args->excite,
                  "lights to measure excitation with, one per band (default: led420 led456 led494 in the\n"
                  "simulated lab; the lab's charge_light on a bench)");
  all->add_option("--charge-s", all_args->charge_s, "decay: seconds of charging (default 5400)")->check(kNonNegative);
  all->add_option("--duration-s", all_args->duration_s, "decay: seconds recorded (default 180)")->check(kPositive);
  all->add_option("--interval-s", all_args->interval_s, "decay: seconds between frames (default 5)")->check(kPositive);
  all->add_option("--decay-span-s", all_args->decay_span_s, kDecaySpanHelp)->check(kPositive);
  all->add_option("--reset-s", all_args->reset_s, "excitation: darkness before each charge (default 900)")
      ->check(kNonNegative);
  all->add_option("--tail-frames", all_args->tail_frames,
                  "excitation: frames of decay tail after each charge, which split the response into the\n"
                  "excited states (default 6; 0: one frame per charge)");
  all->callback([all_args] { RunCaptureAll(*all_args); });
}

// phos capture resume, phos capture verify.
void RegisterCaptureResumeAndVerify(CLI::App* capture) {
  auto resume_dir = std::make_shared<std::string>();
  CLI::App* resume = capture->add_subcommand(
      "resume",
      "Go on with an interrupted session (killed, crashed, camera lost): excitation and LVF calibration go\n"
      "on from the next measurement; an `all` folder keeps its complete parts and finishes the rest. A\n"
      "decay or spectrum cannot continue (the glow faded unobserved): phos says so and keeps its frames.");
  auto resume_json = std::make_shared<bool>(false);
  resume->add_option("DIR", *resume_dir, "the session folder")->required();
  resume->add_flag("--json", *resume_json, "print one JSON object at the end instead of the progress lines");
  resume->callback([resume_dir, resume_json] { RunCaptureResume(*resume_dir, *resume_json); });

  auto verify_args = std::make_shared<VerifyArgs>();
  CLI::App* verify = capture->add_subcommand(
      "verify",
      "Check a session folder (every part of an `all` folder): every record parses, every listed frame\n"
      "exists with its recorded size and XXH3 checksum and reads as an image, stop.json counts what\n"
      "frames.jsonl lists, a torn last line is found. One line per problem; exit 0 when whole, 2 otherwise.\n"
      "Changes nothing (resume repairs what can be).");
  verify->add_option("DIR", verify_args->dir, "the session folder")->required();
  verify->add_flag("--json", verify_args->json, "print the findings as JSON (default: one line per problem)");
  verify->callback([verify_args] {
    // Problems found: the summary line on stderr and exit code 2, as for any bad input.
    if (const std::size_t problems = RunCaptureVerify(*verify_args); problems > 0)
      ThrowUserError(verify_args->dir, "", std::to_string(problems) + " problem(s) found (listed above)");
  });
}

}  // namespace

void RegisterCapture(CLI::App& app) {
  CLI::App* capture = app.add_subcommand(
      "capture",
      "Run a capture protocol (Sec. 8.4) on the simulated lab (--device sim --sim-material M.json) or a real\n"
      "one (--lab LAB.json) and write its session folder as it goes: session.json, frames.jsonl,\n"
      "events.jsonl, frames/*.tif (16-bit), stop.json. Lights go off on every way out.");
  capture->require_subcommand(1);
  RegisterCaptureDecay(capture);
  RegisterCaptureExcitation(capture);
  RegisterCaptureSpectrum(capture);
  RegisterCaptureLvfCalibration(capture);
  RegisterCaptureAll(capture);
  RegisterCaptureResumeAndVerify(capture);
  RequireFiniteNumbers(*capture);
  // Each progress line out as it is said, also into a pipe or a log: a
  // signal ends capture with _Exit, which would drop what a full buffer held.
  capture->preparse_callback([](std::size_t) { std::setvbuf(stdout, nullptr, _IOLBF, 0); });
}

}  // namespace phos::app
