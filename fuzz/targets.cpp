#include "targets.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include <nlohmann/json.hpp>

#include "phos/acquire/lab.h"
#include "phos/acquire/session_records.h"
#include "phos/editor/solve.h"
#include "phos/fit/curve.h"
#include "phos/model/material.h"
#include "phos/model/schedule.h"
#include "phos/model/simulate.h"
#include "phos/render/scene.h"
#include "phos/util/csv.h"
#include "phos/util/error.h"
#include "phos/util/json.h"

namespace phos::fuzz {
namespace {

std::filesystem::path& FixturesDir() {
  static std::filesystem::path dir = PHOS_FUZZ_FIXTURES_DIR;
  return dir;
}

// Runs a loader: a UserError of one line is a proper refusal; one of
// several lines is a finding (every rejection is one line), as is any other
// exception (the `phos` command would print "internal error").
template <typename F>
bool Refusal(F&& load) {
  try {
    load();
    return true;
  } catch (const UserError& e) {
    const std::string_view what = e.what();
    if (what.find('\n') != std::string_view::npos || what.find('\r') != std::string_view::npos)
      throw std::logic_error("a user error of several lines: " + std::string(what));
    return false;
  }
}

// A scratch folder of this process, for the loaders that read a file.
const std::filesystem::path& ScratchDir() {
  static const std::filesystem::path dir = [] {
    std::string pattern = (std::filesystem::temp_directory_path() / "phos-fuzz-XXXXXX").string();
    if (::mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(ScratchDir(), ec);
    });
    return std::filesystem::path(pattern);
  }();
  return dir;
}

void WriteFile(const std::filesystem::path& path, std::string_view data) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(data.data(), static_cast<std::streamsize>(data.size()));
  if (!out) throw std::runtime_error("cannot write " + path.string());
}

void RequireFinite(const std::vector<double>& values, const char* what) {
  for (double v : values)
    if (!std::isfinite(v))
      throw std::logic_error(std::string("an accepted material simulated to a non-finite ") + what);
}

}  // namespace

void SetFixturesDir(const char* dir) { FixturesDir() = dir; }

bool Material(std::string_view data) {
  return Refusal([&] {
    phos::Material material = MaterialFromJson(ParseJsonText(data, "fuzz.json"), "fuzz.json");
    // Accepted means usable: within the documented ranges every output is
    // finite, even at the largest irradiance phos accepts (kr = 1e308 was
    // accepted and gave non-finite output).
    AssumeUnknownKeZero(material);
    for (double E : {1.0, kMaxIrradiance}) {
      const std::vector<double> irradiance(static_cast<std::size_t>(material.band_count()), E);
      SimulationOptions options;
      options.dt_s = 5;
      const SimulationResult result =
          Simulate(material, IrradianceSchedule::ChargeThenDecay(irradiance, 10, 10), options, "fuzz.json");
      RequireFinite(result.r, "state");
      RequireFinite(result.L, "radiance");
    }
  });
}

bool Scene(std::string_view data) {
  return Refusal(
      [&] { render::SceneFromJson(ParseJsonText(data, "fuzz.json"), FixturesDir() / "scenes", "fuzz.json"); });
}

bool ObjMesh(std::string_view data) {
  return Refusal(
      [&] { render::ParseMesh(data, ".obj", FixturesDir() / "scenes/meshes", "fuzz.obj", "", "fuzz.json: mesh"); });
}

bool GltfMesh(std::string_view data) {
  const bool binary = data.substr(0, 4) == "glTF";
  // The same file as a scene's mesh and as its KHR_lights_punctual lights
  // (a light entry {"type": "gltf"}): each either accepts it or refuses it
  // in one line; the verdict is the mesh's (a file of lights alone is no mesh).
  const bool mesh = Refusal([&] {
    render::ParseMesh(data, binary ? ".glb" : ".gltf", FixturesDir() / "scenes/meshes", "fuzz.gltf", "",
                      "fuzz.json: mesh");
  });
  Refusal([&] {
    for (const render::PunctualLight& p : render::ParseGltfLights(data, binary, FixturesDir() / "scenes/meshes",
                                                                   "fuzz.gltf", "fuzz.json: lights[0].file"))
      if (!p.light.position.allFinite() || !p.light.direction.allFinite() || !p.colour.allFinite())
        throw std::logic_error("a glTF light that is not finite: " + p.light.name);
  });
  return mesh;
}

bool Constraints(std::string_view data) {
  return Refusal([&] { editor::ProblemFromJson(ParseJsonText(data, "fuzz.json"), "fuzz.json"); });
}

bool LabConfig(std::string_view data) {
  // Named as a file beside fuzz/seeds/lab/led365.csv, so that an
  // irradiance_csv of the seeds resolves (and is read: a CSV of its own).
  static const std::filesystem::path path = FixturesDir().parent_path() / "fuzz/seeds/lab/fuzz-lab.json";
  return Refusal([&] { LabConfigFromJson(data, path); });
}

bool CurveCsv(std::string_view data) {
  // As `phos fit decay-curve` and `charge-curve` read a file (app/cmd_fit_curve.cpp).
  return Refusal([&] {
    const CsvTable table = ParseCsv(std::string(data), "fuzz.csv");
    if (table.header.size() < 2) ThrowUserError("fuzz.csv", "header", "expected columns t,value[,value...]");
    Curve curve;
    curve.t_s = table.columns[0];
    for (std::size_t c = 1; c < table.header.size(); ++c) {
      curve.channels.push_back(table.columns[c]);
      curve.names.push_back(table.header[c]);
    }
    KeepTimeWindow(&curve, -1e300, 1e300);
    SortByTime(&curve, "fuzz.csv");
    ValidateCurve(curve, 4, "fuzz.csv");
    SmallestTimeStep(curve);
    PeakAfterRise(curve);
    for (const auto& channel : curve.channels) SampleWeights(channel, Weighting::kPoisson);
  });
}

namespace {

// A session folder of this process: session.json, and frames.jsonl,
// events.jsonl and stop.json as hard links to it (one write of the input
// serves the four readers), with frame files for the checks: 000001 as the
// seeds record it (23 bytes, XXH3 f7fe1eae775cab43), 000002 a folder, 000003
// a symbolic link to /dev/zero, 000004 empty; the others are missing.
const std::filesystem::path& SessionDir() {
  static const std::filesystem::path dir = [] {
    const std::filesystem::path d = ScratchDir() / "session";
    std::filesystem::create_directories(d / "frames/000002.tif");
    WriteFile(d / "frames/000001.tif", std::string_view("II*\0phos fuzz frame 1\n", 23));
    std::filesystem::create_symlink("/dev/zero", d / "frames/000003.tif");
    WriteFile(d / "frames/000004.tif", "");
    WriteFile(d / "session.json", "");
    for (const char* name : {"frames.jsonl", "events.jsonl", "stop.json"})
      std::filesystem::create_hard_link(d / "session.json", d / name);
    return d;
  }();
  return dir;
}

}  // namespace

bool SessionRecords(std::string_view data) {
  const std::filesystem::path& dir = SessionDir();
  WriteFile(dir / "session.json", data);  // truncates the one file the four names share
  bool accepted = true;
  accepted &= Refusal([&] { ReadSessionRecord(dir); });
  accepted &= Refusal([&] { ReadStopRecord(dir); });
  accepted &= Refusal([&] { ReadEventRecords(dir); });
  // Each record against its own checksum: a report, never a crash.
  Refusal([&] { RecordChecksumProblems(dir); });
  accepted &= Refusal([&] {
    const FrameRecords records = ReadFrameRecords(dir);
    for (const FrameRecord& frame : records.frames) {
      CheckFrameFile(dir, frame);
      // What a writer records of an accepted frame, a reader accepts.
      try {
        FrameRecord::FromJson(frame.ToJson(), "fuzz: round trip");
      } catch (const UserError& e) {
        throw std::logic_error(std::string("an accepted frame record does not read back: ") + e.what());
      }
    }
  });
  return accepted;
}

}  // namespace phos::fuzz
