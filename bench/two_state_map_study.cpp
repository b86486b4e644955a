// Two-state maps against one-state maps (issue 17, per-pixel maps: "two-state
// maps are supported, with their own figure"). The simulated lab captures a
// decay session of a sample that is one two-state material outside and
// another inside a disk (phos capture decay --sim-material --sim-inset);
// `phos fit map` fits it with --states 1 and --states 2. The figure shows
// the maps of kr (k1), kr2 and the rms residual for both, and a few pixels'
// curves with both fits; the page gives the medians of each region against
// the materials' own rates.
//
// Writes <out>/two-state-map.md, two-state-map.svg (maps) and
// two-state-map-curves.svg.
// Run: build/bin/phos-two-state-map-study --out docs   (make study; seconds)

#include <OpenImageIO/imageio.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "phos/fit/captured_sample.h"
#include "phos/model/closed_form.h"
#include "phos/acquire/session.h"
#include "phos/acquire/session_records.h"
#include "phos/model/material.h"
#include "phos/util/format.h"
#include "phos/util/svg_plot.h"

namespace fs = std::filesystem;

namespace phos {
namespace {

std::string Quoted(const fs::path& p) {
  std::string q = "'";
  for (char c : p.string()) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// Runs a phos command line; its output goes to `log`. An error names the log's last line.
void Run(const std::string& command, const fs::path& log) {
  const int status = std::system((command + " >" + Quoted(log) + " 2>&1").c_str());
  if (status != 0) {
    std::ifstream in(log);
    std::string line, last;
    while (std::getline(in, line))
      if (!line.empty()) last = line;
    throw std::runtime_error(command + " failed: " + last);
  }
}

// A map's channels by name (EXR files keep their own channel order).
struct MapFile {
  int width = 0, height = 0;
  std::vector<std::string> names;
  std::vector<float> pixels;
  float at(int x, int y, const std::string& name) const {
    const auto it = std::find(names.begin(), names.end(), name);
    if (it == names.end()) return std::nanf("");
    return pixels[(static_cast<std::size_t>(y) * width + x) * names.size() + (it - names.begin())];
  }
};

MapFile ReadMap(const fs::path& path) {
  auto in = OIIO::ImageInput::open(path.string());
  if (!in) throw std::runtime_error("cannot read " + path.string());
  MapFile map;
  map.width = in->spec().width;
  map.height = in->spec().height;
  map.names = in->spec().channelnames;
  map.pixels.resize(static_cast<std::size_t>(map.width) * map.height * map.names.size());
  if (!in->read_image(0, 0, 0, static_cast<int>(map.names.size()), OIIO::TypeDesc::FLOAT, map.pixels.data()))
    throw std::runtime_error("cannot read " + path.string());
  return map;
}

// One pixel's curve from the session, as phos fit map reads it: rate per
// second of exposure with the black level removed, at the exposure's middle.
struct PixelCurve {
  std::vector<double> t_s, exposure_s;
  std::vector<std::vector<double>> y;  // per channel
  std::vector<std::string> channel_names;
};

PixelCurve ReadPixelCurve(const fs::path& session, int x, int y) {
  PixelCurve curve;
  std::vector<std::string> notes;
  const CapturedSample::Decay decay = LoadDecaySession(session, &notes);
  int clipped = 0;
  for (const DecaySample& sample : DecaySamples(decay, &clipped)) {
    const Frame frame = ReadFrame(session, sample.frame->record);
    if (curve.y.empty()) {
      curve.y.resize(frame.channels);
      curve.channel_names = frame.channel_names;
    }
    curve.t_s.push_back(sample.t_s);
    curve.exposure_s.push_back(frame.exposure_s);
    for (int c = 0; c < frame.channels; ++c)
      curve.y[c].push_back(
          (frame.pixels[(static_cast<std::size_t>(y) * frame.width + x) * frame.channels + c] - frame.black_level_dn) /
          frame.exposure_s);
  }
  return curve;
}

// The map's model of channel `c` at a frame: the exposure average of each
// exponential (as the map fits it) plus the background.
double Model(const MapFile& map, int x, int y, const std::string& channel, double t, double e) {
  auto term = [](double k, double amplitude, double t_mid, double exposure) {
    if (!std::isfinite(k) || !(amplitude > 0)) return 0.0;
    return amplitude * DecayFactor(k, t_mid - exposure / 2, exposure);
  };
  return term(map.at(x, y, "kr"), map.at(x, y, "amplitude." + channel), t, e) +
         term(map.at(x, y, "kr2"), map.at(x, y, "amplitude2." + channel), t, e) + map.at(x, y, "background." + channel);
}

// A perceptually ordered colour map (viridis, by 5 anchors) for v in [0, 1].
void Viridis(double v, unsigned char* rgb) {
  static const double anchors[5][3] = {{68, 1, 84}, {59, 82, 139}, {33, 145, 140}, {94, 201, 98}, {253, 231, 37}};
  v = std::clamp(v, 0.0, 1.0) * 4;
  const int i = std::min(3, static_cast<int>(v));
  const double f = v - i;
  for (int c = 0; c < 3; ++c)
    rgb[c] = static_cast<unsigned char>(anchors[i][c] * (1 - f) + anchors[i + 1][c] * f + 0.5);
}

std::string Base64(const std::string& bytes) {
  static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (std::size_t i = 0; i < bytes.size(); i += 3) {
    const unsigned b0 = static_cast<unsigned char>(bytes[i]);
    const unsigned b1 = i + 1 < bytes.size() ? static_cast<unsigned char>(bytes[i + 1]) : 0;
    const unsigned b2 = i + 2 < bytes.size() ? static_cast<unsigned char>(bytes[i + 2]) : 0;
    const unsigned n = b0 << 16 | b1 << 8 | b2;
    out += table[n >> 18 & 63];
    out += table[n >> 12 & 63];
    out += i + 1 < bytes.size() ? table[n >> 6 & 63] : '=';
    out += i + 2 < bytes.size() ? table[n & 63] : '=';
  }
  return out;
}

// One map channel as a PNG (log scale from lo to hi, NaN white, `scale`
// screen pixels per map pixel), as a data URI for the SVG.
std::string MapPng(const MapFile& map, const std::string& name, double lo, double hi, int scale, const fs::path& tmp) {
  const int w = map.width * scale, h = map.height * scale;
  std::vector<unsigned char> rgb(static_cast<std::size_t>(w) * h * 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      unsigned char* out = &rgb[(static_cast<std::size_t>(y) * w + x) * 3];
      const double v = map.at(x / scale, y / scale, name);
      if (std::isfinite(v) && v > 0)
        Viridis(std::log(v / lo) / std::log(hi / lo), out);
      else
        out[0] = out[1] = out[2] = 255;
    }
  auto png = OIIO::ImageOutput::create(tmp.string());
  OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::UINT8);
  if (!png || !png->open(tmp.string(), spec) || !png->write_image(OIIO::TypeDesc::UINT8, rgb.data()) || !png->close())
    throw std::runtime_error("cannot write " + tmp.string());
  std::ifstream in(tmp, std::ios::binary);
  std::stringstream bytes;
  bytes << in.rdbuf();
  return "data:image/png;base64," + Base64(bytes.str());
}

double Median(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return !std::isfinite(x); }), v.end());
  if (v.empty()) return NAN;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

std::vector<double> Rates(const Material& material) {
  std::vector<double> kr;
  for (const ExcitedState& state : material.states) kr.push_back(state.kr);
  std::sort(kr.begin(), kr.end());
  return kr;
}

// The study's sample: `width` x `height` pixels, the two materials and
// where its session and scratch files go.
struct StudySample {
  std::string phos_binary, outside, inside;
  int width = 96, height = 64;
  fs::path work, session;
};

// Captures the decay session; returns the command as the page shows it.
std::string CaptureSession(const StudySample& sample) {
  const std::string capture = "phos capture decay --sim-material " + sample.outside + " --sim-inset " + sample.inside +
                              " --sim-size " + std::to_string(sample.width) + "x" + std::to_string(sample.height) +
                              " --sim-inset-radius 0.5 --charge-s 1800 --out SESSION";
  Run(Quoted(sample.phos_binary) + capture.substr(4, capture.find("SESSION") - 4) + Quoted(sample.session),
      sample.work / "capture.log");
  // The page names the fixtures from the repository's root.
  std::string shown = capture;
  for (std::size_t at; (at = shown.find(PHOS_FIXTURES_DIR)) != std::string::npos;)
    shown.replace(at, std::string(PHOS_FIXTURES_DIR).size(), "fixtures");
  return shown;
}

// One `phos fit map --states N`: the map, the seconds it says it took and
// what it said (indented for the page).
struct MapFit {
  MapFile map;
  double seconds = 0;
  std::string said;
};

MapFit FitMap(const StudySample& sample, int states) {
  const fs::path dir = sample.work / ("map" + std::to_string(states));
  Run(Quoted(sample.phos_binary) + " fit map " + Quoted(sample.session) + " --out " + Quoted(dir) + " --states " +
          std::to_string(states),
      sample.work / "fit.log");
  MapFit fit;
  std::ifstream log(sample.work / "fit.log");
  std::string line;
  while (std::getline(log, line)) {
    // The page shows the folders as the commands above name them.
    for (std::size_t at; (at = line.find(dir.string())) != std::string::npos;)
      line.replace(at, dir.string().size(), "MAP" + std::to_string(states));
    fit.said += "    " + line + "\n";
  }
  const std::size_t at = fit.said.find("fitted in ");
  fit.seconds = std::stod(fit.said.substr(at + 10));
  fit.map = ReadMap(dir / "decay-map.exr");
  return fit;
}

struct Region {
  std::vector<double> kr1, k1, k2, rms1, rms2;
  int one_state = 0, pixels = 0;
};

// Regions: the disk is the simulated lab's inset (SimulatedLab::InInset,
// --sim-inset-radius 0.5 of half the height); a ring of 2 pixels around its
// edge is left out of both. 0 outside, 1 inside.
std::array<Region, 2> SplitRegions(const MapFit (&fits)[2], int width, int height) {
  const double cx = (width - 1) / 2.0, cy = (height - 1) / 2.0, radius = 0.5 * height / 2.0;
  std::array<Region, 2> region;
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const double r = std::hypot(x - cx, y - cy);
      if (std::fabs(r - radius) < 2) continue;
      Region& g = region[r < radius ? 1 : 0];
      ++g.pixels;
      g.kr1.push_back(fits[0].map.at(x, y, "kr"));
      g.rms1.push_back(fits[0].map.at(x, y, "rms"));
      g.rms2.push_back(fits[1].map.at(x, y, "rms"));
      if (std::isnan(fits[1].map.at(x, y, "kr2"))) {
        ++g.one_state;
      } else {
        g.k1.push_back(fits[1].map.at(x, y, "kr"));
        g.k2.push_back(fits[1].map.at(x, y, "kr2"));
      }
    }
  return region;
}

// The maps: rows one state / two states; columns kr (k1), kr2, rms; rates on
// a log scale from half the slowest to twice the fastest of both materials.
std::string MapsSvg(const MapFit (&fits)[2], const std::vector<double>& k_out, const std::vector<double>& k_in,
                    const fs::path& work) {
  const int width = fits[0].map.width, height = fits[0].map.height;
  const double k_lo = 0.5 * std::min(k_out[0], k_in[0]), k_hi = 2 * std::max(k_out.back(), k_in.back());
  std::vector<double> all_rms;
  for (const MapFit& fit : fits)
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) all_rms.push_back(fit.map.at(x, y, "rms"));
  std::sort(all_rms.begin(), all_rms.end());
  const double rms_lo = all_rms[all_rms.size() / 100], rms_hi = all_rms[all_rms.size() * 99 / 100];
  const int scale = 3, pw = width * scale, ph = height * scale, gap = 16, top = 40, left = 110;
  std::ostringstream svg;
  const int total_w = left + 3 * (pw + gap), total_h = top + 2 * (ph + gap + 14) + 40;
  svg << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << total_w << "\" height=\"" << total_h
      << "\" font-family=\"sans-serif\" font-size=\"13\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  const char* columns[3] = {"kr (k1 with two states), 1/s", "kr2, 1/s", "rms residual (weighted)"};
  for (int c = 0; c < 3; ++c)
    svg << "<text x=\"" << left + c * (pw + gap) << "\" y=\"" << top - 10 << "\">" << columns[c] << "</text>\n";
  for (int row = 0; row < 2; ++row) {
    const int y0 = top + row * (ph + gap + 14);
    svg << "<text x=\"4\" y=\"" << y0 + ph / 2 << "\">" << (row == 0 ? "--states 1" : "--states 2") << "</text>\n";
    const std::string names[3] = {"kr", "kr2", "rms"};
    for (int c = 0; c < 3; ++c) {
      if (row == 0 && c == 1) continue;  // no kr2 with one state
      const bool rate = c < 2;
      const std::string uri =
          MapPng(fits[row].map, names[c], rate ? k_lo : rms_lo, rate ? k_hi : rms_hi, scale, work / "panel.png");
      svg << "<image x=\"" << left + c * (pw + gap) << "\" y=\"" << y0 << "\" width=\"" << pw << "\" height=\"" << ph
          << "\" href=\"" << uri << "\"/>\n";
    }
  }
  const int bar_y = top + 2 * (ph + gap + 14);
  for (int i = 0; i < 100; ++i) {
    unsigned char rgb[3];
    Viridis(i / 99.0, rgb);
    svg << "<rect x=\"" << left + i * 3 << "\" y=\"" << bar_y << "\" width=\"3\" height=\"10\" fill=\"rgb("
        << int(rgb[0]) << "," << int(rgb[1]) << "," << int(rgb[2]) << ")\"/>";
  }
  svg << "\n<text x=\"" << left + 310 << "\" y=\"" << bar_y + 10 << "\">log scale: rates " << FormatShort(k_lo)
      << " to " << FormatShort(k_hi) << " /s; rms " << FormatShort(rms_lo) << " to " << FormatShort(rms_hi)
      << "; white: NaN (one state kept)</text>\n</svg>\n";
  return svg.str();
}

// Curves of a pixel outside and one inside: data, one-state fit, two-state fit (R channel).
std::string CurvesSvg(const StudySample& sample, const MapFit (&fits)[2]) {
  std::vector<PlotSeries> series;
  const int px[2][2] = {{sample.width / 8, sample.height / 8}, {sample.width / 2, sample.height / 2}};
  const char* where[2] = {"outside", "inside"};
  for (int i = 0; i < 2; ++i) {
    const int x = px[i][0], y = px[i][1];
    const PixelCurve curve = ReadPixelCurve(sample.session, x, y);
    const std::string channel = curve.channel_names[0];
    PlotSeries data(std::string(where[i]) + " (" + std::to_string(x) + "," + std::to_string(y) + ") " + channel +
                    " data");
    data.markers = true;
    data.line = false;
    data.color = PaletteColor(2 * i);
    PlotSeries one(std::string(where[i]) + ": one state"), two(std::string(where[i]) + ": two states");
    one.dashed = true;
    one.color = two.color = PaletteColor(2 * i);
    for (std::size_t j = 0; j < curve.t_s.size(); ++j) {
      data.x.push_back(curve.t_s[j]);
      data.y.push_back(curve.y[0][j]);
      one.x.push_back(curve.t_s[j]);
      one.y.push_back(Model(fits[0].map, x, y, channel, curve.t_s[j], curve.exposure_s[j]));
      two.x.push_back(curve.t_s[j]);
      two.y.push_back(Model(fits[1].map, x, y, channel, curve.t_s[j], curve.exposure_s[j]));
    }
    series.push_back(data);
    series.push_back(one);
    series.push_back(two);
  }
  PlotOptions options;
  options.title = "Two pixels' decays and the maps' fits (red channel)";
  options.x_label = "time after light-off, s";
  options.y_label = "signal, DN/s";
  options.log_y = true;
  return PlotSvg(series, options);
}

// The page.
std::string StudyPage(const StudySample& sample, const std::string& shown, const MapFit (&fits)[2],
                      const std::array<Region, 2>& region, const std::vector<double>& k_out,
                      const std::vector<double>& k_in) {
  std::ostringstream md;
  md << "# Two-state decay maps\n\n"
     << "`phos fit map SESSION --states 2` fits every pixel with two exponentials and a background per\n"
     << "channel, y_c(t) = A1_c exp(-k1 t) + A2_c exp(-k2 t) + B_c with k1 < k2 ([fit.md](fit.md) says how\n"
     << "and when a pixel keeps one state). This page compares it with the one-state map on a simulated sample whose "
        "two-state\n"
     << "material changes across its surface. Written by `build/bin/phos-two-state-map-study --out docs`\n"
     << "(`make study`), which ran:\n\n"
     << "    " << shown << "\n"
     << "    phos fit map SESSION --out MAP1 --states 1\n"
     << "    phos fit map SESSION --out MAP2 --states 2\n\n"
     << "Outside the disk: `" << fs::path(sample.outside).filename().string() << "` (kr " << FormatShort(k_out[0])
     << " and " << FormatShort(k_out.back()) << " /s); inside: `" << fs::path(sample.inside).filename().string()
     << "` (kr " << FormatShort(k_in[0]) << " and " << FormatShort(k_in.back()) << " /s). A ring of 2 pixels\n"
     << "around the disk's edge, where pixels see both, is left out of the numbers.\n\n"
     << "![maps of kr, kr2 and rms for one and two states](two-state-map.svg)\n\n"
     << "![two pixels' curves with both fits](two-state-map-curves.svg)\n\n"
     << "| region | pixels | truth k1, k2 (1/s) | one state: median kr | two states: median k1 | median k2 | "
        "pixels kept at one state | median rms, one state | two states |\n"
     << "|---|---|---|---|---|---|---|---|---|\n";
  for (int r = 0; r < 2; ++r) {
    const std::vector<double>& k = r == 0 ? k_out : k_in;
    const Region& g = region[r];
    md << "| " << (r == 0 ? "outside" : "inside") << " | " << g.pixels << " | " << FormatShort(k[0]) << ", "
       << FormatShort(k.back()) << " | " << FormatShort(Median(g.kr1)) << " | " << FormatShort(Median(g.k1)) << " | "
       << FormatShort(Median(g.k2)) << " | " << g.one_state << " | " << FormatShort(Median(g.rms1)) << " | "
       << FormatShort(Median(g.rms2)) << " |\n";
  }
  md << "\nThe fits took " << FormatShort(fits[0].seconds) << " s (one state) and " << FormatShort(fits[1].seconds)
     << " s (two states) for " << sample.width * sample.height << " pixels, as the commands said:\n\n"
     << fits[0].said << fits[1].said << "\n"
     << "One exponential cannot follow a two-state decay: its kr lies between the two rates and its\n"
     << "residual shows the misfit; two states recover both rates and bring the residual down to the\n"
     << "photon noise. Speed on a megapixel: docs/bench/fit.txt (`BM_DecayMap1MegapixelTwoStates`).\n";
  return md.str();
}

}  // namespace
}  // namespace phos

int main(int argc, char** argv) {
  using namespace phos;
  CLI::App app{
      "Two-state decay maps against one-state maps on a simulated two-material sample (docs/two-state-map.md)"};
  std::string out = "docs";
  StudySample sample;
  sample.phos_binary = PHOS_BINARY;
  sample.outside = std::string(PHOS_FIXTURES_DIR) + "/materials/two-state-ratio20.json";
  sample.inside = std::string(PHOS_FIXTURES_DIR) + "/materials/two-state-ratio7-fast90.json";
  app.add_option("--out", out, "folder for two-state-map.md and its figures");
  app.add_option("--phos", sample.phos_binary, "the phos binary");
  app.add_option("--outside", sample.outside, "the material outside the disk");
  app.add_option("--inside", sample.inside, "the material of the disk");
  CLI11_PARSE(app, argc, argv);
  try {
    sample.work = fs::temp_directory_path() / ("phos-two-state-map-study-" + std::to_string(getpid()));
    fs::remove_all(sample.work);
    fs::create_directories(sample.work);
    sample.session = sample.work / "session";
    const std::string shown = CaptureSession(sample);
    const MapFit fits[2] = {FitMap(sample, 1), FitMap(sample, 2)};
    const std::vector<double> k_out = Rates(LoadMaterial(sample.outside)), k_in = Rates(LoadMaterial(sample.inside));
    const std::array<Region, 2> region = SplitRegions(fits, sample.width, sample.height);
    const std::string maps_svg = MapsSvg(fits, k_out, k_in, sample.work);
    fs::create_directories(out);
    std::ofstream(fs::path(out) / "two-state-map.svg") << maps_svg;
    std::ofstream(fs::path(out) / "two-state-map-curves.svg") << CurvesSvg(sample, fits);
    const std::string md = StudyPage(sample, shown, fits, region, k_out, k_in);
    std::ofstream(fs::path(out) / "two-state-map.md") << md;
    fs::remove_all(sample.work);
    std::cout << md;
  } catch (const std::exception& e) {
    std::cerr << "phos-two-state-map-study: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
