#pragma once
// Line plots as standalone SVG: for docs/, results/ and the HTML reports,
// where people would rather look than read. Linear or log axes, several
// series with a legend. No dependency: SVG is text a browser shows.

#include <limits>
#include <string>
#include <string_view>
#include <vector>

namespace phos {

struct PlotSeries {
  explicit PlotSeries(std::string label_text = "") : label(std::move(label_text)) {}
  std::string label;
  std::vector<double> x, y;  // points with a non-finite (or, on a log axis, non-positive) value are gaps
  std::string color;         // CSS colour; empty: ChannelColor of the label if it names one, else the palette
  bool markers = false;      // draw a dot at each point
  bool line = true;          // join the points
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

// Returns the SVG document. Series with no drawable point are listed in the
// legend only. The axes fit the data (a log axis spans the decades the
// positive values reach, nothing fixed); the legend sits right of the plot,
// and the document grows wider or taller rather than clip a label.
std::string PlotSvg(const std::vector<PlotSeries>& series, const PlotOptions& options);

// A CSS colour for light of this wavelength (approximate, for band curves:
// violet at 400 nm, red at 650 nm; grey outside the visible range).
std::string WavelengthColor(double wavelength_nm);

// The palette used when a series names no colour (colour-blind-safe, after Okabe and Ito).
const std::string& PaletteColor(int index);

// The colour of a camera channel, the same in every plot: R, G and B (or red,
// green, blue, any case, alone or first in a label such as "R measured") are
// red, green and blue. "" for any other name.
std::string ChannelColor(std::string_view channel);

// A channel's colour by name, else the palette's colour by index: what a plot
// of camera channels should use.
std::string ChannelOrPaletteColor(std::string_view channel, int index);

// The colour of light with this spectrum, for a material's curve: band
// radiance (band_radiance[b] emitted between edges_nm[b] and edges_nm[b + 1],
// any scale) through the CIE 1931 functions to sRGB, at full saturation and
// darkened where needed to read on white. Grey when nothing visible is emitted.
std::string SpectrumColor(const std::vector<double>& band_radiance, const std::vector<double>& edges_nm);

// How far apart two "#RRGGBB" colours are (Euclidean, 0-255 per channel): a
// caller giving series their own colours can dash the ones that look alike.
double ColorDistance(const std::string& a, const std::string& b);

}  // namespace phos
