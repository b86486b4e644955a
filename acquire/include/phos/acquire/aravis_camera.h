#pragma once
// GenICam cameras (GigE Vision, USB3 Vision) through Aravis. Exposure and
// gain go through the ArvCamera helpers, which find the feature names each
// camera uses (ExposureTime or ExposureTimeAbs, Gain or GainRaw); no feature
// name is hard-coded here. Tested against Aravis's own fake cameras.

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "phos/acquire/camera.h"
#include "phos/acquire/clock.h"

namespace phos {

class AravisCamera final : public Camera {
 public:
  // `device_id` as Aravis names it ("Fake_1", "127.0.0.1", a serial number).
  // An unknown or unreachable camera is a UserError.
  AravisCamera(const std::string& device_id, const Clock& clock, double timeout_s = 5.0);
  ~AravisCamera() override;

  std::string description() const override;
  // Sets exposure and gain (refused values are UserErrors naming the
  // camera's bounds), acquires one frame, and reads it as 16-bit. On GigE
  // Vision, lost packets are first asked for again (packet resend); a frame
  // that still arrives incomplete (packets missing, a timeout, fewer bytes
  // than its region) is never returned: it is retaken, up to max_retakes()
  // times, and then the capture fails with one line. The frame records how
  // many packets were resent and how many retakes it took.
  Frame Capture(double exposure_s, double gain) override;
  double max_exposure_s() const override;

  // Retakes allowed per frame after an incomplete one (0 to 100). Each costs
  // an exposure, and on a link that loses a frame now and then, 3 make a
  // failure from chance alone rare; more in a row mean a broken link.
  static constexpr int kDefaultMaxRetakes = 3;
  void set_max_retakes(int retakes);
  int max_retakes() const { return max_retakes_; }

  // The GigE Vision stream's counts since its stream was built (a region,
  // binning or format change builds a new one; the fresh stream a retake
  // starts on carries the counts over); all 0 on other interfaces.
  struct StreamStatistics {
    std::uint64_t completed_frames = 0, failed_frames = 0;
    std::uint64_t resend_requests = 0;  // packets asked for again
    std::uint64_t resent_packets = 0;   // of those, the ones that came
    std::uint64_t missing_packets = 0;  // in frames that failed
  };
  StreamStatistics stream_statistics() const;

  // Region of interest in (binned) pixels (the payload, and so the stream's
  // buffers, follow it). One past the binned sensor is a UserError naming
  // `field` (the lab config names its key).
  void SetRegion(int x, int y, int width, int height, std::string_view field = "region");
  // Sums dx x dy sensor pixels into one (more signal per pixel for a faint
  // glow); the region shrinks with it.
  void SetBinning(int dx, int dy);
  std::pair<int, int> binning() const;
  std::pair<int, int> sensor_size() const;

  // Pixel format by its GenICam name: Mono8, Mono10, Mono12, Mono16 or an
  // unpacked Bayer format (BayerRG8, BayerRG12, ...). Frames keep the raw
  // values with adc_bits set from the format; a Bayer frame is one channel
  // named after its pattern (demosaicing would mix what was measured). The
  // camera starts in the deepest mono format it offers.
  void SetPixelFormat(const std::string& name);
  std::string pixel_format() const;
  std::vector<std::string> available_pixel_formats() const;

  // Triggering. kFreeRun: the camera exposes when acquisition starts.
  // kSoftware: acquisition is armed and a software trigger command starts
  // the exposure (the exposure starts when phos says, not when the camera
  // is ready). kHardware: armed, and the exposure starts on a pulse on
  // `source` (e.g. "Line1"); fire_hardware_trigger, if set, is called once
  // armed (a GPIO line of the lab wired to the camera's input). A trigger
  // that never comes is a UserError after the timeout.
  enum class Trigger { kFreeRun, kSoftware, kHardware };
  void SetTrigger(Trigger trigger, const std::string& source = "Line1");
  std::vector<std::string> available_trigger_sources() const;
  std::function<void()> fire_hardware_trigger;

  // What the camera reports now (for tests and the start record).
  double exposure_s() const;
  double gain() const;
  std::uint64_t last_frame_id() const { return last_frame_id_; }
  std::uint64_t last_camera_timestamp_ns() const { return last_camera_timestamp_ns_; }

  // Switches on Aravis's in-process "Fake" interface (device "Fake_1").
  static void EnableFakeInterface();

 private:
  void AllocateBuffers();
  // A fresh stream for a retake, its counts carried over (Capture).
  void RenewStreamForRetake();
  Trigger trigger_ = Trigger::kFreeRun;
  std::string trigger_source_;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  const Clock& clock_;
  double timeout_s_;
  int max_retakes_ = kDefaultMaxRetakes;
  std::uint64_t last_frame_id_ = 0, last_camera_timestamp_ns_ = 0;
};

}  // namespace phos
