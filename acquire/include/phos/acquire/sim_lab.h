#pragma once
// The simulated lab: a phosphorescent sample that glows by the model (Eq. 8.1,
// 8.2, advanced in closed form between light switches), lights with real
// emission spectra, and a camera with spectral sensitivities and a noise
// model (shot noise, read noise, dark current, black level, ADC bits,
// saturation), all on one clock. Protocols drive it through the same Camera
// and Lights interfaces as real hardware.

#include <filesystem>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "phos/acquire/camera.h"
#include "phos/acquire/clock.h"
#include "phos/acquire/lights.h"
#include "phos/model/material.h"
#include "phos/model/spectral.h"

namespace phos {

// A light channel: its emission spectrum (normalized to unit integral) and
// the total irradiance it puts on the sample, in the material's irradiance units.
struct LightSource {
  std::string name;
  SampledSpectrum spectrum;
  double irradiance = 1.0;
};

LightSource LedLight(const std::string& name, double center_nm, double fwhm_nm, double irradiance);
// A phosphor-converted white LED: blue pump at 450 nm plus a broad yellow band.
LightSource WhiteLedLight(const std::string& name, double irradiance);
// A halogen lamp: a 3000 K blackbody from 350 to 800 nm.
LightSource HalogenLight(const std::string& name, double irradiance);
// led365, led405, led420, led456, led494 (filtered, one per band of Table
// 8.1's measured ke), white, lamp: the lab of the method (Sec. 8.4),
// irradiance 1 each; then the LVF calibration's sources of known wavelength (Sec. 8.4.2):
// the mercury lines at 435.8 and 546.1 nm ("hg436", "hg546") and a HeNe
// laser line at 632.8 nm ("hene633") behind a diffuser, which only light the
// white reference.
std::vector<LightSource> DefaultLights();
// The known centre wavelength of each calibration source of DefaultLights().
struct KnownLine {
  std::string light;
  double wavelength_nm;
};
std::vector<KnownLine> DefaultCalibrationLines();

// A linear variable filter (Sec. 8.4.2): a band-pass whose centre moves
// linearly across the image, from start_nm at the left edge to end_nm at the
// right, Gaussian of fwhm_nm; placed in front of the camera for spectra.
struct LinearVariableFilter {
  double start_nm = 380, end_nm = 720;
  double fwhm_nm = 25;
  double peak_transmission = 0.6;
  // The pass band's centre at pixel column x (centre of the pixel).
  double CenterNm(double x, int width) const { return start_nm + (end_nm - start_nm) * (x + 0.5) / width; }
};

struct CameraModel {
  int width = 64, height = 48;
  std::vector<std::string> channel_names = {"R", "G", "B"};
  // Relative spectral sensitivity per channel (default: Gaussians at 600,
  // 540 and 460 nm, 90 nm wide; docs/capture.md).
  std::vector<SampledSpectrum> sensitivity;
  double electrons_per_unit = 2e5;  // photo-electrons per second per unit of sensitivity-weighted radiance
  double read_noise_e = 5;
  double dark_current_e_per_s = 2;
  double full_well_e = 15000;
  double gain_dn_per_e = 0.27;  // full well (15000 e) lands above the ADC's top, so clipping shows in the DN
  double black_level_dn = 64;
  int adc_bits = 12;
  double readout_s = 0.01;
  double max_exposure_s = 30;
  unsigned seed = 1;
  LinearVariableFilter lvf;  // used while the filter is in the light path
};
CameraModel DefaultCameraModel();
// The default camera with the spectral sensitivities of a CSV file: a column
// wavelength_nm (increasing) and one column per channel, named by its header
// ("R,G,B" for a colour camera, "Y" for a mono one). Values are relative;
// negative, non-increasing or missing data is a UserError naming the file.
CameraModel CameraModelFromCsv(const std::filesystem::path& path);

class SimulatedLab final : public Camera {
 public:
  // The sample: `material` with diffuse `albedo` per band of its grid.
  SimulatedLab(Material material, std::vector<double> albedo, std::vector<LightSource> lights, CameraModel camera,
               Clock& clock);

  Lights& lights() { return *lights_; }

  // What the operator (or a motorized slide) changes between protocols:
  // the LVF in front of the camera or not; the sample or the white
  // reference (reflectance 1, no phosphor) in the field of view. While the
  // white reference is there, the sample sits in the dark and keeps decaying.
  void SetLvfInPath(bool in_path);
  void SetWhiteReferenceInView(bool in_view);
  bool lvf_in_path() const { return lvf_in_path_; }
  // A spatially varying sample: `inset` (same band grid) fills a centred disk
  // of `radius_fraction` of the half-height; the rest is the sample's own
  // material. Each part charges and decays by its own model.
  void SetInset(Material inset, double radius_fraction);
  bool InInset(int x, int y) const;
  bool white_reference_in_view() const { return white_reference_; }
  const CameraModel& camera_model() const { return camera_; }
  std::string description() const override;
  Frame Capture(double exposure_s, double gain) override;
  double max_exposure_s() const override { return camera_.max_exposure_s; }

  // The sample's states now (for tests).
  std::vector<double> StateNow();
  // Band-integrated irradiance on the sample from the lights that are on.
  std::vector<double> IrradianceNow() const;
  // What one light puts on the sample, per band of the material's grid (what
  // a bench measures with a calibrated spectroradiometer once per LED).
  std::vector<double> SourceBandIrradiance(const std::string& light) const;

 private:
  void AdvanceTo(double t_s);

  Material material_;
  std::vector<double> albedo_;
  std::vector<LightSource> sources_;
  std::vector<std::vector<double>> source_E_;  // per source, per band
  CameraModel camera_;
  // How the camera sees, without the LVF (one column stands for all) and
  // through it (one entry per column): the weight of the sample's emission
  // per band, and the reflection of each light off the sample and off the
  // white reference, integrated over wavelength (so narrow lines stay narrow).
  struct Optics {
    std::vector<std::vector<std::vector<double>>> emission;        // [column][channel][band]
    std::vector<std::vector<std::vector<double>>> sample_reflect;  // [source][column][channel]
    std::vector<std::vector<std::vector<double>>> white_reflect;   // [source][column][channel]
  };
  Optics MakeOptics(bool through_lvf) const;
  Optics plain_, lvf_;
  bool lvf_in_path_ = false, white_reference_ = false;
  Clock& clock_;
  std::unique_ptr<RecordingLights> lights_;
  std::vector<double> r_;
  std::optional<Material> inset_;
  std::vector<double> inset_r_;
  double inset_radius_ = 0;
  double t_state_;
  std::mt19937_64 rng_;
};

}  // namespace phos
