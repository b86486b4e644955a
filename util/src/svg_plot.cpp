#include "phos/util/svg_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

namespace phos {
namespace {

std::string Escape(const std::string& text) {
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
  double Map(double v) const { return log ? (std::log10(v) - std::log10(lo)) / (std::log10(hi) - std::log10(lo)) : (v - lo) / (hi - lo); }
  bool Drawable(double v) const { return std::isfinite(v) && (!log || v > 0); }

  // Rounds the range out to nice values and returns the tick positions.
  std::vector<double> Ticks() {
    std::vector<double> ticks;
    if (log) {
      double e0 = std::floor(std::log10(lo)), e1 = std::ceil(std::log10(hi));
      if (e1 <= e0) e1 = e0 + 1;
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
      if (m * magnitude >= raw) { step = m * magnitude; break; }
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
  if (nm >= 380 && nm < 440) { r = (440 - nm) / 60; b = 1; }
  else if (nm >= 440 && nm < 490) { g = (nm - 440) / 50; b = 1; }
  else if (nm >= 490 && nm < 510) { g = 1; b = (510 - nm) / 20; }
  else if (nm >= 510 && nm < 580) { r = (nm - 510) / 70; g = 1; }
  else if (nm >= 580 && nm < 645) { r = 1; g = (645 - nm) / 65; }
  else if (nm >= 645 && nm <= 780) { r = 1; }
  else return "#888888";
  char buffer[16];
  std::snprintf(buffer, sizeof buffer, "#%02X%02X%02X", static_cast<int>(r * 210), static_cast<int>(g * 190),
                static_cast<int>(b * 230));
  return buffer;
}

const std::string& PaletteColor(int index) {
  static const std::vector<std::string> palette = {"#0072B2", "#D55E00", "#009E73", "#CC79A7",
                                                   "#E69F00", "#56B4E9", "#000000", "#F0E442",
                                                   "#7F7F7F", "#8C564B", "#9467BD"};
  return palette[static_cast<size_t>(index) % palette.size()];
}

std::string PlotSvg(const std::vector<PlotSeries>& series, const PlotOptions& options) {
  Axis ax{options.log_x}, ay{options.log_y};
  double xlo = INFINITY, xhi = -INFINITY, ylo = INFINITY, yhi = -INFINITY;
  for (const PlotSeries& s : series)
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!ax.Drawable(s.x[i]) || !ay.Drawable(s.y[i])) continue;
      xlo = std::min(xlo, s.x[i]); xhi = std::max(xhi, s.x[i]);
      ylo = std::min(ylo, s.y[i]); yhi = std::max(yhi, s.y[i]);
    }
  if (!std::isfinite(xlo)) { xlo = options.log_x ? 1 : 0; xhi = options.log_x ? 10 : 1; }
  if (!std::isfinite(ylo)) { ylo = options.log_y ? 1 : 0; yhi = options.log_y ? 10 : 1; }
  if (!options.log_y && ylo > 0 && ylo < 0.5 * yhi) ylo = 0;  // show the zero line when the data nearly reach it
  ax.lo = std::isnan(options.x_min) ? xlo : options.x_min;
  ax.hi = std::isnan(options.x_max) ? xhi : options.x_max;
  ay.lo = std::isnan(options.y_min) ? ylo : options.y_min;
  ay.hi = std::isnan(options.y_max) ? yhi : options.y_max;
  std::vector<double> xticks = ax.Ticks(), yticks = ay.Ticks();

  const double W = options.width_px, H = options.height_px;
  const double left = 78, right = 190, top = options.title.empty() ? 20 : 42, bottom = 56;
  const double pw = W - left - right, ph = H - top - bottom;
  auto px = [&](double x) { return left + ax.Map(x) * pw; };
  auto py = [&](double y) { return top + (1 - ay.Map(y)) * ph; };

  std::ostringstream svg;
  svg << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << W << "\" height=\"" << H
      << "\" viewBox=\"0 0 " << W << " " << H << "\" font-family=\"sans-serif\" font-size=\"12\">\n"
      << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  if (!options.title.empty())
    svg << "<text x=\"" << Num(left + pw / 2) << "\" y=\"24\" text-anchor=\"middle\" font-size=\"15\">"
        << Escape(options.title) << "</text>\n";
  // Grid and ticks.
  svg << "<g stroke=\"#e3e3e3\" stroke-width=\"1\">\n";
  for (double t : xticks) svg << "<line x1=\"" << Num(px(t)) << "\" y1=\"" << Num(top) << "\" x2=\"" << Num(px(t)) << "\" y2=\"" << Num(top + ph) << "\"/>\n";
  for (double t : yticks) svg << "<line x1=\"" << Num(left) << "\" y1=\"" << Num(py(t)) << "\" x2=\"" << Num(left + pw) << "\" y2=\"" << Num(py(t)) << "\"/>\n";
  svg << "</g>\n<rect x=\"" << Num(left) << "\" y=\"" << Num(top) << "\" width=\"" << Num(pw) << "\" height=\"" << Num(ph)
      << "\" fill=\"none\" stroke=\"#333\"/>\n";
  for (double t : xticks)
    svg << "<text x=\"" << Num(px(t)) << "\" y=\"" << Num(top + ph + 16) << "\" text-anchor=\"middle\">" << TickLabel(t) << "</text>\n";
  for (double t : yticks)
    svg << "<text x=\"" << Num(left - 6) << "\" y=\"" << Num(py(t) + 4) << "\" text-anchor=\"end\">" << TickLabel(t) << "</text>\n";
  svg << "<text x=\"" << Num(left + pw / 2) << "\" y=\"" << Num(H - 14) << "\" text-anchor=\"middle\">" << Escape(options.x_label) << "</text>\n";
  svg << "<text transform=\"translate(18," << Num(top + ph / 2) << ") rotate(-90)\" text-anchor=\"middle\">" << Escape(options.y_label) << "</text>\n";

  // Data, clipped to the plot area.
  svg << "<clipPath id=\"plotarea\"><rect x=\"" << Num(left) << "\" y=\"" << Num(top) << "\" width=\"" << Num(pw)
      << "\" height=\"" << Num(ph) << "\"/></clipPath>\n<g clip-path=\"url(#plotarea)\">\n";
  for (size_t k = 0; k < series.size(); ++k) {
    const PlotSeries& s = series[k];
    std::string color = s.color.empty() ? PaletteColor(static_cast<int>(k)) : s.color;
    if (s.line) {
      std::string path;
      bool pen_down = false;
      for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
        if (!ax.Drawable(s.x[i]) || !ay.Drawable(s.y[i])) { pen_down = false; continue; }
        path += (pen_down ? "L" : "M") + Num(px(s.x[i])) + " " + Num(py(s.y[i])) + " ";
        pen_down = true;
      }
      if (!path.empty())
        svg << "<path d=\"" << path << "\" fill=\"none\" stroke=\"" << color << "\" stroke-width=\"1.8\""
            << (s.dashed ? " stroke-dasharray=\"6 4\"" : "") << "/>\n";
    }
    if (s.markers)
      for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
        if (ax.Drawable(s.x[i]) && ay.Drawable(s.y[i]))
          svg << "<circle cx=\"" << Num(px(s.x[i])) << "\" cy=\"" << Num(py(s.y[i])) << "\" r=\"2.6\" fill=\"" << color << "\"/>\n";
  }
  svg << "</g>\n";
  // Legend.
  double ly = top + 8;
  for (size_t k = 0; k < series.size(); ++k) {
    const PlotSeries& s = series[k];
    if (s.label.empty()) continue;
    std::string color = s.color.empty() ? PaletteColor(static_cast<int>(k)) : s.color;
    double lx = left + pw + 14;
    if (s.line)
      svg << "<line x1=\"" << Num(lx) << "\" y1=\"" << Num(ly) << "\" x2=\"" << Num(lx + 22) << "\" y2=\"" << Num(ly)
          << "\" stroke=\"" << color << "\" stroke-width=\"2\"" << (s.dashed ? " stroke-dasharray=\"6 4\"" : "") << "/>\n";
    if (s.markers) svg << "<circle cx=\"" << Num(lx + 11) << "\" cy=\"" << Num(ly) << "\" r=\"3\" fill=\"" << color << "\"/>\n";
    svg << "<text x=\"" << Num(lx + 28) << "\" y=\"" << Num(ly + 4) << "\">" << Escape(s.label) << "</text>\n";
    ly += 18;
  }
  svg << "</svg>\n";
  return svg.str();
}

}  // namespace phos
