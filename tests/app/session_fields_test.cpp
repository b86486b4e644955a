// Every field a capture protocol records is required (acquire's
// protocol_records.h owns them): dropped from a session `phos capture all`
// wrote, each one in turn, `phos capture verify` lists it as a problem naming
// the file, the line and the field, and `phos fit session` refuses with one
// line naming it (exit 2), never fitting with a default in its place.

#include <gtest/gtest.h>

#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "phos/acquire/session_records.h"
#include "phos/util/json.h"
#include "test_util.h"

namespace phos {
namespace {

namespace fs = std::filesystem;
using testing::RunPhos;

// What a dropped field must produce: verify lists `expected` (exit 2, one
// line per problem), fit session says it in one line (exit 2).
void ExpectNamed(const fs::path& folder, const std::string& expected, const std::string& what) {
  const auto verify = RunPhos("capture verify " + folder.string());
  EXPECT_EQ(verify.exit_code, 2) << what;
  EXPECT_NE(verify.out.find(expected), std::string::npos) << what << ": " << verify.out;
  const fs::path out = folder.parent_path() / "m.json";
  const auto fit = RunPhos("fit session " + folder.string() + " --out " + out.string());
  EXPECT_TRUE(testing::IsOneLineUserError(fit, expected)) << what;
  EXPECT_FALSE(fs::exists(out)) << what;
}

// Each line of frames.jsonl of one kind ("" for every kind but the LVF
// calibration's, whose dark, line and flat frames each hold other fields):
// the first frame of each kind has its protocol fields dropped in turn.
void DropEachFrameField(const fs::path& folder, const std::string& part) {
  const fs::path frames = folder / part / "frames.jsonl";
  const std::string original = testing::ReadText(frames);
  const std::vector<nlohmann::json> lines = testing::ReadJsonLines(frames);
  const std::set<std::string> kEnvelope(std::begin(kFrameRecordKeys), std::end(kFrameRecordKeys));
  std::set<std::string> kinds_done;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const std::string kind = lines[i].value("kind", "");
    if (!kinds_done.insert(kind).second) continue;
    for (const auto& [key, value] : lines[i].items()) {
      if (kEnvelope.count(key)) continue;
      std::vector<nlohmann::json> edited = lines;
      edited[i].erase(key);
      std::string text;
      for (const nlohmann::json& line : edited) text += line.dump() + "\n";
      testing::WriteText(frames, text);
      ExpectNamed(folder, "frames.jsonl:" + std::to_string(i + 1) + ": " + key, part + " " + kind + " " + key);
    }
  }
  testing::WriteText(frames, original);
}

// Each setting of a part's session.json dropped in turn (nested objects'
// keys too, named with their path).
void DropEachSetting(const fs::path& folder, const std::string& part) {
  const fs::path path = folder / part / "session.json";
  const std::string original = testing::ReadText(path);
  const nlohmann::json start = nlohmann::json::parse(original);
  for (const auto& [key, value] : start["settings"].items()) {
    nlohmann::json edited = start;
    edited["settings"].erase(key);
    testing::WriteText(path, edited.dump(2));
    ExpectNamed(folder, "session.json: settings: " + key, part + " settings." + key);
    if (!value.is_object()) continue;
    for (const auto& [inner, ignored] : value.items()) {
      nlohmann::json nested = start;
      nested["settings"][key].erase(inner);
      testing::WriteText(path, nested.dump(2));
      ExpectNamed(folder, "settings: " + key + ": " + inner, part + " settings." + key + "." + inner);
    }
  }
  testing::WriteText(path, original);
}

// A small capture of the orange preset; the command's exit code.
int CaptureOrange(const fs::path& out) {
  return RunPhos("capture all --sim-material " + testing::Fixture("materials/orange.json").string() +
                 " --sim-size 48x12 --out " + out.string())
      .exit_code;
}

TEST(SessionFields, EveryRecordedFieldIsRequiredByVerifyAndFit) {
  testing::TempDir dir;
  const fs::path c = dir / "c";
  ASSERT_EQ(CaptureOrange(c), 0);
  ASSERT_EQ(RunPhos("capture verify " + c.string()).exit_code, 0);
  for (const char* part : {"lvf-calibration", "spectrum", "decay", "excitation"}) {
    DropEachFrameField(c, part);
    DropEachSetting(c, part);
  }
  // The devices the fit reads ke with: their band irradiance, and the grid.
  for (const char* key : {"light_band_irradiance", "bands_nm", "device"}) {
    const fs::path path = c / "decay" / "session.json";
    const std::string original = testing::ReadText(path);
    nlohmann::json edited = nlohmann::json::parse(original);
    edited["devices"].erase(key);
    testing::WriteText(path, edited.dump(2));
    ExpectNamed(c, "session.json: devices: " + std::string(key), std::string("devices.") + key);
    testing::WriteText(path, original);
  }
  // Whole again: verify and the fit say nothing.
  EXPECT_EQ(RunPhos("capture verify " + c.string()).exit_code, 0);
  EXPECT_EQ(RunPhos("fit session " + c.string() + " --out " + (dir / "m.json").string()).exit_code, 0);
}

// The case that showed the fault: an LVF calibration frame without its
// wavelength was fitted without a word, and verify called the session whole.
TEST(SessionFields, ACalibrationLineWithoutItsWavelengthIsNamed) {
  testing::TempDir dir;
  const fs::path c = dir / "c";
  ASSERT_EQ(CaptureOrange(c), 0);
  const fs::path frames = c / "lvf-calibration" / "frames.jsonl";
  std::vector<nlohmann::json> lines = testing::ReadJsonLines(frames);
  std::size_t at = 0;
  while (at < lines.size() && !lines[at].contains("wavelength_nm")) ++at;
  ASSERT_LT(at, lines.size());
  lines[at].erase("wavelength_nm");
  std::string text;
  for (const nlohmann::json& line : lines) text += line.dump() + "\n";
  testing::WriteText(frames, text);
  ExpectNamed(c, "frames.jsonl:" + std::to_string(at + 1) + ": wavelength_nm: missing", "wavelength_nm");
}

// The numbers of a record are protected by its own checksum, and a frame
// by its file's: each change below, made after the capture, is listed by
// verify and refused by fit session, naming the file and line. Before
// record checksums, exposure_s times 4 made fit session write kr 12% off
// while verify said ok; frames without xxh3 and size_bytes went unchecked.
TEST(SessionFields, EveryRecordIsProtectedByItsOwnChecksum) {
  testing::TempDir dir;
  const fs::path c = dir / "c";
  ASSERT_EQ(CaptureOrange(c), 0);
  const auto edit_line = [&](const fs::path& path, int line, auto&& change, bool sign) {
    const std::string original = testing::ReadText(path);
    std::vector<nlohmann::json> lines = testing::ReadJsonLines(path);
    change(lines.at(line - 1));
    if (sign) lines[line - 1] = WithRecordChecksum(lines[line - 1]);
    std::string text;
    for (const nlohmann::json& l : lines) text += l.dump() + "\n";
    testing::WriteText(path, text);
    return original;
  };
  const fs::path frames = c / "decay" / "frames.jsonl";
  std::string original = edit_line(
      frames, 3, [](nlohmann::json& l) { l["exposure_s"] = l["exposure_s"].get<double>() * 4; }, false);
  ExpectNamed(c, "decay/frames.jsonl:3: does not match its record_xxh3", "exposure_s x4");
  testing::WriteText(frames, original);

  const fs::path events = c / "excitation" / "events.jsonl";
  original = edit_line(
      events, 2, [](nlohmann::json& l) { l.erase(kRecordChecksumKey); }, false);
  ExpectNamed(c, "excitation/events.jsonl:2: has no record_xxh3", "an event without its checksum");
  testing::WriteText(events, original);

  for (const char* part : {"decay", "."}) {
    const fs::path start = c / part / "session.json";
    original = testing::ReadText(start);
    nlohmann::json edited = nlohmann::json::parse(original);
    edited["started_utc"] = "2020-01-01T00:00:00Z";
    testing::WriteText(start, edited.dump(2));
    ExpectNamed(c, "session.json: does not match its record_xxh3", std::string(part) + " session.json");
    testing::WriteText(start, original);
  }
  const fs::path stop = c / "spectrum" / "stop.json";
  original = testing::ReadText(stop);
  nlohmann::json edited_stop = nlohmann::json::parse(original);
  edited_stop["frames"] = edited_stop["frames"].get<int>() + 1;
  testing::WriteText(stop, edited_stop.dump(2));
  ExpectNamed(c, "spectrum/stop.json: does not match its record_xxh3", "stop.json");
  testing::WriteText(stop, original);

  // A frame record that never had its file's checksum (signed without it):
  // nothing could tell a replaced frame, and that is a problem of its own.
  original = edit_line(
      frames, 2,
      [](nlohmann::json& l) {
        l.erase("xxh3");
        l.erase("size_bytes");
      },
      true);
  ExpectNamed(c, "decay/frames.jsonl:2: gives no xxh3 and size_bytes", "no file checksum");
  testing::WriteText(frames, original);

  // A frame replaced by a valid image of another size: its checksum says so,
  // to fit session too (which fits the records, not the pixels).
  const fs::path frame = c / "decay" / "frames" / "000002.tif";
  const fs::path kept = dir / "kept.tif";
  fs::copy_file(frame, kept);
  fs::copy_file(c / "lvf-calibration" / "frames" / "000001.tif", frame, fs::copy_options::overwrite_existing);
  ExpectNamed(c, "000002.tif: is ", "a replaced frame");
  fs::copy_file(kept, frame, fs::copy_options::overwrite_existing);

  EXPECT_EQ(RunPhos("capture verify " + c.string()).exit_code, 0);
  EXPECT_EQ(RunPhos("fit session " + c.string() + " --out " + (dir / "m.json").string()).exit_code, 0);
}

// A session written by phos 0.1 before the records were typed
// (fixtures/sessions/orange-0.1: `phos capture all --sim-material
// fixtures/materials/orange.json --sim-size 24x8 --excite led420 led456
// --tail-frames 2 --duration-s 90`, previews removed) reads as whole and fits
// back its material.
TEST(SessionFields, ASessionOfTheFormatBeforeKeepsWorking) {
  testing::TempDir dir;
  const fs::path session = testing::Fixture("sessions/orange-0.1");
  const auto verify = RunPhos("capture verify " + session.string());
  EXPECT_EQ(verify.exit_code, 0) << verify.out << verify.err;
  const auto fit = RunPhos("fit session " + session.string() + " --out " + (dir / "m.json").string() + " --json");
  ASSERT_EQ(fit.exit_code, 0) << fit.err;
  const nlohmann::json fitted = ReadJsonFile(dir / "m.json");
  const nlohmann::json truth = ReadJsonFile(testing::Fixture("materials/orange.json"));
  ASSERT_EQ(fitted["states"].size(), 1u);
  const double kr = fitted["states"][0]["kr"], kr_truth = truth["states"][0]["kr"];
  EXPECT_NEAR(kr, kr_truth, 0.02 * kr_truth);
}

}  // namespace
}  // namespace phos
