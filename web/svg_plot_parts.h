// The pieces the plots of web/svg_plot.h are made of, shared by its files: svg_plot_scale.cc
// (ticks, scales, axis domains, decimation), svg_plot_frame.cc (the frame around the data:
// margins, axes, legend, title, notes), svg_plot.cc (line and scatter plots) and
// svg_plot_bars.cc (bar charts and histograms). Internal to web/; pure functions, thread-safe.
#ifndef CALIBD_WEB_SVG_PLOT_PARTS_H_
#define CALIBD_WEB_SVG_PLOT_PARTS_H_

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <iterator>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "web/svg_plot.h"

namespace calibd::web::svg_parts {

inline constexpr const char* kGrid = "#e6e9ed";
inline constexpr const char* kAxis = "#8a949e";
inline constexpr const char* kInk = "#1c232b";
inline constexpr const char* kMuted = "#5d6874";
inline constexpr double kCharWidth = 6.3;  // average glyph width at 11 px, for layout estimates

// Okabe–Ito palette without yellow (too light on paper).
inline constexpr const char* kPalette[] = {"#0072B2", "#D55E00", "#009E73", "#CC79A7",
                                           "#E69F00", "#56B4E9", "#000000"};
inline constexpr size_t kPaletteSize = std::size(kPalette);

// Compact coordinate: one decimal, no trailing ".0"; non-finite values as 0, clamped to ±1e6.
std::string N(double v);

// The CSS class suffix of a plot name: [a-z0-9-] kept (capitals lowered, '_' and ' ' as '-').
std::string SafeClassName(const std::string& name);

// Width in pixels of `s` at `char_width` per code point.
double EstimateTextWidth(const std::string& s, double char_width = kCharWidth);

// `s` cut to `max_chars` code points, with "…" when it was longer.
std::string Truncate(const std::string& s, size_t max_chars);

// Palette index of a series with colour option `color` (-1: automatic) at position `index`.
inline size_t ColorIndex(int color, size_t index) {
  return color >= 0 ? static_cast<size_t>(color) : index;
}

// Whether `v` can be drawn on an axis of type `t` (finite; positive on a log axis).
inline bool Usable(double v, ScaleType t) {
  return std::isfinite(v) && (t == ScaleType::kLinear || v > 0);
}

// Extent of values, accumulated (non-finite values are ignored).
struct Extent {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  void Add(double v) {
    if (!std::isfinite(v)) return;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  bool empty() const { return !(lo <= hi); }
};

// Final domain of an axis from the data extent: the fixed one of `axis` when it has one, else
// whole decades (log) or whole nice steps (linear) around the data.
std::pair<double, double> AxisDomain(const AxisOptions& axis, Extent e);

// The ticks of an axis over the domain [d0, d1], with their labels.
struct AxisTicks {
  std::vector<double> values;
  std::vector<std::string> labels;
  std::vector<double> minor;  // log axes: unlabelled 2..9 multiples
};
AxisTicks MakeTicks(const AxisOptions& axis, double d0, double d1);

// The parts of every plot: frame, grid, ticks, titles, legend and notes. Pixels, y down.
struct Frame {
  int width = 640, height = 360;
  double left = 60, right = 16, top = 30, bottom = 44;
  double px0() const { return left; }
  double px1() const { return width - right; }
  double py0() const { return height - bottom; }  // bottom of the plot area
  double py1() const { return top; }
};

// One entry of a legend: its text and how its swatch is drawn.
struct LegendEntry {
  std::string label;
  std::string color;
  std::string dash;
  Marker marker = Marker::kNone;
  bool line = true;
  bool box = false;  // filled box swatch (bars)
};

// One marker of shape `m` centred on (x, y) (empty for Marker::kNone).
std::string MarkerSvg(Marker m, double x, double y, const std::string& color, double r = 3.2);

// Lays out the legend entries in rows at the top of the plot area of `f` and moves the plot
// area's top below them; returns the legend's SVG (empty without entries).
std::string LegendAbove(const std::vector<LegendEntry>& entries, Frame* f);

// The opening <svg> element with <title> and <desc> (the description, then `extra_desc`).
std::string SvgOpen(const PlotOptions& o, const std::string& extra_desc);

// Size and margins of `f` from the plot's size, the y tick labels, the axis titles, the room
// `extra_bottom` below the x axis and the number of note lines under the plot.
void LayoutFrame(const PlotOptions& o, const AxisTicks& yt, double extra_bottom, size_t notes,
                 Frame* f);

// Grid, ticks, labels, axis titles for numeric axes (x ticks only when `draw_x_ticks`).
std::string AxesSvg(const PlotOptions& o, const Frame& f, const Scale& sx, const Scale& sy,
                    const AxisTicks& xt, const AxisTicks& yt, bool draw_x_ticks);

std::string TitleSvg(const PlotOptions& o, const Frame& f);  // empty without a title
std::string NotesSvg(const std::vector<std::string>& notes, const Frame& f);
// "no data" in the middle of the plot area.
std::string NoDataSvg(const Frame& f);

// An id for the plot's clip path, from its name, title and drawn `body` (stable per content).
std::string ClipId(const PlotOptions& o, const std::string& body);

// "N what": a note counting what was left out.
std::string PluralNote(size_t n, const char* what);

// Final linear domains with equal data units per pixel on both axes.
void EqualAspect(const Frame& f, std::pair<double, double>* dx, std::pair<double, double>* dy);

}  // namespace calibd::web::svg_parts

#endif  // CALIBD_WEB_SVG_PLOT_PARTS_H_
