// phos-appearance-study: the paper's appearance metric (Fig. 8.13: CIEDE2000
// between photographs of a material and renderings of its fit, average 5.46
// for nc = 2 against 13.16 for nc = 1), measured through the simulated lab.
//
// Each material (the two-state fixtures, a seeded family of random two-state
// materials, the single-state Table 8.1 presets) is captured as
// `phos capture all` captures it (the phos binary itself runs, so the study
// follows the protocols as they change), fitted with FitSession twice (nc = 1
// and nc = 2), and the fitted material is compared with the true one as the
// simulated camera sees their glow: a charge under led405 (the decay
// protocol's light) from a dark-adapted sample, and the decay after it. At
// each time both glows go through the same stated conversion to CIELAB
// (docs/appearance.md) and CIEDE2000 (Sharma, Wu and Dalal 2005) compares them.
//
//   phos-appearance-study --out docs     (docs/appearance.csv, .md, .svg, -charge.svg)

#include <CLI/CLI.hpp>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

#include "phos/acquire/sim_lab.h"
#include "phos/fit/session_fit.h"
#include "phos/model/material.h"
#include "phos/model/rate_equation.h"
#include "phos/model/schedule.h"
#include "phos/model/simulate.h"
#include "phos/model/synthetic.h"
#include "phos/util/colour.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/progress.h"
#include "phos/util/svg_plot.h"

namespace phos {
namespace {

namespace fs = std::filesystem;

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
constexpr const char* kChargeLight = "led405";  // what the decay protocol charges with (capture all's default)
constexpr double kChargeS = 60;
// Fig. 8.13 compares at 0.01 s and 20 s after light-off; these add the
// charge and the decay's whole span.
const std::vector<double> kChargeTimesS = {1, 5, 10, 30, 60};
const std::vector<double> kDecayTimesS = {0.01, 0.1, 0.5, 1, 2, 5, 10, 20, 60, 120};
// Photographic exposure metered on the true material: its Y is middle grey.
constexpr double kMeteredY = 0.18;

// ---- how the camera sees a glow, in CIELAB ---------------------------------

// The stated conversion (docs/appearance.md): the simulated camera's linear
// RGB of a glow, a 3x3 matrix onto CIE 1931 XYZ, an exposure, then CIELAB
// against D65.
struct CameraColour {
  // Camera RGB of unit radiance in each band: the band mean of each
  // channel's sensitivity, as the simulated lab weighs a sample's emission
  // (uniform density inside a band; no LVF, no noise).
  std::vector<Tristimulus> band_rgb;
  // CIE XYZ of the same single-band spectra (the CMFs' band means).
  std::vector<Tristimulus> band_xyz;
  ColourMatrix rgb_to_xyz;
};

CameraColour MakeCameraColour(const CameraModel& camera, const SpectralGrid& grid) {
  if (camera.sensitivity.size() != 3) ThrowUserError("camera", "", "the appearance metric needs an RGB camera");
  CameraColour c;
  for (int b = 0; b < grid.band_count(); ++b) {
    Tristimulus rgb;
    for (int k = 0; k < 3; ++k)
      rgb[k] = camera.sensitivity[k].Integrate(grid.lower_nm(b), grid.upper_nm(b)) / grid.width_nm(b);
    c.band_rgb.push_back(rgb);
    c.band_xyz.push_back(Cie1931CmfBandMean(grid.lower_nm(b), grid.upper_nm(b)));
  }
  // Every glow is a non-negative mix of the single-band spectra, so the
  // matrix is the least-squares fit over them.
  c.rgb_to_xyz = FitColourMatrix(c.band_rgb, c.band_xyz);
  return c;
}

// Weighted sum of per-band tristimuli with band radiance Lp.
Tristimulus OfRadiance(const std::vector<Tristimulus>& per_band, const std::vector<double>& Lp) {
  Tristimulus t = {0, 0, 0};
  for (std::size_t b = 0; b < Lp.size(); ++b)
    for (int k = 0; k < 3; ++k) t[k] += per_band[b][k] * Lp[b];
  return t;
}

Tristimulus CameraXyz(const CameraColour& c, const std::vector<double>& Lp) {
  return Apply(c.rgb_to_xyz, OfRadiance(c.band_rgb, Lp));
}

// CIEDE2000 of `test` against `reference` after one exposure that makes the
// reference's Y middle grey of the D65 white (Y = 1): brightness errors count.
// NaN when the reference is black.
double ExposedDifference(const Tristimulus& reference, const Tristimulus& test) {
  if (!(reference[1] > 0)) return kNan;
  const double exposure = kMeteredY / reference[1];
  const Tristimulus white = D65WhiteXyz();
  Tristimulus r, t;
  for (int k = 0; k < 3; ++k) {
    r[k] = exposure * reference[k];
    t[k] = exposure * test[k];
  }
  return Ciede2000(XyzToLab(r, white), XyzToLab(t, white));
}

// ---- a material under the charge and the decay ------------------------------

struct Moment {
  std::string phase;  // "charge" (t since light-on) or "decay" (t since light-off)
  double t_s;
};

std::vector<Moment> Moments() {
  std::vector<Moment> m;
  for (double t : kChargeTimesS) m.push_back({"charge", t});
  for (double t : kDecayTimesS) m.push_back({"decay", t});
  return m;
}

// Emitted radiance per band at a moment, from a dark-adapted start: Eq. 8.1
// in closed form (ClosedFormState) under the charge's band irradiance E,
// then in the dark.
std::vector<double> GlowAt(const Material& material, const std::vector<double>& E, const Moment& moment) {
  const std::vector<double> a = ExcitationRates(material, E, material.name);
  std::vector<double> r(a.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double kr = material.states[i].kr;
    r[i] = moment.phase == "charge" ? ClosedFormState(0, a[i], kr, moment.t_s)
                                    : ClosedFormState(ClosedFormState(0, a[i], kr, kChargeS), 0, kr, moment.t_s);
  }
  return EmittedRadiance(material, r.data());
}

// ---- the materials -----------------------------------------------------------

struct Truth {
  std::string name, family;  // family: "two-state fixture", "random two-state", "single-state preset"
  fs::path file;
  Material material;
};

std::vector<Truth> Truths(int random_count, const fs::path& scratch) {
  const fs::path dir = fs::path(PHOS_FIXTURES_DIR) / "materials";
  std::vector<Truth> truths;
  std::vector<fs::path> fixtures;
  for (const auto& entry : fs::directory_iterator(dir))
    if (entry.path().filename().string().rfind("two-state-", 0) == 0 && entry.path().extension() == ".json")
      fixtures.push_back(entry.path());
  std::sort(fixtures.begin(), fixtures.end());
  for (const fs::path& f : fixtures) truths.push_back({f.stem().string(), "two-state fixture", f, LoadMaterial(f)});
  for (int seed = 1; seed <= random_count; ++seed) {
    Truth t{"", "random two-state", "", RandomTwoStateMaterial(static_cast<std::uint64_t>(seed))};
    t.name = t.material.name;
    t.file = scratch / (t.name + ".json");
    SaveMaterial(t.material, t.file);
    truths.push_back(std::move(t));
  }
  for (const char* preset : {"blue", "green", "orange", "pink", "purple", "red", "white", "yellow"}) {
    const fs::path f = dir / (std::string(preset) + ".json");
    truths.push_back({preset, "single-state preset", f, LoadMaterial(f)});
  }
  return truths;
}

std::string Quoted(const fs::path& p) {
  std::string q = "'";
  for (char c : p.string()) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// `phos capture all` of the truth into `session`; an error names the log's last line.
void CaptureAll(const fs::path& phos, const Truth& truth, const fs::path& session) {
  fs::remove_all(session);
  const fs::path log = session.string() + ".log";
  const std::string command = Quoted(phos) + " capture all --sim-material " + Quoted(truth.file) + " --out " +
                              Quoted(session) + " >" + Quoted(log) + " 2>&1";
  int status = std::system(command.c_str());
  // 126/127: the binary could not be run, e.g. while a build relinks it; wait and try again.
  for (int retry = 0; retry < 3 && WIFEXITED(status) && (WEXITSTATUS(status) == 126 || WEXITSTATUS(status) == 127);
       ++retry) {
    sleep(10);
    status = std::system(command.c_str());
  }
  if (status != 0) {
    std::ifstream in(log);
    std::string line, last;
    while (std::getline(in, line))
      if (!line.empty()) last = line;
    throw std::runtime_error("phos capture all failed (exit code " +
                             std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + "): " + last);
  }
}

// ---- one material's result ------------------------------------------------------

struct FitResult {
  int nc = 0;
  std::vector<double> dE00;      // per moment; NaN where the truth is black
  std::vector<double> dE00_eye;  // the same through the CIE observer's XYZ instead of the camera's
  std::string error;             // why there is none
};

struct Result {
  const Truth* truth = nullptr;
  FitResult fits[2];               // nc = 1, nc = 2
  std::vector<double> camera_eye;  // per moment: the camera's colour against the CIE observer's, on the truth
  std::string error;               // the capture's
  double seconds = 0;
};

FitResult FitAndCompare(const fs::path& session, const Truth& truth, int nc, const CameraColour& colour,
                        const std::vector<double>& E) {
  FitResult r;
  r.nc = nc;
  try {
    SessionFitOptions options;
    options.components = nc;
    const Material fitted = FitSession(session, options).material;
    for (const Moment& m : Moments()) {
      const std::vector<double> true_Lp = GlowAt(truth.material, E, m), fitted_Lp = GlowAt(fitted, E, m);
      r.dE00.push_back(ExposedDifference(CameraXyz(colour, true_Lp), CameraXyz(colour, fitted_Lp)));
      r.dE00_eye.push_back(
          ExposedDifference(OfRadiance(colour.band_xyz, true_Lp), OfRadiance(colour.band_xyz, fitted_Lp)));
    }
  } catch (const std::exception& e) {
    r.dE00.clear();
    r.dE00_eye.clear();
    r.error = e.what();
  }
  return r;
}

struct Stats {
  double mean = kNan, min = kNan, max = kNan;
  int count = 0;
};

Stats StatsOf(const std::vector<double>& values) {
  Stats s;
  double sum = 0;
  for (double v : values) {
    if (!std::isfinite(v)) continue;
    s.min = s.count ? std::min(s.min, v) : v;
    s.max = s.count ? std::max(s.max, v) : v;
    sum += v;
    ++s.count;
  }
  if (s.count) s.mean = sum / s.count;
  return s;
}

std::string Cell(double v) { return std::isfinite(v) ? FormatShort(v, 3) : "-"; }

double At(const std::vector<double>& dE, const std::string& phase, double t_s) {
  const std::vector<Moment> moments = Moments();
  for (std::size_t k = 0; k < moments.size() && k < dE.size(); ++k)
    if (moments[k].phase == phase && moments[k].t_s == t_s) return dE[k];
  return kNan;
}

// Captures one truth, fits it with nc = 1 and 2 and compares each fit.
Result StudyMaterial(const Truth& truth, const fs::path& phos_binary, const fs::path& scratch, bool keep,
                     const CameraColour& colour, const std::vector<double>& E) {
  const auto t0 = std::chrono::steady_clock::now();
  Result r;
  r.truth = &truth;
  const fs::path session = scratch / truth.name;
  try {
    CaptureAll(phos_binary, truth, session);
    for (int k = 0; k < 2; ++k) r.fits[k] = FitAndCompare(session, truth, k + 1, colour, E);
    for (const Moment& m : Moments()) {
      const std::vector<double> Lp = GlowAt(truth.material, E, m);
      r.camera_eye.push_back(ExposedDifference(OfRadiance(colour.band_xyz, Lp), CameraXyz(colour, Lp)));
    }
  } catch (const std::exception& e) {
    r.error = e.what();
  }
  if (!keep) fs::remove_all(session);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

// The progress line of a material.
std::string ProgressLine(const Result& r) {
  std::string line = "  " + r.truth->name + " (" + r.truth->family + "): ";
  if (!r.error.empty()) line += "not captured: " + r.error + " ";
  for (const FitResult& f : r.fits) {
    if (!r.error.empty()) break;
    line += "nc=" + std::to_string(f.nc) + " ";
    line += f.error.empty() ? "mean dE00 " + Cell(StatsOf(f.dE00).mean) + "  " : "not fitted (" + f.error + ")  ";
  }
  return line + "(" + FormatShort(r.seconds, 2) + " s)";
}

std::string Csv(const std::vector<Result>& results) {
  const std::vector<Moment> moments = Moments();
  std::string csv = "material,family,nc_fit,phase,t_s,dE00,dE00_cie_observer\n";
  for (const Result& r : results)
    for (const FitResult& f : r.fits)
      for (std::size_t k = 0; k < f.dE00.size(); ++k)
        csv += r.truth->name + "," + r.truth->family + "," + std::to_string(f.nc) + "," + moments[k].phase + "," +
               FormatDouble(moments[k].t_s) + "," + FormatDouble(f.dE00[k]) + "," + FormatDouble(f.dE00_eye[k]) + "\n";
  return csv;
}

const char* const kFamilies[] = {"two-state fixture", "random two-state", "single-state preset"};

std::string IntroSection() {
  const std::vector<Moment> moments = Moments();
  std::string md =
      "<!-- written by: build/bin/phos-appearance-study --out docs (make study) -->\n"
      "# The appearance metric: CIEDE2000 between true and fitted materials\n\n"
      "The paper judges its fits by how they look (Fig. 8.13): CIEDE2000 between photographs of each material "
      "and renderings of its fit, at 0.01 s and 20 s after light-off, average **5.46 for nc = 2 against 13.16 for "
      "nc = 1**. Here the photographs are the simulated camera's view of the true material, so the metric "
      "isolates the capture-and-fit pipeline: every material below was captured by `phos capture all` in the "
      "simulated lab (noise and all), fitted by `FitSession` with nc = 1 and with nc = 2 (`--components`), and the "
      "fitted material's glow compared with the truth's at " +
      std::to_string(moments.size()) + " times: " + std::to_string(kChargeTimesS.size()) + " during a " +
      FormatShort(kChargeS) + " s charge under " + kChargeLight +
      " (the decay protocol's light, its band irradiance from `SimulatedLab::SourceBandIrradiance`) from a "
      "dark-adapted sample, at t = ";
  for (std::size_t k = 0; k < kChargeTimesS.size(); ++k) md += (k ? ", " : "") + FormatShort(kChargeTimesS[k]);
  md += " s after light-on, and " + std::to_string(kDecayTimesS.size()) + " in the decay after it, at t = ";
  for (std::size_t k = 0; k < kDecayTimesS.size(); ++k) md += (k ? ", " : "") + FormatShort(kDecayTimesS[k]);
  md +=
      " s after light-off. The glow only: the charge light's reflection is the same for both and is left out "
      "(as a long-pass filter in front of the camera would). Per-time values: [appearance.csv](appearance.csv); "
      "plots: [appearance.svg](appearance.svg) (decay), [appearance-charge.svg](appearance-charge.svg) (charge).\n\n";
  return md;
}

std::string ConversionSection(const CameraColour& colour) {
  std::string md;
  md +=
      "## The conversion\n\n"
      "1. **Camera RGB.** The simulated lab's default camera (`DefaultCameraModel`: Gaussian sensitivities at "
      "600, 540 and 460 nm, 90 nm FWHM), noise-free and linear: each channel sees band b's radiance Lp[b] "
      "weighted by the band mean of its sensitivity, the weight the simulated lab gives a sample's emission "
      "(uniform density inside a band). Noise, black level and clipping are left out: they belong to a "
      "photograph, not to the material.\n"
      "2. **RGB to XYZ.** A 3x3 matrix M fitted by least squares (`FitColourMatrix`) so that the camera RGB of "
      "each of the eight single-band spectra (radiance 1 in one band) maps onto its CIE 1931 XYZ, the band mean "
      "of the colour matching functions (the multi-lobe fit of Wyman, Sloan and Shirley, JCGT 2013, the one the "
      "renderer uses). Every glow is a non-negative mix of those eight spectra, which is why they are the "
      "training set. This is a camera characterization: a camera's colour is never exactly the eye's (the "
      "Luther condition), and the column *camera vs eye* below says by how much (CIEDE2000 between M times "
      "the camera RGB and the CIE XYZ of the true glow, exposed the same way; mean over the times).\n"
      "3. **Exposure.** At each time, like a photograph metered on the true material: one factor scales both "
      "the true and the fitted XYZ so that the true Y is " +
      FormatShort(kMeteredY) +
      " of the white's "
      "(middle grey). The fitted material is judged at the truth's exposure, so a brightness error counts "
      "(about 6% of Y is one unit of L* at middle grey).\n"
      "4. **CIELAB** against the D65 white (XYZ 0.95047, 1, 1.08883; CIE 15:2004), then **CIEDE2000** "
      "(kL = kC = kH = 1, Sharma, Wu and Dalal 2005; `util/colour.h`, tested against their 34 pairs). "
      "Below 1 is not perceptible.\n\n"
      "M (rows X, Y, Z; columns camera R, G, B):\n\n";
  for (const auto& row : colour.rgb_to_xyz)
    md += "    " + FormatShort(row[0], 5) + "  " + FormatShort(row[1], 5) + "  " + FormatShort(row[2], 5) + "\n";
  return md + "\n";
}

// Each two-state material's average dE00 over the times, of its nc = k + 1 fit.
// `eye`: through the CIE observer instead of the camera.
std::vector<double> TwoStateAverages(const std::vector<Result>& results, int k, bool eye = false) {
  std::vector<double> averages;
  for (const Result& r : results) {
    const Stats s = StatsOf(eye ? r.fits[k].dE00_eye : r.fits[k].dE00);
    if (r.truth->material.state_count() == 2 && s.count) averages.push_back(s.mean);
  }
  return averages;
}

std::string FamilySection(const std::vector<Result>& results) {
  std::string md;
  md +=
      "## Per family\n\n"
      "Mean over the family's materials of each material's average over the times; min and max over all "
      "materials and times; how many materials average under 1 with nc = 2, and those that do not.\n\n"
      "| family | materials | nc=1 mean | nc=1 min | nc=1 max | nc=2 mean | nc=2 min | nc=2 max | nc=2 average < 1 "
      "| nc=2 average >= 1 |\n"
      "|---|---|---|---|---|---|---|---|---|---|\n";
  for (const std::string family : kFamilies) {
    int materials = 0;
    std::string cells;
    int under_one = 0, fitted2 = 0;
    std::string over_one;
    for (int k = 0; k < 2; ++k) {
      std::vector<double> averages, all;
      for (const Result& r : results) {
        if (r.truth->family != family) continue;
        if (k == 0) ++materials;
        const Stats s = StatsOf(r.fits[k].dE00);
        if (s.count == 0) continue;
        averages.push_back(s.mean);
        all.insert(all.end(), r.fits[k].dE00.begin(), r.fits[k].dE00.end());
        if (k == 1) {
          ++fitted2;
          under_one += s.mean < 1;
          if (s.mean >= 1) over_one += (over_one.empty() ? "" : ", ") + r.truth->name + " (" + Cell(s.mean) + ")";
        }
      }
      const Stats over = StatsOf(all);
      cells += " " + Cell(StatsOf(averages).mean) + " | " + Cell(over.min) + " | " + Cell(over.max) + " |";
    }
    md += "| " + family + " | " + std::to_string(materials) + " |" + cells + " " + std::to_string(under_one) + " of " +
          std::to_string(fitted2) + " | " + (over_one.empty() ? "-" : over_one) + " |\n";
  }
  const std::vector<double> one = TwoStateAverages(results, 0), two = TwoStateAverages(results, 1);
  md += "\nTwo-state materials (fixtures and random family together, " + std::to_string(two.size()) +
        " fitted with nc = 2): average dE00 **" + Cell(StatsOf(one).mean) + " for nc = 1, " + Cell(StatsOf(two).mean) +
        " for nc = 2**. The paper, on photographs of measured materials: 13.16 for nc = 1, 5.46 for nc = 2. Goal: "
        "nc = 2 fits of two-state truths under 1. Seen by the CIE observer instead of the camera "
        "(XYZ straight from the band radiance, same exposure; column dE00_cie_observer of the CSV): " +
        Cell(StatsOf(TwoStateAverages(results, 0, true)).mean) + " for nc = 1, " +
        Cell(StatsOf(TwoStateAverages(results, 1, true)).mean) + " for nc = 2.\n\n";
  return md;
}

std::string MaterialSection(const std::vector<Result>& results, int random_count, std::size_t material_count,
                            double total_s, int threads) {
  const std::vector<Moment> moments = Moments();
  std::string md;
  md +=
      "## Per material\n\n"
      "dE00 over the " +
      std::to_string(moments.size()) +
      " times: average, minimum and maximum, and at Fig. "
      "8.13's two times (0.01 s and 20 s after light-off).\n\n"
      "| material | family | true nc | nc=1 avg | nc=1 min | nc=1 max | nc=1 at 0.01 s / 20 s | nc=2 avg | nc=2 min "
      "| nc=2 max | nc=2 at 0.01 s / 20 s | camera vs eye |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  std::vector<std::string> notes;
  for (const Result& r : results) {
    md +=
        "| " + r.truth->name + " | " + r.truth->family + " | " + std::to_string(r.truth->material.state_count()) + " |";
    for (const FitResult& f : r.fits) {
      const Stats s = StatsOf(f.dE00);
      md += " " + Cell(s.mean) + " | " + Cell(s.min) + " | " + Cell(s.max) + " | " + Cell(At(f.dE00, "decay", 0.01)) +
            " / " + Cell(At(f.dE00, "decay", 20)) + " |";
      if (!f.error.empty())
        notes.push_back(r.truth->name + ", nc = " + std::to_string(f.nc) + ": not fitted: " + f.error);
    }
    md += " " + Cell(StatsOf(r.camera_eye).mean) + " |\n";
    if (!r.error.empty()) notes.push_back(r.truth->name + ": not captured: " + r.error);
  }
  if (!notes.empty()) {
    md += "\nLeft out:\n\n";
    for (const std::string& n : notes) md += "- " + n + "\n";
  }
  md += "\nThe random family is `RandomTwoStateMaterial(seed)` (model/synthetic.h) for seeds 1 to " +
        std::to_string(random_count) +
        ": rate ratios 2-50, fast shares 10-90%, the ranges the pipeline is held "
        "to recover. " +
        std::to_string(material_count) + " materials, " + FormatShort(total_s, 3) + " s on " + std::to_string(threads) +
        " threads.\n\n"
        "Made by `build/bin/phos-appearance-study --out docs` (`make study`).\n";
  return md;
}

// For the plot's legend, which has little room.
std::string ShortFamily(const std::string& family) {
  if (family == "two-state fixture") return "2-state fixtures";
  if (family == "random two-state") return "2-state random";
  return "1-state presets";
}

// dE00 against time in one phase: the mean over each family, nc = 1 dashed and nc = 2 solid.
std::string PlotOfPhase(const std::vector<Result>& results, const std::string& phase) {
  const std::vector<Moment> moments = Moments();
  std::vector<PlotSeries> series;
  int colour_index = 0;
  for (const std::string family : kFamilies) {
    for (int k = 0; k < 2; ++k) {
      PlotSeries s(ShortFamily(family) + ", nc=" + std::to_string(k + 1));
      s.color = PaletteColor(colour_index);
      s.dashed = k == 0;
      s.markers = true;
      for (std::size_t m = 0; m < moments.size(); ++m) {
        if (moments[m].phase != phase) continue;
        std::vector<double> at;
        for (const Result& r : results)
          if (r.truth->family == family && m < r.fits[k].dE00.size()) at.push_back(r.fits[k].dE00[m]);
        const Stats st = StatsOf(at);
        if (st.count == 0) continue;
        s.x.push_back(moments[m].t_s);
        s.y.push_back(st.mean);
      }
      series.push_back(s);
    }
    ++colour_index;
  }
  PlotOptions options;
  options.title = "CIEDE2000, true vs fitted, " + std::string(phase == "decay" ? "after" : "during") + " a " +
                  FormatShort(kChargeS) + " s charge (dashed: nc = 1, solid: nc = 2)";
  options.x_label = phase == "decay" ? "time after light-off (s)" : "time after light-on (s)";
  options.y_label = "CIEDE2000 (mean over the family)";
  options.log_x = true;
  options.log_y = true;
  return PlotSvg(series, options);
}

}  // namespace
}  // namespace phos

int main(int argc, char** argv) {
  using namespace phos;
  CLI::App app{
      "The paper's appearance metric (Fig. 8.13): CIEDE2000 between each true material and its nc = 1 and "
      "nc = 2 fits, as the simulated camera sees them over a charge and the decay after it."};
  std::string out = "docs", phos_binary = PHOS_BINARY;
  int random_count = 20, threads = 2;
  bool keep = false;
  app.add_option("--out", out, "folder for appearance.csv, .md, .svg and -charge.svg (default docs)");
  app.add_option("--random", random_count, "random two-state materials, seeds 1..N (default 20)")
      ->check(CLI::Range(0, 1000));
  app.add_option("--threads", threads, "materials captured and fitted at once (default 2)")->check(CLI::Range(1, 64));
  app.add_option("--phos", phos_binary, "the phos binary that captures (default: this build's)");
  app.add_flag("--keep-sessions", keep, "keep the captured sessions (their folder is printed)");
  CLI11_PARSE(app, argc, argv);
  try {
    const auto start = std::chrono::steady_clock::now();
    const fs::path scratch = fs::temp_directory_path() / ("phos-appearance-study-" + std::to_string(getpid()));
    fs::create_directories(scratch);
    const std::vector<Truth> truths = Truths(random_count, scratch);
    const SpectralGrid grid = SpectralGrid::Paper();
    for (const Truth& t : truths)
      if (!(t.material.bands == grid))
        ThrowUserError(t.file.string(), "bands", "the study compares on the paper's 8 bands");
    const CameraModel camera = DefaultCameraModel();
    const CameraColour colour = MakeCameraColour(camera, grid);
    // The charge light's band irradiance on the sample, as the lab measures it.
    VirtualClock clock;
    const SimulatedLab lab(truths.front().material,
                           std::vector<double>(static_cast<std::size_t>(grid.band_count()), 0.8), DefaultLights(),
                           camera, clock);
    const std::vector<double> E = lab.SourceBandIrradiance(kChargeLight);

    std::printf("phos-appearance-study: %zu materials (capture all, then FitSession with nc = 1 and 2), %d at once\n",
                truths.size(), threads);
    std::vector<Result> results(truths.size());
    {
      std::mutex print;
      ProgressBar progress("appearance study", truths.size());
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
      tbb::parallel_for(
          std::size_t(0), truths.size(),
          [&](std::size_t i) {
            results[i] = StudyMaterial(truths[i], phos_binary, scratch, keep, colour, E);
            {
              std::lock_guard<std::mutex> lock(print);
              std::printf("%s\n", ProgressLine(results[i]).c_str());
              std::fflush(stdout);
            }
            progress.Advance();
          },
          tbb::simple_partitioner());
    }
    if (keep)
      std::printf("sessions kept in %s\n", scratch.string().c_str());
    else
      fs::remove_all(scratch);

    const double total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    WriteFileAtomically(fs::path(out) / "appearance.csv", Csv(results));
    const std::string md = IntroSection() + ConversionSection(colour) + FamilySection(results) +
                           MaterialSection(results, random_count, truths.size(), total_s, threads);
    WriteFileAtomically(fs::path(out) / "appearance.md", md);
    WriteFileAtomically(fs::path(out) / "appearance.svg", PlotOfPhase(results, "decay"));
    WriteFileAtomically(fs::path(out) / "appearance-charge.svg", PlotOfPhase(results, "charge"));
    std::printf("%s", md.c_str());
    std::printf("two-state materials: average dE00 %s (nc = 1), %s (nc = 2); written to %s/appearance.{md,csv,svg}\n",
                Cell(StatsOf(TwoStateAverages(results, 0)).mean).c_str(),
                Cell(StatsOf(TwoStateAverages(results, 1)).mean).c_str(), out.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "phos-appearance-study: %s\n", e.what());
    return 2;
  }
  return 0;
}
