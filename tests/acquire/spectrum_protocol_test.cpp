// The LVF in the simulated lab, the LVF-calibration and spectrum protocols,
// and resuming interrupted sessions. Truths: a narrow line through the filter
// peaks at the column whose pass band is centred on it; a sample's glow
// through the filter follows its emission spectrum; a resumed session
// measures nothing twice and overwrites nothing.

#include <algorithm>
#include <cmath>
#include <gtest/gtest.h>
#include <map>
#include <set>

#include "phos/acquire/protocols.h"
#include "phos/acquire/sim_lab.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "acquire/lab_util.h"
#include "test_util.h"

namespace phos {
namespace {

using testing::ReadJsonLines;

using testing::Lab;

// Mean signal of each column (all channels summed), black level removed.
std::vector<double> ColumnProfile(const Frame& frame) {
  std::vector<double> profile(static_cast<std::size_t>(frame.width), 0.0);
  for (int y = 0; y < frame.height; ++y)
    for (int x = 0; x < frame.width; ++x)
      for (int c = 0; c < frame.channels; ++c)
        profile[x] += (frame.pixels[(static_cast<std::size_t>(y) * frame.width + x) * frame.channels + c] -
                       frame.black_level_dn) /
                      frame.height;
  return profile;
}

// Intensity-weighted column of the peak (the 5 columns around the maximum).
double PeakCentroid(const std::vector<double>& profile) {
  const int peak = static_cast<int>(std::max_element(profile.begin(), profile.end()) - profile.begin());
  double sum = 0, weighted = 0;
  for (int x = std::max(0, peak - 2); x <= std::min<int>(profile.size() - 1, peak + 2); ++x) {
    sum += std::max(0.0, profile[x]);
    weighted += std::max(0.0, profile[x]) * x;
  }
  return weighted / sum;
}

TEST(SimulatedLab, ALineThroughTheFilterPeaksWhereThePassBandIsCentredOnIt) {
  Lab lab("orange");
  lab.lab.SetWhiteReferenceInView(true);
  lab.lab.SetLvfInPath(true);
  const LinearVariableFilter& lvf = lab.lab.camera_model().lvf;
  const int width = lab.lab.camera_model().width;
  for (const KnownLine& line : DefaultCalibrationLines()) {
    lab.lab.lights().Set(line.light, true);
    const Frame frame = lab.lab.Capture(0.05, 1);
    lab.lab.lights().Set(line.light, false);
    const double expected_x = (line.wavelength_nm - lvf.start_nm) / (lvf.end_nm - lvf.start_nm) * width - 0.5;
    EXPECT_NEAR(PeakCentroid(ColumnProfile(frame)), expected_x, 0.5) << line.light;
  }
  // The sample, hidden behind the white reference, saw none of it.
  for (double r : lab.lab.StateNow()) EXPECT_EQ(r, 0.0);
  // Without the filter, the line lights every column alike.
  lab.lab.SetLvfInPath(false);
  lab.lab.lights().Set("hg546", true);
  const std::vector<double> flat = ColumnProfile(lab.lab.Capture(0.05, 1));
  const auto [lo, hi] = std::minmax_element(flat.begin(), flat.end());
  EXPECT_GT(*lo, 0.8 * *hi);
}

TEST(LvfCalibrationProtocol, RecordsADarkFrameEachLineAndTheFlatFieldWellExposed) {
  Lab lab("orange");
  testing::TempDir dir;
  LvfCalibrationOptions options;
  for (const KnownLine& line : DefaultCalibrationLines()) options.lines.push_back({line.light, line.wavelength_nm});
  {
    SessionWriter session(dir / "s", {{"protocol", "lvf-calibration"}});
    RunLvfCalibrationProtocol(lab.lab, lab.lab.lights(), lab.clock, session, lab.Rig(), options);
  }
  EXPECT_EQ(ReadJsonFile(dir / "s" / "stop.json")["how"], "complete");
  for (const std::string& light : lab.lab.lights().channels()) EXPECT_FALSE(lab.lab.lights().IsOn(light));
  EXPECT_FALSE(lab.lab.lvf_in_path());
  EXPECT_FALSE(lab.lab.white_reference_in_view());

  // The last frame of each source is the well-exposed one; its peak is where
  // the filter passes the line.
  std::map<std::string, nlohmann::json> last;
  for (const nlohmann::json& line : ReadJsonLines(dir / "s" / "frames.jsonl")) last[line.value("light", "dark")] = line;
  ASSERT_EQ(last.size(), 5u);  // dark, 3 lines, the lamp
  EXPECT_EQ(last["dark"]["kind"], "dark");
  EXPECT_EQ(last["lamp"]["kind"], "flat");
  const LinearVariableFilter& lvf = lab.lab.camera_model().lvf;
  for (const KnownLine& known : DefaultCalibrationLines()) {
    const nlohmann::json& line = last[known.light];
    EXPECT_EQ(line["kind"], "line");
    EXPECT_EQ(line["wavelength_nm"].get<double>(), known.wavelength_nm);
    EXPECT_GE(line["peak_column_fraction"].get<double>(), options.exposure.low_fraction);
    EXPECT_LE(line["peak_column_fraction"].get<double>(), options.exposure.high_fraction);
    EXPECT_EQ(line["saturated_fraction"].get<double>(), 0.0);
    const Frame frame = ReadFrame(dir / "s", line);
    const double expected_x = (known.wavelength_nm - lvf.start_nm) / (lvf.end_nm - lvf.start_nm) * frame.width - 0.5;
    EXPECT_NEAR(PeakCentroid(ColumnProfile(frame)), expected_x, 0.5) << known.light;
  }
}

TEST(SpectrumProtocol, TheGlowThroughTheFilterFollowsTheEmissionSpectrum) {
  Lab lab("orange");
  testing::TempDir dir;
  SpectrumProtocolOptions options;
  options.charge_light = "led405";
  SpectrumProtocolResult result;
  {
    SessionWriter session(dir / "s", {{"protocol", "spectrum"}});
    result = RunSpectrumProtocol(lab.lab, lab.lab.lights(), lab.clock, session, lab.Rig(), options);
  }
  EXPECT_EQ(ReadJsonFile(dir / "s" / "stop.json")["how"], "complete");
  EXPECT_EQ(result.well_exposed, options.frames);
  EXPECT_FALSE(lab.lab.lvf_in_path());
  const std::vector<nlohmann::json> lines = ReadJsonLines(dir / "s" / "frames.jsonl");
  ASSERT_EQ(static_cast<int>(lines.size()), result.frames);
  // One charge per frame: every frame starts first_delay_s after its light-off.
  for (const nlohmann::json& line : lines)
    EXPECT_NEAR(line["delay_after_light_off_s"].get<double>(), options.first_delay_s, 1e-9);
  // Orange emits 7.7 in 587.5-625 nm and 0.04 in 400-437.5 nm (Table 8.1):
  // the columns passing the first are far brighter than those passing the
  // second, and nothing was reflected (all lights off).
  const Frame frame = ReadFrame(dir / "s", lines.back());
  EXPECT_EQ(frame.black_level_dn, lines.back()["black_level_dn"].get<double>());
  const std::vector<double> profile = ColumnProfile(frame);
  const LinearVariableFilter& lvf = lab.lab.camera_model().lvf;
  auto column = [&](double nm) {
    return static_cast<int>((nm - lvf.start_nm) / (lvf.end_nm - lvf.start_nm) * frame.width);
  };
  EXPECT_GT(profile[column(606)], 20 * std::max(1.0, profile[column(419)]));
  const double peak_nm = lvf.CenterNm(std::max_element(profile.begin(), profile.end()) - profile.begin(), frame.width);
  EXPECT_GT(peak_nm, 575);
  EXPECT_LT(peak_nm, 640);
}

// A camera that works `frames_left` times and then is gone (a cable pulled).
class DisappearingCamera final : public Camera {
 public:
  DisappearingCamera(Camera& inner, int frames_left) : inner_(inner), left_(frames_left) {}
  std::string description() const override { return "disappearing"; }
  Frame Capture(double exposure_s, double gain) override {
    if (left_-- <= 0) ThrowUserError("camera 'test'", "acquisition", "no frame arrived in time (disconnected?)");
    return inner_.Capture(exposure_s, gain);
  }
  double max_exposure_s() const override { return inner_.max_exposure_s(); }

 private:
  Camera& inner_;
  int left_;
};

TEST(ExcitationProtocol, ResumingMeasuresOnlyWhatIsMissingAndOverwritesNothing) {
  Lab lab("orange");
  testing::TempDir dir;
  ExcitationProtocolOptions options;
  options.lights = {"led405", "led365"};
  options.exposure_s = 0.2;
  {
    // Two whole measurements (a frame and its 6-frame tail each), then 3 frames of the third.
    DisappearingCamera camera(lab.lab, 17);
    SessionWriter session(dir / "s", {{"protocol", "excitation"}});
    EXPECT_THROW(RunExcitationProtocol(camera, lab.lab.lights(), lab.clock, session, options), UserError);
  }
  EXPECT_EQ(ReadJsonFile(dir / "s" / "stop.json")["how"], "failed");
  EXPECT_NE(ReadJsonFile(dir / "s" / "stop.json")["why"].get<std::string>().find("disconnected"), std::string::npos);
  const std::string first_frame = testing::ReadText(dir / "s" / "frames" / "000001.tif");
  ASSERT_EQ(ReadJsonLines(dir / "s" / "frames.jsonl").size(), 17u);

  const ExcitationDone done = ReadExcitationDone(dir / "s");
  EXPECT_EQ(done.size(), 2u);  // the cut one is not done
  {
    std::unique_ptr<SessionWriter> session = SessionWriter::Reopen(dir / "s");
    EXPECT_EQ(session->frame_count(), 17);
    RunExcitationProtocol(lab.lab, lab.lab.lights(), lab.clock, *session, options, done);
  }
  EXPECT_EQ(ReadJsonFile(dir / "s" / "stop.json")["how"], "complete");
  EXPECT_EQ(testing::ReadText(dir / "s" / "frames" / "000001.tif"), first_frame);
  // Every (light, charge time) measured whole once, the cut one kept as it
  // was and taken again; frames numbered 1..n without a gap.
  int seq = 0;
  for (const nlohmann::json& line : ReadJsonLines(dir / "s" / "frames.jsonl")) EXPECT_EQ(line["seq"].get<int>(), ++seq);
  std::set<std::pair<std::string, double>> seen;
  int cut = 0;
  for (const testing::ExcitationCharge& charge : testing::ExcitationCharges(dir / "s" / "frames.jsonl")) {
    if (charge.frames == 3) {
      ++cut;
      continue;
    }
    EXPECT_EQ(charge.frames, 7);
    EXPECT_TRUE(seen.insert({charge.light, charge.charge_s}).second) << charge.light << " " << charge.charge_s;
  }
  EXPECT_EQ(cut, 1);
  EXPECT_GT(seq, 70);
  std::set<std::string> lights;
  for (const auto& measured : seen) lights.insert(measured.first);
  EXPECT_EQ(lights.size(), 2u);
  // The resume is on record, with how the session had stopped.
  bool resumed = false;
  for (const nlohmann::json& event : ReadJsonLines(dir / "s" / "events.jsonl"))
    resumed = resumed || (event["event"] == "resume" && event.contains("previous_stop") &&
                          event["previous_stop"]["how"] == "failed");
  EXPECT_TRUE(resumed);
  // A complete session has nothing to resume.
  EXPECT_THROW(SessionWriter::Reopen(dir / "s"), UserError);
}

TEST(LvfCalibrationProtocol, ResumingSkipsTheSourcesAlreadyCalibrated) {
  Lab lab("orange");
  testing::TempDir dir;
  LvfCalibrationOptions options;
  for (const KnownLine& line : DefaultCalibrationLines()) options.lines.push_back({line.light, line.wavelength_nm});
  {
    DisappearingCamera camera(lab.lab, 4);
    SessionWriter session(dir / "s", {{"protocol", "lvf-calibration"}});
    EXPECT_THROW(RunLvfCalibrationProtocol(camera, lab.lab.lights(), lab.clock, session, lab.Rig(), options),
                 UserError);
  }
  const std::vector<std::string> done = ReadLvfCalibrationDone(dir / "s");
  ASSERT_FALSE(done.empty());
  EXPECT_EQ(done[0], "");  // the dark frame
  {
    std::unique_ptr<SessionWriter> session = SessionWriter::Reopen(dir / "s");
    RunLvfCalibrationProtocol(lab.lab, lab.lab.lights(), lab.clock, *session, lab.Rig(), options, done);
  }
  const std::vector<std::string> all = ReadLvfCalibrationDone(dir / "s");
  EXPECT_EQ(all.size(), 5u);
  EXPECT_EQ(std::set<std::string>(all.begin(), all.end()).size(), 5u);  // none twice
}

TEST(SpectrumProtocol, BadOptionsAreClearErrors) {
  Lab lab("orange");
  testing::TempDir dir;
  SpectrumProtocolOptions options;
  options.charge_light = "led405";
  options.frames = 0;
  SessionWriter session(dir / "s", {{"protocol", "spectrum"}});
  try {
    RunSpectrumProtocol(lab.lab, lab.lab.lights(), lab.clock, session, lab.Rig(), options);
    FAIL();
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("need at least 1 frame"), std::string::npos) << e.what();
  }
  LvfCalibrationOptions calibration;
  calibration.lines = {{"hg436", 435.8}};
  try {
    RunLvfCalibrationProtocol(lab.lab, lab.lab.lights(), lab.clock, session, lab.Rig(), calibration);
    FAIL();
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("at least 2 sources"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace phos
