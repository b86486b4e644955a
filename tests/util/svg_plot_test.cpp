#include "phos/util/svg_plot.h"

#include <cmath>
#include <gtest/gtest.h>

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

}  // namespace
}  // namespace phos
