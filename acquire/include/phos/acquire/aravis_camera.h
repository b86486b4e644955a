#pragma once
// GenICam cameras (GigE Vision, USB3 Vision) through Aravis. Exposure and
// gain go through the ArvCamera helpers, which find the feature names each
// camera uses (ExposureTime or ExposureTimeAbs, Gain or GainRaw); no feature
// name is hard-coded here. Tested against Aravis's own fake cameras.

#include <memory>
#include <string>

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
  // camera's bounds), acquires one frame, and reads it as 16-bit. A frame
  // that arrives incomplete (lost packets) is retaken, up to 3 tries.
  Frame Capture(double exposure_s, double gain) override;
  double max_exposure_s() const override;

  // Region of interest in sensor pixels (the payload, and so the stream's
  // buffers, follow it).
  void SetRegion(int x, int y, int width, int height);

  // What the camera reports now (for tests and the start record).
  double exposure_s() const;
  double gain() const;
  std::uint64_t last_frame_id() const { return last_frame_id_; }
  std::uint64_t last_camera_timestamp_ns() const { return last_camera_timestamp_ns_; }

  // Switches on Aravis's in-process "Fake" interface (device "Fake_1").
  static void EnableFakeInterface();

 private:
  void AllocateBuffers();
  struct Impl;
  std::unique_ptr<Impl> impl_;
  const Clock& clock_;
  double timeout_s_;
  std::uint64_t last_frame_id_ = 0, last_camera_timestamp_ns_ = 0;
};

}  // namespace phos
