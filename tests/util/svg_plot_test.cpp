#include "phos/util/svg_plot.h"

#include <array>
#include <cmath>
#include <cstdlib>
#include <gtest/gtest.h>
#include <string>

namespace phos {
namespace {

int Count(const std::string& text, const std::string& what) {
  int n = 0;
  for (size_t p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

TEST(PlotSvg, DrawsOnePathPerSeriesAndALegend) {
  PlotSeries a{"decay"}, b{"charge"};
  for (int i = 0; i < 50; ++i) {
    a.x.push_back(i);
    a.y.push_back(std::exp(-0.1 * i));
    b.x.push_back(i);
    b.y.push_back(1 - std::exp(-0.1 * i));
  }
  PlotOptions options;
  options.title = "a < b & c";
  std::string svg = PlotSvg({a, b}, options);
  EXPECT_EQ(svg.rfind("<svg", 0), 0u);
  EXPECT_EQ(Count(svg, "<path d="), 2);
  EXPECT_NE(svg.find(">decay</text>"), std::string::npos);
  EXPECT_NE(svg.find("a &lt; b &amp; c"), std::string::npos);  // escaped
}

TEST(PlotSvg, LogAxisLeavesGapsAtNonPositiveValues) {
  PlotSeries s{"s"};
  s.x = {1, 2, 3, 4, 5};
  s.y = {1, 0.1, 0, 0.01, 0.001};  // the 0 cannot be drawn on a log axis
  PlotOptions options;
  options.log_y = true;
  std::string svg = PlotSvg({s}, options);
  // Two runs of the line: M..L, then a new M after the gap.
  std::string path = svg.substr(svg.find("<path d="));
  path = path.substr(0, path.find("/>"));
  EXPECT_EQ(Count(path, "M"), 2);
  EXPECT_NE(svg.find(">0.001<"), std::string::npos);
}

// The red, green and blue parts of "#RRGGBB".
std::array<int, 3> Rgb(const std::string& hex) {
  EXPECT_EQ(hex.size(), 7u) << hex;
  std::array<int, 3> c{};
  for (int i = 0; i < 3; ++i) c[i] = static_cast<int>(std::strtol(hex.substr(1 + 2 * i, 2).c_str(), nullptr, 16));
  return c;
}

// The value of attribute `name` of the <svg> element.
double SvgAttribute(const std::string& svg, const std::string& name) {
  const std::size_t at = svg.find(" " + name + "=\"");
  EXPECT_NE(at, std::string::npos) << name;
  return std::atof(svg.c_str() + at + name.size() + 3);
}

TEST(PlotColors, ChannelsAreRedGreenAndBlue) {
  for (const char* name : {"R", "r", "red", "R measured", "R (fit)"}) {
    const auto c = Rgb(ChannelColor(name));
    EXPECT_TRUE(c[0] > c[1] && c[0] > c[2]) << name;
  }
  for (const char* name : {"G", "green", "G fit"}) {
    const auto c = Rgb(ChannelColor(name));
    EXPECT_TRUE(c[1] > c[0] && c[1] > c[2]) << name;
  }
  for (const char* name : {"B", "Blue", "B measured"}) {
    const auto c = Rgb(ChannelColor(name));
    EXPECT_TRUE(c[2] > c[0] && c[2] > c[1]) << name;
  }
  EXPECT_EQ(ChannelColor("bottle"), "");
  EXPECT_EQ(ChannelColor("r_1"), "");  // a state, not a channel
  EXPECT_EQ(ChannelColor("value"), "");
  EXPECT_EQ(ChannelOrPaletteColor("value", 2), PaletteColor(2));
  EXPECT_EQ(ChannelOrPaletteColor("G", 0), ChannelColor("G"));
}

TEST(PlotColors, ASeriesNamedAfterAChannelIsDrawnInItsColour) {
  // In the order B, G, R: the palette by index would give R the third colour (green).
  std::vector<PlotSeries> series;
  for (const char* name : {"B", "G", "R"}) {
    PlotSeries s{name};
    s.x = {0, 1, 2};
    s.y = {3, 2, 1};
    series.push_back(s);
  }
  const std::string svg = PlotSvg(series, PlotOptions{});
  for (const char* name : {"B", "G", "R"})
    EXPECT_NE(svg.find("stroke=\"" + ChannelColor(name) + "\" stroke-width=\"1.8\""), std::string::npos) << name;
}

TEST(PlotColors, AMaterialsColourIsTheLightItEmits) {
  const std::vector<double> paper = {400, 437.5, 475, 512.5, 550, 587.5, 625, 662.5, 700};
  // green.json's Lambda: most of it at 512.5-550 nm.
  const auto green = Rgb(SpectrumColor({0, 0, 0.07, 0.64, 0.05, 0, 0, 0}, paper));
  EXPECT_GT(green[1], green[0]);
  EXPECT_GT(green[1], green[2]);
  const auto red = Rgb(SpectrumColor({0, 0, 0, 0, 0, 0.1, 0.8, 0.3}, paper));
  EXPECT_GT(red[0], red[1]);
  EXPECT_GT(red[0], red[2]);
  const auto blue = Rgb(SpectrumColor({0.3, 0.8, 0.1, 0, 0, 0, 0, 0}, paper));
  EXPECT_GT(blue[2], blue[0]);
  EXPECT_GT(blue[2], blue[1]);
  // The scale does not matter; nothing visible is grey.
  EXPECT_EQ(SpectrumColor({0, 0, 0.7, 6.4, 0.5, 0, 0, 0}, paper),
            SpectrumColor({0, 0, 0.07, 0.64, 0.05, 0, 0, 0}, paper));
  EXPECT_EQ(SpectrumColor(std::vector<double>(8, 0.0), paper), "#888888");
  EXPECT_EQ(SpectrumColor({1, 1}, {300, 320, 340}), "#888888");  // ultraviolet only
  // Light enough to read on white: no channel mix as pale as yellow at full brightness.
  const auto yellow = Rgb(SpectrumColor({0, 0, 0, 0, 1, 1, 0, 0}, paper));
  EXPECT_LT(0.2126 * yellow[0] + 0.7152 * yellow[1] + 0.0722 * yellow[2], 200);
  EXPECT_LT(ColorDistance("#000000", "#000000"), 1e-12);
  EXPECT_NEAR(ColorDistance("#FF0000", "#000000"), 255, 1e-9);
}

TEST(PlotSvg, LongLegendLabelsFitInTheDocument) {
  const std::string label = "two-state-ratio20-fast10 measured through the LVF, first frame of each exposure";
  PlotSeries s{label};
  s.x = {0, 1};
  s.y = {1, 2};
  const std::string svg = PlotSvg({s}, PlotOptions{});
  const double width = SvgAttribute(svg, "width");
  const std::size_t text = svg.find(">" + label + "</text>");
  ASSERT_NE(text, std::string::npos);
  const std::size_t x = svg.rfind("<text x=\"", text);
  const double left = std::atof(svg.c_str() + x + 9);
  // 0.6 em per character is wider than the average sans-serif character.
  EXPECT_LE(left + 0.6 * 12 * static_cast<double>(label.size()), width);
  EXPECT_GT(width, 760);  // the document grew, not the label clipped
}

TEST(PlotSvg, ManyLegendLinesMakeTheDocumentTaller) {
  std::vector<PlotSeries> series;
  for (int i = 0; i < 40; ++i) {
    PlotSeries s{"series " + std::to_string(i)};
    s.x = {0, 1};
    s.y = {1.0 * i, 2.0 * i};
    series.push_back(s);
  }
  const std::string svg = PlotSvg(series, PlotOptions{});
  const double height = SvgAttribute(svg, "height");
  const std::size_t last = svg.find(">series 39</text>");
  ASSERT_NE(last, std::string::npos);
  const std::size_t y = svg.find("y=\"", svg.rfind("<text x=\"", last));
  EXPECT_LE(std::atof(svg.c_str() + y + 3), height);
}

TEST(PlotSvg, TheLogAxisSpansTheData) {
  PlotSeries s{"decay"};
  for (int i = 0; i <= 300; ++i) {
    s.x.push_back(i);
    s.y.push_back(std::exp(-0.227 * i));  // down to 3e-30
  }
  PlotOptions options;
  options.log_y = true;
  const std::string svg = PlotSvg({s}, options);
  // The lowest tick is at or below the data's smallest value, whatever the decades.
  double lowest = INFINITY;
  for (std::size_t p = svg.find("text-anchor=\"end\">"); p != std::string::npos;
       p = svg.find("text-anchor=\"end\">", p + 1))
    lowest = std::min(lowest, std::atof(svg.c_str() + p + 18));
  EXPECT_LE(lowest, std::exp(-0.227 * 300));
  EXPECT_GT(lowest, std::exp(-0.227 * 300) * 1e-9);  // and not far below it
}

// plot --log-y on denormal radiances wrote -nan coordinates (the axis began
// at 10^-324, 0 in double), and a label with a NUL wrote a raw NUL, which no
// XML reader takes. Denormals are gaps on a log axis like zeros; text is Printable.
TEST(PlotSvg, DenormalsOnALogAxisAndControlCharactersInLabelsGiveValidNumbersAndText) {
  PlotSeries s(std::string("glow\0\x1b[31m", 10));
  s.x = {0, 1, 2, 3};
  s.y = {1e-3, 5e-324, 1e-310, 1e-5};
  PlotOptions options;
  options.log_y = true;
  options.title = "a\nb";
  for (double y_min : {std::nan(""), 0.0, 5e-324}) {
    options.y_min = y_min;
    const std::string svg = PlotSvg({s}, options);
    EXPECT_EQ(svg.find("nan"), std::string::npos) << y_min;
    EXPECT_EQ(svg.find("inf"), std::string::npos) << y_min;
    for (char c : svg) EXPECT_TRUE(c == '\n' || static_cast<unsigned char>(c) >= 0x20) << int(c);
    EXPECT_NE(svg.find("glow\\x00\\x1b[31m"), std::string::npos);
    EXPECT_NE(svg.find("a\\nb"), std::string::npos);
  }
}

}  // namespace
}  // namespace phos
