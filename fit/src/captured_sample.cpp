#include "phos/fit/captured_sample.h"

#include "phos/model/material.h"
#include "phos/util/error.h"

namespace phos {
namespace {

namespace fs = std::filesystem;

std::string StopOf(const fs::path& dir) {
  const std::optional<StopRecord> stop = ReadStopRecord(dir);
  return stop ? stop->how : "";
}

// A part's devices: its own record's, or the folder's (a part a protocol
// wrote through the library alone may have none).
DevicesRecord DevicesOf(const SessionRecord& record, const std::string& where, const DevicesRecord& folder) {
  return record.devices.empty() ? folder : DevicesRecord::FromJson(record.devices, where + ": devices");
}

// A session of the part's protocol in part_dir.
template <typename Part>
Part LoadPart(const fs::path& part_dir, const DevicesRecord& folder, std::vector<std::string>* notes) {
  using Fields = typename Part::FieldsType;
  const std::string protocol = Fields::kProtocol;
  const std::string where = (part_dir / "session.json").string();
  const SessionRecord record = ReadSessionRecord(part_dir);
  if (record.protocol != protocol)
    ThrowUserError(where, "protocol", "expected \"" + protocol + "\", got \"" + record.protocol + "\"");
  Part part;
  part.source = part_dir.string();
  part.settings = Part::SettingsType::FromJson(record.settings, where + ": settings");
  part.devices = DevicesOf(record, where, folder);
  // Every frame checked (size and checksum, as resume does): a fit is never
  // built on a bad frame.
  const FrameRecords records = ReadFrameRecords(part_dir);
  RequireGoodFrames(part_dir, records);
  if (records.torn)
    notes->push_back((part_dir / "frames.jsonl").string() +
                     ": torn last line left out ('phos capture resume' repairs it)");
  part.frames = ReadProtocolFrames<Fields>(part_dir, records);
  part.switches = ReadLightSwitchEvents(part_dir);
  part.stop = StopOf(part_dir);
  // Last, so a record that lacks a field is named as such first.
  RequireRecordChecksums(part_dir);
  return part;
}

// The part of an `all` folder, if it was captured.
template <typename Part>
std::optional<Part> LoadPartOf(const fs::path& dir, const DevicesRecord& folder, std::vector<std::string>* notes) {
  const fs::path part_dir = dir / Part::FieldsType::kProtocol;
  std::error_code ec;
  if (!fs::exists(part_dir / "session.json", ec)) return std::nullopt;
  return LoadPart<Part>(part_dir, folder, notes);
}

}  // namespace

CapturedSample LoadCapturedSample(const fs::path& dir) {
  const SessionRecord top = ReadSessionRecord(dir);
  const std::string where = (dir / "session.json").string();
  if (top.protocol != AllSettings::kProtocol)
    ThrowUserError(dir.string(), "",
                   "is a '" + top.protocol + "' session; fit session takes the folder of 'phos capture all'");
  CapturedSample sample;
  sample.source = dir.string();
  sample.stop = StopOf(dir);
  DevicesRecord devices;
  if (!top.devices.empty()) {
    devices = DevicesRecord::FromJson(top.devices, where + ": devices");
    sample.bands.edges_nm = devices.bands_nm;
  }
  if (!top.sample.empty()) {
    const SampleRecord recorded = SampleRecord::FromJson(top.sample, where + ": sample");
    if (recorded.material) sample.name = MaterialFromJson(*recorded.material, where + ": sample").name;
  }
  // Every part read (and its frames checked) before any is fitted: a damaged
  // session is refused naming the record or frame, never fitted in part.
  sample.calibration = LoadPartOf<CapturedSample::Calibration>(dir, devices, &sample.notes);
  sample.spectrum = LoadPartOf<CapturedSample::Spectrum>(dir, devices, &sample.notes);
  sample.decay = LoadPartOf<CapturedSample::Decay>(dir, devices, &sample.notes);
  sample.excitation = LoadPartOf<CapturedSample::Excitation>(dir, devices, &sample.notes);
  RequireRecordChecksums(dir);
  return sample;
}

CapturedSample::Decay LoadDecaySession(const fs::path& dir, std::vector<std::string>* notes) {
  const std::string protocol = ReadSessionRecord(dir).protocol;
  if (protocol != DecayFrameFields::kProtocol)
    ThrowUserError(dir.string(), "",
                   "is a '" + protocol + "' session; a decay map needs a decay session" +
                       (protocol == AllSettings::kProtocol ? " (this folder's decay part: phos fit map " +
                                                                 (dir / DecayFrameFields::kProtocol).string() + ")"
                                                           : ""));
  return LoadPart<CapturedSample::Decay>(dir, DevicesRecord{}, notes);
}

DecayCharge ChargeBeforeDecay(const CapturedSample::Decay& decay) {
  DecayCharge charge;
  charge.band_irradiance = decay.devices.BandIrradiance(decay.settings.charge_light);
  charge.charge_s = decay.settings.charge_s;
  if (!(charge.charge_s > 0)) charge.band_irradiance.clear();
  return charge;
}

std::vector<DecaySample> DecaySamples(const CapturedSample::Decay& decay, int* clipped) {
  std::vector<DecaySample> samples;
  *clipped = 0;
  for (const ProtocolFrame<DecayFrameFields>& frame : decay.frames) {
    if (frame.fields.signal.clipped()) {
      ++*clipped;
      continue;
    }
    samples.push_back({&frame, frame.fields.delay_after_light_off_s + frame.record.exposure_s / 2});
  }
  return samples;
}

}  // namespace phos
