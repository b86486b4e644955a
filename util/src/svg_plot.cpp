#include "phos/util/svg_plot.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include "phos/util/colour.h"
#include "phos/util/format.h"

namespace phos {
namespace {

// The visible range (CIE 15): light outside it has no colour.
constexpr double kVisibleLowerNm = 380, kVisibleUpperNm = 780;

// Text for SVG: Printable (a NUL or an ESC is no XML character), then XML's escapes.
std::string Escape(const std::string& raw) {
  const std::string text = Printable(raw);
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

// Width of a line of text at this font size, a little more than the average
// of sans-serif fonts (about 0.55 of the size per character), so that what is
// laid out by it fits.
double TextWidth(const std::string& text, double font_px) { return 0.6 * font_px * static_cast<double>(text.size()); }

std::string Num(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.2f", v);
  return buffer;
}

std::string TickLabel(double v) {
  char buffer[32];
  if (v == 0) return "0";
  double a = std::fabs(v);
  if (a >= 1e5 || a < 1e-3)
    std::snprintf(buffer, sizeof buffer, "%.0e", v);
  else
    std::snprintf(buffer, sizeof buffer, "%g", v);
  std::string s = buffer;
  // 1e-05 -> 1e-5
  if (auto e = s.find("e"); e != std::string::npos) {
    std::string mantissa = s.substr(0, e), exponent = s.substr(e + 1);
    bool negative = exponent[0] == '-';
    size_t first = exponent.find_first_not_of("+-0");
    exponent = first == std::string::npos ? "0" : exponent.substr(first);
    s = mantissa + "e" + (negative ? "-" : "") + exponent;
  }
  return s;
}

struct Axis {
  bool log = false;
  double lo = 0, hi = 1;
  double Map(double v) const {
    return log ? (std::log10(v) - std::log10(lo)) / (std::log10(hi) - std::log10(lo)) : (v - lo) / (hi - lo);
  }
  // On a log axis, positive and normal: a denormal radiance (5e-324) made the
  // axis start at 10^-324, which is 0 in double, and every coordinate -nan.
  bool Drawable(double v) const { return std::isfinite(v) && (!log || v >= std::numeric_limits<double>::min()); }

  // Rounds the range out to nice values and returns the tick positions.
  std::vector<double> Ticks() {
    std::vector<double> ticks;
    if (log) {
      // Decades within double's normal range, whatever limits were asked (a
      // y_min of 0 or a denormal): 10^-307 to 10^308.
      double e0 = lo > 0 ? std::floor(std::log10(lo)) : -307, e1 = hi > 0 ? std::ceil(std::log10(hi)) : e0 + 1;
      e0 = std::clamp(e0, -307.0, 307.0);
      e1 = std::clamp(e1, e0 + 1, 308.0);
      lo = std::pow(10.0, e0);
      hi = std::pow(10.0, e1);
      int step = std::max(1, static_cast<int>(std::ceil((e1 - e0) / 8)));
      for (double e = e0; e <= e1 + 1e-9; e += step) ticks.push_back(std::pow(10.0, e));
      return ticks;
    }
    if (hi <= lo) {
      double pad = lo == 0 ? 1 : std::fabs(lo) * 0.1;
      lo -= pad;
      hi += pad;
    }
    double raw = (hi - lo) / 6;
    double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
    double step = magnitude;
    for (double m : {1.0, 2.0, 2.5, 5.0, 10.0})
      if (m * magnitude >= raw) {
        step = m * magnitude;
        break;
      }
    lo = std::floor(lo / step + 1e-9) * step;
    hi = std::ceil(hi / step - 1e-9) * step;
    for (double t = lo; t <= hi + step * 1e-6; t += step) ticks.push_back(std::fabs(t) < step * 1e-9 ? 0 : t);
    return ticks;
  }
};

}  // namespace

std::string WavelengthColor(double nm) {
  // Piecewise-linear hue ramp after Bruton's approximation of the visible
  // spectrum, darkened a little so thin lines read on white.
  double r = 0, g = 0, b = 0;
  if (nm >= kVisibleLowerNm && nm < 440) {
    r = (440 - nm) / 60;
    b = 1;
  } else if (nm >= 440 && nm < 490) {
    g = (nm - 440) / 50;
    b = 1;
  } else if (nm >= 490 && nm < 510) {
    g = 1;
    b = (510 - nm) / 20;
  } else if (nm >= 510 && nm < 580) {
    r = (nm - 510) / 70;
    g = 1;
  } else if (nm >= 580 && nm < 645) {
    r = 1;
    g = (645 - nm) / 65;
  } else if (nm >= 645 && nm <= kVisibleUpperNm) {
    r = 1;
  } else
    return "#888888";
  char buffer[16];
  std::snprintf(buffer, sizeof buffer, "#%02X%02X%02X", static_cast<int>(r * 210), static_cast<int>(g * 190),
                static_cast<int>(b * 230));
  return buffer;
}

const std::string& PaletteColor(int index) {
  static const std::vector<std::string> palette = {"#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9",
                                                   "#000000", "#F0E442", "#7F7F7F", "#8C564B", "#9467BD"};
  return palette[static_cast<size_t>(index) % palette.size()];
}

std::string ChannelColor(std::string_view channel) {
  std::string first;
  for (char c : channel) {
    if (c == ' ' || c == '(' || c == ',') break;
    first += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  }
  if (first == "r" || first == "red") return "#D62728";
  if (first == "g" || first == "green") return "#2CA02C";
  if (first == "b" || first == "blue") return "#1F77B4";
  return "";
}

std::string ChannelOrPaletteColor(std::string_view channel, int index) {
  std::string color = ChannelColor(channel);
  return color.empty() ? PaletteColor(index) : color;
}

std::string SpectrumColor(const std::vector<double>& band_radiance, const std::vector<double>& edges_nm) {
  if (edges_nm.size() != band_radiance.size() + 1) return "#888888";
  Tristimulus xyz{0, 0, 0};
  for (std::size_t b = 0; b < band_radiance.size(); ++b) {
    if (!(band_radiance[b] > 0) || !std::isfinite(band_radiance[b])) continue;
    // Band radiance of uniform density over the band: XYZ = L_b times the
    // band's mean CMF, over the part of the band inside the visible range.
    const double lower = std::max(edges_nm[b], kVisibleLowerNm), upper = std::min(edges_nm[b + 1], kVisibleUpperNm);
    if (!(upper > lower)) continue;
    const double visible = (upper - lower) / (edges_nm[b + 1] - edges_nm[b]);
    const Tristimulus cmf = Cie1931CmfBandMean(lower, upper);
    for (int i = 0; i < 3; ++i) xyz[i] += band_radiance[b] * visible * cmf[i];
  }
  Tristimulus rgb = XyzToLinearSrgb(xyz);
  // Narrow-band light lies outside sRGB: desaturate it toward white (add the
  // same to every channel) until it fits, which keeps its hue, where clipping
  // would make different greens one.
  const double lowest = std::min({rgb[0], rgb[1], rgb[2]});
  if (lowest < 0)
    for (double& c : rgb) c -= lowest;
  const double peak = std::max({rgb[0], rgb[1], rgb[2]});
  if (!(peak > 0)) return "#888888";
  for (double& c : rgb) c /= peak;
  // A thin line of luminance above ~0.35 (yellow, light green) fades into white paper.
  const double luminance = LinearSrgbLuminance(rgb[0], rgb[1], rgb[2]);
  if (luminance > 0.35)
    for (double& c : rgb) c *= 0.35 / luminance;
  auto encode = [](double linear) {
    const double v = linear <= 0.0031308 ? 12.92 * linear : 1.055 * std::pow(linear, 1 / 2.4) - 0.055;  // sRGB
    return static_cast<int>(std::lround(std::clamp(v, 0.0, 1.0) * 255));
  };
  char buffer[16];
  std::snprintf(buffer, sizeof buffer, "#%02X%02X%02X", encode(rgb[0]), encode(rgb[1]), encode(rgb[2]));
  return buffer;
}

double ColorDistance(const std::string& a, const std::string& b) {
  auto channels = [](const std::string& hex) {
    std::array<double, 3> c{0, 0, 0};
    if (hex.size() == 7 && hex[0] == '#')
      for (int i = 0; i < 3; ++i) c[i] = std::strtol(hex.substr(1 + 2 * i, 2).c_str(), nullptr, 16);
    return c;
  };
  const auto x = channels(a), y = channels(b);
  return std::sqrt((x[0] - y[0]) * (x[0] - y[0]) + (x[1] - y[1]) * (x[1] - y[1]) + (x[2] - y[2]) * (x[2] - y[2]));
}

namespace {

// Where PlotSvg draws: the axes, rounded out to their ticks, the plot area and
// the document's size.
struct PlotLayout {
  Axis ax, ay;
  std::vector<double> xticks, yticks;
  double left = 0, top = 0, bottom = 0, pw = 0, ph = 0, W = 0, H = 0;
  double px(double x) const { return left + ax.Map(x) * pw; }
  double py(double y) const { return top + (1 - ay.Map(y)) * ph; }
};

// The axes' ranges: the drawable data's, or the options' limits where given.
void FitAxes(const std::vector<PlotSeries>& series, const PlotOptions& options, Axis& ax, Axis& ay) {
  double xlo = INFINITY, xhi = -INFINITY, ylo = INFINITY, yhi = -INFINITY;
  for (const PlotSeries& s : series)
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!ax.Drawable(s.x[i]) || !ay.Drawable(s.y[i])) continue;
      xlo = std::min(xlo, s.x[i]);
      xhi = std::max(xhi, s.x[i]);
      ylo = std::min(ylo, s.y[i]);
      yhi = std::max(yhi, s.y[i]);
    }
  if (!std::isfinite(xlo)) {
    xlo = options.log_x ? 1 : 0;
    xhi = options.log_x ? 10 : 1;
  }
  if (!std::isfinite(ylo)) {
    ylo = options.log_y ? 1 : 0;
    yhi = options.log_y ? 10 : 1;
  }
  if (!options.log_y && ylo > 0 && ylo < 0.5 * yhi) ylo = 0;  // show the zero line when the data nearly reach it
  ax.lo = std::isnan(options.x_min) ? xlo : options.x_min;
  ax.hi = std::isnan(options.x_max) ? xhi : options.x_max;
  ay.lo = std::isnan(options.y_min) ? ylo : options.y_min;
  ay.hi = std::isnan(options.y_max) ? yhi : options.y_max;
}

PlotLayout LayOutPlot(const std::vector<PlotSeries>& series, const PlotOptions& options) {
  PlotLayout l;
  l.ax = Axis{options.log_x};
  l.ay = Axis{options.log_y};
  FitAxes(series, options, l.ax, l.ay);
  l.xticks = l.ax.Ticks();
  l.yticks = l.ay.Ticks();

  // The plot area is what width_px and height_px leave beside a legend of
  // 190 px; a legend that needs more, or a longer title, widens the document,
  // and more legend lines than the plot is tall make it taller.
  l.left = 78;
  l.top = options.title.empty() ? 20 : 42;
  l.bottom = 56;
  l.pw = options.width_px - l.left - 190;
  l.ph = options.height_px - l.top - l.bottom;
  double legend_width = 0;
  int legend_lines = 0;
  for (const PlotSeries& s : series)
    if (!s.label.empty()) {
      legend_width = std::max(legend_width, 28 + TextWidth(s.label, 12));
      ++legend_lines;
    }
  const double right = std::max(190.0, 14 + legend_width + 10);
  l.W = std::max(l.left + l.pw + right, TextWidth(options.title, 15) + 20);
  l.H = std::max<double>(options.height_px, l.top + 8 + 18.0 * legend_lines + 8);
  return l;
}

// The document's head, the title, the grid, the ticks and the axis labels.
void WriteFrame(std::ostringstream& svg, const PlotLayout& l, const PlotOptions& options) {
  const double left = l.left, top = l.top, bottom = l.bottom, pw = l.pw, ph = l.ph, W = l.W, H = l.H;
  svg << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << W << "\" height=\"" << H << "\" viewBox=\"0 0 " << W
      << " " << H << "\" font-family=\"sans-serif\" font-size=\"12\">\n"
      << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  if (!options.title.empty())
    svg << "<text x=\""
        << Num(std::clamp(left + pw / 2, TextWidth(options.title, 15) / 2 + 10,
                          W - TextWidth(options.title, 15) / 2 - 10))
        << "\" y=\"24\" text-anchor=\"middle\" font-size=\"15\">" << Escape(options.title) << "</text>\n";
  // Grid and ticks.
  svg << "<g stroke=\"#e3e3e3\" stroke-width=\"1\">\n";
  for (double t : l.xticks)
    svg << "<line x1=\"" << Num(l.px(t)) << "\" y1=\"" << Num(top) << "\" x2=\"" << Num(l.px(t)) << "\" y2=\""
        << Num(top + ph) << "\"/>\n";
  for (double t : l.yticks)
    svg << "<line x1=\"" << Num(left) << "\" y1=\"" << Num(l.py(t)) << "\" x2=\"" << Num(left + pw) << "\" y2=\""
        << Num(l.py(t)) << "\"/>\n";
  svg << "</g>\n<rect x=\"" << Num(left) << "\" y=\"" << Num(top) << "\" width=\"" << Num(pw) << "\" height=\""
      << Num(ph) << "\" fill=\"none\" stroke=\"#333\"/>\n";
  for (double t : l.xticks)
    svg << "<text x=\"" << Num(l.px(t)) << "\" y=\"" << Num(top + ph + 16) << "\" text-anchor=\"middle\">"
        << TickLabel(t) << "</text>\n";
  for (double t : l.yticks)
    svg << "<text x=\"" << Num(left - 6) << "\" y=\"" << Num(l.py(t) + 4) << "\" text-anchor=\"end\">" << TickLabel(t)
        << "</text>\n";
  svg << "<text x=\"" << Num(left + pw / 2) << "\" y=\"" << Num(top + ph + bottom - 14) << "\" text-anchor=\"middle\">"
      << Escape(options.x_label) << "</text>\n";
  svg << "<text transform=\"translate(18," << Num(top + ph / 2) << ") rotate(-90)\" text-anchor=\"middle\">"
      << Escape(options.y_label) << "</text>\n";
}

// Series k's colour: its own, else its channel's or the palette's.
std::string SeriesColor(const PlotSeries& s, size_t k) {
  return s.color.empty() ? ChannelOrPaletteColor(s.label, static_cast<int>(k)) : s.color;
}

// Data, clipped to the plot area.
void WriteData(std::ostringstream& svg, const PlotLayout& l, const std::vector<PlotSeries>& series) {
  svg << "<clipPath id=\"plotarea\"><rect x=\"" << Num(l.left) << "\" y=\"" << Num(l.top) << "\" width=\"" << Num(l.pw)
      << "\" height=\"" << Num(l.ph) << "\"/></clipPath>\n<g clip-path=\"url(#plotarea)\">\n";
  for (size_t k = 0; k < series.size(); ++k) {
    const PlotSeries& s = series[k];
    const std::string color = SeriesColor(s, k);
    if (s.line) {
      std::string path;
      bool pen_down = false;
      for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
        if (!l.ax.Drawable(s.x[i]) || !l.ay.Drawable(s.y[i])) {
          pen_down = false;
          continue;
        }
        // Appended piece by piece: "L" + std::string trips GCC 12's false
        // -Wrestrict (its bug 105329) in Release builds.
        path += pen_down ? 'L' : 'M';
        path += Num(l.px(s.x[i]));
        path += ' ';
        path += Num(l.py(s.y[i]));
        path += ' ';
        pen_down = true;
      }
      if (!path.empty())
        svg << "<path d=\"" << path << "\" fill=\"none\" stroke=\"" << color << "\" stroke-width=\"1.8\""
            << (s.dashed ? " stroke-dasharray=\"6 4\"" : "") << "/>\n";
    }
    if (s.markers)
      for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
        if (l.ax.Drawable(s.x[i]) && l.ay.Drawable(s.y[i]))
          svg << "<circle cx=\"" << Num(l.px(s.x[i])) << "\" cy=\"" << Num(l.py(s.y[i])) << "\" r=\"2.6\" fill=\""
              << color << "\"/>\n";
  }
  svg << "</g>\n";
}

void WriteLegend(std::ostringstream& svg, const PlotLayout& l, const std::vector<PlotSeries>& series) {
  double ly = l.top + 8;
  for (size_t k = 0; k < series.size(); ++k) {
    const PlotSeries& s = series[k];
    if (s.label.empty()) continue;
    const std::string color = SeriesColor(s, k);
    double lx = l.left + l.pw + 14;
    if (s.line)
      svg << "<line x1=\"" << Num(lx) << "\" y1=\"" << Num(ly) << "\" x2=\"" << Num(lx + 22) << "\" y2=\"" << Num(ly)
          << "\" stroke=\"" << color << "\" stroke-width=\"2\"" << (s.dashed ? " stroke-dasharray=\"6 4\"" : "")
          << "/>\n";
    if (s.markers)
      svg << "<circle cx=\"" << Num(lx + 11) << "\" cy=\"" << Num(ly) << "\" r=\"3\" fill=\"" << color << "\"/>\n";
    svg << "<text x=\"" << Num(lx + 28) << "\" y=\"" << Num(ly + 4) << "\">" << Escape(s.label) << "</text>\n";
    ly += 18;
  }
}

}  // namespace

std::string PlotSvg(const std::vector<PlotSeries>& series, const PlotOptions& options) {
  const PlotLayout layout = LayOutPlot(series, options);
  std::ostringstream svg;
  WriteFrame(svg, layout, options);
  WriteData(svg, layout, series);
  WriteLegend(svg, layout, series);
  svg << "</svg>\n";
  return svg.str();
}

}  // namespace phos
