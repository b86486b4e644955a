#pragma once
// A captured sample, read: the folder `phos capture all` writes, typed by the
// session records' owner (phos/acquire/protocol_records.h), every listed
// frame checked against its recorded size and checksum. FitSession
// (session_fit.h) fits it in memory, so a test can build one without files.

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "phos/acquire/protocol_records.h"
#include "phos/model/spectral.h"

namespace phos {

struct CapturedSample {
  // One part (protocol) of the folder: its settings, the devices it ran on,
  // its frames with their protocol's fields, the light switches it recorded,
  // and how it stopped.
  template <typename Settings, typename Fields>
  struct Part {
    using SettingsType = Settings;
    using FieldsType = Fields;
    std::string source;  // its folder, for messages
    Settings settings;
    DevicesRecord devices;
    std::vector<ProtocolFrame<Fields>> frames;
    std::vector<LightSwitchEvent> switches;
    std::string stop;  // complete, aborted, failed, or "" (killed, or still running)
  };
  using Calibration = Part<LvfCalibrationOptions, LvfCalibrationFrameFields>;
  using Spectrum = Part<SpectrumProtocolOptions, SpectrumFrameFields>;
  using Decay = Part<DecayProtocolOptions, DecayFrameFields>;
  using Excitation = Part<ExcitationProtocolOptions, ExcitationFrameFields>;

  std::string source;           // the folder
  std::string stop;             // how the whole capture stopped ("" if it did not)
  std::string name = "sample";  // the simulated sample's material name, if any
  SpectralGrid bands = SpectralGrid::Paper();
  std::optional<Calibration> calibration;
  std::optional<Spectrum> spectrum;
  std::optional<Decay> decay;
  std::optional<Excitation> excitation;
  // What loading noted: a torn last line left out.
  std::vector<std::string> notes;
};

// Reads an `all` folder. Not a capture session, another protocol's session,
// a record that lacks a field or has one of the wrong type, or a listed
// frame whose file is not as recorded: a UserError naming the file, the
// line and the field (or the frame). A part not captured is absent.
CapturedSample LoadCapturedSample(const std::filesystem::path& dir);

// A decay session on its own (phos fit map), typed and its frames checked
// as LoadCapturedSample's; a torn last line left out is said in `notes`.
// Another protocol's session is a UserError naming the folder (and, for an
// `all` folder, its decay part).
CapturedSample::Decay LoadDecaySession(const std::filesystem::path& dir, std::vector<std::string>* notes);

// How a decay's sample was charged: the charge light's band irradiance and
// the charge time, when the session records both (band_irradiance empty
// otherwise: a lab config may give none for the light).
struct DecayCharge {
  double charge_s = 0;
  std::vector<double> band_irradiance;
};
DecayCharge ChargeBeforeDecay(const CapturedSample::Decay& decay);

// The frames every decay fit uses (Sec. 8.4.4): the unclipped ones, each
// sampled at the middle of its exposure (t_s after light-off); `clipped`
// counts those left out.
struct DecaySample {
  const ProtocolFrame<DecayFrameFields>* frame;
  double t_s;
};
std::vector<DecaySample> DecaySamples(const CapturedSample::Decay& decay, int* clipped);

}  // namespace phos
