#pragma once
// Line plots as standalone SVG: for docs/, results/ and the HTML reports,
// where people would rather look than read. Linear or log axes, several
// series with a legend. No dependency: SVG is text a browser shows.

#include <limits>
#include <string>
#include <vector>

namespace phos {

struct PlotSeries {
  explicit PlotSeries(std::string label_text = "") : label(std::move(label_text)) {}
  std::string label;
  std::vector<double> x, y;   // points with a non-finite (or, on a log axis, non-positive) value are gaps
  std::string color;          // CSS colour; empty picks one from the palette
  bool markers = false;       // draw a dot at each point
  bool line = true;           // join the points
  bool dashed = false;
};

struct PlotOptions {
  std::string title;
  std::string x_label, y_label;
  bool log_x = false, log_y = false;
  int width_px = 760, height_px = 480;
  // Fixed axis limits; NaN means fit the data.
  double x_min = std::numeric_limits<double>::quiet_NaN(), x_max = std::numeric_limits<double>::quiet_NaN();
  double y_min = std::numeric_limits<double>::quiet_NaN(), y_max = std::numeric_limits<double>::quiet_NaN();
};

// Returns the SVG document. Series with no drawable point are listed in the legend only.
std::string PlotSvg(const std::vector<PlotSeries>& series, const PlotOptions& options);

// A CSS colour for light of this wavelength (approximate, for band curves:
// violet at 400 nm, red at 650 nm; grey outside the visible range).
std::string WavelengthColor(double wavelength_nm);

// The palette used when a series names no colour (colour-blind-safe, after Okabe and Ito).
const std::string& PaletteColor(int index);

}  // namespace phos
