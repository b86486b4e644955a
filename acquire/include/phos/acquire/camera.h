#pragma once
// The camera a protocol drives: exposure, gain, and frames with timestamps.
// Back ends: the simulated lab (sim_lab.h) and Aravis for GigE Vision / USB3
// Vision cameras (aravis_camera.h), which also set ROI, binning, pixel format
// and trigger.

#include <cstdint>
#include <string>
#include <vector>

namespace phos {

struct Frame {
  int width = 0, height = 0, channels = 0;  // channels interleaved per pixel
  std::vector<std::uint16_t> pixels;        // raw digital numbers
  std::vector<std::string> channel_names;   // "R", "G", "B" or "Y"
  int adc_bits = 16;
  double black_level_dn = 0;
  double exposure_s = 0, gain = 1;
  double t_start_s = 0;                   // start of the exposure on the protocol's (host's) clock
  std::uint64_t camera_timestamp_ns = 0;  // the camera's own clock, where it has one
  double sensor_temperature_c = 0;
  // What the link took to deliver the frame whole: packets the camera sent
  // again on request (GigE Vision packet resend), and frames taken again
  // because the one before arrived incomplete. A camera without a packet
  // link (the simulated lab, Aravis's in-process fake) reports 0 resent.
  std::uint64_t packets_resent = 0;
  int retakes = 0;

  // Mean of one channel minus the black level, in DN.
  double MeanSignal(int channel) const;
  // Fraction of pixels at the ADC's top (saturated).
  double SaturatedFraction() const;
};

class Camera {
 public:
  virtual ~Camera() = default;
  virtual std::string description() const = 0;
  // Exposes for exposure_s from now (the clock advances by the exposure and
  // the readout). An exposure the camera cannot do is a UserError.
  virtual Frame Capture(double exposure_s, double gain) = 0;
  virtual double max_exposure_s() const = 0;
};

}  // namespace phos
