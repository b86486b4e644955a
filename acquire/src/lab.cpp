#include "phos/acquire/lab.h"

#include <gpiod.hpp>

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <set>

#include "phos/model/material.h"
#include "phos/util/csv.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"

namespace phos {
namespace {

// The largest sensor side a lab config may name, in pixels (docs/fuzzing.md, "Limits").
constexpr int kMaxSensorPixels = 65536;

}  // namespace

nlohmann::json LabConfig::ToJson() const {
  nlohmann::json channels_json = nlohmann::json::object();
  for (const LabChannel& c : channels) {
    channels_json[c.name] = {{"line", c.line}, {"active_low", c.active_low}};
    if (!c.band_irradiance.empty()) channels_json[c.name]["band_irradiance"] = c.band_irradiance;
  }
  nlohmann::json lines = nlohmann::json::array();
  for (const CalibrationLine& l : calibration_lines)
    lines.push_back({{"light", l.light}, {"wavelength_nm", l.wavelength_nm}});
  nlohmann::json camera_json = {{"aravis", camera}, {"binning", {binning_x, binning_y}}, {"timeout_s", timeout_s}};
  if (!pixel_format.empty()) camera_json["pixel_format"] = pixel_format;
  if (region) camera_json["region"] = *region;
  switch (trigger) {
    case AravisCamera::Trigger::kFreeRun: camera_json["trigger"] = "free-run"; break;
    case AravisCamera::Trigger::kSoftware: camera_json["trigger"] = "software"; break;
    case AravisCamera::Trigger::kHardware:
      camera_json["trigger"] = {{"hardware", trigger_source}, {"gpio_channel", trigger_channel}};
      break;
  }
  return {
      {"schema", "phos.lab/1"},
      {"camera", camera_json},
      {"lights", {{"backend", lights_backend}, {"chip", chip}, {"channels", channels_json}}},
      {"charge_light", charge_light},
      {"calibration_lines", lines},
      {"flat_field", {{"light", flat_light}, {"temperature_k", flat_temperature_k}, {"irradiance", flat_irradiance}}},
      {"bands_nm", bands.edges_nm},
      {"rig", rig}};
}

LabConfig LoadLabConfig(const std::filesystem::path& path) { return LabConfigFromJson(ReadFileText(path), path); }

namespace {

// "camera": the Aravis device and how it is set up.
void ReadLabCamera(const JsonField& camera, LabConfig& config) {
  camera.RejectUnknownKeys({"aravis", "pixel_format", "binning", "region", "trigger", "timeout_s", "note"});
  config.camera = camera["aravis"].NonEmptyString();
  if (auto f = camera.Optional("pixel_format")) config.pixel_format = f->NonEmptyString();
  if (auto f = camera.Optional("binning")) {
    const std::vector<double> b = f->NumberArray(2, 1);
    if (b[0] != std::floor(b[0]) || b[1] != std::floor(b[1]) || b[0] > 16 || b[1] > 16)
      f->Fail("expected 2 whole numbers in 1-16");
    config.binning_x = static_cast<int>(b[0]);
    config.binning_y = static_cast<int>(b[1]);
  }
  if (auto f = camera.Optional("region")) {
    // Whole pixels of a sensor of at most kMaxSensorPixels a side: a region of
    // 1e9 crashed in the camera (ASan SEGV), and 1e10 does not fit an int.
    if (f->ArraySize() != 4) f->Fail("expected [x, y, width, height]");
    std::array<int, 4> r{};
    for (int i = 0; i < 4; ++i) r[i] = f->At(i).Integer(i < 2 ? 0 : 1, kMaxSensorPixels);
    if (r[0] + r[2] > kMaxSensorPixels || r[1] + r[3] > kMaxSensorPixels)
      f->Fail("the region reaches past " + std::to_string(kMaxSensorPixels) +
              " pixels, the largest sensor phos accepts");
    config.region = r;
  }
  if (auto f = camera.Optional("timeout_s")) config.timeout_s = f->NumberInRange(0.1, 3600);
  if (auto f = camera.Optional("trigger")) {
    if (f->value().is_string()) {
      const std::string t = f->String();
      if (t == "software")
        config.trigger = AravisCamera::Trigger::kSoftware;
      else if (t == "free-run")
        config.trigger = AravisCamera::Trigger::kFreeRun;
      else
        f->Fail("expected \"software\", \"free-run\" or {\"hardware\": \"Line1\", \"gpio_channel\": ...}");
    } else {
      f->RejectUnknownKeys({"hardware", "gpio_channel"});
      config.trigger = AravisCamera::Trigger::kHardware;
      config.trigger_source = (*f)["hardware"].NonEmptyString();
      config.trigger_channel = (*f)["gpio_channel"].NonEmptyString();
    }
  }
}

// "bands_nm": the band edges the lights' irradiance is integrated over.
void ReadLabBands(const JsonField& f, LabConfig& config) {
  if (f.ArraySize() > static_cast<std::size_t>(kMaxBands) + 1)
    f.Fail("more than the limit of " + std::to_string(kMaxBands) + " bands");
  config.bands.edges_nm = f.NumberArray(0, 100);
  if (config.bands.edges_nm.size() < 2) f.Fail("expected at least 2 band edges");
  for (std::size_t i = 0; i < config.bands.edges_nm.size(); ++i)
    if (config.bands.edges_nm[i] > kMaxWavelengthNm) f.At(i).Fail("expected a wavelength of at most 1e5 nm");
  for (std::size_t i = 1; i < config.bands.edges_nm.size(); ++i)
    if (!(config.bands.edges_nm[i] > config.bands.edges_nm[i - 1])) f.Fail("band edges must increase");
}

// A channel's "irradiance_csv", integrated over the bands.
std::vector<double> ReadIrradianceCsv(const JsonField& f, const std::filesystem::path& path,
                                      const SpectralGrid& bands) {
  // Relative to the config file, as a user writes it next to the config.
  std::filesystem::path csv = f.NonEmptyString();
  if (csv.is_relative()) csv = path.parent_path() / csv;
  const CsvTable table = ReadCsv(csv);
  const int nm = table.Find("wavelength_nm"), value = table.Find("irradiance");
  if (nm < 0 || value < 0) f.Fail("'" + csv.string() + "' needs columns wavelength_nm,irradiance");
  SampledSpectrum spectrum{table.columns[nm], table.columns[value]};
  // A header alone (or one row) integrates to 0 in every band, and the
  // light was recorded as dark: refused, as is a spectrum that misses
  // every band of bands_nm.
  if (spectrum.value.size() < 2)
    f.Fail("'" + csv.string() + "' has " + std::to_string(spectrum.value.size()) +
           " row(s) of wavelength_nm,irradiance; a spectrum needs at least 2");
  for (std::size_t i = 0; i < spectrum.value.size(); ++i) {
    if (spectrum.value[i] < 0) f.Fail("'" + csv.string() + "': irradiance must be >= 0");
    if (i > 0 && !(spectrum.wavelength_nm[i] > spectrum.wavelength_nm[i - 1]))
      f.Fail("'" + csv.string() + "': wavelength_nm must increase");
  }
  std::vector<double> band_irradiance = IntegrateOverBands(spectrum, bands);
  if (std::none_of(band_irradiance.begin(), band_irradiance.end(), [](double e) { return e > 0; }))
    f.Fail("'" + csv.string() + "' gives 0 irradiance in every band of bands_nm (" +
           FormatDouble(bands.edges_nm.front()) + " to " + FormatDouble(bands.edges_nm.back()) +
           " nm): the light would be recorded as dark");
  return band_irradiance;
}

// "lights": the backend, its chip and the named channels (each GPIO line once).
void ReadLabLights(const JsonField& lights, const std::filesystem::path& path, LabConfig& config) {
  lights.RejectUnknownKeys({"backend", "chip", "channels", "note"});
  if (auto f = lights.Optional("backend")) {
    config.lights_backend = f->String();
    if (config.lights_backend != "gpiod" && config.lights_backend != "none")
      f->Fail("expected \"gpiod\" or \"none\" (a dry run)");
  }
  if (auto f = lights.Optional("chip")) config.chip = f->NonEmptyString();
  JsonField channels = lights["channels"];
  if (!channels.value().is_object() || channels.value().empty()) channels.Fail("expected an object of named channels");
  std::set<unsigned> used;
  for (const auto& [name, unused] : channels.value().items()) {
    JsonField channel = channels[name];
    channel.RejectUnknownKeys({"line", "active_low", "irradiance_csv", "note"});
    LabChannel c;
    c.name = name;
    c.line = static_cast<unsigned>(channel["line"].Integer(0, 1023));
    if (auto f = channel.Optional("active_low")) {
      if (!f->value().is_boolean()) f->Fail("expected true or false");
      c.active_low = f->value().get<bool>();
    }
    if (!used.insert(c.line).second)
      channel["line"].Fail("GPIO line " + std::to_string(c.line) + " is used by two channels");
    if (auto f = channel.Optional("irradiance_csv")) c.band_irradiance = ReadIrradianceCsv(*f, path, config.bands);
    config.channels.push_back(c);
  }
}

bool HasChannel(const LabConfig& config, const std::string& name) {
  return std::any_of(config.channels.begin(), config.channels.end(),
                     [&](const LabChannel& c) { return c.name == name; });
}

}  // namespace

LabConfig LabConfigFromJson(std::string_view text, const std::filesystem::path& path) {
  const nlohmann::json document = ParseJsonText(text, path.string());
  JsonField root(document, path.string());
  root.RejectUnknownKeys(
      {"schema", "camera", "lights", "charge_light", "calibration_lines", "flat_field", "rig", "bands_nm", "note"});
  if (root["schema"].String() != "phos.lab/1") root["schema"].Fail("expected \"phos.lab/1\"");
  LabConfig config;
  config.source = path;

  JsonField camera = root["camera"];
  ReadLabCamera(camera, config);
  if (auto f = root.Optional("bands_nm")) ReadLabBands(*f, config);
  ReadLabLights(root["lights"], path, config);
  if (config.trigger == AravisCamera::Trigger::kHardware && !HasChannel(config, config.trigger_channel))
    camera["trigger"]["gpio_channel"].Fail("no light channel '" + config.trigger_channel + "' in lights.channels");

  if (auto f = root.Optional("charge_light")) config.charge_light = f->NonEmptyString();
  if (!HasChannel(config, config.charge_light))
    root.Fail("charge_light '" + config.charge_light + "' is not a channel of lights.channels");
  if (auto f = root.Optional("calibration_lines")) {
    for (std::size_t i = 0; i < f->ArraySize(); ++i) {
      JsonField line = f->At(i);
      line.RejectUnknownKeys({"light", "wavelength_nm", "note"});
      CalibrationLine l{line["light"].NonEmptyString(), line["wavelength_nm"].NumberInRange(200, 1200)};
      if (!HasChannel(config, l.light)) line["light"].Fail("'" + l.light + "' is not a channel of lights.channels");
      config.calibration_lines.push_back(l);
    }
  }
  if (auto f = root.Optional("flat_field")) {
    f->RejectUnknownKeys({"light", "temperature_k", "irradiance"});
    config.flat_light = (*f)["light"].NonEmptyString();
    config.flat_temperature_k = (*f)["temperature_k"].NumberInRange(1000, 10000);
    if (auto g = f->Optional("irradiance")) config.flat_irradiance = g->NumberAtLeast(1e-12);
  }
  if (auto f = root.Optional("rig")) {
    config.rig = f->String();
    if (config.rig != "prompt" && config.rig != "fixed") f->Fail("expected \"prompt\" or \"fixed\"");
  }
  return config;
}

struct GpiodLights::Impl {
  gpiod::chip chip;
  std::vector<LabChannel> channels;
  std::vector<gpiod::line> lines;
  std::vector<bool> state;
};

GpiodLights::GpiodLights(const std::string& chip, const std::vector<LabChannel>& channels, const Clock& clock)
    : impl_(std::make_unique<Impl>()), clock_(clock) {
  try {
    impl_->chip.open(chip, gpiod::chip::OPEN_LOOKUP);
  } catch (const std::exception& e) {
    ThrowUserError("GPIO chip '" + chip + "'", "open",
                   std::string(e.what()) + " (is it the right chip? see gpiodetect)");
  }
  impl_->channels = channels;
  for (const LabChannel& c : channels) {
    try {
      gpiod::line line = impl_->chip.get_line(c.line);
      gpiod::line_request request{"phos", gpiod::line_request::DIRECTION_OUTPUT,
                                  c.active_low ? gpiod::line_request::FLAG_ACTIVE_LOW : std::bitset<32>{}};
      line.request(request, 0);  // off from the start
      impl_->lines.push_back(line);
      impl_->state.push_back(false);
    } catch (const std::exception& e) {
      ThrowUserError("GPIO chip '" + chip + "'", "line " + std::to_string(c.line) + " ('" + c.name + "')",
                     std::string(e.what()) + " (in use by another program? see gpioinfo)");
    }
  }
}

GpiodLights::~GpiodLights() {
  // Off before the lines are released (a released line may float).
  try {
    AllOff();
  } catch (...) {}
}

std::vector<std::string> GpiodLights::channels() const {
  std::vector<std::string> names;
  for (const LabChannel& c : impl_->channels) names.push_back(c.name);
  return names;
}

void GpiodLights::Set(const std::string& channel, bool on) {
  for (std::size_t i = 0; i < impl_->channels.size(); ++i) {
    if (impl_->channels[i].name != channel) continue;
    try {
      impl_->lines[i].set_value(on ? 1 : 0);
    } catch (const std::exception& e) {
      ThrowUserError("GPIO", "channel '" + channel + "'", std::string("cannot switch: ") + e.what());
    }
    impl_->state[i] = on;
    events_.push_back({clock_.now_s(), channel, on});
    return;
  }
  const std::string known = JoinComma(impl_->channels, &LabChannel::name);
  ThrowUserError("", "light", "unknown channel '" + channel + "' (this lab has: " + known + ")");
}

bool GpiodLights::IsOn(const std::string& channel) const {
  for (std::size_t i = 0; i < impl_->channels.size(); ++i)
    if (impl_->channels[i].name == channel) return impl_->state[i];
  return false;
}

std::unique_ptr<OpenedLab> OpenLab(const LabConfig& config) {
  auto lab = std::make_unique<OpenedLab>();
  // Lights first, so they are off (requested low) before anything else happens.
  std::vector<std::string> names;
  for (const LabChannel& c : config.channels) names.push_back(c.name);
  if (config.lights_backend == "gpiod")
    lab->lights = std::make_unique<GpiodLights>(config.chip, config.channels, lab->clock);
  else
    lab->lights = std::make_unique<RecordingLights>(names, lab->clock);
  if (config.camera.rfind("Fake_", 0) == 0) AravisCamera::EnableFakeInterface();  // Aravis's simulator
  lab->camera = std::make_unique<AravisCamera>(config.camera, lab->clock, config.timeout_s);
  AravisCamera& camera = *lab->camera;
  if (!config.pixel_format.empty()) camera.SetPixelFormat(config.pixel_format);
  if (config.binning_x != 1 || config.binning_y != 1) camera.SetBinning(config.binning_x, config.binning_y);
  if (config.region)
    camera.SetRegion((*config.region)[0], (*config.region)[1], (*config.region)[2], (*config.region)[3],
                     "camera.region");
  camera.SetTrigger(config.trigger, config.trigger_source);
  if (config.trigger == AravisCamera::Trigger::kHardware) {
    Lights* lights = lab->lights.get();
    Clock* clock = &lab->clock;
    const std::string channel = config.trigger_channel;
    camera.fire_hardware_trigger = [lights, clock, channel] {
      lights->Set(channel, true);  // a 1 ms pulse; cameras trigger on the rising edge
      clock->SleepFor(0.001);
      lights->Set(channel, false);
    };
  }
  if (config.rig == "prompt") {
    lab->rig = [](const std::string& what, bool in_place) {
      const std::string thing = what == "lvf" ? "the linear variable filter in front of the camera"
                                              : "the white reference in place of the sample";
      std::fprintf(stderr, "phos capture: %s %s, then press Enter: ", in_place ? "put" : "remove", thing.c_str());
      std::string ignored;
      if (!std::getline(std::cin, ignored))
        ThrowUserError("", "rig",
                       "no operator to " + std::string(in_place ? "put " : "remove ") + thing +
                           " (stdin closed); set \"rig\": \"fixed\" for a rig that needs no change");
    };
  } else {
    lab->rig = [](const std::string&, bool) {};
  }
  // What each measured light puts on the sample per band: the fit needs it for ke.
  DevicesRecord& d = lab->description;
  for (const LabChannel& c : config.channels)
    if (!c.band_irradiance.empty()) d.light_band_irradiance[c.name] = c.band_irradiance;
  d.device = "lab";
  d.camera = camera.description();
  d.bands_nm = config.bands.edges_nm;
  d.pixel_format = camera.pixel_format();
  d.lights = names;
  d.lights_backend = config.lights_backend;
  d.clock = "system (monotonic)";
  d.lab_config = config.source.string();
  d.lab = config.ToJson();
  return lab;
}

}  // namespace phos
