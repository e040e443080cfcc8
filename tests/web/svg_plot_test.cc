#include "web/svg_plot.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "web/html.h"

namespace calibd::web {
namespace {

void ExpectTicks(const std::vector<double>& got, const std::vector<double>& want) {
  ASSERT_EQ(got.size(), want.size());
  for (size_t i = 0; i < got.size(); ++i) {
    EXPECT_NEAR(got[i], want[i], std::fabs(want[i]) * 1e-12 + 1e-15) << "tick " << i;
  }
}

size_t Count(const std::string& s, const std::string& needle) {
  size_t n = 0;
  for (size_t p = s.find(needle); p != std::string::npos; p = s.find(needle, p + 1)) ++n;
  return n;
}

// A minimal well-formedness check: one <svg> root that is closed, balanced angle brackets,
// no NaN/inf leaking into coordinates.
void ExpectValidSvg(const std::string& svg, const std::string& name) {
  EXPECT_EQ(svg.rfind("<svg ", 0), 0u) << svg.substr(0, 80);
  EXPECT_EQ(svg.substr(svg.size() - 6), "</svg>");
  EXPECT_EQ(Count(svg, "<svg "), 1u);
  EXPECT_EQ(Count(svg, "<"), Count(svg, ">"));
  EXPECT_NE(svg.find("class=\"plot plot-" + name + "\""), std::string::npos);
  EXPECT_NE(svg.find("role=\"img\""), std::string::npos);
  EXPECT_NE(svg.find("viewBox=\"0 0 "), std::string::npos);
  EXPECT_NE(svg.find("<title>"), std::string::npos);
  EXPECT_EQ(svg.find("nan"), std::string::npos);
  EXPECT_EQ(svg.find("inf"), std::string::npos);
}

TEST(NiceTicks, UnitIntervalStepsByTwoTenths) {
  ExpectTicks(NiceLinearTicks(0, 1, 5), {0, 0.2, 0.4, 0.6, 0.8, 1.0});
  EXPECT_DOUBLE_EQ(NiceStep(0, 1, 5), 0.2);
}

TEST(NiceTicks, SmallRangeUsesMillesimalSteps) {
  ExpectTicks(NiceLinearTicks(0.0013, 0.0071, 5), {0.002, 0.003, 0.004, 0.005, 0.006, 0.007});
  EXPECT_EQ(FormatTick(0.003, 0.001), "0.003");
}

TEST(NiceTicks, StepsAreOneTwoOrFiveTimesAPowerOfTen) {
  for (double span : {0.37, 1.0, 2.2, 7.9, 13.0, 480.0, 6.3e-6, 1e7}) {
    const double step = NiceStep(-span / 3, span, 5);
    const double mant = step / std::pow(10.0, std::floor(std::log10(step) + 1e-12));
    EXPECT_TRUE(std::fabs(mant - 1) < 1e-9 || std::fabs(mant - 2) < 1e-9 ||
                std::fabs(mant - 5) < 1e-9)
        << span << " -> " << step;
    const auto ticks = NiceLinearTicks(-span / 3, span, 5);
    EXPECT_GE(ticks.size(), 3u);
    EXPECT_LE(ticks.size(), 12u);
  }
}

TEST(NiceTicks, NegativeRangeHasExactZeroAndNoMinusZeroLabel) {
  const auto ticks = NiceLinearTicks(-0.3, 0.3, 6);
  bool zero = false;
  for (double t : ticks) zero |= (t == 0 && !std::signbit(t));
  EXPECT_TRUE(zero);
  EXPECT_EQ(FormatTick(-0.0, 0.1), "0");
  EXPECT_EQ(FormatTick(-1e-18, 0.1), "0");
  EXPECT_EQ(FormatTick(-0.2, 0.1), "-0.2");
}

TEST(NiceTicks, DegenerateRangesGiveNoTicks) {
  EXPECT_TRUE(NiceLinearTicks(1, 1).empty());
  EXPECT_TRUE(NiceLinearTicks(0, std::numeric_limits<double>::quiet_NaN()).empty());
  EXPECT_TRUE(NiceLinearTicks(0, std::numeric_limits<double>::infinity()).empty());
  ExpectTicks(NiceLinearTicks(1, 0, 5), {0, 0.2, 0.4, 0.6, 0.8, 1.0});  // swapped
}

TEST(LogTicksTest, OneTickPerDecadeFromMicroToHundred) {
  ExpectTicks(LogTicks(1e-6, 1e2), {1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1, 10, 100});
  EXPECT_EQ(FormatTick(1e-6, 0), "1e-6");
  EXPECT_EQ(FormatTick(1e-2, 0), "0.01");
  EXPECT_EQ(FormatTick(100, 0), "100");
  EXPECT_EQ(FormatTick(1e8, 0), "1e8");
}

TEST(LogTicksTest, ManyDecadesAreThinnedAndFewGetTwoAndFive) {
  const auto many = LogTicks(1e-20, 1e10, 9);
  EXPECT_LE(many.size(), 9u);
  EXPECT_GE(many.size(), 5u);
  ExpectTicks(LogTicks(1, 10), {1, 2, 5, 10});
  EXPECT_TRUE(LogTicks(0, 10).empty());
  EXPECT_TRUE(LogTicks(-1, 10).empty());
}

TEST(FormatTickTest, LargeAndTinyLinearValuesUseExponents) {
  EXPECT_EQ(FormatTick(2.5e8, 5e7), "2.5e8");
  EXPECT_EQ(FormatTick(2e-6, 1e-6), "2e-6");
  EXPECT_EQ(FormatTick(1500, 500), "1500");
}

TEST(Decimation, KeepsExtremesAndShrinksLargeSeries) {
  const size_t n = 100000;
  std::vector<double> x(n), y(n);
  for (size_t i = 0; i < n; ++i) {
    x[i] = static_cast<double>(i);
    y[i] = std::sin(i * 0.001);
  }
  y[31337] = 42.0;   // a single-sample spike
  y[77777] = -17.0;  // and a dip
  const auto keep = DecimateMinMax(x, y, 2000);
  EXPECT_LE(keep.size(), 2002u);
  bool spike = false, dip = false;
  for (size_t i : keep) {
    spike |= i == 31337;
    dip |= i == 77777;
  }
  EXPECT_TRUE(spike);
  EXPECT_TRUE(dip);
  EXPECT_EQ(keep.front(), 0u);
  EXPECT_EQ(keep.back(), n - 1);
  for (size_t k = 1; k < keep.size(); ++k) EXPECT_LT(keep[k - 1], keep[k]);
}

TEST(Decimation, DropsNonFinitePointsAndKeepsSmallSeriesWhole) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const auto keep = DecimateMinMax({0, 1, 2, 3}, {1, nan, 3, INFINITY}, 100);
  ASSERT_EQ(keep.size(), 2u);
  EXPECT_EQ(keep[0], 0u);
  EXPECT_EQ(keep[1], 2u);
}

TEST(XYPlot, HundredThousandPointSeriesStaysSmallAndKeepsPeak) {
  const size_t n = 100000;
  Series s;
  s.label = "|omega|";
  s.x.resize(n);
  s.y.resize(n);
  for (size_t i = 0; i < n; ++i) {
    s.x[i] = static_cast<double>(i);
    s.y[i] = 30 + std::sin(i * 0.01);
  }
  s.y[54321] = 99.5;
  PlotOptions o;
  o.name = "excitation";
  o.title = "Excitation";
  o.x.title = "sample";
  o.y.title = "|omega| (rad/s)";
  const std::string svg = RenderXYPlot(o, {s});
  ExpectValidSvg(svg, "excitation");
  EXPECT_LT(svg.size(), 100u * 1024u);
  // The peak is kept: the y axis reaches 100 (its nice upper end).
  EXPECT_NE(svg.find(">100</text>"), std::string::npos);
  EXPECT_NE(svg.find("decimated"), std::string::npos);
}

TEST(XYPlot, EmptyInputGivesValidSvgSayingNoData) {
  PlotOptions o;
  o.name = "empty";
  const std::string svg = RenderXYPlot(o, {});
  ExpectValidSvg(svg, "empty");
  EXPECT_NE(svg.find("no data"), std::string::npos);
  Series s;  // a series with no points
  ExpectValidSvg(RenderXYPlot(o, {s}), "empty");
}

TEST(XYPlot, OnePointAndAllEqualValuesDoNotCollapseTheAxis) {
  PlotOptions o;
  o.name = "one";
  Series one;
  one.x = {3};
  one.y = {7};
  const std::string a = RenderXYPlot(o, {one});
  ExpectValidSvg(a, "one");
  EXPECT_NE(a.find("<circle"), std::string::npos);  // a lone point is drawn as a marker
  Series flat;
  flat.x = {0, 1, 2, 3};
  flat.y = {5, 5, 5, 5};
  o.name = "flat";
  ExpectValidSvg(RenderXYPlot(o, {flat}), "flat");
  o.y.type = ScaleType::kLog10;
  o.name = "flat-log";
  ExpectValidSvg(RenderXYPlot(o, {flat}), "flat-log");
  flat.y = {0, 0, 0, 0};
  o.y.type = ScaleType::kLinear;
  o.name = "zeros";
  ExpectValidSvg(RenderXYPlot(o, {flat}), "zeros");
}

TEST(XYPlot, NonFiniteValuesAreSkippedWithANote) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Series s;
  s.x = {0, 1, 2, 3, 4};
  s.y = {1, nan, INFINITY, -INFINITY, 2};
  PlotOptions o;
  o.name = "nonfinite";
  const std::string svg = RenderXYPlot(o, {s});
  ExpectValidSvg(svg, "nonfinite");
  EXPECT_NE(svg.find("3 non-finite point(s) not shown"), std::string::npos);
}

TEST(XYPlot, NonPositiveValuesOnLogAxisAreSkippedWithANote) {
  Series s;
  s.x = {1, 2, 3, 4, 5};
  s.y = {10, 1, 0, -1, 1e-4};
  s.marker = Marker::kCircle;
  PlotOptions o;
  o.name = "singular-values";
  o.y.type = ScaleType::kLog10;
  const std::string svg = RenderXYPlot(o, {s});
  ExpectValidSvg(svg, "singular-values");
  EXPECT_NE(svg.find("2 zero or negative value(s) not shown on the log axis"), std::string::npos);
  EXPECT_EQ(Count(svg, "<circle"), 3u);
  EXPECT_NE(svg.find(">1e-4</text>"), std::string::npos);
  EXPECT_NE(svg.find(">10</text>"), std::string::npos);
}

TEST(XYPlot, TextIsEscapedEverywhere) {
  const std::string evil = "<script>alert(1)</script>\"><img src=x onerror=alert(1)>";
  Series s;
  s.label = evil;
  s.x = {0, 1};
  s.y = {0, 1};
  s.point_labels = {evil, evil};
  PlotOptions o;
  o.name = evil;
  o.title = evil;
  o.description = evil;
  o.x.title = evil;
  o.y.title = evil;
  o.notes = {evil};
  o.ref_lines = {{true, 0.5, evil, true}};
  const std::string svg = RenderXYPlot(o, {s});
  EXPECT_EQ(svg.find("<script"), std::string::npos);
  EXPECT_EQ(svg.find("<img"), std::string::npos);
  EXPECT_NE(svg.find("&quot;&gt;&lt;img"), std::string::npos);
  BarSeries b{evil, {1, 2}, {}, -1};
  const std::string bars = RenderBarChart(o, {evil, evil}, {b, b});
  EXPECT_EQ(bars.find("<script"), std::string::npos);
  EXPECT_EQ(bars.find("<img"), std::string::npos);
  Histogram h = MakeHistogram({1, 2, 3}, 3, evil);
  const std::string hist = RenderHistogram(o, {h});
  EXPECT_EQ(hist.find("<script"), std::string::npos);
  EXPECT_EQ(hist.find("<img"), std::string::npos);
}

TEST(XYPlot, EllipsesErrorBarsLegendAndEqualAspect) {
  Series nominal, est;
  nominal.label = "nominal";
  nominal.x = {0, 6.3, 0, 6.3};
  nominal.y = {0, 0, 6.3, 6.3};
  nominal.line = false;
  nominal.marker = Marker::kOpenCircle;
  est = nominal;
  est.label = "estimated";
  est.marker = Marker::kCross;
  est.ellipses = {{0.01, 0.002, 0.02}, {0.01, 0, 0.01}, {0.04, -0.01, 0.01}, {0, 0, 0}};
  est.y_err = {0.1, 0.1, 0.1, 0.1};
  PlotOptions o;
  o.name = "positions-xy";
  o.equal_aspect = true;
  o.x.title = "x (mm)";
  o.y.title = "y (mm)";
  const std::string svg = RenderXYPlot(o, {nominal, est});
  ExpectValidSvg(svg, "positions-xy");
  EXPECT_NE(svg.find("class=\"ellipses\""), std::string::npos);
  EXPECT_NE(svg.find("class=\"error-bars\""), std::string::npos);
  EXPECT_NE(svg.find("class=\"legend\""), std::string::npos);
  EXPECT_NE(svg.find(">estimated</text>"), std::string::npos);
}

// ---- Geometry read back from an SVG (the attributes the renderer writes).

// The value of attribute `name` in the element starting at `at` ("" when absent).
std::string Attr(const std::string& svg, size_t at, const std::string& name) {
  const size_t end = svg.find('>', at);
  const size_t p = svg.find(" " + name + "=\"", at);
  if (p == std::string::npos || p > end) return "";
  const size_t v = p + name.size() + 3;
  return svg.substr(v, svg.find('"', v) - v);
}
double NumAttr(const std::string& svg, size_t at, const std::string& name) {
  const std::string v = Attr(svg, at, name);
  return v.empty() ? std::nan("") : std::stod(v);
}

// The plot frame: the axes' outlined rect (x0, y0 top, x1, y1 bottom).
struct Box {
  double x0, y0, x1, y1;
};
Box FrameOf(const std::string& svg) {
  const size_t r = svg.rfind("<rect", svg.find("fill=\"none\" stroke=\"#8a949e\""));
  const double x = NumAttr(svg, r, "x"), y = NumAttr(svg, r, "y");
  return {x, y, x + NumAttr(svg, r, "width"), y + NumAttr(svg, r, "height")};
}

// Every <text> inside the group whose opening tag contains `group` (e.g. "point-labels"), as
// (x, y, anchor, text).
struct Text {
  double x, y;
  std::string anchor, text;
};
std::vector<Text> TextsIn(const std::string& svg, const std::string& group) {
  std::vector<Text> out;
  for (size_t g = svg.find(group); g != std::string::npos; g = svg.find(group, g + 1)) {
    const size_t end = svg.find("</g>", g);
    for (size_t t = svg.find("<text", g); t != std::string::npos && t < end;
         t = svg.find("<text", t + 1)) {
      const size_t open = svg.find('>', t) + 1;
      out.push_back({NumAttr(svg, t, "x"), NumAttr(svg, t, "y"), Attr(svg, t, "text-anchor"),
                     svg.substr(open, svg.find("</text>", open) - open)});
    }
  }
  return out;
}

// The box a text covers at `char_width` px per character (the renderer's own estimate).
Box TextBox(const Text& t, double char_width, double height) {
  size_t n = 0;
  for (unsigned char c : t.text) n += (c & 0xC0) != 0x80;
  const double w = static_cast<double>(n) * char_width;
  const double x0 = t.anchor == "end" ? t.x - w : t.anchor == "middle" ? t.x - w / 2 : t.x;
  return {x0, t.y - height + 2, x0 + w, t.y + 2};
}
bool Overlap(const Box& a, const Box& b) {
  return a.x0 < b.x1 && b.x0 < a.x1 && a.y0 < b.y1 && b.y0 < a.y1;
}

TEST(XYPlotLayout, TheXAxisCoversEveryBandNotOnlyThePoints) {
  // A failed imu job's timeline: intervals from 0.5 s to 29.5 s, the one marker between 13.5 s
  // and 17 s. Every interval is drawn whole inside the frame.
  PlotOptions o;
  o.name = "bands";
  o.bands = {{0.5, 3, "1"}, {13.5, 17, "2"}, {27, 29.5, "3"}};
  Series mid;
  mid.line = false;
  mid.x = {15.25};
  mid.y = {3.5};
  const std::string svg = RenderXYPlot(o, {mid});
  ExpectValidSvg(svg, "bands");
  const Box f = FrameOf(svg);
  size_t rects = 0;
  for (size_t r = svg.find("fill=\"#cfe3f3\""); r != std::string::npos;
       r = svg.find("fill=\"#cfe3f3\"", r + 1)) {
    const size_t at = svg.rfind("<rect", r);
    const double x = NumAttr(svg, at, "x"), w = NumAttr(svg, at, "width");
    EXPECT_GE(x, f.x0 - 0.1);
    EXPECT_LE(x + w, f.x1 + 0.1);
    EXPECT_GT(w, 0.05 * (f.x1 - f.x0)) << "band " << rects << " is clipped";
    ++rects;
  }
  EXPECT_EQ(rects, 3u);
}

TEST(XYPlotLayout, AConstantSeriesIsDrawnInsideTheFrameNotOnIt) {
  // A constant |ω| (the rig turned at one rate) with the axis from zero: the line would sit on
  // the frame's top edge.
  for (double value : {2.0, 0.5, -3.0, 1e-3}) {
    PlotOptions o;
    o.name = "flat";
    o.y.include_zero = true;
    Series s;
    for (int i = 0; i < 50; ++i) {
      s.x.push_back(i);
      s.y.push_back(value);
    }
    const std::string svg = RenderXYPlot(o, {s});
    ExpectValidSvg(svg, "flat");
    const Box f = FrameOf(svg);
    const size_t line = svg.find("class=\"line\"");
    ASSERT_NE(line, std::string::npos);
    const std::string d = Attr(svg, line, "d");
    const double y = std::stod(d.substr(d.find(' ') + 1));
    const double margin = 0.05 * (f.y1 - f.y0);
    EXPECT_GT(y, f.y0 + margin) << value << ": " << d.substr(0, 40);
    EXPECT_LT(y, f.y1 - margin) << value;
  }
}

TEST(XYPlotLayout, SeriesPastThePaletteStillLookDifferentInTheLegend) {
  // Twelve triads (drift of positions): series 0 and 7 used to share colour and style.
  for (bool markers : {false, true}) {
    PlotOptions o;
    o.name = "many";
    o.width = 1400;  // room for every legend entry
    std::vector<Series> series;
    for (int i = 0; i < 14; ++i) {
      Series s;
      s.label = "t" + std::to_string(i);
      s.x = {0, 1};
      s.y = {double(i), double(i) + 1};
      if (markers) s.marker = Marker::kCircle;
      series.push_back(s);
    }
    const std::string svg = RenderXYPlot(o, series);
    std::vector<std::string> styles;
    const size_t legend = svg.find("class=\"legend\"");
    ASSERT_NE(legend, std::string::npos);
    for (size_t l = svg.find("<line", legend);
         l != std::string::npos && l < svg.find("</g>", legend); l = svg.find("<line", l + 1)) {
      styles.push_back(Attr(svg, l, "stroke") + "|" + Attr(svg, l, "stroke-dasharray"));
    }
    ASSERT_EQ(styles.size(), 14u);
    for (size_t a = 0; a < styles.size(); ++a) {
      for (size_t b = a + 1; b < styles.size(); ++b) {
        EXPECT_NE(styles[a], styles[b]) << "series " << a << " and " << b;
      }
    }
  }
  // Past two rounds of the palette a series with markers gets another marker shape.
  std::vector<Series> series(16);
  for (int i = 0; i < 16; ++i) {
    series[i].x = {0};
    series[i].y = {double(i)};
    series[i].marker = Marker::kCircle;
  }
  PlotOptions o;
  o.name = "markers";
  const std::string svg = RenderXYPlot(o, series);
  const size_t s14 = svg.find("series series-14");
  ASSERT_NE(s14, std::string::npos);
  EXPECT_EQ(svg.find("<circle", s14), svg.find("<circle", svg.find("series series-15")))
      << "series 14 is drawn with circles like series 0";
}

TEST(XYPlotLayout, PointLabelsNeverOverlapAndLabelsOfOnePointAreJoined) {
  // Sensitivity axes projected onto a plane: twelve sensors close together, two of them on the
  // same spot (their axes project to the same point).
  PlotOptions o;
  o.name = "axes";
  o.x.min = o.y.min = -1.25;
  o.x.max = o.y.max = 1.25;
  o.equal_aspect = true;
  o.height = 520;
  Series est;
  est.line = false;
  est.marker = Marker::kCross;
  for (int i = 0; i < 12; ++i) {
    est.x.push_back(0.02 * (i % 4));
    est.y.push_back(0.03 * (i / 4));
    est.point_labels.push_back("sensor" + std::to_string(i));
  }
  est.x.push_back(0);
  est.y.push_back(0);
  est.point_labels.push_back("twin");
  const std::string svg = RenderXYPlot(o, {est});
  ExpectValidSvg(svg, "axes");
  const auto texts = TextsIn(svg, "class=\"point-labels\"");
  ASSERT_FALSE(texts.empty());
  std::vector<Box> boxes;
  for (const Text& t : texts) boxes.push_back(TextBox(t, 6.3 * 9.5 / 11, 10));
  for (size_t a = 0; a < boxes.size(); ++a) {
    for (size_t b = a + 1; b < boxes.size(); ++b) {
      EXPECT_FALSE(Overlap(boxes[a], boxes[b])) << texts[a].text << " / " << texts[b].text;
    }
  }
  EXPECT_NE(svg.find(">sensor0, twin<"), std::string::npos);
  // Every label is drawn or counted in a note.
  size_t drawn = 0;
  for (const Text& t : texts) drawn += 1 + std::count(t.text.begin(), t.text.end(), ',');
  if (drawn < 13) {
    EXPECT_NE(svg.find(std::to_string(13 - drawn) + " point label(s) left out"), std::string::npos);
  }
  EXPECT_GE(drawn, 8u);
}

TEST(XYPlotLayout, ReferenceLineLabelsNeverOverlap) {
  // The Allan plot's τ markers: 1 s and 3 s are close together on six decades.
  PlotOptions o;
  o.name = "allan";
  o.x.type = o.y.type = ScaleType::kLog10;
  o.ref_lines.push_back({true, 1.0, "\xCF\x84 = 1 s: N", true});
  o.ref_lines.push_back({true, 3.0, "\xCF\x84 = 3 s: K", true});
  o.ref_lines.push_back({false, 1e-3, "noise floor", true});
  o.ref_lines.push_back({false, 1.2e-3, "configured", true});
  Series s;
  s.x = {0.01, 0.1, 1, 10, 100, 1000, 10000};
  s.y = {1e-2, 3e-3, 1e-3, 4e-4, 3e-4, 5e-4, 1e-3};
  const std::string svg = RenderXYPlot(o, {s});
  ExpectValidSvg(svg, "allan");
  const auto texts = TextsIn(svg, "class=\"ref-line\"");
  ASSERT_EQ(texts.size(), 4u);
  for (size_t a = 0; a < texts.size(); ++a) {
    for (size_t b = a + 1; b < texts.size(); ++b) {
      EXPECT_FALSE(Overlap(TextBox(texts[a], 6.3, 11), TextBox(texts[b], 6.3, 11)))
          << texts[a].text << " / " << texts[b].text;
    }
  }
}

TEST(BarChart, LogAxisSkipsNonPositiveAndHandlesNoCategories) {
  PlotOptions o;
  o.name = "residual-rms";
  o.y.type = ScaleType::kLog10;
  BarSeries s{"rms", {0.04, 0, 0.001}, {}, -1};
  const std::string svg = RenderBarChart(o, {"accelerometer", "zero", "gyroscope"}, {s});
  ExpectValidSvg(svg, "residual-rms");
  EXPECT_NE(svg.find("1 zero or negative value(s)"), std::string::npos);
  EXPECT_EQ(Count(svg, "<rect x="), 2u + 2u);  // two bars plus the two frame rects
  ExpectValidSvg(RenderBarChart(o, {}, {}), "residual-rms");
  // Many long category names rotate and still give a valid SVG.
  std::vector<std::string> cats;
  std::vector<double> vals;
  for (int i = 0; i < 96; ++i) {
    cats.push_back("accelerometer_triad_" + std::to_string(i));
    vals.push_back(i + 1.0);
  }
  o.y.type = ScaleType::kLinear;
  const std::string many = RenderBarChart(o, cats, {{"v", vals, {}, -1}});
  ExpectValidSvg(many, "residual-rms");
  EXPECT_NE(many.find("rotate(-40"), std::string::npos);
}

TEST(XYPlot, ExtremeMagnitudesStayFiniteAndSmall) {
  Series s;
  s.x = {-1e308, 0, 1e308, 4.9e-324};
  s.y = {1e308, -1e308, 4.9e-324, 0};
  s.y_err = {1e308, 1e308, 1e308, 1e308};
  s.ellipses = {{1e308, 1e308, 1e308}, {-1, 0, -1}, {0, 0, 0}, {1, 2, 3}};
  PlotOptions o;
  o.name = "extreme";
  const std::string svg = RenderXYPlot(o, {s});
  ExpectValidSvg(svg, "extreme");
  EXPECT_LT(svg.size(), 20000u);
  o.y.type = ScaleType::kLog10;
  o.x.type = ScaleType::kLog10;
  ExpectValidSvg(RenderXYPlot(o, {s}), "extreme");
  ExpectValidSvg(RenderBarChart(o, {"a", "b"}, {{"v", {1e308, 4.9e-324}, {1e308}, 3}}), "extreme");
  ExpectValidSvg(RenderHistogram(o, {MakeHistogram({-1e308, 1e308}, 10)}), "extreme");
  EXPECT_EQ(FormatDuration(1e300).find("d"), FormatDuration(1e300).size() - 1);
}

TEST(HistogramTest, CountsAllFiniteValuesAndRendersDegenerateOnes) {
  const Histogram h = MakeHistogram({0, 1, 2, 3, NAN, 4}, 4);
  ASSERT_EQ(h.counts.size(), 4u);
  double total = 0;
  for (double c : h.counts) total += c;
  EXPECT_EQ(total, 5);
  PlotOptions o;
  o.name = "residual-histogram";
  ExpectValidSvg(RenderHistogram(o, {h}), "residual-histogram");
  ExpectValidSvg(RenderHistogram(o, {MakeHistogram({2, 2, 2}, 5)}), "residual-histogram");
  ExpectValidSvg(RenderHistogram(o, {MakeHistogram({}, 5)}), "residual-histogram");
}

TEST(HtmlHelpers, EscapingAndNumberFormatting) {
  EXPECT_EQ(EscapeText("<a href=\"x\">&'"), "&lt;a href=&quot;x&quot;&gt;&amp;&#39;");
  EXPECT_EQ(EscapeAttr("a\nb"), "a&#10;b");
  EXPECT_EQ(EscapeText("bad \xFF byte"), "bad \xEF\xBF\xBD byte");
  EXPECT_EQ(EscapeText("\xC2\xB5m"), "\xC2\xB5m");
  EXPECT_EQ(UrlEncode("a b/<c>"), "a%20b%2F%3Cc%3E");
  EXPECT_EQ(FormatSig(0.00123456, 3), "0.00123");
  EXPECT_EQ(FormatSig(1.5e-7, 2), "1.5e-7");
  EXPECT_EQ(FormatSig(-0.0, 3), "0");
  EXPECT_EQ(FormatMicrometres(2.04e-6), "2.04 \xC2\xB5m");
  EXPECT_EQ(FormatSI(0.00123, "V"), "1.23 mV");
  EXPECT_EQ(FormatDuration(185), "3 min 05 s");
  double t = 0;
  ASSERT_TRUE(ParseTimestamp("1970-01-02T00:00:01Z", &t));
  EXPECT_DOUBLE_EQ(t, 86401);
  ASSERT_TRUE(ParseTimestamp("2026-11-22 04:04:04.5", &t));
  EXPECT_FALSE(ParseTimestamp("yesterday", &t));
}

}  // namespace
}  // namespace calibd::web
