// The Aravis back end against Aravis's own in-process fake camera ("Fake"
// interface, device Fake_1). The fake fills Mono8 frames with a diagonal ramp
// scaled by 1 + gain + log10(exposure_us / 10000) (arvfakecamera.c), so every
// pixel can be predicted from the exposure, the gain and the frame id.

#include "phos/acquire/aravis_camera.h"

#include <arv.h>
#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <gtest/gtest.h>

#include "phos/acquire/lab.h"
#include "phos/acquire/lights.h"
#include "phos/acquire/protocols.h"
#include "phos/acquire/session.h"
#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

class AravisFake : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { AravisCamera::EnableFakeInterface(); }
  SystemClock clock;
};

// The GigE Vision fake camera, served on 127.0.0.1 by this process; a new
// one per test (it keeps register state). It takes the GigE Vision control
// port (3956) on loopback, and two fakes there would answer each other's
// packets, so the tests that start one (ctest runs them as processes side by
// side) take turns through a lock file.
class AravisGvFake : public ::testing::Test {
 protected:
  void SetUp() override {
    lock_fd_ = ::open("/tmp/phos-aravis-gv-fake.lock", O_CREAT | O_RDWR | O_CLOEXEC, 0666);
    ASSERT_GE(lock_fd_, 0);
    ASSERT_EQ(::flock(lock_fd_, LOCK_EX), 0);
    fake_ = arv_gv_fake_camera_new("lo", "GV01");
    ASSERT_TRUE(fake_ != nullptr && arv_gv_fake_camera_is_running(fake_));
  }
  void TearDown() override {
    if (fake_) g_object_unref(fake_);
    if (lock_fd_ >= 0) ::close(lock_fd_);
  }
  // The fake drops this share of its stream packets (leaders, payload and
  // trailers alike), each by a draw from GLib's global random generator,
  // which the seed fixes so a run loses the same packets each time. Aravis
  // 0.8's fake never answers a resend request, so every loss it makes ends
  // in a retake here.
  void LosePackets(double ratio, guint32 seed) {
    g_random_set_seed(seed);
    g_object_set(fake_, "gvsp-lost-ratio", ratio, nullptr);
  }
  SystemClock clock;
  ArvGvFakeCamera* fake_ = nullptr;
  int lock_fd_ = -1;
};

// The fake's pixel at (x, y): the ramp value times the scale, clamped and
// truncated, as arv_fake_camera_diagonal_ramp does for Mono8 and Mono16.
int FakePixel(int x, int y, std::uint64_t frame_id, double exposure_s, double gain, int bits) {
  const double scale = 1.0 + gain + std::log10(exposure_s * 1e6 / 10000.0);
  if (bits == 16) {
    const double value = static_cast<double>((256 * x + 256 * frame_id + 256 * y) % 65535) * scale;
    return static_cast<int>(std::clamp(value, 0.0, 65535.0));
  }
  const double value = static_cast<double>((x + frame_id + y) % 255) * scale;
  return static_cast<int>(std::clamp(value, 0.0, 255.0));
}

// Pixels of `frame` that differ from what the fake defines for it.
int Mismatches(const Frame& frame, std::uint64_t frame_id, double exposure_s, double gain) {
  int mismatches = 0;
  for (int y = 0; y < frame.height; ++y)
    for (int x = 0; x < frame.width; ++x)
      mismatches += frame.pixels[static_cast<std::size_t>(y) * frame.width + x] !=
                    FakePixel(x, y, frame_id, exposure_s, gain, frame.adc_bits);
  return mismatches;
}

TEST_F(AravisFake, SetsAndReadsBackExposureAndGain) {
  AravisCamera camera("Fake_1", clock);
  EXPECT_NE(camera.description().find("Fake_1"), std::string::npos);
  camera.Capture(0.02, 2);
  EXPECT_NEAR(camera.exposure_s(), 0.02, 1e-9);
  EXPECT_NEAR(camera.gain(), 2, 1e-9);
  camera.Capture(0.005, 0);
  EXPECT_NEAR(camera.exposure_s(), 0.005, 1e-9);
  EXPECT_NEAR(camera.gain(), 0, 1e-9);
}

void ExpectBrightnessAsTheFakeDefines(AravisCamera& camera) {
  struct Setting {
    double exposure_s, gain;
  } settings[] = {{0.01, 0}, {0.01, 2}, {0.1, 0}, {0.001, 1}};
  double previous_mean = -1;
  for (const Setting& s : settings) {
    Frame frame = camera.Capture(s.exposure_s, s.gain);
    ASSERT_GT(frame.width, 0);
    ASSERT_EQ(frame.pixels.size(), static_cast<std::size_t>(frame.width) * frame.height);
    ASSERT_EQ(frame.channels, 1);
    ASSERT_TRUE(frame.adc_bits == 8 || frame.adc_bits == 16);  // Mono16 where the fake offers it
    EXPECT_NEAR(frame.exposure_s, s.exposure_s, 1e-9);
    EXPECT_EQ(Mismatches(frame, camera.last_frame_id(), s.exposure_s, s.gain), 0)
        << "exposure " << s.exposure_s << " gain " << s.gain;
    const double mean = frame.MeanSignal(0);
    if (previous_mean >= 0 && s.gain == 2) {
      EXPECT_GT(mean, previous_mean);  // scale 3 against 1 (much of it clips, hence only "brighter")
    }
    previous_mean = mean;
  }
}

TEST_F(AravisFake, BrightnessFollowsExposureAndGainAsTheFakeDefines) {
  AravisCamera camera("Fake_1", clock);
  ExpectBrightnessAsTheFakeDefines(camera);
}

TEST_F(AravisGvFake, OverLoopbackBrightnessFollowsExposureAndGain) {
  AravisCamera camera("127.0.0.1", clock);
  EXPECT_NE(camera.description().find("127.0.0.1"), std::string::npos);
  camera.SetRegion(0, 0, 128, 128);  // fewer packets on loopback
  camera.Capture(0.02, 1);
  EXPECT_NEAR(camera.exposure_s(), 0.02, 1e-9);
  EXPECT_NEAR(camera.gain(), 1, 1e-9);
  ExpectBrightnessAsTheFakeDefines(camera);
  // A clean link: every frame came whole the first time.
  EXPECT_EQ(camera.stream_statistics().failed_frames, 0u);
}

// What the link took for each frame of a run of captures, with every frame
// checked against the fake's own pixels: a frame is whole or not returned.
struct LinkWork {
  int frames = 0, retakes = 0;
  std::uint64_t packets_resent = 0;
};
LinkWork CaptureWholeFrames(AravisCamera& camera, int frames) {
  const struct {
    double exposure_s, gain;
  } settings[] = {{0.01, 0}, {0.01, 2}, {0.1, 0}, {0.001, 1}};  // settings change between frames
  LinkWork work;
  for (int i = 0; i < frames; ++i) {
    const auto& s = settings[i % 4];
    const Frame frame = camera.Capture(s.exposure_s, s.gain);
    EXPECT_EQ(Mismatches(frame, camera.last_frame_id(), s.exposure_s, s.gain), 0) << "frame " << i;
    EXPECT_LE(frame.retakes, camera.max_retakes());
    ++work.frames;
    work.retakes += frame.retakes;
    work.packets_resent += frame.packets_resent;
  }
  return work;
}

TEST_F(AravisGvFake, AtOnePercentPacketLossEveryFrameReturnedIsWholeAndLostPacketsAreAskedFor) {
  AravisCamera camera("127.0.0.1", clock, 2.0);
  camera.SetRegion(0, 0, 256, 128);  // 64 KiB of Mono16: 47 packets, 62% of the frames arrive whole
  camera.set_max_retakes(12);
  LosePackets(0.01, 1);
  const LinkWork work = CaptureWholeFrames(camera, 16);
  const AravisCamera::StreamStatistics stream = camera.stream_statistics();
  std::printf("1%% loss: %d frames, %d retakes, %llu resend requests, %llu packets resent\n", work.frames, work.retakes,
              static_cast<unsigned long long>(stream.resend_requests),
              static_cast<unsigned long long>(stream.resent_packets));
  EXPECT_GT(stream.resend_requests, 0u);  // packet resend is on
  EXPECT_GT(stream.failed_frames, 0u);    // and the fake's losses were seen
  EXPECT_GT(work.retakes, 0);
  EXPECT_LE(static_cast<std::uint64_t>(work.retakes), stream.failed_frames);  // each retake follows a failed frame
  EXPECT_LE(work.packets_resent, stream.resent_packets);
}

TEST_F(AravisGvFake, AtTenPercentPacketLossFramesAreRetakenUntilWholeAndTheRetakesCounted) {
  AravisCamera camera("127.0.0.1", clock, 2.0);
  camera.SetRegion(0, 0, 64, 32);  // 4 KiB of Mono16: 5 packets, 59% of the frames arrive whole
  camera.set_max_retakes(20);      // 41% ^ 21: a frame that fails 21 times in a row, 1e-8
  LosePackets(0.1, 2);
  const LinkWork work = CaptureWholeFrames(camera, 20);
  const AravisCamera::StreamStatistics stream = camera.stream_statistics();
  std::printf("10%% loss: %d frames, %d retakes, %llu failed frames in the stream\n", work.frames, work.retakes,
              static_cast<unsigned long long>(stream.failed_frames));
  EXPECT_GT(work.retakes, 0);  // no retake in 20 frames: 59% ^ 20, 3e-5
  EXPECT_LE(static_cast<std::uint64_t>(work.retakes), stream.failed_frames);
  EXPECT_GT(stream.completed_frames, 0u);
}

TEST_F(AravisGvFake, WhenEvenRetakesBringNoWholeFrameTheCaptureFailsInOneLine) {
  AravisCamera camera("127.0.0.1", clock, 1.0);
  camera.SetRegion(0, 0, 128, 128);  // 25 packets: at 50% loss, a whole frame once in 3e7
  EXPECT_THROW(camera.set_max_retakes(-1), UserError);
  EXPECT_THROW(camera.set_max_retakes(101), UserError);
  EXPECT_EQ(camera.max_retakes(), AravisCamera::kDefaultMaxRetakes);
  camera.set_max_retakes(2);
  LosePackets(0.5, 3);
  try {
    camera.Capture(0.01, 0);
    FAIL() << "a frame came whole through a link that loses half its packets";
  } catch (const UserError& e) {
    const std::string message = e.what();
    std::printf("%s\n", message.c_str());
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    EXPECT_EQ(message.rfind("camera '127.0.0.1': acquisition: 3 tries in a row arrived incomplete (the last: ", 0), 0u)
        << message;
    EXPECT_NE(message.find("packets missing"), std::string::npos) << message;
    EXPECT_NE(message.find("check the link"), std::string::npos) << message;
  }
  // The link heals, and the camera takes whole frames again.
  LosePackets(0, 3);
  const Frame frame = camera.Capture(0.01, 0);
  EXPECT_EQ(Mismatches(frame, camera.last_frame_id(), 0.01, 0), 0);
}

// Passes every frame through and keeps what the link took for it and the
// fake's frame id, to hold a session's records against.
class TallyCamera final : public Camera {
 public:
  explicit TallyCamera(AravisCamera& camera) : camera_(camera) {}
  std::string description() const override { return camera_.description(); }
  double max_exposure_s() const override { return camera_.max_exposure_s(); }
  Frame Capture(double exposure_s, double gain) override {
    Frame frame = camera_.Capture(exposure_s, gain);
    frames.push_back({camera_.last_frame_id(), frame.retakes, frame.packets_resent});
    return frame;
  }
  struct Taken {
    std::uint64_t frame_id;
    int retakes;
    std::uint64_t packets_resent;
  };
  std::vector<Taken> frames;

 private:
  AravisCamera& camera_;
};

TEST_F(AravisGvFake, ADecaySessionAtTenPercentPacketLossRecordsEachFramesRetakesAndKeepsOnlyWholeFrames) {
  testing::TempDir dir;
  AravisCamera camera("127.0.0.1", clock, 2.0);
  camera.SetRegion(0, 0, 64, 80);  // 10 KiB of Mono16: 9 packets, 39% of the frames arrive whole
  camera.set_max_retakes(30);
  LosePackets(0.1, 4);
  TallyCamera tally(camera);
  RecordingLights lights({"led405"}, clock);
  DecayProtocolOptions options;
  options.charge_light = "led405";
  options.charge_s = 0;
  options.interval_s = 0.25;
  options.duration_s = 2.5;
  options.early_frames = 0;
  options.initial_exposure_s = 0.002;
  options.max_exposure_s = 0.05;
  {
    SessionWriter session(dir / "s", {{"protocol", "decay"}});
    RunDecayProtocol(tally, lights, clock, session, options);
  }
  const FrameRecords records = ReadFrameRecords(dir / "s");
  ASSERT_EQ(records.frames.size(), tally.frames.size());
  ASSERT_GE(records.frames.size(), 4u);  // slots a long retake overran are skipped
  EXPECT_TRUE(CheckSession(dir / "s").clean());
  EXPECT_EQ(ReadStopRecord(dir / "s")->how, "complete");
  int retakes = 0;
  for (std::size_t i = 0; i < records.frames.size(); ++i) {
    const FrameRecord& record = records.frames[i];
    EXPECT_EQ(record.retakes, tally.frames[i].retakes) << "frame " << record.seq;
    EXPECT_EQ(record.packets_resent, tally.frames[i].packets_resent) << "frame " << record.seq;
    retakes += record.retakes;
    // What the session kept is the whole frame, pixel for pixel.
    const Frame kept = ReadFrame(dir / "s", record);
    EXPECT_EQ(Mismatches(kept, tally.frames[i].frame_id, record.exposure_s, record.gain), 0) << "frame " << record.seq;
  }
  EXPECT_GT(retakes, 0);  // none in the session's frames: 39% ^ frames, 1e-3 for 7
  for (const JsonLine& line : ReadJsonLinesFile(dir / "s" / "frames.jsonl").records) {
    EXPECT_TRUE(line.value.contains("retakes")) << line.line;
    EXPECT_TRUE(line.value.contains("packets_resent")) << line.line;
  }
}

TEST_F(AravisFake, RefusedSettingsAndMissingCamerasAreClearErrors) {
  AravisCamera camera("Fake_1", clock);
  try {
    camera.Capture(1e7, 0);
    FAIL() << "an impossible exposure was accepted";
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("camera 'Fake_1': exposure: refuses 1e+07 s"), std::string::npos) << e.what();
  }
  EXPECT_THROW(AravisCamera("No_Such_Camera_42", clock), UserError);
}

// A lab config's camera.region of [0, 0, 65536, 65536] passed the config's
// checks (each side at most 65536) and Aravis's fake set it, then wrote its
// frames past its buffer: a segfault. A region past the (binned) sensor is
// refused where it is set, naming the config's key; one inside it is set.
TEST_F(AravisFake, ARegionPastTheSensorIsRefusedNamingTheConfigKey) {
  const testing::TempDir dir;
  auto config = [&](const std::string& region, const std::string& binning) {
    return LabConfigFromJson(R"({"schema": "phos.lab/1", "camera": {"aravis": "Fake_1", "binning": )" + binning +
                                 R"(, "region": )" + region + R"(, "trigger": "software"},
                                "lights": {"backend": "none", "channels": {"led405": {"line": 17}}}, "rig": "fixed"})",
                             dir / "lab.json");
  };
  AravisCamera probe("Fake_1", clock, 2.0);
  const auto [width, height] = probe.sensor_size();
  const std::string sensor = std::to_string(width) + " x " + std::to_string(height);
  EXPECT_EQ(testing::ErrorOfType<UserError>([&] { OpenLab(config("[0, 0, 65536, 65536]", "[1, 1]")); }),
            "camera 'Fake_1': camera.region: [0, 0, 65536, 65536] reaches past the sensor, which is " + sensor +
                " pixels at binning 1x1 (x + width and y + height at most those)");
  // Binned 2x2, the whole sensor is past the binned one by one pixel more.
  const std::string whole = "[1, 0, " + std::to_string(width / 2) + ", " + std::to_string(height / 2) + "]";
  EXPECT_NE(testing::ErrorOfType<UserError>([&] { OpenLab(config(whole, "[2, 2]")); }).find("camera.region: " + whole),
            std::string::npos);
  EXPECT_EQ(testing::ErrorOfType<UserError>([&] { probe.SetRegion(0, 0, width, 0); }).find("camera 'Fake_1': region: "),
            0u);
  EXPECT_EQ(OpenLab(config("[0, 0, " + std::to_string(width) + ", " + std::to_string(height) + "]", "[1, 1]"))
                ->camera->Capture(0.01, 0)
                .width,
            width);
}

// A lab light's irradiance_csv with a header only was read as a light of 0
// in every band, in silence: it is refused, as is one row, and a spectrum
// outside every band; one within the bands is read.
TEST(LabConfig, AnIrradianceCsvThatGivesNoIrradianceIsRefused) {
  const testing::TempDir dir;
  auto error = [&](const std::string& csv) {
    testing::WriteText(dir / "led.csv", csv);
    return testing::ErrorOfType<UserError>([&] {
      LabConfigFromJson(R"({"schema": "phos.lab/1", "camera": {"aravis": "Fake_1"}, "lights": {"backend": "none",
                           "channels": {"led405": {"line": 1, "irradiance_csv": "led.csv"}}}})",
                        dir / "lab.json");
    });
  };
  const std::string where =
      (dir / "lab.json").string() + ": lights.channels.led405.irradiance_csv: '" + (dir / "led.csv").string() + "' ";
  EXPECT_EQ(error("wavelength_nm,irradiance\n"),
            where + "has 0 row(s) of wavelength_nm,irradiance; a spectrum needs at least 2");
  EXPECT_EQ(error("wavelength_nm,irradiance\n405,1\n"),
            where + "has 1 row(s) of wavelength_nm,irradiance; a spectrum needs at least 2");
  EXPECT_EQ(
      error("wavelength_nm,irradiance\n1000,1\n1100,1\n"),
      where + "gives 0 irradiance in every band of bands_nm (400 to 700 nm): the light would be recorded as dark");
  EXPECT_EQ(error("wavelength_nm,irradiance\n395,0\n405,1\n415,0\n"), "(no error)");
}

TEST_F(AravisFake, PixelFormatsBinningAndTheSoftwareTrigger) {
  AravisCamera camera("Fake_1", clock, 2.0);
  const std::vector<std::string> formats = camera.available_pixel_formats();
  ASSERT_NE(std::find(formats.begin(), formats.end(), "Mono8"), formats.end());
  camera.SetPixelFormat("Mono8");
  EXPECT_EQ(camera.pixel_format(), "Mono8");
  EXPECT_EQ(camera.Capture(0.01, 0).adc_bits, 8);
  EXPECT_THROW(camera.SetPixelFormat("Mono7"), UserError);

  // The whole sensor, then 2x2 binning: the region follows the binned sensor.
  const auto [sensor_width, sensor_height] = camera.sensor_size();
  camera.SetRegion(0, 0, sensor_width, sensor_height);
  EXPECT_EQ(camera.Capture(0.01, 0).width, sensor_width);
  camera.SetBinning(2, 2);
  EXPECT_EQ(camera.binning(), (std::pair<int, int>{2, 2}));
  const Frame binned = camera.Capture(0.01, 0);
  EXPECT_EQ(binned.width, sensor_width / 2);
  EXPECT_EQ(binned.height, sensor_height / 2);
  EXPECT_THROW(camera.SetBinning(1000, 1), UserError);
  camera.SetBinning(1, 1);

  // Software trigger: the frame comes when phos triggers, and it is the
  // frame the fake defines for that exposure and gain.
  camera.SetTrigger(AravisCamera::Trigger::kSoftware);
  const double before = clock.now_s();
  Frame frame = camera.Capture(0.02, 1);
  EXPECT_GE(frame.t_start_s, before);
  EXPECT_GT(frame.camera_timestamp_ns, 0u);
  EXPECT_EQ(Mismatches(frame, camera.last_frame_id(), 0.02, 1), 0);
}

TEST_F(AravisFake, AHardwareTriggerIsArmedAndFiredThroughTheLabsLine) {
  // Aravis's fake exposes on its own clock whatever the source (only its
  // software trigger is simulated), so what can be checked here is the
  // arming: the source must exist, and the lab's GPIO pulse is fired once
  // per frame, after arming.
  AravisCamera camera("Fake_1", clock, 2.0);
  std::string line;
  for (const std::string& s : camera.available_trigger_sources())
    if (s.rfind("Line", 0) == 0) line = s;
  if (line.empty()) GTEST_SKIP() << "this Aravis fake has no Line trigger source";
  camera.SetTrigger(AravisCamera::Trigger::kHardware, line);
  int pulses = 0;
  camera.fire_hardware_trigger = [&] { ++pulses; };
  camera.Capture(0.01, 0);
  camera.Capture(0.01, 0);
  EXPECT_EQ(pulses, 2);
  try {
    camera.SetTrigger(AravisCamera::Trigger::kHardware, "Line99");
    FAIL() << "an unknown trigger source was accepted";
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("has no trigger source 'Line99'"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace phos
