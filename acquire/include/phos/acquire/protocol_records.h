#pragma once
// What each capture protocol records (docs/capture.md, "The record format"),
// typed, with ToJson/FromJson, owned here beside the session records
// (session_records.h) and used by every writer and reader: the protocols,
// `capture resume` and `verify`, the fits and the commands. No other part
// reads a session field by its key.
//
//   session.json  "settings": the protocol's options (DecayProtocolOptions,
//                 ...; AllSettings for `phos capture all`), "devices":
//                 DevicesRecord, "sample": SampleRecord
//   frames.jsonl  each FrameRecord's protocol fields: DecayFrameFields, ...
//   events.jsonl  LightSwitchEvent, ExposureEvent, CalibratedEvent and others
//
// Every field a protocol writes is required when its record is read: a
// record that lacks one, or has one of the wrong type, is a UserError naming
// the file, the line and the field, never a default. The one exception is
// the decay's span_s, written only when set: its absence is the schedule
// sessions had before it (DecayProtocolOptions).
//
// In the session library (no image decoding), so fits read these without
// linking the devices.

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "phos/acquire/session_records.h"
#include "phos/util/json.h"

namespace phos {

// ---- settings: each protocol's options ------------------------------------------

// Exposure control shared by the protocols: keep the brightest channel's
// mean signal between these fractions of the ADC range above black.
struct AutoExposure {
  double initial_exposure_s = 0.05;
  double min_exposure_s = 1e-4;
  double max_exposure_s = 4;
  double low_fraction = 0.15, high_fraction = 0.7;

  bool IsValid(std::string* error) const;
  nlohmann::json ToJson() const;
  static AutoExposure FromJson(const nlohmann::json& j, const std::string& where);
};

// Decay after saturation (Sec. 8.4.4): charge with the strongest light, light
// off, then frames on a schedule starting a few ms after light-off. The
// exposure grows as the glow fades (and shrinks if it saturates) to keep the
// signal well above the noise; every frame records its exposure and its
// delay after light-off, so fits can normalize.
struct DecayProtocolOptions {
  std::string charge_light;      // the channel to saturate with
  double charge_s = 5400;        // 90 minutes
  double interval_s = 5;         // one frame every
  double duration_s = 180;       // of decay
  double first_delay_s = 0.005;  // light-off to the first exposure
  // Frames between the first and the second slot, at delays halving from
  // interval_s / 2 down: a state that decays in well under interval_s (the
  // fast state of a two-state material, kr up to a few 1/s) is seen by
  // several frames, not one. A slot a slow camera cannot take is skipped.
  // 0: the plain schedule.
  int early_frames = 6;
  double initial_exposure_s = 0.05;
  double max_exposure_s = 4;
  double gain = 1;
  // Auto-exposure keeps the brightest channel's mean signal between these
  // fractions of the ADC range above black. Not recorded: a session resumes
  // and fits with these values.
  double low_fraction = 0.15, high_fraction = 0.7;
  // A decay over hours (`--decay-span-s`): > 0 replaces the schedule above
  // (interval_s, duration_s, early_frames) with frames log-spaced in delay,
  // kSpanFramesPerDecade per decade, from the first slot at or after
  // kSpanFirstSlot_s to span_s, and the exposure of each frame is predicted
  // from the glow's fade (DecayFrameDelays, RunDecayProtocol). 0: not set,
  // the schedule above. Written to session.json as "span_s" only when set,
  // so a session without it (every session before it existed) reads as the
  // schedule above.
  double span_s = 0;
  static constexpr int kSpanFramesPerDecade = 10;
  static constexpr double kSpanFirstSlot_s = 0.1;
  // The shortest span: one decade of log-spaced frames.
  static constexpr double kSpanMin_s = 10 * kSpanFirstSlot_s;

  bool IsValid(std::string* error) const;
  nlohmann::json ToJson() const;
  static DecayProtocolOptions FromJson(const nlohmann::json& j, const std::string& where);
};

// Excitation per light (Sec. 8.4.6): see RunExcitationProtocol (protocols.h).
struct ExcitationProtocolOptions {
  std::vector<std::string> lights;  // channels to measure, one after the other
  double reset_s = 900;             // darkness before each charge (several 1/kr)
  double first_charge_s = 1;
  double max_charge_s = 4096;
  double plateau_growth = 1.03;  // stop doubling when a doubling adds < 3%
  double delay_s = 0.05;         // light-off to exposure
  double exposure_s = 1;
  double gain = 1;
  int tail_frames = 6;         // 0: one frame per charge (the paper's design)
  double tail_growth = 2;      // each tail frame's exposure over the one before
  double high_fraction = 0.7;  // a tail frame above this share of the range stops the growth

  bool IsValid(std::string* error) const;
  nlohmann::json ToJson() const;
  static ExcitationProtocolOptions FromJson(const nlohmann::json& j, const std::string& where);
};

// Emission spectrum through the LVF (Sec. 8.4.2): see RunSpectrumProtocol.
struct SpectrumProtocolOptions {
  std::string charge_light;
  double charge_s = 600;
  double recharge_s = 300;
  int frames = 4;
  double first_delay_s = 0.005;
  double gain = 1;
  AutoExposure exposure{0.2, 1e-4, 8, 0.15, 0.7};

  bool IsValid(std::string* error) const;
  nlohmann::json ToJson() const;
  static SpectrumProtocolOptions FromJson(const nlohmann::json& j, const std::string& where);
};

// LVF calibration (Sec. 8.4.2): see RunLvfCalibrationProtocol.
struct CalibrationLine {
  std::string light;
  double wavelength_nm;
};

struct LvfCalibrationOptions {
  std::vector<CalibrationLine> lines;
  std::string flat_light = "lamp";
  double flat_temperature_k = 3000;
  double flat_irradiance = 1;  // on the white reference, in the material's units (1: relative only)
  double gain = 1;
  AutoExposure exposure{0.05, 1e-4, 8, 0.15, 0.7};
  int max_tries = 12;  // exposure steps per source before giving up

  bool IsValid(std::string* error) const;
  nlohmann::json ToJson() const;
  static LvfCalibrationOptions FromJson(const nlohmann::json& j, const std::string& where);
};

// `phos capture all`: the four parts' settings, run in kAllOrder.
inline const std::vector<std::string> kAllOrder = {"lvf-calibration", "spectrum", "decay", "excitation"};
struct AllSettings {
  static constexpr const char* kProtocol = "all";
  LvfCalibrationOptions calibration;
  SpectrumProtocolOptions spectrum;
  DecayProtocolOptions decay;
  ExcitationProtocolOptions excitation;

  // A part's settings as its own session.json records them.
  nlohmann::json PartToJson(const std::string& protocol) const;
  nlohmann::json ToJson() const;  // {"parts": {...}, "order": kAllOrder}
  static AllSettings FromJson(const nlohmann::json& j, const std::string& where);
};

// ---- session.json: devices and sample -----------------------------------------------

// What a session ran on: the simulated lab or a real one.
struct DevicesRecord {
  std::string device;  // "sim" or "lab"
  std::string camera;  // the camera's own description
  std::vector<std::string> lights;
  std::string clock;
  std::vector<double> bands_nm;  // the band grid of light_band_irradiance
  // What each light puts on the sample per band, in the material's units:
  // the fit needs it for ke. A lab config may leave a light out.
  std::map<std::string, std::vector<double>> light_band_irradiance;
  // The simulated lab's camera: its seed, model file ("" default) and size.
  unsigned seed = 1;
  std::string camera_csv;
  int width = 0, height = 0;
  // A real lab: its config file, pixel format, lights back end and the config as read.
  std::string lab_config, pixel_format, lights_backend;
  nlohmann::json lab = nlohmann::json::object();

  bool simulated() const { return device == "sim"; }
  // The band irradiance of a light ({} when the session has none for it).
  std::vector<double> BandIrradiance(const std::string& light) const;
  nlohmann::json ToJson() const;
  static DevicesRecord FromJson(const nlohmann::json& j, const std::string& where);
};

// What was measured: the simulated sample's material (the material file's
// JSON, read by model/'s MaterialFromJson) and albedo, with an optional
// inset of another material; or a note for a real sample.
struct SampleRecord {
  std::string material_file;
  std::optional<nlohmann::json> material;
  std::vector<double> albedo;
  std::optional<nlohmann::json> inset_material;
  double inset_radius_fraction = 0.5;
  std::string note;

  nlohmann::json ToJson() const;
  static SampleRecord FromJson(const nlohmann::json& j, const std::string& where);
};

// Reads a start record's settings (as its protocol's options), devices and
// sample as their types, for `verify`: a UserError naming the first that is
// missing or mistyped. Sessions a protocol wrote through the library alone
// may have none of the three; what is there must be whole.
void CheckStartRecord(const SessionRecord& record, const std::string& where);

// ---- frames.jsonl: each protocol's fields --------------------------------------------

// What every frame record measures of its frame (black removed): each
// channel's mean, the share of clipped pixels and, through the LVF, the
// column profile (all channels summed) and its brightest column as a share
// of the ADC's range.
struct FrameSignal {
  std::vector<double> mean_signal_dn;
  double saturated_fraction = 0;
  bool lvf = false;
  std::vector<double> column_mean_dn;  // lvf only
  double peak_column_fraction = 0;     // lvf only

  bool clipped() const { return saturated_fraction > 0; }
  double SumDn() const;  // over channels
  void AddTo(nlohmann::json* j) const;
  static FrameSignal FromJson(const JsonField& f, bool lvf);
};

struct DecayFrameFields {
  static constexpr bool kThroughLvf = false;  // its signal has a column profile
  static constexpr const char* kProtocol = "decay";
  double delay_after_light_off_s = 0;
  FrameSignal signal;

  nlohmann::json ToJson() const;
  static DecayFrameFields FromJson(const JsonField& f);
};

// One frame of an excitation measurement: its charge's first frame (tail 0)
// or one of the tail_frames after it, all with the charge's light-off time.
struct ExcitationFrameFields {
  static constexpr bool kThroughLvf = false;  // its signal has a column profile
  static constexpr const char* kProtocol = "excitation";
  std::string light;
  double charge_s = 0;
  double light_off_s = 0;  // on the run's clock
  double delay_after_light_off_s = 0;
  int tail = 0, tail_frames = 0;
  FrameSignal signal;

  nlohmann::json ToJson() const;
  static ExcitationFrameFields FromJson(const JsonField& f);
};

struct SpectrumFrameFields {
  static constexpr bool kThroughLvf = true;  // its signal has a column profile
  static constexpr const char* kProtocol = "spectrum";
  double delay_after_light_off_s = 0;
  FrameSignal signal;  // through the LVF

  nlohmann::json ToJson() const;
  static SpectrumFrameFields FromJson(const JsonField& f);
};

// A calibration frame: the dark frame, a source of known wavelength (line),
// or the flat field under a lamp of known colour temperature and irradiance.
struct LvfCalibrationFrameFields {
  static constexpr bool kThroughLvf = true;  // its signal has a column profile
  static constexpr const char* kProtocol = "lvf-calibration";
  enum class Kind { kDark, kLine, kFlat };
  Kind kind = Kind::kDark;
  std::string light;         // line and flat
  double wavelength_nm = 0;  // line
  double temperature_k = 0;  // flat
  double irradiance = 0;     // flat
  FrameSignal signal;        // through the LVF

  static LvfCalibrationFrameFields Dark();
  static LvfCalibrationFrameFields Line(const std::string& light, double wavelength_nm);
  static LvfCalibrationFrameFields Flat(const std::string& light, double temperature_k, double irradiance);
  nlohmann::json ToJson() const;
  static LvfCalibrationFrameFields FromJson(const JsonField& f);
};

// A frame's record with its protocol's fields read.
template <typename Fields>
struct ProtocolFrame {
  FrameRecord record;
  int line = 0;  // in frames.jsonl
  Fields fields;
};

// Every frame of a session of that protocol, typed: a UserError naming
// frames.jsonl's line and the field when one is missing or mistyped (the
// frame records themselves are read by ReadFrameRecords).
template <typename Fields>
std::vector<ProtocolFrame<Fields>> ReadProtocolFrames(const std::filesystem::path& session_dir,
                                                      const FrameRecords& records);
template <typename Fields>
std::vector<ProtocolFrame<Fields>> ReadProtocolFrames(const std::filesystem::path& session_dir) {
  return ReadProtocolFrames<Fields>(session_dir, ReadFrameRecords(session_dir));
}

// What is wrong with each frame record's protocol fields, for a session of
// `protocol` ("all" has none): one line per bad record, naming it.
std::vector<std::string> ProtocolFieldProblems(const std::filesystem::path& session_dir, const std::string& protocol,
                                               const FrameRecords& records);

// ---- events.jsonl --------------------------------------------------------------------

// A light switched (by a protocol, or off by the signal handler, which
// records no time: t_s is then NaN).
struct LightSwitchEvent {
  double t_s = 0;
  std::string channel;
  bool on = false;
  nlohmann::json ToJson() const;
};
// Whether the frame `seq` was well exposed (spectrum, calibration).
struct ExposureEvent {
  double t_s = 0;
  int seq = 0;
  bool well_exposed = false;
  nlohmann::json ToJson() const;
};
// A calibration source measured ("" is the dark frame).
struct CalibratedEvent {
  double t_s = 0;
  std::string light;
  nlohmann::json ToJson() const;
};
// A rig change (the LVF or the white reference in place or removed).
struct RigEvent {
  double t_s = 0;
  std::string what;
  bool in_place = false;
  nlohmann::json ToJson() const;
};
// A protocol's start or end.
struct ProtocolEvent {
  double t_s = 0;
  std::string protocol, phase;
  nlohmann::json ToJson() const;
};

// The events of one kind in a session, typed; a malformed one is a UserError
// naming events.jsonl's line and the field.
std::vector<LightSwitchEvent> ReadLightSwitchEvents(const std::filesystem::path& session_dir);
std::vector<ExposureEvent> ReadExposureEvents(const std::filesystem::path& session_dir);
std::vector<CalibratedEvent> ReadCalibratedEvents(const std::filesystem::path& session_dir);
// How many times a session was resumed (its "resume" events).
int CountResumes(const std::filesystem::path& session_dir);
// The "resume" event a protocol records when it goes on, with what it kept.
nlohmann::json ResumeEvent(double t_s, const char* kept_key, const nlohmann::json& kept);

}  // namespace phos
