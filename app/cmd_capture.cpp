// phos capture <protocol>: run a capture protocol against a device and write
// the session folder as it goes. So far: decay and excitation, on the
// simulated lab.

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
  std::string device = "sim", sim_material, out;
  double sim_albedo = 0.8;
  unsigned seed = 1;
};

// The simulated lab every protocol runs on with --device sim, and the start
// record that describes it.
struct SimSetup {
  VirtualClock clock;
  Material material;
  std::vector<double> albedo;
  std::unique_ptr<SimulatedLab> lab;

  explicit SimSetup(const CaptureArgs& args) {
    if (args.device != "sim")
      ThrowUserError("", "--device", "only 'sim' (the simulated lab) is available so far; real cameras are to come");
    if (!(args.sim_albedo >= 0 && args.sim_albedo <= 1))
      ThrowUserError("", "--sim-albedo", "expected a reflectance in [0, 1], got " + FormatDouble(args.sim_albedo));
    material = LoadMaterial(args.sim_material);
    albedo = material.albedo ? *material.albedo
                             : std::vector<double>(static_cast<std::size_t>(material.band_count()), args.sim_albedo);
    CameraModel camera = DefaultCameraModel();
    camera.seed = args.seed;
    lab = std::make_unique<SimulatedLab>(material, albedo, DefaultLights(), camera, clock);
  }

  nlohmann::json StartRecord(const std::string& protocol, const CaptureArgs& args, nlohmann::json settings) {
    settings["seed"] = args.seed;
    return {{"protocol", protocol},
            {"sample", {{"material_file", args.sim_material}, {"material", MaterialToJson(material)}, {"albedo", albedo}}},
            {"devices", {{"camera", lab->description()}, {"lights", lab->lights().channels()}, {"clock", "virtual"}}},
            {"settings", settings},
            {"versions", {{"phos", "0.1.0"}}}};
  }
};

void AddSimOptions(CLI::App* cmd, CaptureArgs& args) {
  cmd->add_option("--device", args.device, "sim (the simulated lab; default)");
  cmd->add_option("--sim-material", args.sim_material, "material file of the simulated sample")->required();
  cmd->add_option("--sim-albedo", args.sim_albedo, "sample reflectance when the material has none (default 0.8)");
  cmd->add_option("--out", args.out, "session folder to create (new or empty)")->required();
  cmd->add_option("--seed", args.seed, "noise seed of the simulated camera (default 1)");
}

struct DecayArgs : CaptureArgs {
  std::string light = "led405";
  DecayProtocolOptions decay;
};

void RunCaptureDecay(DecayArgs args) {
  args.decay.charge_light = args.light;
  std::string error;
  if (!args.decay.IsValid(&error)) ThrowUserError("", "decay protocol", error);
  SimSetup sim(args);
  SessionWriter session(args.out, sim.StartRecord("decay", args,
                                                  {{"charge_light", args.decay.charge_light},
                                                   {"charge_s", args.decay.charge_s},
                                                   {"interval_s", args.decay.interval_s},
                                                   {"duration_s", args.decay.duration_s},
                                                   {"first_delay_s", args.decay.first_delay_s},
                                                   {"initial_exposure_s", args.decay.initial_exposure_s},
                                                   {"max_exposure_s", args.decay.max_exposure_s}}));
  DecayProtocolResult result = RunDecayProtocol(*sim.lab, sim.lab->lights(), sim.clock, session, args.decay);
  std::printf("phos capture decay: %d frames over %s s after a %s s charge under '%s' -> %s\n", result.frames,
              FormatDouble(args.decay.duration_s).c_str(), FormatDouble(args.decay.charge_s).c_str(),
              args.decay.charge_light.c_str(), args.out.c_str());
}

struct ExcitationArgs : CaptureArgs {
  ExcitationProtocolOptions excitation;
};

void RunCaptureExcitation(ExcitationArgs args) {
  if (args.excitation.lights.empty()) args.excitation.lights = {"led405"};
  std::string error;
  if (!args.excitation.IsValid(&error)) ThrowUserError("", "excitation protocol", error);
  SimSetup sim(args);
  SessionWriter session(args.out, sim.StartRecord("excitation", args,
                                                  {{"lights", args.excitation.lights},
                                                   {"reset_s", args.excitation.reset_s},
                                                   {"first_charge_s", args.excitation.first_charge_s},
                                                   {"max_charge_s", args.excitation.max_charge_s},
                                                   {"plateau_growth", args.excitation.plateau_growth},
                                                   {"delay_s", args.excitation.delay_s},
                                                   {"exposure_s", args.excitation.exposure_s}}));
  ExcitationProtocolResult result =
      RunExcitationProtocol(*sim.lab, sim.lab->lights(), sim.clock, session, args.excitation);
  std::printf("phos capture excitation: %d frames for %zu light(s) -> %s\n", result.frames,
              args.excitation.lights.size(), args.out.c_str());
}

}  // namespace

void RegisterCapture(CLI::App& app) {
  CLI::App* capture = app.add_subcommand("capture", "Run a capture protocol and write its session folder as it goes.");
  capture->require_subcommand(1);

  auto decay_args = std::make_shared<DecayArgs>();
  CLI::App* decay = capture->add_subcommand(
      "decay",
      "Decay after saturation (Sec. 8.4.4): charge with one light, switch it off, then take frames on a\n"
      "schedule starting a few ms after light-off, the exposure growing as the glow fades. Writes\n"
      "session.json, frames.jsonl, events.jsonl, frames/*.tif (16-bit) and stop.json into --out.");
  AddSimOptions(decay, *decay_args);
  decay->add_option("--light", decay_args->light,
                    "light channel to charge with: led365, led405 (default), white, lamp. It must only reach\n"
                    "bands whose ke the material knows");
  decay->add_option("--charge-s", decay_args->decay.charge_s, "seconds of charging (default 5400, 90 min)");
  decay->add_option("--interval-s", decay_args->decay.interval_s, "seconds between frames (default 5)");
  decay->add_option("--duration-s", decay_args->decay.duration_s, "seconds of decay to record (default 180)");
  decay->add_option("--first-delay-s", decay_args->decay.first_delay_s, "light-off to the first exposure (default 0.005)");
  decay->add_option("--max-exposure-s", decay_args->decay.max_exposure_s, "longest exposure (default 4)");
  decay->callback([decay_args] { RunCaptureDecay(*decay_args); });

  auto excitation_args = std::make_shared<ExcitationArgs>();
  CLI::App* excitation = capture->add_subcommand(
      "excitation",
      "Excitation per light (Sec. 8.4.6): for each light, reset in darkness, charge for t, switch off,\n"
      "wait a fixed short delay and expose; t doubles from --first-charge-s until a doubling adds less\n"
      "than 3%, then the midpoints of the rising part are measured too.");
  AddSimOptions(excitation, *excitation_args);
  excitation->add_option("--light", excitation_args->excitation.lights,
                         "light channel(s) to measure, one after the other (default led405)");
  excitation->add_option("--reset-s", excitation_args->excitation.reset_s, "darkness before each charge (default 900)");
  excitation->add_option("--first-charge-s", excitation_args->excitation.first_charge_s, "first charge time (default 1)");
  excitation->add_option("--max-charge-s", excitation_args->excitation.max_charge_s, "longest charge (default 4096)");
  excitation->add_option("--delay-s", excitation_args->excitation.delay_s, "light-off to the exposure (default 0.05)");
  excitation->add_option("--exposure-s", excitation_args->excitation.exposure_s, "exposure (default 1)");
  excitation->callback([excitation_args] { RunCaptureExcitation(*excitation_args); });
}

}  // namespace phos::app
