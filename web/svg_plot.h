// Small inline-SVG plotting module for the HTML reports.
//
// Pure functions: data in, an `<svg>` element (as a string) out. No I/O, no global state,
// thread-safe. Every plot is a self-contained `<svg class="plot plot-NAME" role="img"
// viewBox="..."><title>...</title>...` that scales to its container (width 100%), prints well
// (fixed colour-blind-safe palette plus dash patterns), and never fails: degenerate input (no
// data, one point, all values equal, NaN/Inf, non-positive values on a log axis) yields a valid
// SVG with a short note saying what was left out. Every piece of text is escaped.
//
// Large series are decimated before drawing (min and max per bucket, in index order), so peaks
// survive and a 100 000-point series costs a few tens of kilobytes.
#ifndef CALIBD_WEB_SVG_PLOT_H_
#define CALIBD_WEB_SVG_PLOT_H_

#include <array>
#include <cstddef>
#include <string>
#include <vector>

namespace calibd::web {

enum class ScaleType { kLinear, kLog10 };

// ---------------------------------------------------------------------------------------------
// Ticks and scales (exposed for tests and for callers that lay out their own figures).

// "Nice" linear ticks covering [lo, hi]: multiples of a 1-2-5 × 10^k step, about `target` of
// them, all inside [lo, hi] (within rounding). lo > hi is swapped; lo == hi or non-finite input
// gives an empty vector. Values within step·1e-9 of zero are returned as exactly 0.
std::vector<double> NiceLinearTicks(double lo, double hi, int target = 5);

// Step of NiceLinearTicks(lo, hi, target) (0 when there are none).
double NiceStep(double lo, double hi, int target = 5);

// Ticks for a log10 axis covering [lo, hi] (both > 0): powers of ten (every k-th decade when
// there are more than `max_decades` of them); when [lo, hi] spans less than about two decades,
// also 2× and 5× multiples that fall inside. Empty for non-positive or non-finite input.
std::vector<double> LogTicks(double lo, double hi, int max_decades = 9);

// Label for a tick value on an axis whose tick spacing is `step` (linear) or 0 (log axis):
// "0", "0.2", "-1.5", "0.0013", "1e-06" → "1e-6", "2.5e+08" → "2.5e8". Never "-0".
std::string FormatTick(double value, double step);

// Maps a data interval onto a pixel interval. For kLog10 the domain must be positive (it is
// clamped to a tiny positive value otherwise).
class Scale {
 public:
  Scale() = default;
  Scale(ScaleType type, double d0, double d1, double r0, double r1);
  double operator()(double v) const;
  ScaleType type() const { return type_; }
  double d0() const { return d0_; }
  double d1() const { return d1_; }

 private:
  ScaleType type_ = ScaleType::kLinear;
  double d0_ = 0, d1_ = 1, r0_ = 0, r1_ = 1;
};

// Decimates a series to at most about `max_points` points: the series is cut into
// max_points/2 buckets of consecutive indices and each contributes its minimum-y and maximum-y
// point, in index order; the first and last points are always kept. Points with non-finite x or
// y are dropped first. Returns the kept indices into the input (ascending). Series of at most
// `max_points` finite points are returned whole.
std::vector<size_t> DecimateMinMax(const std::vector<double>& x, const std::vector<double>& y,
                                   size_t max_points);

// The fixed palette (Okabe–Ito, without yellow): colour of series i (cycles).
const char* PaletteColor(size_t i);

// ---------------------------------------------------------------------------------------------
// Plot descriptions.

enum class Marker { kNone, kCircle, kCross, kSquare, kOpenCircle };

struct AxisOptions {
  std::string title;  // with unit, e.g. "position x (mm)"
  ScaleType type = ScaleType::kLinear;
  bool include_zero = false;  // extend the domain to 0 (linear only)
  double min = 0, max = 0;    // fixed domain when min < max (else automatic)
  int target_ticks = 6;
};

// A 2x2 covariance (xx, xy, yy), one standard deviation squared, in data units.
using Cov2 = std::array<double, 3>;

struct Series {
  std::string label;  // legend text; empty: not in the legend
  std::vector<double> x, y;
  bool line = true;  // polyline through the points (in order)
  Marker marker = Marker::kNone;
  int color = -1;  // palette index; -1: the series' index
  bool dashed = false;
  double line_width = 1.6;
  // Optional, same length as x when non-empty:
  std::vector<double> y_err;              // symmetric error bar ±y_err
  std::vector<double> x_err;              // symmetric error bar ±x_err
  std::vector<Cov2> ellipses;             // 1σ ellipse around each point
  std::vector<std::string> point_labels;  // small text next to each point (escaped)
};

// A straight reference line across the plot area (vertical at x, or horizontal at y).
struct RefLine {
  bool vertical = true;
  double at = 0;
  std::string label;
  bool dashed = true;
};

// A shaded vertical band over [x0, x1] in data units (e.g. a static interval on a timeline),
// drawn behind the data, with a short label at its top (escaped; empty: none).
struct Band {
  double x0 = 0, x1 = 0;
  std::string label;
};

// One segment from (x0,y0) to (x1,y1) in data units (used for "nominal → estimated" links).
struct Segment {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  int color = -1;  // -1: grey
};

struct PlotOptions {
  std::string name;         // CSS class suffix: class="plot plot-NAME"; [a-z0-9-] kept
  std::string title;        // <title> and the visible heading inside the SVG
  std::string description;  // <desc>, optional
  AxisOptions x, y;
  int width = 640, height = 360;  // viewBox size; the SVG scales to its container
  bool equal_aspect = false;      // same data units per pixel on both axes
  size_t max_points = 2000;       // per series, after which DecimateMinMax is used
  std::vector<RefLine> ref_lines;
  std::vector<Band> bands;  // RenderXYPlot only
  std::vector<Segment> segments;
  std::vector<std::string> notes;  // extra lines printed under the plot area
  bool legend = true;
};

// Line / scatter plot of any number of series on linear or log axes.
std::string RenderXYPlot(const PlotOptions& options, const std::vector<Series>& series);

struct BarSeries {
  std::string label;           // legend text
  std::vector<double> values;  // one per category (NaN: no bar)
  std::vector<double> errors;  // optional ±1σ per category
  int color = -1;
};

// Grouped bar chart: categories along x, one bar per series in each group. The y axis may be
// log10 (non-positive values are then skipped with a note); linear axes always include 0.
// Category labels are rotated when they are many or long.
std::string RenderBarChart(const PlotOptions& options, const std::vector<std::string>& categories,
                           const std::vector<BarSeries>& series);

struct Histogram {
  std::string label;
  std::vector<double> edges;  // bin edges, size = counts.size() + 1, ascending
  std::vector<double> counts;
  int color = -1;
};

// Builds a histogram of the finite values with `bins` equal bins over their range.
Histogram MakeHistogram(const std::vector<double>& values, int bins, std::string label = "");

// Histogram(s) as outlined step bars on a numeric x axis (several are overlaid).
std::string RenderHistogram(const PlotOptions& options, const std::vector<Histogram>& histograms);

}  // namespace calibd::web

#endif  // CALIBD_WEB_SVG_PLOT_H_
