#include "phos/acquire/protocol_records.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"

namespace phos {
namespace fs = std::filesystem;

namespace {

constexpr double kLargest = std::numeric_limits<double>::max();

// A per-channel or per-column array: 1 to 65536 finite numbers.
std::vector<double> SignalArray(const JsonField& f) {
  const std::size_t n = f.ArraySize();
  if (n == 0 || n > 65536) f.Fail("expected an array of 1 to 65536 numbers, got " + std::to_string(n));
  return f.NumberArray();
}

std::vector<std::string> StringArray(const JsonField& f) {
  std::vector<std::string> values;
  for (std::size_t i = 0; i < f.ArraySize(); ++i) values.push_back(f.At(i).String());
  return values;
}

}  // namespace

// ---- settings ---------------------------------------------------------------------

bool AutoExposure::IsValid(std::string* error) const {
  if (!(min_exposure_s > 0) || !(initial_exposure_s >= min_exposure_s) || !(max_exposure_s >= initial_exposure_s))
    return *error = "need 0 < min exposure <= initial exposure <= max exposure", false;
  if (!(low_fraction > 0 && low_fraction < high_fraction && high_fraction < 1))
    return *error = "need 0 < low fraction < high fraction < 1", false;
  return true;
}

nlohmann::json AutoExposure::ToJson() const {
  return {{"initial_exposure_s", initial_exposure_s},
          {"min_exposure_s", min_exposure_s},
          {"max_exposure_s", max_exposure_s},
          {"low_fraction", low_fraction},
          {"high_fraction", high_fraction}};
}

AutoExposure AutoExposure::FromJson(const nlohmann::json& j, const std::string& where) {
  const JsonField f(j, where);
  AutoExposure a;
  a.initial_exposure_s = f["initial_exposure_s"].NumberAtLeast(0);
  a.min_exposure_s = f["min_exposure_s"].NumberAtLeast(0);
  a.max_exposure_s = f["max_exposure_s"].NumberAtLeast(0);
  a.low_fraction = f["low_fraction"].NumberInRange(0, 1);
  a.high_fraction = f["high_fraction"].NumberInRange(0, 1);
  return a;
}

bool DecayProtocolOptions::IsValid(std::string* error) const {
  if (charge_light.empty()) return *error = "no charge light named", false;
  if (!(charge_s >= 0)) return *error = "charge time must be >= 0", false;
  if (!(interval_s > 0) || !(duration_s > 0)) return *error = "interval and duration must be > 0", false;
  if (!(first_delay_s >= 0)) return *error = "first delay must be >= 0", false;
  if (early_frames < 0 || early_frames > 20) return *error = "early frames must be 0-20", false;
  if (!(initial_exposure_s > 0) || !(max_exposure_s >= initial_exposure_s))
    return *error = "need 0 < initial exposure <= max exposure", false;
  if (!(low_fraction > 0 && low_fraction < high_fraction && high_fraction < 1))
    return *error = "need 0 < low fraction < high fraction < 1", false;
  if (span_s == 0) return true;  // not set: the schedule of interval_s and duration_s
  if (!std::isfinite(span_s) || !(span_s > 0))
    return *error =
               "the decay span (--decay-span-s) must be a finite number of seconds > 0, got " + FormatDouble(span_s),
           false;
  if (span_s < kSpanMin_s || !(span_s > 10 * first_delay_s))
    return *error = "the decay span (--decay-span-s) of " + FormatDouble(span_s) +
                    " s is too short: it needs at least " + FormatDouble(std::max(kSpanMin_s, 10 * first_delay_s)) +
                    " s (a decade of log-spaced frames after the first delay)",
           false;
  return true;
}

nlohmann::json DecayProtocolOptions::ToJson() const {
  nlohmann::json j = {{"charge_light", charge_light},
                      {"charge_s", charge_s},
                      {"interval_s", interval_s},
                      {"duration_s", duration_s},
                      {"first_delay_s", first_delay_s},
                      {"early_frames", early_frames},
                      {"initial_exposure_s", initial_exposure_s},
                      {"max_exposure_s", max_exposure_s},
                      {"gain", gain}};
  if (span_s != 0) j["span_s"] = span_s;  // absent: the schedule of interval_s and duration_s
  return j;
}

DecayProtocolOptions DecayProtocolOptions::FromJson(const nlohmann::json& j, const std::string& where) {
  const JsonField f(j, where);
  DecayProtocolOptions o;
  o.charge_light = f["charge_light"].String();
  o.charge_s = f["charge_s"].NumberAtLeast(0);
  o.interval_s = f["interval_s"].Number();
  o.duration_s = f["duration_s"].Number();
  o.first_delay_s = f["first_delay_s"].Number();
  o.early_frames = f["early_frames"].Integer(0, 20);
  o.initial_exposure_s = f["initial_exposure_s"].Number();
  o.max_exposure_s = f["max_exposure_s"].Number();
  o.gain = f["gain"].NumberInRange(1e-6, 1e6);
  // Optional, unlike every other key: sessions before it have none and keep
  // their schedule. When there, a span IsValid would take.
  if (const std::optional<JsonField> span = f.Optional("span_s")) o.span_s = span->NumberAtLeast(kSpanMin_s);
  return o;
}

bool ExcitationProtocolOptions::IsValid(std::string* error) const {
  if (lights.empty()) return *error = "no light to measure", false;
  if (!(reset_s >= 0) || !(delay_s >= 0)) return *error = "reset and delay must be >= 0", false;
  if (!(first_charge_s > 0) || !(max_charge_s >= first_charge_s))
    return *error = "need 0 < first charge <= max charge", false;
  if (!(plateau_growth > 1)) return *error = "plateau growth must be > 1", false;
  if (!(exposure_s > 0)) return *error = "exposure must be > 0", false;
  if (tail_frames < 0 || tail_frames > 20) return *error = "tail frames must be 0-20", false;
  if (!(tail_growth >= 1) || !(tail_growth <= 16)) return *error = "tail growth must be 1-16", false;
  if (!(high_fraction > 0 && high_fraction < 1)) return *error = "high fraction must be in (0, 1)", false;
  return true;
}

nlohmann::json ExcitationProtocolOptions::ToJson() const {
  return {{"lights", lights},
          {"reset_s", reset_s},
          {"first_charge_s", first_charge_s},
          {"max_charge_s", max_charge_s},
          {"plateau_growth", plateau_growth},
          {"delay_s", delay_s},
          {"exposure_s", exposure_s},
          {"gain", gain},
          {"tail_frames", tail_frames},
          {"tail_growth", tail_growth},
          {"high_fraction", high_fraction}};
}

ExcitationProtocolOptions ExcitationProtocolOptions::FromJson(const nlohmann::json& j, const std::string& where) {
  const JsonField f(j, where);
  ExcitationProtocolOptions o;
  o.lights = StringArray(f["lights"]);
  o.reset_s = f["reset_s"].Number();
  o.first_charge_s = f["first_charge_s"].Number();
  o.max_charge_s = f["max_charge_s"].Number();
  o.plateau_growth = f["plateau_growth"].Number();
  o.delay_s = f["delay_s"].Number();
  o.exposure_s = f["exposure_s"].Number();
  o.gain = f["gain"].NumberInRange(1e-6, 1e6);
  o.tail_frames = f["tail_frames"].Integer(0, 20);
  o.tail_growth = f["tail_growth"].Number();
  o.high_fraction = f["high_fraction"].Number();
  return o;
}

bool SpectrumProtocolOptions::IsValid(std::string* error) const {
  if (charge_light.empty()) return *error = "no charge light named", false;
  if (!(charge_s >= 0) || !(recharge_s >= 0)) return *error = "charge times must be >= 0", false;
  if (frames < 1) return *error = "need at least 1 frame", false;
  if (!(first_delay_s >= 0)) return *error = "first delay must be >= 0", false;
  return exposure.IsValid(error);
}

nlohmann::json SpectrumProtocolOptions::ToJson() const {
  return {{"charge_light", charge_light},   {"charge_s", charge_s}, {"recharge_s", recharge_s},     {"frames", frames},
          {"first_delay_s", first_delay_s}, {"gain", gain},         {"exposure", exposure.ToJson()}};
}

SpectrumProtocolOptions SpectrumProtocolOptions::FromJson(const nlohmann::json& j, const std::string& where) {
  const JsonField f(j, where);
  SpectrumProtocolOptions o;
  o.charge_light = f["charge_light"].String();
  o.charge_s = f["charge_s"].NumberAtLeast(0);
  o.recharge_s = f["recharge_s"].NumberAtLeast(0);
  o.frames = f["frames"].Integer(1, 100000);
  o.first_delay_s = f["first_delay_s"].Number();
  o.gain = f["gain"].NumberInRange(1e-6, 1e6);
  f["exposure"];  // present, so its own reader names the settings' key
  o.exposure = AutoExposure::FromJson(j["exposure"], where + ": exposure");
  return o;
}

bool LvfCalibrationOptions::IsValid(std::string* error) const {
  if (lines.size() < 2) return *error = "need at least 2 sources of known wavelength", false;
  for (const CalibrationLine& line : lines)
    if (!(line.wavelength_nm > 200 && line.wavelength_nm < 1200))
      return *error = "wavelength of '" + line.light + "' must be in 200-1200 nm", false;
  if (flat_light.empty() || !(flat_temperature_k > 0))
    return *error = "need a flat-field lamp and its temperature", false;
  if (max_tries < 1) return *error = "max tries must be >= 1", false;
  return exposure.IsValid(error);
}

nlohmann::json LvfCalibrationOptions::ToJson() const {
  nlohmann::json line_records = nlohmann::json::array();
  for (const CalibrationLine& l : lines)
    line_records.push_back({{"light", l.light}, {"wavelength_nm", l.wavelength_nm}});
  return {{"lines", line_records},
          {"flat_light", flat_light},
          {"flat_temperature_k", flat_temperature_k},
          {"flat_irradiance", flat_irradiance},
          {"gain", gain},
          {"max_tries", max_tries},
          {"exposure", exposure.ToJson()}};
}

LvfCalibrationOptions LvfCalibrationOptions::FromJson(const nlohmann::json& j, const std::string& where) {
  const JsonField f(j, where);
  LvfCalibrationOptions o;
  const JsonField lines = f["lines"];
  for (std::size_t i = 0; i < lines.ArraySize(); ++i)
    o.lines.push_back({lines.At(i)["light"].String(), lines.At(i)["wavelength_nm"].Number()});
  o.flat_light = f["flat_light"].String();
  o.flat_temperature_k = f["flat_temperature_k"].NumberAtLeast(0);
  o.flat_irradiance = f["flat_irradiance"].NumberAtLeast(0);
  o.gain = f["gain"].NumberInRange(1e-6, 1e6);
  o.max_tries = f["max_tries"].Integer(1, 1000);
  f["exposure"];
  o.exposure = AutoExposure::FromJson(j["exposure"], where + ": exposure");
  return o;
}

nlohmann::json AllSettings::PartToJson(const std::string& protocol) const {
  if (protocol == LvfCalibrationFrameFields::kProtocol) return calibration.ToJson();
  if (protocol == SpectrumFrameFields::kProtocol) return spectrum.ToJson();
  if (protocol == DecayFrameFields::kProtocol) return decay.ToJson();
  if (protocol == ExcitationFrameFields::kProtocol) return excitation.ToJson();
  ThrowUserError("", "protocol", "unknown protocol '" + protocol + "'");
}

nlohmann::json AllSettings::ToJson() const {
  nlohmann::json parts = nlohmann::json::object();
  for (const std::string& protocol : kAllOrder) parts[protocol] = PartToJson(protocol);
  return {{"parts", parts}, {"order", kAllOrder}};
}

AllSettings AllSettings::FromJson(const nlohmann::json& j, const std::string& where) {
  const JsonField f(j, where);
  const JsonField parts = f["parts"];
  for (const std::string& protocol : kAllOrder) parts[protocol];  // each present, named when not
  AllSettings s;
  const nlohmann::json& p = j["parts"];
  s.calibration = LvfCalibrationOptions::FromJson(p["lvf-calibration"], where + ": parts.lvf-calibration");
  s.spectrum = SpectrumProtocolOptions::FromJson(p["spectrum"], where + ": parts.spectrum");
  s.decay = DecayProtocolOptions::FromJson(p["decay"], where + ": parts.decay");
  s.excitation = ExcitationProtocolOptions::FromJson(p["excitation"], where + ": parts.excitation");
  return s;
}

// ---- devices and sample ------------------------------------------------------------

std::vector<double> DevicesRecord::BandIrradiance(const std::string& light) const {
  auto it = light_band_irradiance.find(light);
  return it == light_band_irradiance.end() ? std::vector<double>{} : it->second;
}

nlohmann::json DevicesRecord::ToJson() const {
  nlohmann::json irradiance = nlohmann::json::object();
  for (const auto& [light, values] : light_band_irradiance) irradiance[light] = values;
  nlohmann::json j = {{"device", device},
                      {"camera", camera},
                      {"lights", lights},
                      {"clock", clock},
                      {"light_band_irradiance", irradiance},
                      {"bands_nm", bands_nm}};
  if (simulated()) {
    j["seed"] = seed;
    j["camera_csv"] = camera_csv;
    j["size"] = {width, height};
  } else {
    j["pixel_format"] = pixel_format;
    j["lights_backend"] = lights_backend;
    j["lab_config"] = lab_config;
    j["lab"] = lab;
  }
  return j;
}

DevicesRecord DevicesRecord::FromJson(const nlohmann::json& j, const std::string& where) {
  const JsonField f(j, where);
  DevicesRecord d;
  d.device = f["device"].String();
  if (d.device != "sim" && d.device != "lab")
    f["device"].Fail("expected \"sim\" or \"lab\", got " + DescribeJson(j["device"]));
  d.camera = f["camera"].String();
  d.lights = StringArray(f["lights"]);
  d.clock = f["clock"].String();
  const JsonField irradiance = f["light_band_irradiance"];
  if (!j["light_band_irradiance"].is_object())
    irradiance.Fail("expected an object, got " + DescribeJson(j["light_band_irradiance"]));
  for (const auto& [light, values] : j["light_band_irradiance"].items())
    d.light_band_irradiance[light] = irradiance[light].NumberArray(0, 0.0);
  d.bands_nm = f["bands_nm"].NumberArray();
  if (d.simulated()) {
    if (!f["seed"].value().is_number_unsigned() || f["seed"].value().get<std::uint64_t>() > 0xffffffffu)
      f["seed"].Fail("expected a whole number from 0 to 4294967295, got " + DescribeJson(j["seed"]));
    d.seed = j["seed"].get<unsigned>();
    d.camera_csv = f["camera_csv"].String();
    const JsonField size = f["size"];
    if (size.ArraySize() != 2) size.Fail("expected [width, height]");
    d.width = size.At(0).Integer(0, 1 << 20);
    d.height = size.At(1).Integer(0, 1 << 20);
  } else {
    d.pixel_format = f["pixel_format"].String();
    d.lights_backend = f["lights_backend"].String();
    d.lab_config = f["lab_config"].String();
    f["lab"];
    d.lab = j["lab"];
  }
  return d;
}

nlohmann::json SampleRecord::ToJson() const {
  if (!material) return {{"note", note}};
  nlohmann::json j = {{"material_file", material_file}, {"material", *material}, {"albedo", albedo}};
  if (inset_material) j["inset"] = {{"material", *inset_material}, {"radius_fraction", inset_radius_fraction}};
  return j;
}

SampleRecord SampleRecord::FromJson(const nlohmann::json& j, const std::string& where) {
  const JsonField f(j, where);
  SampleRecord s;
  if (!f.Has("material")) {
    s.note = f["note"].String();
    return s;
  }
  s.material_file = f["material_file"].String();
  f["material"].Has("states");  // an object; model/'s MaterialFromJson reads it
  s.material = j["material"];
  s.albedo = f["albedo"].NumberArray(0, 0.0);
  if (auto inset = f.Optional("inset")) {
    (*inset)["material"].Has("states");
    s.inset_material = j["inset"]["material"];
    s.inset_radius_fraction = (*inset)["radius_fraction"].NumberInRange(0, 1);
  }
  return s;
}

void CheckStartRecord(const SessionRecord& record, const std::string& where) {
  if (!record.settings.empty()) {
    const std::string settings = where + ": settings";
    if (record.protocol == "all")
      AllSettings::FromJson(record.settings, settings);
    else if (record.protocol == DecayFrameFields::kProtocol)
      DecayProtocolOptions::FromJson(record.settings, settings);
    else if (record.protocol == ExcitationFrameFields::kProtocol)
      ExcitationProtocolOptions::FromJson(record.settings, settings);
    else if (record.protocol == SpectrumFrameFields::kProtocol)
      SpectrumProtocolOptions::FromJson(record.settings, settings);
    else if (record.protocol == LvfCalibrationFrameFields::kProtocol)
      LvfCalibrationOptions::FromJson(record.settings, settings);
  }
  if (!record.devices.empty()) DevicesRecord::FromJson(record.devices, where + ": devices");
  if (!record.sample.empty()) SampleRecord::FromJson(record.sample, where + ": sample");
}

// ---- frames --------------------------------------------------------------------

double FrameSignal::SumDn() const {
  double sum = 0;
  for (double v : mean_signal_dn) sum += v;
  return sum;
}

void FrameSignal::AddTo(nlohmann::json* j) const {
  (*j)["mean_signal_dn"] = mean_signal_dn;
  (*j)["saturated_fraction"] = saturated_fraction;
  if (!lvf) return;
  (*j)["lvf"] = true;
  (*j)["column_mean_dn"] = column_mean_dn;
  (*j)["peak_column_fraction"] = peak_column_fraction;
}

FrameSignal FrameSignal::FromJson(const JsonField& f, bool lvf) {
  FrameSignal s;
  s.mean_signal_dn = SignalArray(f["mean_signal_dn"]);
  s.saturated_fraction = f["saturated_fraction"].NumberInRange(0, 1);
  s.lvf = lvf;
  if (!lvf) return s;
  if (!f["lvf"].Boolean()) f["lvf"].Fail("expected true: the frame was taken through the LVF");
  s.column_mean_dn = SignalArray(f["column_mean_dn"]);
  s.peak_column_fraction = f["peak_column_fraction"].NumberInRange(0, kLargest);
  return s;
}

nlohmann::json DecayFrameFields::ToJson() const {
  nlohmann::json j = {{"delay_after_light_off_s", delay_after_light_off_s}};
  signal.AddTo(&j);
  return j;
}

DecayFrameFields DecayFrameFields::FromJson(const JsonField& f) {
  DecayFrameFields d;
  d.delay_after_light_off_s = f["delay_after_light_off_s"].Number();
  d.signal = FrameSignal::FromJson(f, kThroughLvf);
  return d;
}

nlohmann::json ExcitationFrameFields::ToJson() const {
  nlohmann::json j = {{"light", light},
                      {"charge_s", charge_s},
                      {"delay_after_light_off_s", delay_after_light_off_s},
                      {"light_off_s", light_off_s},
                      {"tail", tail},
                      {"tail_frames", tail_frames}};
  signal.AddTo(&j);
  return j;
}

ExcitationFrameFields ExcitationFrameFields::FromJson(const JsonField& f) {
  ExcitationFrameFields e;
  e.light = f["light"].String();
  e.charge_s = f["charge_s"].NumberInRange(0, kLargest);
  e.light_off_s = f["light_off_s"].Number();
  e.delay_after_light_off_s = f["delay_after_light_off_s"].Number();
  e.tail_frames = f["tail_frames"].Integer(0, 1000);
  e.tail = f["tail"].Integer(0, e.tail_frames);
  e.signal = FrameSignal::FromJson(f, kThroughLvf);
  return e;
}

nlohmann::json SpectrumFrameFields::ToJson() const {
  nlohmann::json j = {{"kind", "spectrum"}, {"delay_after_light_off_s", delay_after_light_off_s}};
  signal.AddTo(&j);
  return j;
}

SpectrumFrameFields SpectrumFrameFields::FromJson(const JsonField& f) {
  SpectrumFrameFields s;
  if (f["kind"].String() != "spectrum") f["kind"].Fail("expected \"spectrum\", got " + DescribeJson(f["kind"].value()));
  s.delay_after_light_off_s = f["delay_after_light_off_s"].Number();
  s.signal = FrameSignal::FromJson(f, kThroughLvf);
  return s;
}

LvfCalibrationFrameFields LvfCalibrationFrameFields::Dark() { return {}; }

LvfCalibrationFrameFields LvfCalibrationFrameFields::Line(const std::string& light, double wavelength_nm) {
  LvfCalibrationFrameFields c;
  c.kind = Kind::kLine;
  c.light = light;
  c.wavelength_nm = wavelength_nm;
  return c;
}

LvfCalibrationFrameFields LvfCalibrationFrameFields::Flat(const std::string& light, double temperature_k,
                                                          double irradiance) {
  LvfCalibrationFrameFields c;
  c.kind = Kind::kFlat;
  c.light = light;
  c.temperature_k = temperature_k;
  c.irradiance = irradiance;
  return c;
}

nlohmann::json LvfCalibrationFrameFields::ToJson() const {
  nlohmann::json j;
  switch (kind) {
    case Kind::kDark: j = {{"kind", "dark"}}; break;
    case Kind::kLine: j = {{"kind", "line"}, {"light", light}, {"wavelength_nm", wavelength_nm}}; break;
    case Kind::kFlat:
      j = {{"kind", "flat"}, {"light", light}, {"temperature_k", temperature_k}, {"irradiance", irradiance}};
      break;
  }
  signal.AddTo(&j);
  return j;
}

LvfCalibrationFrameFields LvfCalibrationFrameFields::FromJson(const JsonField& f) {
  LvfCalibrationFrameFields c;
  const std::string kind = f["kind"].String();
  if (kind == "dark") {
    c.kind = Kind::kDark;
  } else if (kind == "line") {
    c.kind = Kind::kLine;
    c.light = f["light"].String();
    c.wavelength_nm = f["wavelength_nm"].NumberInRange(0, kLargest);
  } else if (kind == "flat") {
    c.kind = Kind::kFlat;
    c.light = f["light"].String();
    c.temperature_k = f["temperature_k"].NumberInRange(0, kLargest);
    c.irradiance = f["irradiance"].NumberInRange(0, kLargest);
  } else {
    f["kind"].Fail("expected \"dark\", \"line\" or \"flat\", got " + DescribeJson(f["kind"].value()));
  }
  c.signal = FrameSignal::FromJson(f, kThroughLvf);
  return c;
}

namespace {
std::string FrameWhere(const fs::path& session_dir, int line) {
  return (session_dir / "frames.jsonl").string() + ":" + std::to_string(line);
}
}  // namespace

template <typename Fields>
std::vector<ProtocolFrame<Fields>> ReadProtocolFrames(const fs::path& session_dir, const FrameRecords& records) {
  std::vector<ProtocolFrame<Fields>> frames;
  for (std::size_t i = 0; i < records.frames.size(); ++i) {
    const JsonField f(records.frames[i].protocol, FrameWhere(session_dir, records.lines[i]));
    frames.push_back({records.frames[i], records.lines[i], Fields::FromJson(f)});
  }
  return frames;
}

template std::vector<ProtocolFrame<DecayFrameFields>> ReadProtocolFrames(const fs::path&, const FrameRecords&);
template std::vector<ProtocolFrame<ExcitationFrameFields>> ReadProtocolFrames(const fs::path&, const FrameRecords&);
template std::vector<ProtocolFrame<SpectrumFrameFields>> ReadProtocolFrames(const fs::path&, const FrameRecords&);
template std::vector<ProtocolFrame<LvfCalibrationFrameFields>> ReadProtocolFrames(const fs::path&, const FrameRecords&);

namespace {
template <typename Fields>
void CollectFieldProblems(const fs::path& session_dir, const FrameRecords& records,
                          std::vector<std::string>* problems) {
  for (std::size_t i = 0; i < records.frames.size(); ++i) {
    try {
      Fields::FromJson(JsonField(records.frames[i].protocol, FrameWhere(session_dir, records.lines[i])));
    } catch (const UserError& e) {
      problems->push_back(e.what());
    }
  }
}
}  // namespace

std::vector<std::string> ProtocolFieldProblems(const fs::path& session_dir, const std::string& protocol,
                                               const FrameRecords& records) {
  std::vector<std::string> problems;
  if (protocol == DecayFrameFields::kProtocol)
    CollectFieldProblems<DecayFrameFields>(session_dir, records, &problems);
  else if (protocol == ExcitationFrameFields::kProtocol)
    CollectFieldProblems<ExcitationFrameFields>(session_dir, records, &problems);
  else if (protocol == SpectrumFrameFields::kProtocol)
    CollectFieldProblems<SpectrumFrameFields>(session_dir, records, &problems);
  else if (protocol == LvfCalibrationFrameFields::kProtocol)
    CollectFieldProblems<LvfCalibrationFrameFields>(session_dir, records, &problems);
  return problems;
}

// ---- events ---------------------------------------------------------------------

nlohmann::json LightSwitchEvent::ToJson() const {
  return {{"t_s", t_s}, {"event", "light"}, {"channel", channel}, {"on", on}};
}
nlohmann::json ExposureEvent::ToJson() const {
  return {{"t_s", t_s}, {"event", "exposure"}, {"seq", seq}, {"well_exposed", well_exposed}};
}
nlohmann::json CalibratedEvent::ToJson() const { return {{"t_s", t_s}, {"event", "calibrated"}, {"light", light}}; }
nlohmann::json RigEvent::ToJson() const {
  return {{"t_s", t_s}, {"event", "rig"}, {"what", what}, {"in_place", in_place}};
}
nlohmann::json ProtocolEvent::ToJson() const {
  return {{"t_s", t_s}, {"event", "protocol"}, {"protocol", protocol}, {"phase", phase}};
}

nlohmann::json ResumeEvent(double t_s, const char* kept_key, const nlohmann::json& kept) {
  return {{"t_s", t_s}, {"event", "resume"}, {kept_key, kept}};
}

namespace {
// Each event of one kind, read with `read` from its field; the others are skipped.
template <typename Event, typename Read>
std::vector<Event> ReadEventsOf(const fs::path& session_dir, const char* kind, Read read) {
  const fs::path path = session_dir / "events.jsonl";
  const JsonLinesFile file = ReadJsonLinesFile(path);
  std::vector<Event> events;
  for (const JsonLine& line : file.records) {
    const JsonField f(line.value, path.string() + ":" + std::to_string(line.line));
    if (f["event"].String() != kind) continue;
    events.push_back(read(f));
  }
  return events;
}
// Events written by the signal handler have no time.
double EventTime(const JsonField& f) {
  return f.Has("t_s") ? f["t_s"].Number() : std::numeric_limits<double>::quiet_NaN();
}
}  // namespace

std::vector<LightSwitchEvent> ReadLightSwitchEvents(const fs::path& session_dir) {
  return ReadEventsOf<LightSwitchEvent>(session_dir, "light", [](const JsonField& f) {
    return LightSwitchEvent{EventTime(f), f["channel"].String(), f["on"].Boolean()};
  });
}

std::vector<ExposureEvent> ReadExposureEvents(const fs::path& session_dir) {
  return ReadEventsOf<ExposureEvent>(session_dir, "exposure", [](const JsonField& f) {
    return ExposureEvent{EventTime(f), f["seq"].Integer(0, std::numeric_limits<int>::max()),
                         f["well_exposed"].Boolean()};
  });
}

std::vector<CalibratedEvent> ReadCalibratedEvents(const fs::path& session_dir) {
  return ReadEventsOf<CalibratedEvent>(session_dir, "calibrated", [](const JsonField& f) {
    return CalibratedEvent{EventTime(f), f["light"].String()};
  });
}

int CountResumes(const fs::path& session_dir) {
  int resumes = 0;
  for (const nlohmann::json& event : ReadEventRecords(session_dir)) resumes += event["event"] == "resume";
  return resumes;
}

}  // namespace phos
