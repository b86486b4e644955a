#pragma once
// A real lab: the lab config file (phos.lab/1) that maps light channels to
// GPIO lines and names the camera, the libgpiod back end for the lights, and
// the devices a protocol runs on when `phos capture --lab LAB.json` is given.
// docs/lab.md describes the format, the wiring and each protocol's duration.

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "phos/acquire/aravis_camera.h"
#include "phos/acquire/clock.h"
#include "phos/acquire/lights.h"
#include "phos/acquire/protocol_records.h"
#include "phos/acquire/protocols.h"
#include "phos/model/spectral.h"

namespace phos {

struct LabChannel {
  std::string name;         // "led365", "shutter", "camera_trigger", ...
  unsigned line = 0;        // offset on the GPIO chip
  bool active_low = false;  // true for the usual relay boards: low = on
  // What the light puts on the sample, per band of LabConfig::bands, from a
  // spectroradiometer reading (irradiance_csv: wavelength_nm, irradiance per
  // nm, in the material's irradiance units). Empty: not measured, and the fit
  // reports this light's excitation rate but cannot turn it into ke.
  std::vector<double> band_irradiance;
};

struct LabConfig {
  std::filesystem::path source;
  // Camera (Aravis device id: serial, IP address, "Fake_1" for Aravis's simulator).
  std::string camera;
  std::string pixel_format;  // empty: the deepest mono format
  int binning_x = 1, binning_y = 1;
  std::optional<std::array<int, 4>> region;  // x, y, width, height
  AravisCamera::Trigger trigger = AravisCamera::Trigger::kSoftware;
  std::string trigger_source = "Line1";  // hardware trigger input
  std::string trigger_channel;           // GPIO channel wired to it
  double timeout_s = 5;
  // Lights: "gpiod" (GPIO lines on `chip`) or "none" (a dry run: switches
  // are recorded, nothing is driven; for trying a camera alone).
  std::string lights_backend = "gpiod";
  std::string chip = "gpiochip0";
  std::vector<LabChannel> channels;
  // The protocols' defaults for this lab.
  std::string charge_light = "led405";
  std::vector<CalibrationLine> calibration_lines;
  std::string flat_light = "lamp";
  double flat_temperature_k = 3000;
  double flat_irradiance = 1;  // on the white reference; 1 = relative (Lambda's scale is then relative too)
  SpectralGrid bands = SpectralGrid::Paper();  // the grid of band_irradiance and of fitted materials
  // "prompt": the operator moves the LVF and the white reference when asked
  // (Enter on the terminal); "fixed": nothing to move (tests, fixed rigs).
  std::string rig = "prompt";

  nlohmann::json ToJson() const;
};

// Reads and checks a lab config; every problem is one UserError naming the
// file and the field.
LabConfig LoadLabConfig(const std::filesystem::path& path);
// The same from the file's text: path names it in messages and in
// LabConfig::source, and an irradiance_csv is relative to its folder
// (LoadLabConfig is ReadFileText, then this; the fuzz harness calls it).
LabConfig LabConfigFromJson(std::string_view text, const std::filesystem::path& path);

// Lights on GPIO lines through libgpiod (v1.6 C++ API). All lines are
// requested as outputs and driven to "off" at once (a lab powers up dark);
// active-low lines are handled by the kernel's active-low flag, so "on" is
// always 1 here. A chip or line that cannot be opened is a UserError.
class GpiodLights final : public Lights {
 public:
  GpiodLights(const std::string& chip, const std::vector<LabChannel>& channels, const Clock& clock);
  ~GpiodLights() override;
  std::vector<std::string> channels() const override;
  void Set(const std::string& channel, bool on) override;
  bool IsOn(const std::string& channel) const override;
  const std::vector<LightEvent>& events() const { return events_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  const Clock& clock_;
  std::vector<LightEvent> events_;
};

// The devices of a lab config, opened: camera set up as configured, lights
// off, and the rig change (prompt or fixed).
struct OpenedLab {
  SystemClock clock;
  std::unique_ptr<AravisCamera> camera;
  std::unique_ptr<Lights> lights;
  RigChange rig;
  DevicesRecord description;  // for the session's start record
};
std::unique_ptr<OpenedLab> OpenLab(const LabConfig& config);

}  // namespace phos
