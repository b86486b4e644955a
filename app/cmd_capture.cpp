// phos capture <protocol>: run a capture protocol against a device and write
// the session folder as it goes. So far: the decay protocol on the simulated lab.

#include <cstdio>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "commands.h"
#include "phos/acquire/protocols.h"
#include "phos/acquire/sim_lab.h"
#include "phos/model/material.h"
#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos::app {
namespace {

struct CaptureArgs {
  std::string device = "sim", sim_material, out, light = "led405";
  double sim_albedo = 0.8;
  unsigned seed = 1;
  DecayProtocolOptions decay;
};

void RunCaptureDecay(CaptureArgs args) {
  if (args.device != "sim")
    ThrowUserError("", "--device", "only 'sim' (the simulated lab) is available so far; the Aravis back end is to come");
  if (args.sim_material.empty()) ThrowUserError("", "--sim-material", "required with --device sim");
  if (!(args.sim_albedo >= 0 && args.sim_albedo <= 1))
    ThrowUserError("", "--sim-albedo", "expected a reflectance in [0, 1], got " + FormatDouble(args.sim_albedo));
  Material material = LoadMaterial(args.sim_material);
  std::vector<double> albedo =
      material.albedo ? *material.albedo : std::vector<double>(static_cast<std::size_t>(material.band_count()), args.sim_albedo);
  std::string error;
  args.decay.charge_light = args.light;
  if (!args.decay.IsValid(&error)) ThrowUserError("", "decay protocol", error);

  VirtualClock clock;
  CameraModel camera = DefaultCameraModel();
  camera.seed = args.seed;
  SimulatedLab lab(material, albedo, DefaultLights(), camera, clock);
  nlohmann::json start = {
      {"protocol", "decay"},
      {"sample", {{"material_file", args.sim_material}, {"material", MaterialToJson(material)}, {"albedo", albedo}}},
      {"devices", {{"camera", lab.description()}, {"lights", lab.lights().channels()}, {"clock", "virtual"}}},
      {"settings",
       {{"charge_light", args.decay.charge_light},
        {"charge_s", args.decay.charge_s},
        {"interval_s", args.decay.interval_s},
        {"duration_s", args.decay.duration_s},
        {"first_delay_s", args.decay.first_delay_s},
        {"initial_exposure_s", args.decay.initial_exposure_s},
        {"max_exposure_s", args.decay.max_exposure_s},
        {"seed", args.seed}}},
      {"versions", {{"phos", "0.1.0"}}}};
  SessionWriter session(args.out, start);
  DecayProtocolResult result = RunDecayProtocol(lab, lab.lights(), clock, session, args.decay);
  std::printf("phos capture decay: %d frames over %s s after a %s s charge under '%s' -> %s\n", result.frames,
              FormatDouble(args.decay.duration_s).c_str(), FormatDouble(args.decay.charge_s).c_str(),
              args.decay.charge_light.c_str(), args.out.c_str());
}

}  // namespace

void RegisterCapture(CLI::App& app) {
  CLI::App* capture = app.add_subcommand("capture", "Run a capture protocol and write its session folder as it goes.");
  capture->require_subcommand(1);
  auto args = std::make_shared<CaptureArgs>();
  CLI::App* decay = capture->add_subcommand(
      "decay",
      "Decay after saturation (Sec. 8.4.4): charge with one light, switch it off, then take frames on a\n"
      "schedule starting a few ms after light-off, the exposure growing as the glow fades. Writes\n"
      "session.json, frames.jsonl, events.jsonl, frames/*.tif (16-bit) and stop.json into --out.");
  decay->add_option("--device", args->device, "sim (the simulated lab; default)");
  decay->add_option("--sim-material", args->sim_material, "material file of the simulated sample")->required();
  decay->add_option("--sim-albedo", args->sim_albedo, "sample reflectance when the material has none (default 0.8)");
  decay->add_option("--out", args->out, "session folder to create (new or empty)")->required();
  decay->add_option("--light", args->light,
                    "light channel to charge with: led365, led405 (default), white, lamp. It must only reach\n"
                    "bands whose ke the material knows");
  decay->add_option("--charge-s", args->decay.charge_s, "seconds of charging (default 5400, 90 min)");
  decay->add_option("--interval-s", args->decay.interval_s, "seconds between frames (default 5)");
  decay->add_option("--duration-s", args->decay.duration_s, "seconds of decay to record (default 180)");
  decay->add_option("--first-delay-s", args->decay.first_delay_s, "light-off to the first exposure (default 0.005)");
  decay->add_option("--max-exposure-s", args->decay.max_exposure_s, "longest exposure (default 4)");
  decay->add_option("--seed", args->seed, "noise seed of the simulated camera (default 1)");
  decay->callback([args] { RunCaptureDecay(*args); });
}

}  // namespace phos::app
