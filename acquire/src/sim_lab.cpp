#include "phos/acquire/sim_lab.h"

#include <algorithm>
#include <cmath>

#include "phos/model/rate_equation.h"
#include "phos/model/schedule.h"
#include "phos/model/simulate.h"
#include "phos/util/csv.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/math.h"

namespace phos {
double Frame::MeanSignal(int channel) const {
  double sum = 0;
  const std::size_t pixels_count = static_cast<std::size_t>(width) * height;
  for (std::size_t p = 0; p < pixels_count; ++p) sum += pixels[p * channels + channel];
  return sum / static_cast<double>(pixels_count) - black_level_dn;
}

double Frame::SaturatedFraction() const {
  const std::uint16_t top = static_cast<std::uint16_t>((1u << adc_bits) - 1);
  std::size_t saturated = 0;
  for (std::uint16_t v : pixels) saturated += v >= top;
  return pixels.empty() ? 0.0 : static_cast<double>(saturated) / static_cast<double>(pixels.size());
}

LightSource LedLight(const std::string& name, double center_nm, double fwhm_nm, double irradiance) {
  return {name, LedSpectrum(center_nm, fwhm_nm), irradiance};
}

LightSource WhiteLedLight(const std::string& name, double irradiance) { return {name, WhiteLedSpectrum(), irradiance}; }

LightSource HalogenLight(const std::string& name, double irradiance) {
  return {name, BlackbodySpectrum(3000, 350, 800), irradiance};
}

std::vector<LightSource> DefaultLights() {
  // led420, led456 and led494 are LEDs behind band-pass filters, each inside
  // one of the bands 400-437.5, 437.5-475 and 475-512.5 nm where Table 8.1
  // measured ke (their Gaussians end at 4 sigma): excitation per band, as
  // Sec. 8.4.6 measures it.
  std::vector<LightSource> lights = {LedLight("led365", 365, 10, 1.0), LedLight("led405", 405, 15, 1.0),
                                     LedLight("led420", 420, 10, 1.0), LedLight("led456", 456, 10, 1.0),
                                     LedLight("led494", 494, 8, 1.0),  WhiteLedLight("white", 1.0),
                                     HalogenLight("lamp", 1.0)};
  // Spectral lines are far narrower than the LVF (25 nm); 1 nm stands for them.
  for (const KnownLine& line : DefaultCalibrationLines())
    lights.push_back(LedLight(line.light, line.wavelength_nm, 1.0, 1.0));
  return lights;
}

std::vector<KnownLine> DefaultCalibrationLines() { return {{"hg436", 435.8}, {"hg546", 546.1}, {"hene633", 632.8}}; }

CameraModel DefaultCameraModel() {
  CameraModel camera;
  camera.sensitivity = {GaussianSpectrum(600, 90), GaussianSpectrum(540, 90), GaussianSpectrum(460, 90)};
  return camera;
}

CameraModel CameraModelFromCsv(const std::filesystem::path& path) {
  const CsvTable table = ReadCsv(path);
  const int wavelength = table.Find("wavelength_nm");
  if (wavelength < 0) ThrowUserError(path.string(), "", "needs a column wavelength_nm (then one column per channel)");
  if (table.header.size() < 2)
    ThrowUserError(path.string(), "", "needs at least one channel column beside wavelength_nm");
  if (table.row_count() < 2) ThrowUserError(path.string(), "", "needs at least 2 rows");
  const std::vector<double>& nm = table.columns[wavelength];
  for (std::size_t i = 1; i < nm.size(); ++i)
    if (!(nm[i] > nm[i - 1]))
      ThrowUserError(path.string(), "wavelength_nm", "must increase (row " + std::to_string(i + 2) + ")");
  CameraModel camera = DefaultCameraModel();
  camera.channel_names.clear();
  camera.sensitivity.clear();
  for (std::size_t c = 0; c < table.header.size(); ++c) {
    if (static_cast<int>(c) == wavelength) continue;
    double peak = 0;
    for (double v : table.columns[c]) {
      if (v < 0) ThrowUserError(path.string(), table.header[c], "sensitivity must be >= 0");
      peak = std::max(peak, v);
    }
    if (peak <= 0) ThrowUserError(path.string(), table.header[c], "is zero everywhere: this channel would see nothing");
    camera.channel_names.push_back(table.header[c]);
    camera.sensitivity.push_back({nm, table.columns[c]});
  }
  return camera;
}

SimulatedLab::SimulatedLab(Material material, std::vector<double> albedo, std::vector<LightSource> lights,
                           CameraModel camera, Clock& clock)
    : material_(std::move(material)),
      albedo_(std::move(albedo)),
      sources_(std::move(lights)),
      camera_(std::move(camera)),
      clock_(clock),
      rng_(camera_.seed) {
  const int nb = material_.band_count();
  PHOS_CHECK(static_cast<int>(albedo_.size()) == nb);
  if (camera_.sensitivity.empty()) camera_.sensitivity = DefaultCameraModel().sensitivity;
  PHOS_CHECK(camera_.sensitivity.size() == camera_.channel_names.size());
  std::vector<std::string> names;
  for (const LightSource& source : sources_) {
    names.push_back(source.name);
    std::vector<double> E = IntegrateOverBands(source.spectrum, material_.bands);
    for (double& e : E) e *= source.irradiance;
    source_E_.push_back(E);
  }
  plain_ = MakeOptics(false);
  lvf_ = MakeOptics(true);
  lights_ = std::make_unique<RecordingLights>(names, clock_);
  // The state follows the lights: advance it to the moment of every switch
  // under the irradiance that held until then.
  lights_->before_change = [this](const std::string& channel, bool on) {
    AdvanceTo(clock_.now_s());
    if (!on || white_reference_) return;  // the sample in the dark sees no light
    // Refuse, before it happens, a light the sample's model cannot take (ke
    // unknown in a band it reaches): the light stays off.
    std::vector<double> E = IrradianceNow();
    for (std::size_t s = 0; s < sources_.size(); ++s)
      if (sources_[s].name == channel)
        for (std::size_t b = 0; b < E.size(); ++b) E[b] += source_E_[s][b];
    // The simulated sample is all the user chose of it: the remedy is another light.
    const std::string remedy = "charge it with a light outside that band (--light, or the protocol's light options)";
    ExcitationRates(material_, E, "simulated sample '" + material_.name + "' under '" + channel + "'", remedy);
    if (inset_) ExcitationRates(*inset_, E, "simulated inset '" + inset_->name + "' under '" + channel + "'", remedy);
  };
  r_.assign(static_cast<std::size_t>(material_.state_count()), 0.0);
  t_state_ = clock_.now_s();
}

SimulatedLab::Optics SimulatedLab::MakeOptics(bool through_lvf) const {
  // Everything is integrated on one fine wavelength grid (0.1 nm, far below
  // the 1 nm lines), by the midpoint rule.
  constexpr double kStepNm = 0.1, kLowerNm = 300, kUpperNm = 900;
  const int n = static_cast<int>((kUpperNm - kLowerNm) / kStepNm);
  std::vector<double> nm(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) nm[i] = kLowerNm + (i + 0.5) * kStepNm;
  const int columns = through_lvf ? camera_.width : 1;
  const int channels = static_cast<int>(camera_.sensitivity.size());
  const int nb = material_.band_count();
  std::vector<int> band_of(static_cast<std::size_t>(n), -1);
  for (int i = 0; i < n; ++i)
    for (int b = 0; b < nb; ++b)
      if (nm[i] >= material_.bands.lower_nm(b) && nm[i] < material_.bands.upper_nm(b)) band_of[i] = b;
  std::vector<std::vector<double>> sensitivity(static_cast<std::size_t>(channels));
  for (int c = 0; c < channels; ++c)
    for (int i = 0; i < n; ++i) sensitivity[c].push_back(camera_.sensitivity[c].Evaluate(nm[i]));
  std::vector<std::vector<double>> source(sources_.size());
  for (std::size_t s = 0; s < sources_.size(); ++s)
    for (int i = 0; i < n; ++i) source[s].push_back(sources_[s].spectrum.Evaluate(nm[i]));

  Optics optics;
  optics.emission.assign(columns, std::vector<std::vector<double>>(channels, std::vector<double>(nb, 0.0)));
  optics.sample_reflect.assign(sources_.size(),
                               std::vector<std::vector<double>>(columns, std::vector<double>(channels, 0.0)));
  optics.white_reflect = optics.sample_reflect;
  const double sigma = camera_.lvf.fwhm_nm / 2.3548;
  std::vector<double> transmission(static_cast<std::size_t>(n), 1.0);
  for (int x = 0; x < columns; ++x) {
    if (through_lvf) {
      const double center = camera_.lvf.CenterNm(x, camera_.width);
      for (int i = 0; i < n; ++i)
        transmission[i] = camera_.lvf.peak_transmission * std::exp(-0.5 * std::pow((nm[i] - center) / sigma, 2));
    }
    for (int c = 0; c < channels; ++c) {
      // Emission has a uniform density inside each band (the model's own
      // assumption), so its weight is the band mean of sensitivity x filter.
      for (int i = 0; i < n; ++i)
        if (band_of[i] >= 0)
          optics.emission[x][c][band_of[i]] +=
              sensitivity[c][i] * transmission[i] * kStepNm / material_.bands.width_nm(band_of[i]);
      for (std::size_t s = 0; s < sources_.size(); ++s) {
        double sample = 0, white = 0;
        for (int i = 0; i < n; ++i) {
          const double seen = source[s][i] * sensitivity[c][i] * transmission[i] * kStepNm;
          white += seen;
          if (band_of[i] >= 0) sample += albedo_[band_of[i]] * seen;
        }
        // Lambertian: radiance = reflectance * irradiance / pi.
        optics.sample_reflect[s][x][c] = sources_[s].irradiance * sample / kPi;
        optics.white_reflect[s][x][c] = sources_[s].irradiance * white / kPi;
      }
    }
  }
  return optics;
}

std::vector<double> SimulatedLab::SourceBandIrradiance(const std::string& light) const {
  for (std::size_t s = 0; s < sources_.size(); ++s)
    if (sources_[s].name == light) return source_E_[s];
  ThrowUserError("", "light", "unknown channel '" + light + "'");
}

void SimulatedLab::SetLvfInPath(bool in_path) { lvf_in_path_ = in_path; }

void SimulatedLab::SetWhiteReferenceInView(bool in_view) {
  // The sample's state follows what it saw until now.
  AdvanceTo(clock_.now_s());
  white_reference_ = in_view;
}

std::string SimulatedLab::description() const {
  return "simulated lab: sample '" + material_.name + "', " + std::to_string(camera_.width) + "x" +
         std::to_string(camera_.height) + " " + std::to_string(camera_.channel_names.size()) + "-channel camera, " +
         std::to_string(camera_.adc_bits) + "-bit";
}

std::vector<double> SimulatedLab::IrradianceNow() const {
  std::vector<double> E(static_cast<std::size_t>(material_.band_count()), 0.0);
  if (white_reference_) return E;  // the sample is out of the lights' way
  for (std::size_t s = 0; s < sources_.size(); ++s)
    if (lights_->IsOn(sources_[s].name))
      for (std::size_t b = 0; b < E.size(); ++b) E[b] += source_E_[s][b];
  return E;
}

void SimulatedLab::AdvanceTo(double t_s) {
  // The irradiance since the last advance is the one now: every switch
  // advances the state first (before_change), so it held throughout.
  if (t_s <= t_state_) return;
  const std::vector<double> a =
      ExcitationRates(material_, IrradianceNow(), "simulated sample '" + material_.name + "'");
  for (int i = 0; i < material_.state_count(); ++i)
    r_[i] = ExactStep(r_[i], a[i], material_.states[i].kr, t_s - t_state_);
  if (inset_) {
    const std::vector<double> b = ExcitationRates(*inset_, IrradianceNow(), "simulated inset '" + inset_->name + "'");
    for (int i = 0; i < inset_->state_count(); ++i)
      inset_r_[i] = ExactStep(inset_r_[i], b[i], inset_->states[i].kr, t_s - t_state_);
  }
  t_state_ = t_s;
}

void SimulatedLab::SetInset(Material inset, double radius_fraction) {
  if (!(inset.bands == material_.bands))
    ThrowUserError("simulated inset '" + inset.name + "'", "bands_nm", "must be the sample's band grid");
  if (!(radius_fraction > 0 && radius_fraction <= 1))
    ThrowUserError("", "inset radius", "expected a fraction in (0, 1]");
  AdvanceTo(clock_.now_s());
  inset_ = std::move(inset);
  inset_r_.assign(static_cast<std::size_t>(inset_->state_count()), 0.0);
  inset_radius_ = radius_fraction;
}

bool SimulatedLab::InInset(int x, int y) const {
  if (!inset_) return false;
  const double dx = x + 0.5 - camera_.width / 2.0, dy = y + 0.5 - camera_.height / 2.0;
  const double r = inset_radius_ * camera_.height / 2.0;
  return dx * dx + dy * dy < r * r;
}

std::vector<double> SimulatedLab::StateNow() {
  AdvanceTo(clock_.now_s());
  return r_;
}

Frame SimulatedLab::Capture(double exposure_s, double gain) {
  if (!(exposure_s > 0) || exposure_s > camera_.max_exposure_s)
    ThrowUserError("", "exposure",
                   "the camera cannot expose for " + FormatDouble(exposure_s) + " s (0 to " +
                       FormatDouble(camera_.max_exposure_s) + " s)");
  if (!(gain >= 1) || gain > 64) ThrowUserError("", "gain", "the camera cannot apply gain " + FormatDouble(gain));
  AdvanceTo(clock_.now_s());
  Frame frame;
  frame.width = camera_.width;
  frame.height = camera_.height;
  frame.channels = static_cast<int>(camera_.channel_names.size());
  frame.channel_names = camera_.channel_names;
  frame.adc_bits = camera_.adc_bits;
  frame.black_level_dn = camera_.black_level_dn;
  frame.exposure_s = exposure_s;
  frame.gain = gain;
  frame.t_start_s = clock_.now_s();
  frame.sensor_temperature_c = 25.0;

  // Radiance integrated over the exposure, per band: emission (Eq. 8.2 with
  // r integrated in closed form under the constant irradiance), unless the
  // white reference hides the sample.
  const std::vector<double> E = IrradianceNow();
  const int nb = material_.band_count();
  // Eq. 8.2 integrated over the exposure for one material and its states.
  auto emission_of = [&](const Material& material, const std::vector<double>& r) {
    std::vector<double> emission(static_cast<std::size_t>(nb), 0.0);
    if (white_reference_) return emission;
    const std::vector<double> a = ExcitationRates(material, E, "simulated sample '" + material.name + "'");
    std::vector<double> r_integral(r.size());
    for (int i = 0; i < material.state_count(); ++i)
      r_integral[i] = StateIntegral(a[i], material.states[i].kr, exposure_s, r[i]);
    return EmittedRadiance(material, r_integral.data());
  };
  const std::vector<double> emission = emission_of(material_, r_);
  const std::vector<double> inset_emission = inset_ ? emission_of(*inset_, inset_r_) : emission;

  const Optics& optics = lvf_in_path_ ? lvf_ : plain_;
  const int columns = static_cast<int>(optics.emission.size());
  const double top = static_cast<double>((1u << camera_.adc_bits) - 1);
  frame.pixels.resize(static_cast<std::size_t>(frame.width) * frame.height * frame.channels);
  std::normal_distribution<double> read_noise(0.0, camera_.read_noise_e);
  for (int x = 0; x < frame.width; ++x) {
    const int column = columns == 1 ? 0 : x;
    for (int c = 0; c < frame.channels; ++c) {
      // Mean photo-electrons in a pixel of this column: dark current, the
      // glow, and the diffuse reflection of every light that is on.
      double signal = 0, inset_signal = 0;
      for (int b = 0; b < nb; ++b) {
        signal += optics.emission[column][c][b] * emission[b];
        inset_signal += optics.emission[column][c][b] * inset_emission[b];
      }
      double reflected = 0;
      for (std::size_t s = 0; s < sources_.size(); ++s)
        if (lights_->IsOn(sources_[s].name))
          reflected += exposure_s * (white_reference_ ? optics.white_reflect : optics.sample_reflect)[s][column][c];
      const double dark_e = camera_.dark_current_e_per_s * exposure_s;
      std::poisson_distribution<long long> shot(dark_e + camera_.electrons_per_unit * (signal + reflected));
      std::poisson_distribution<long long> inset_shot(dark_e + camera_.electrons_per_unit * (inset_signal + reflected));
      for (int y = 0; y < frame.height; ++y) {
        const long long count = InInset(x, y) ? inset_shot(rng_) : shot(rng_);
        const double electrons = std::min(static_cast<double>(count), camera_.full_well_e) + read_noise(rng_);
        const double dn = std::round(electrons * camera_.gain_dn_per_e * gain + camera_.black_level_dn);
        frame.pixels[(static_cast<std::size_t>(y) * frame.width + x) * frame.channels + c] =
            static_cast<std::uint16_t>(std::clamp(dn, 0.0, top));
      }
    }
  }
  clock_.SleepFor(exposure_s + camera_.readout_s);
  AdvanceTo(clock_.now_s());
  return frame;
}

}  // namespace phos
