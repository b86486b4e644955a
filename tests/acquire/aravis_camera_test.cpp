// The Aravis back end against Aravis's own in-process fake camera ("Fake"
// interface, device Fake_1). The fake fills Mono8 frames with a diagonal ramp
// scaled by 1 + gain + log10(exposure_us / 10000) (arvfakecamera.c), so every
// pixel can be predicted from the exposure, the gain and the frame id.

#include "phos/acquire/aravis_camera.h"

#include <arv.h>

#include <algorithm>
#include <cmath>
#include <gtest/gtest.h>

#include "phos/util/error.h"

namespace phos {
namespace {

class AravisFake : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { AravisCamera::EnableFakeInterface(); }
  SystemClock clock;
};

// The GigE Vision fake camera, served on 127.0.0.1 by this process; a new
// one per test (it keeps register state).
class AravisGvFake : public ::testing::Test {
 protected:
  void SetUp() override {
    fake_ = arv_gv_fake_camera_new("lo", "GV01");
    ASSERT_TRUE(fake_ != nullptr && arv_gv_fake_camera_is_running(fake_));
  }
  void TearDown() override {
    if (fake_) g_object_unref(fake_);
  }
  SystemClock clock;
  ArvGvFakeCamera* fake_ = nullptr;
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
    int mismatches = 0;
    for (int y = 0; y < frame.height; ++y)
      for (int x = 0; x < frame.width; ++x)
        mismatches += frame.pixels[static_cast<std::size_t>(y) * frame.width + x] !=
                      FakePixel(x, y, camera.last_frame_id(), s.exposure_s, s.gain, frame.adc_bits);
    EXPECT_EQ(mismatches, 0) << "exposure " << s.exposure_s << " gain " << s.gain;
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
}

TEST_F(AravisFake, RefusedSettingsAndMissingCamerasAreClearErrors) {
  AravisCamera camera("Fake_1", clock);
  try {
    camera.Capture(1e7, 0);
    FAIL() << "an impossible exposure was accepted";
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("camera 'Fake_1': exposure: refuses 1e+07 s"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(AravisCamera("No_Such_Camera_42", clock), UserError);
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
  int mismatches = 0;
  for (int y = 0; y < frame.height; ++y)
    for (int x = 0; x < frame.width; ++x)
      mismatches += frame.pixels[static_cast<std::size_t>(y) * frame.width + x] !=
                    FakePixel(x, y, camera.last_frame_id(), 0.02, 1, frame.adc_bits);
  EXPECT_EQ(mismatches, 0);
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
