#include "web/svg_plot.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "web/html.h"

namespace calibd::web {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr const char* kGrid = "#e6e9ed";
constexpr const char* kAxis = "#8a949e";
constexpr const char* kInk = "#1c232b";
constexpr const char* kMuted = "#5d6874";
constexpr double kCharWidth = 6.3;  // average glyph width at 11 px, for layout estimates

// Okabe–Ito palette without yellow (too light on paper).
constexpr const char* kPalette[] = {"#0072B2", "#D55E00", "#009E73", "#CC79A7",
                                    "#E69F00", "#56B4E9", "#000000"};
constexpr size_t kPaletteSize = sizeof(kPalette) / sizeof(kPalette[0]);
// Dash patterns cycle with a different period, so series stay distinct in grey print.
constexpr const char* kDashes[] = {"", "6 3", "2 2", "8 3 2 3"};

// Compact coordinate: one decimal, no trailing ".0".
std::string N(double v) {
  if (!std::isfinite(v)) v = 0;
  v = std::max(-1e6, std::min(1e6, v));  // far outside any viewBox: clamp, keep the SVG small
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.1f", v);
  std::string s(buf);
  if (s.size() > 2 && s.compare(s.size() - 2, 2, ".0") == 0) s.resize(s.size() - 2);
  if (s == "-0") s = "0";
  return s;
}

std::string SafeClassName(const std::string& name) {
  std::string out;
  for (char c : name) {
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
    if ((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-') {
      out += c;
    } else if (c == '_' || c == ' ') {
      out += '-';
    }
  }
  return out.empty() ? "unnamed" : out;
}

uint64_t Fnv1a(const std::string& s, uint64_t h = 1469598103934665603ULL) {
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ULL;
  }
  return h;
}

double EstimateTextWidth(const std::string& s, double char_width = kCharWidth) {
  // Count code points, not bytes.
  size_t n = 0;
  for (unsigned char c : s) n += (c & 0xC0) != 0x80;
  return static_cast<double>(n) * char_width;
}

std::string Truncate(const std::string& s, size_t max_chars) {
  size_t n = 0;
  for (size_t i = 0; i < s.size(); ++i) {
    if ((static_cast<unsigned char>(s[i]) & 0xC0) != 0x80) {
      if (n == max_chars) return s.substr(0, i) + "\xE2\x80\xA6";
      ++n;
    }
  }
  return s;
}

constexpr double kLabelCharWidth = kCharWidth * 9.5 / 11;  // point labels (9.5 px)
constexpr double kBandCharWidth = kCharWidth * 9 / 11;     // band labels (9 px)

// Boxes of text already placed in a plot (pixel coordinates, y down).
class Occupancy {
 public:
  void Add(double x0, double y0, double x1, double y1) { boxes_.push_back({x0, y0, x1, y1}); }
  bool Overlaps(double x0, double y0, double x1, double y1) const {
    for (const auto& b : boxes_) {
      if (x0 < b[2] && b[0] < x1 && y0 < b[3] && b[1] < y1) return true;
    }
    return false;
  }

 private:
  std::vector<std::array<double, 4>> boxes_;
};

// How a series is drawn. Colours cycle through the palette; past its end the dash pattern
// changes (and, past two rounds, the marker of a series that has one), so that series 0 and 7
// never look alike.
struct SeriesStyle {
  std::string color;
  std::string dash;  // stroke-dasharray, "" solid
  Marker marker = Marker::kNone;
};

SeriesStyle StyleOf(const Series& se, size_t index) {
  const size_t ci = se.color >= 0 ? static_cast<size_t>(se.color) : index;
  const size_t round = ci / kPaletteSize;
  SeriesStyle st;
  st.color = kPalette[ci % kPaletteSize];
  // Round 0: solid (dashed: 6 3); round 1: 2 2 (8 3 2 3); round 2 as 0, round 3 as 1, ...
  const size_t dash = (se.dashed ? 1 : 0) + 2 * (round % 2);
  st.dash = kDashes[dash % (sizeof(kDashes) / sizeof(kDashes[0]))];
  st.marker = se.marker;
  if (se.marker != Marker::kNone && round >= 2) {
    static constexpr Marker kCycle[] = {Marker::kCircle, Marker::kSquare, Marker::kOpenCircle,
                                        Marker::kCross};
    size_t at = 0;
    while (at < 4 && kCycle[at] != se.marker) ++at;
    st.marker = kCycle[(at + round / 2) % 4];
  }
  return st;
}

bool Usable(double v, ScaleType t) {
  return std::isfinite(v) && (t == ScaleType::kLinear || v > 0);
}

// Extent of values, accumulated.
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

// Final domain of an axis from the data extent.
std::pair<double, double> AxisDomain(const AxisOptions& axis, Extent e) {
  if (axis.min < axis.max && std::isfinite(axis.min) && std::isfinite(axis.max) &&
      (axis.type == ScaleType::kLinear || axis.min > 0)) {
    return {axis.min, axis.max};
  }
  if (axis.type == ScaleType::kLog10) {
    if (e.empty()) return {1, 10};
    double lo = std::pow(10.0, std::floor(std::log10(e.lo) + 1e-9));
    double hi = std::pow(10.0, std::ceil(std::log10(e.hi) - 1e-9));
    if (!(lo < hi)) {
      lo /= 10;
      hi *= 10;
    }
    if (!std::isfinite(lo) || !std::isfinite(hi) || lo <= 0) return {1, 10};
    return {lo, hi};
  }
  // Data of one value (a constant |ω|): drawn inside the frame, never on its edge.
  const bool flat =
      !e.empty() && !(e.hi - e.lo > std::max(std::fabs(e.lo), std::fabs(e.hi)) * 1e-12);
  const double value = e.lo;
  if (axis.include_zero) e.Add(0);
  if (e.empty()) return {0, 1};
  double lo = e.lo, hi = e.hi;
  if (!(hi - lo > std::max(std::fabs(lo), std::fabs(hi)) * 1e-12)) {
    const double pad = lo == 0 ? 1 : std::fabs(lo) * 0.1;
    lo -= pad;
    hi += pad;
  }
  double step = NiceStep(lo, hi, axis.target_ticks);
  if (step > 0 && std::isfinite(step)) {
    lo = std::floor(lo / step + 1e-9) * step;
    hi = std::ceil(hi / step - 1e-9) * step;
  }
  if (flat && std::isfinite(lo) && std::isfinite(hi) && lo < hi) {
    if (!(step > 0 && std::isfinite(step))) step = (hi - lo) / 4;
    const double room = 0.05 * (hi - lo);
    if (hi - value < room) hi += step;
    if (value - lo < room) lo -= step;
  }
  if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo < hi)) return {0, 1};
  return {lo, hi};
}

struct AxisTicks {
  std::vector<double> values;
  std::vector<std::string> labels;
  std::vector<double> minor;  // log axes: unlabelled 2..9 multiples
};

AxisTicks MakeTicks(const AxisOptions& axis, double d0, double d1) {
  AxisTicks t;
  if (axis.type == ScaleType::kLog10) {
    t.values = LogTicks(d0, d1);
    for (double v : t.values) t.labels.push_back(FormatTick(v, 0));
    const double decades = std::log10(d1 / d0);
    if (decades <= 6) {
      for (int k = static_cast<int>(std::floor(std::log10(d0))); k <= std::ceil(std::log10(d1));
           ++k) {
        for (int m = 2; m <= 9; ++m) {
          const double v = m * std::pow(10.0, k);
          if (v > d0 * (1 + 1e-9) && v < d1 * (1 - 1e-9)) t.minor.push_back(v);
        }
      }
    }
  } else {
    const double step = NiceStep(d0, d1, axis.target_ticks);
    t.values = NiceLinearTicks(d0, d1, axis.target_ticks);
    for (double v : t.values) t.labels.push_back(FormatTick(v, step));
  }
  return t;
}

// The parts of every plot: frame, grid, ticks, titles, legend and notes.
struct Frame {
  int width = 640, height = 360;
  double left = 60, right = 16, top = 30, bottom = 44;
  double px0() const { return left; }
  double px1() const { return width - right; }
  double py0() const { return height - bottom; }  // bottom of the plot area
  double py1() const { return top; }
};

struct LegendEntry {
  std::string label;
  std::string color;
  std::string dash;
  Marker marker = Marker::kNone;
  bool line = true;
  bool box = false;  // filled box swatch (bars)
};

std::string MarkerSvg(Marker m, double x, double y, const std::string& color, double r = 3.2) {
  switch (m) {
    case Marker::kNone:
      return "";
    case Marker::kCircle:
      return "<circle cx=\"" + N(x) + "\" cy=\"" + N(y) + "\" r=\"" + N(r) + "\" fill=\"" + color +
             "\"/>";
    case Marker::kOpenCircle:
      return "<circle cx=\"" + N(x) + "\" cy=\"" + N(y) + "\" r=\"" + N(r + 0.6) +
             "\" fill=\"#fff\" stroke=\"" + color + "\" stroke-width=\"1.4\"/>";
    case Marker::kSquare:
      return "<rect x=\"" + N(x - r) + "\" y=\"" + N(y - r) + "\" width=\"" + N(2 * r) +
             "\" height=\"" + N(2 * r) + "\" fill=\"" + color + "\"/>";
    case Marker::kCross:
      return "<path d=\"M" + N(x - r) + " " + N(y - r) + "L" + N(x + r) + " " + N(y + r) + "M" +
             N(x - r) + " " + N(y + r) + "L" + N(x + r) + " " + N(y - r) + "\" stroke=\"" + color +
             "\" stroke-width=\"1.6\" fill=\"none\"/>";
  }
  return "";
}

// Lays out legend entries in rows above the plot area; returns the SVG and the height used.
std::string LegendSvg(const std::vector<LegendEntry>& entries, double x0, double x1, double y0,
                      double* height_used) {
  std::string out;
  const size_t kMaxEntries = 14;
  double x = x0, y = y0 + 8;
  int rows = entries.empty() ? 0 : 1;
  std::string body;
  size_t shown = 0;
  for (const auto& e : entries) {
    if (shown == kMaxEntries) break;
    const std::string text = Truncate(e.label, 64);
    const double w = 26 + EstimateTextWidth(text) + 14;
    if (x + w > x1 && x > x0) {
      x = x0;
      y += 16;
      ++rows;
    }
    if (e.box) {
      body += "<rect x=\"" + N(x) + "\" y=\"" + N(y - 5) + "\" width=\"18\" height=\"10\" fill=\"" +
              e.color + "\" fill-opacity=\"0.8\"/>";
    } else {
      if (e.line) {
        body += "<line x1=\"" + N(x) + "\" y1=\"" + N(y) + "\" x2=\"" + N(x + 18) + "\" y2=\"" +
                N(y) + "\" stroke=\"" + e.color + "\" stroke-width=\"1.8\"" +
                (e.dash.empty() ? "" : " stroke-dasharray=\"" + e.dash + "\"") + "/>";
      }
      body += MarkerSvg(e.marker, x + 9, y, e.color);
    }
    body +=
        "<text x=\"" + N(x + 24) + "\" y=\"" + N(y + 3.8) + "\">" + EscapeText(text) + "</text>";
    x += w;
    ++shown;
  }
  if (entries.size() > shown) {
    const std::string more = "\xE2\x80\xA6 " + std::to_string(entries.size() - shown) + " more";
    if (x + EstimateTextWidth(more) > x1 && x > x0) {
      x = x0;
      y += 16;
      ++rows;
    }
    body += "<text x=\"" + N(x) + "\" y=\"" + N(y + 3.8) + "\" fill=\"" + kMuted + "\">" +
            EscapeText(more) + "</text>";
  }
  if (!body.empty()) out = "<g class=\"legend\" font-size=\"11\">" + body + "</g>";
  *height_used = rows * 16.0;
  return out;
}

std::string SvgOpen(const PlotOptions& o, const std::string& extra_desc) {
  std::string out = "<svg xmlns=\"http://www.w3.org/2000/svg\" class=\"plot plot-" +
                    SafeClassName(o.name) + "\" viewBox=\"0 0 " + std::to_string(o.width) + " " +
                    std::to_string(o.height) + "\" width=\"" + std::to_string(o.width) +
                    "\" height=\"" + std::to_string(o.height) +
                    "\" role=\"img\" font-family=\"system-ui,-apple-system,'Segoe UI',Roboto,"
                    "Helvetica,Arial,sans-serif\" font-size=\"11\" fill=\"" +
                    kInk + "\">";
  out += "<title>" + EscapeText(o.title.empty() ? o.name : o.title) + "</title>";
  std::string desc = o.description;
  if (!extra_desc.empty()) desc += (desc.empty() ? "" : " ") + extra_desc;
  if (!desc.empty()) out += "<desc>" + EscapeText(desc) + "</desc>";
  return out;
}

// Margins from the tick labels and titles; returns the legend height reserved.
void LayoutFrame(const PlotOptions& o, const AxisTicks& yt, size_t legend_entries_hint,
                 double extra_bottom, size_t notes, Frame* f) {
  f->width = std::max(o.width, 160);
  f->height = std::max(o.height, 120);
  double label_w = 0;
  for (const auto& l : yt.labels) label_w = std::max(label_w, EstimateTextWidth(l));
  f->left = std::min(12 + label_w + (o.y.title.empty() ? 6 : 22), f->width * 0.4);
  f->right = 26;
  f->top = o.title.empty() ? 10 : 28;
  (void)legend_entries_hint;
  f->bottom = 22 + (o.x.title.empty() ? 4 : 18) + extra_bottom + 13.0 * static_cast<double>(notes);
}

// Grid, ticks, labels, axis titles for numeric axes.
std::string AxesSvg(const PlotOptions& o, const Frame& f, const Scale& sx, const Scale& sy,
                    const AxisTicks& xt, const AxisTicks& yt, bool draw_x_ticks) {
  std::string grid, ticks, labels;
  const double x0 = f.px0(), x1 = f.px1(), y0 = f.py0(), y1 = f.py1();
  for (double v : yt.minor) {
    const double y = sy(v);
    grid += "M" + N(x0) + " " + N(y) + "H" + N(x1);
  }
  std::string minor_grid = grid;
  grid.clear();
  for (size_t i = 0; i < yt.values.size(); ++i) {
    const double y = sy(yt.values[i]);
    if (y < y1 - 0.5 || y > y0 + 0.5) continue;
    grid += "M" + N(x0) + " " + N(y) + "H" + N(x1);
    ticks += "M" + N(x0 - 4) + " " + N(y) + "H" + N(x0);
    labels += "<text x=\"" + N(x0 - 7) + "\" y=\"" + N(y + 3.8) + "\" text-anchor=\"end\">" +
              EscapeText(yt.labels[i]) + "</text>";
  }
  if (draw_x_ticks) {
    for (double v : xt.minor) {
      const double x = sx(v);
      minor_grid += "M" + N(x) + " " + N(y0) + "V" + N(y1);
    }
    for (size_t i = 0; i < xt.values.size(); ++i) {
      const double x = sx(xt.values[i]);
      if (x < x0 - 0.5 || x > x1 + 0.5) continue;
      grid += "M" + N(x) + " " + N(y0) + "V" + N(y1);
      ticks += "M" + N(x) + " " + N(y0) + "V" + N(y0 + 4);
      labels += "<text x=\"" + N(x) + "\" y=\"" + N(y0 + 16) + "\" text-anchor=\"middle\">" +
                EscapeText(xt.labels[i]) + "</text>";
    }
  }
  std::string out = "<g class=\"axes\">";
  out += "<rect x=\"" + N(x0) + "\" y=\"" + N(y1) + "\" width=\"" + N(x1 - x0) + "\" height=\"" +
         N(y0 - y1) + "\" fill=\"#fff\" stroke=\"none\"/>";
  if (!minor_grid.empty()) {
    out += "<path d=\"" + minor_grid + "\" stroke=\"#f1f3f5\" stroke-width=\"1\" fill=\"none\"/>";
  }
  if (!grid.empty()) {
    out += "<path d=\"" + grid + "\" stroke=\"" + kGrid + "\" stroke-width=\"1\" fill=\"none\"/>";
  }
  out += "<rect x=\"" + N(x0) + "\" y=\"" + N(y1) + "\" width=\"" + N(x1 - x0) + "\" height=\"" +
         N(y0 - y1) + "\" fill=\"none\" stroke=\"" + kAxis + "\" stroke-width=\"1\"/>";
  if (!ticks.empty()) {
    out += "<path d=\"" + ticks + "\" stroke=\"" + kAxis + "\" stroke-width=\"1\" fill=\"none\"/>";
  }
  out += "<g class=\"tick-labels\" fill=\"" + std::string(kInk) + "\">" + labels + "</g>";
  if (!o.x.title.empty()) {
    out += "<text class=\"axis-title axis-title-x\" x=\"" + N((x0 + x1) / 2) + "\" y=\"" +
           N(y0 + (draw_x_ticks ? 32 : 34)) + "\" text-anchor=\"middle\" font-size=\"11.5\">" +
           EscapeText(o.x.title) + "</text>";
  }
  if (!o.y.title.empty()) {
    const double cx = 12, cy = (y0 + y1) / 2;
    out += "<text class=\"axis-title axis-title-y\" x=\"" + N(cx) + "\" y=\"" + N(cy) +
           "\" transform=\"rotate(-90 " + N(cx) + " " + N(cy) +
           ")\" text-anchor=\"middle\" font-size=\"11.5\">" + EscapeText(o.y.title) + "</text>";
  }
  out += "</g>";
  return out;
}

std::string TitleSvg(const PlotOptions& o, const Frame& f) {
  if (o.title.empty()) return "";
  return "<text class=\"plot-title\" x=\"" + N(f.px0()) +
         "\" y=\"17\" font-size=\"13\" font-weight=\"600\">" + EscapeText(o.title) + "</text>";
}

std::string NotesSvg(const std::vector<std::string>& notes, const Frame& f) {
  if (notes.empty()) return "";
  std::string out = "<g class=\"notes\" font-size=\"10.5\" fill=\"" + std::string(kMuted) + "\">";
  double y = f.height - 5 - 13.0 * static_cast<double>(notes.size() - 1);
  for (const auto& n : notes) {
    out += "<text x=\"" + N(f.px0()) + "\" y=\"" + N(y) + "\">" + EscapeText(n) + "</text>";
    y += 13;
  }
  return out + "</g>";
}

std::string ClipId(const PlotOptions& o, const std::string& body) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%016llx",
                static_cast<unsigned long long>(Fnv1a(body, Fnv1a(o.name + o.title))));
  return "clip-" + SafeClassName(o.name) + "-" + std::string(buf, 10);
}

std::string PluralNote(size_t n, const char* what) { return std::to_string(n) + " " + what; }

// Final linear domains with equal data units per pixel on both axes.
void EqualAspect(const Frame& f, std::pair<double, double>* dx, std::pair<double, double>* dy) {
  const double w = f.px1() - f.px0(), h = f.py0() - f.py1();
  if (w <= 0 || h <= 0) return;
  const double sx = (dx->second - dx->first) / w, sy = (dy->second - dy->first) / h;
  if (sx > sy) {
    const double c = (dy->first + dy->second) / 2, half = sx * h / 2;
    *dy = {c - half, c + half};
  } else {
    const double c = (dx->first + dx->second) / 2, half = sy * w / 2;
    *dx = {c - half, c + half};
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------

double NiceStep(double lo, double hi, int target) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) return 0;
  if (lo > hi) std::swap(lo, hi);
  const double span = hi - lo;
  if (!(span > 0) || !std::isfinite(span)) return 0;
  if (target < 1) target = 1;
  const double raw = span / target;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  const double norm = raw / mag;
  double nice;
  if (norm < 1.5) {
    nice = 1;
  } else if (norm < 3.5) {
    nice = 2;
  } else if (norm < 7.5) {
    nice = 5;
  } else {
    nice = 10;
  }
  return nice * mag;
}

std::vector<double> NiceLinearTicks(double lo, double hi, int target) {
  std::vector<double> out;
  const double step = NiceStep(lo, hi, target);
  if (!(step > 0) || !std::isfinite(step)) return out;
  if (lo > hi) std::swap(lo, hi);
  const double k0 = std::ceil(lo / step - 1e-9), k1 = std::floor(hi / step + 1e-9);
  if (!(k1 - k0 < 1000)) return out;
  for (double k = k0; k <= k1; k += 1) {
    double v = k * step;
    // Snap to the decimal grid of the step, so 0.1*3 prints and compares as 0.3.
    const double decimals = std::max(0.0, -std::floor(std::log10(step)) + 1);
    if (decimals < 15) {
      const double p = std::pow(10.0, decimals);
      v = std::round(v * p) / p;
    }
    if (std::fabs(v) < step * 1e-9) v = 0;
    out.push_back(v);
  }
  return out;
}

std::vector<double> LogTicks(double lo, double hi, int max_decades) {
  std::vector<double> out;
  if (!std::isfinite(lo) || !std::isfinite(hi) || lo <= 0 || hi <= 0) return out;
  if (lo > hi) std::swap(lo, hi);
  const int k0 = static_cast<int>(std::ceil(std::log10(lo) - 1e-9));
  const int k1 = static_cast<int>(std::floor(std::log10(hi) + 1e-9));
  const int decades = k1 - k0 + 1;
  if (max_decades < 1) max_decades = 1;
  const int every = decades > max_decades ? (decades + max_decades - 1) / max_decades : 1;
  for (int k = k0; k <= k1; ++k) {
    if ((k - k0) % every == 0) out.push_back(std::pow(10.0, k));
  }
  if (std::log10(hi / lo) < 2.05) {
    // Few decades: add 2× and 5× multiples.
    for (int k = k0 - 1; k <= k1; ++k) {
      for (int m : {2, 5}) {
        const double v = m * std::pow(10.0, k);
        if (v >= lo * (1 - 1e-9) && v <= hi * (1 + 1e-9)) out.push_back(v);
      }
    }
    std::sort(out.begin(), out.end());
  }
  return out;
}

std::string FormatTick(double value, double step) {
  if (!std::isfinite(value)) return "";
  char buf[64];
  if (step > 0) {
    if (std::fabs(value) < step * 1e-9) return "0";
    const int decimals = std::max(0, static_cast<int>(-std::floor(std::log10(step) + 1e-9)));
    const double a = std::fabs(value);
    if (a >= 1e6 || decimals > 4) {
      const int sig = std::max(1, static_cast<int>(std::floor(std::log10(a) + 1e-9)) -
                                      static_cast<int>(std::floor(std::log10(step) + 1e-9)) + 1);
      std::snprintf(buf, sizeof(buf), "%.*e", std::min(sig - 1, 15), value);
    } else {
      std::snprintf(buf, sizeof(buf), "%.*f", decimals, value);
    }
  } else {
    const double a = std::fabs(value);
    if (a == 0) return "0";
    if (a >= 1e-3 && a < 1e5) {
      const int decimals = std::max(0, static_cast<int>(-std::floor(std::log10(a) + 1e-9)));
      std::snprintf(buf, sizeof(buf), "%.*f", decimals, value);
    } else {
      std::snprintf(buf, sizeof(buf), "%.0e", value);
    }
  }
  std::string s(buf);
  // Strip trailing zeros of a mantissa in exponent form: "2.50e-07" -> "2.5e-7".
  const size_t e = s.find('e');
  if (e != std::string::npos) {
    std::string mant = s.substr(0, e), exp = s.substr(e + 1);
    if (mant.find('.') != std::string::npos) {
      while (!mant.empty() && mant.back() == '0') mant.pop_back();
      if (!mant.empty() && mant.back() == '.') mant.pop_back();
    }
    bool neg = false;
    if (!exp.empty() && (exp[0] == '+' || exp[0] == '-')) {
      neg = exp[0] == '-';
      exp.erase(0, 1);
    }
    while (exp.size() > 1 && exp[0] == '0') exp.erase(0, 1);
    s = mant + "e" + (neg ? "-" : "") + exp;
  }
  if (s.size() > 1 && s[0] == '-' && s.find_first_not_of("-0.") == std::string::npos) s.erase(0, 1);
  return s;
}

Scale::Scale(ScaleType type, double d0, double d1, double r0, double r1)
    : type_(type), d0_(d0), d1_(d1), r0_(r0), r1_(r1) {
  if (type_ == ScaleType::kLog10) {
    if (!(d0_ > 0)) d0_ = 1e-300;
    if (!(d1_ > 0)) d1_ = d0_ * 10;
  }
  if (d0_ == d1_) d1_ = d0_ + 1;
}

double Scale::operator()(double v) const {
  double t;
  if (type_ == ScaleType::kLog10) {
    if (!(v > 0)) return std::numeric_limits<double>::quiet_NaN();
    t = (std::log10(v) - std::log10(d0_)) / (std::log10(d1_) - std::log10(d0_));
  } else {
    t = (v - d0_) / (d1_ - d0_);
  }
  return r0_ + t * (r1_ - r0_);
}

std::vector<size_t> DecimateMinMax(const std::vector<double>& x, const std::vector<double>& y,
                                   size_t max_points) {
  const size_t n = std::min(x.size(), y.size());
  std::vector<size_t> finite;
  finite.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    if (std::isfinite(x[i]) && std::isfinite(y[i])) finite.push_back(i);
  }
  if (max_points < 4) max_points = 4;
  if (finite.size() <= max_points) return finite;
  const size_t buckets = max_points / 2 - 1;
  std::vector<size_t> out;
  out.reserve(max_points + 2);
  out.push_back(finite.front());
  const size_t m = finite.size();
  for (size_t b = 0; b < buckets; ++b) {
    const size_t begin = b * m / buckets, end = (b + 1) * m / buckets;
    if (begin >= end) continue;
    size_t imin = finite[begin], imax = finite[begin];
    for (size_t k = begin; k < end; ++k) {
      const size_t i = finite[k];
      if (y[i] < y[imin]) imin = i;
      if (y[i] > y[imax]) imax = i;
    }
    const size_t a = std::min(imin, imax), c = std::max(imin, imax);
    if (a != out.back()) out.push_back(a);
    if (c != out.back()) out.push_back(c);
  }
  if (finite.back() != out.back()) out.push_back(finite.back());
  return out;
}

const char* PaletteColor(size_t i) { return kPalette[i % kPaletteSize]; }

// ---------------------------------------------------------------------------------------------

std::string RenderXYPlot(const PlotOptions& o, const std::vector<Series>& series) {
  std::vector<std::string> notes = o.notes;
  const ScaleType tx = o.x.type, ty = o.y.type;

  // Which points are drawable, per series (after decimation).
  std::vector<std::vector<size_t>> keep(series.size());
  size_t non_finite = 0, non_positive = 0, decimated_from = 0;
  Extent ex, ey;
  for (size_t s = 0; s < series.size(); ++s) {
    const Series& se = series[s];
    const size_t n = std::min(se.x.size(), se.y.size());
    std::vector<double> xs(n), ys(n);
    for (size_t i = 0; i < n; ++i) {
      const double xv = se.x[i], yv = se.y[i];
      if (!std::isfinite(xv) || !std::isfinite(yv)) {
        ++non_finite;
        xs[i] = ys[i] = std::numeric_limits<double>::quiet_NaN();
      } else if (!Usable(xv, tx) || !Usable(yv, ty)) {
        ++non_positive;
        xs[i] = ys[i] = std::numeric_limits<double>::quiet_NaN();
      } else {
        xs[i] = xv;
        ys[i] = yv;
      }
    }
    keep[s] = DecimateMinMax(xs, ys, o.max_points);
    size_t usable = 0;
    for (size_t i = 0; i < n; ++i) usable += std::isfinite(xs[i]) ? 1 : 0;
    if (keep[s].size() < usable) decimated_from = std::max(decimated_from, usable);
    for (size_t i : keep[s]) {
      ex.Add(xs[i]);
      ey.Add(ys[i]);
      auto add_err = [&](const std::vector<double>& err, Extent* e, double c, ScaleType t) {
        if (i < err.size() && std::isfinite(err[i])) {
          const double a = c - std::fabs(err[i]), b = c + std::fabs(err[i]);
          if (Usable(a, t)) e->Add(a);
          if (Usable(b, t)) e->Add(b);
        }
      };
      add_err(se.y_err, &ey, ys[i], ty);
      add_err(se.x_err, &ex, xs[i], tx);
      if (i < se.ellipses.size() && tx == ScaleType::kLinear && ty == ScaleType::kLinear) {
        const Cov2& c = se.ellipses[i];
        if (std::isfinite(c[0]) && std::isfinite(c[2]) && c[0] >= 0 && c[2] >= 0) {
          ex.Add(xs[i] - std::sqrt(c[0]));
          ex.Add(xs[i] + std::sqrt(c[0]));
          ey.Add(ys[i] - std::sqrt(c[2]));
          ey.Add(ys[i] + std::sqrt(c[2]));
        }
      }
    }
  }
  for (const auto& seg : o.segments) {
    if (Usable(seg.x0, tx) && Usable(seg.y0, ty) && Usable(seg.x1, tx) && Usable(seg.y1, ty)) {
      ex.Add(seg.x0);
      ex.Add(seg.x1);
      ey.Add(seg.y0);
      ey.Add(seg.y1);
    }
  }
  for (const auto& r : o.ref_lines) {
    if (Usable(r.at, r.vertical ? tx : ty)) (r.vertical ? ex : ey).Add(r.at);
  }
  if (non_finite > 0) notes.push_back(PluralNote(non_finite, "non-finite point(s) not shown."));
  if (non_positive > 0) {
    notes.push_back(
        PluralNote(non_positive, "zero or negative value(s) not shown on the log axis."));
  }
  if (decimated_from > 0) {
    notes.push_back("Large series decimated (" + std::to_string(decimated_from) +
                    " points \xE2\x86\x92 min/max per bucket; peaks kept).");
  }
  const bool empty = ex.empty();
  if (empty) notes.push_back("No data to plot.");
  // The x axis covers every band (a static interval far from the plotted points stays visible).
  for (const auto& b : o.bands) {
    if (Usable(b.x0, tx) && Usable(b.x1, tx)) {
      ex.Add(b.x0);
      ex.Add(b.x1);
    }
  }

  std::pair<double, double> dx = AxisDomain(o.x, ex), dy = AxisDomain(o.y, ey);

  // Styles, then legend entries.
  std::vector<SeriesStyle> styles;
  for (size_t s = 0; s < series.size(); ++s) styles.push_back(StyleOf(series[s], s));
  std::vector<LegendEntry> legend;
  if (o.legend) {
    for (size_t s = 0; s < series.size(); ++s) {
      const Series& se = series[s];
      if (se.label.empty()) continue;
      legend.push_back(
          {se.label, styles[s].color, styles[s].dash, styles[s].marker, se.line, false});
    }
  }

  Frame f;
  AxisTicks yt = MakeTicks(o.y, dy.first, dy.second);
  // A plot with point labels keeps a line for the note on labels left out.
  bool point_labels = false;
  for (const Series& se : series) point_labels = point_labels || !se.point_labels.empty();
  LayoutFrame(o, yt, legend.size(), 0, notes.size() + (point_labels ? 1 : 0), &f);
  double legend_h = 0;
  std::string legend_svg = LegendSvg(legend, f.px0(), f.px1(), f.top, &legend_h);
  f.top += legend_h + (legend_h > 0 ? 6 : 0);
  if (o.equal_aspect && tx == ScaleType::kLinear && ty == ScaleType::kLinear) {
    EqualAspect(f, &dx, &dy);
    yt = MakeTicks(o.y, dy.first, dy.second);
  }
  const AxisTicks xt = MakeTicks(o.x, dx.first, dx.second);
  const Scale sx(tx, dx.first, dx.second, f.px0(), f.px1());
  const Scale sy(ty, dy.first, dy.second, f.py0(), f.py1());

  std::string body;
  // Text placed inside the plot area (band, reference-line and point labels): each avoids what
  // was placed before it.
  Occupancy occupied;
  // Shaded bands, behind everything else; labels at the top of the plot area (a label that
  // would overlap its neighbour's goes one row lower).
  if (!o.bands.empty()) {
    body += "<g class=\"bands\">";
    for (const auto& b : o.bands) {
      double a = sx(b.x0), c = sx(b.x1);
      if (!std::isfinite(a) || !std::isfinite(c)) continue;
      if (a > c) std::swap(a, c);
      a = std::max(a, f.px0());
      c = std::min(c, f.px1());
      if (c < a) continue;
      body += "<rect x=\"" + N(a) + "\" y=\"" + N(f.py1()) + "\" width=\"" +
              N(std::max(c - a, 0.6)) + "\" height=\"" + N(f.py0() - f.py1()) +
              "\" fill=\"#cfe3f3\" fill-opacity=\"0.75\"/>";
      if (!b.label.empty()) {
        const double w = EstimateTextWidth(b.label, kBandCharWidth), mid = (a + c) / 2;
        double y = f.py1() + 10;
        for (int row = 0; row < 3 && occupied.Overlaps(mid - w / 2, y - 8, mid + w / 2, y + 1);
             ++row) {
          y += 10;
        }
        occupied.Add(mid - w / 2, y - 8, mid + w / 2, y + 1);
        body += "<text x=\"" + N(mid) + "\" y=\"" + N(y) +
                "\" text-anchor=\"middle\" font-size=\"9\" fill=\"" + kMuted + "\">" +
                EscapeText(b.label) + "</text>";
      }
    }
    body += "</g>";
  }
  // Reference lines.
  for (const auto& r : o.ref_lines) {
    const double p = r.vertical ? sx(r.at) : sy(r.at);
    if (!std::isfinite(p)) continue;
    body += "<g class=\"ref-line\">";
    if (r.vertical) {
      body += "<line x1=\"" + N(p) + "\" y1=\"" + N(f.py0()) + "\" x2=\"" + N(p) + "\" y2=\"" +
              N(f.py1()) + "\"";
    } else {
      body += "<line x1=\"" + N(f.px0()) + "\" y1=\"" + N(p) + "\" x2=\"" + N(f.px1()) +
              "\" y2=\"" + N(p) + "\"";
    }
    body += " stroke=\"#6b7580\" stroke-width=\"1.2\"" +
            std::string(r.dashed ? " stroke-dasharray=\"5 4\"" : "") + "/>";
    if (!r.label.empty()) {
      // Next to its line, at the top (vertical) or the right (horizontal); a label that would
      // overlap one placed before moves a row down (vertical) or to the other side of its line.
      const double w = EstimateTextWidth(r.label);
      if (r.vertical) {
        const bool right_half = p > (f.px0() + f.px1()) / 2;
        const double x0 = right_half ? p - 4 - w : p + 4;
        double y = f.py1() + 12;
        for (int row = 0; row < 6 && occupied.Overlaps(x0, y - 9, x0 + w, y + 2); ++row) y += 13;
        occupied.Add(x0, y - 9, x0 + w, y + 2);
        body += "<text x=\"" + N(right_half ? p - 4 : p + 4) + "\" y=\"" + N(y) +
                "\" text-anchor=\"" + (right_half ? "end" : "start") + "\" fill=\"" + kMuted +
                "\">" + EscapeText(r.label) + "</text>";
      } else {
        const double x1 = f.px1() - 4;
        double y = p - 4;
        if (occupied.Overlaps(x1 - w, y - 9, x1, y + 2)) y = p + 13;
        occupied.Add(x1 - w, y - 9, x1, y + 2);
        body += "<text x=\"" + N(x1) + "\" y=\"" + N(y) + "\" text-anchor=\"end\" fill=\"" +
                kMuted + "\">" + EscapeText(r.label) + "</text>";
      }
    }
    body += "</g>";
  }
  // Segments.
  if (!o.segments.empty()) {
    std::string grey, coloured;
    for (const auto& seg : o.segments) {
      const double a = sx(seg.x0), b = sy(seg.y0), c = sx(seg.x1), d = sy(seg.y1);
      if (!std::isfinite(a) || !std::isfinite(b) || !std::isfinite(c) || !std::isfinite(d)) {
        continue;
      }
      const std::string p = "M" + N(a) + " " + N(b) + "L" + N(c) + " " + N(d);
      if (seg.color < 0) {
        grey += p;
      } else {
        coloured += "<path d=\"" + p + "\" stroke=\"" +
                    PaletteColor(static_cast<size_t>(seg.color)) + "\" stroke-width=\"1.2\"/>";
      }
    }
    body += "<g class=\"segments\" fill=\"none\">";
    if (!grey.empty()) body += "<path d=\"" + grey + "\" stroke=\"#8a949e\" stroke-width=\"1\"/>";
    body += coloured + "</g>";
  }
  // Series.
  size_t labels_left_out = 0;
  for (size_t s = 0; s < series.size(); ++s) {
    const Series& se = series[s];
    const std::string& color = styles[s].color;
    body += "<g class=\"series series-" + std::to_string(s) + "\">";
    // Ellipses first (under the markers).
    if (!se.ellipses.empty() && tx == ScaleType::kLinear && ty == ScaleType::kLinear) {
      std::string d;
      for (size_t i : keep[s]) {
        if (i >= se.ellipses.size()) continue;
        const Cov2& c = se.ellipses[i];
        if (!std::isfinite(c[0]) || !std::isfinite(c[1]) || !std::isfinite(c[2])) continue;
        const double tr = (c[0] + c[2]) / 2,
                     disc =
                         std::sqrt(std::max(0.0, (c[0] - c[2]) * (c[0] - c[2]) / 4 + c[1] * c[1]));
        const double l1 = std::max(0.0, tr + disc), l2 = std::max(0.0, tr - disc);
        const double th = 0.5 * std::atan2(2 * c[1], c[0] - c[2]);
        const double r1 = std::sqrt(l1), r2 = std::sqrt(l2);
        const double ct = std::cos(th), st = std::sin(th);
        for (int k = 0; k <= 36; ++k) {
          const double t = 2 * kPi * k / 36;
          const double u = r1 * std::cos(t), v = r2 * std::sin(t);
          const double px = sx(se.x[i] + ct * u - st * v), py = sy(se.y[i] + st * u + ct * v);
          d += (k == 0 ? "M" : "L") + N(px) + " " + N(py);
        }
        d += "Z";
      }
      if (!d.empty()) {
        body += "<path class=\"ellipses\" d=\"" + d + "\" fill=\"" + color +
                "\" fill-opacity=\"0.12\" stroke=\"" + color + "\" stroke-width=\"1\"/>";
      }
    }
    // Error bars.
    if (!se.y_err.empty() || !se.x_err.empty()) {
      std::string d;
      for (size_t i : keep[s]) {
        const double px = sx(se.x[i]), py = sy(se.y[i]);
        if (i < se.y_err.size() && std::isfinite(se.y_err[i])) {
          const double e = std::fabs(se.y_err[i]);
          double a = sy(se.y[i] - e), b = sy(se.y[i] + e);
          if (!std::isfinite(a)) a = f.py0();
          if (std::isfinite(b)) {
            d += "M" + N(px) + " " + N(a) + "V" + N(b) + "M" + N(px - 3) + " " + N(a) + "h6M" +
                 N(px - 3) + " " + N(b) + "h6";
          }
        }
        if (i < se.x_err.size() && std::isfinite(se.x_err[i])) {
          const double e = std::fabs(se.x_err[i]);
          double a = sx(se.x[i] - e), b = sx(se.x[i] + e);
          if (!std::isfinite(a)) a = f.px0();
          if (std::isfinite(b)) {
            d += "M" + N(a) + " " + N(py) + "H" + N(b) + "M" + N(a) + " " + N(py - 3) + "v6M" +
                 N(b) + " " + N(py - 3) + "v6";
          }
        }
      }
      if (!d.empty()) {
        body += "<path class=\"error-bars\" d=\"" + d + "\" stroke=\"" + color +
                "\" stroke-width=\"1\" fill=\"none\"/>";
      }
    }
    // Line.
    if (se.line && keep[s].size() >= 2) {
      std::string d;
      for (size_t k = 0; k < keep[s].size(); ++k) {
        const size_t i = keep[s][k];
        d += (k == 0 ? "M" : "L") + N(sx(se.x[i])) + " " + N(sy(se.y[i]));
      }
      const std::string& dash = styles[s].dash;
      body += "<path class=\"line\" d=\"" + d + "\" fill=\"none\" stroke=\"" + color +
              "\" stroke-width=\"" + N(se.line_width) + "\" stroke-linejoin=\"round\"" +
              (dash.empty() ? std::string() : " stroke-dasharray=\"" + dash + "\"") + "/>";
    }
    // Markers (one path for crosses, keeps the SVG small).
    if (se.marker != Marker::kNone || (!se.line && !keep[s].empty()) || keep[s].size() == 1) {
      const Marker m = styles[s].marker == Marker::kNone ? Marker::kCircle : styles[s].marker;
      std::string d;
      for (size_t i : keep[s]) {
        const double px = sx(se.x[i]), py = sy(se.y[i]);
        if (m == Marker::kCross) {
          d += "M" + N(px - 3.2) + " " + N(py - 3.2) + "l6.4 6.4m-6.4 0l6.4-6.4";
        } else {
          d += MarkerSvg(m, px, py, color);
        }
      }
      if (m == Marker::kCross) {
        body += "<path class=\"markers\" d=\"" + d + "\" stroke=\"" + color +
                "\" stroke-width=\"1.6\" fill=\"none\"/>";
      } else {
        body += "<g class=\"markers\">" + d + "</g>";
      }
    }
    // Point labels: the labels of points drawn on the same spot are joined ("s1, s4"), and each
    // label goes to the first of several places around its point where it overlaps no label,
    // no labelled point and no reference-line label placed before it; one with no free place is
    // left out (and counted in a note).
    if (!se.point_labels.empty()) {
      struct Spot {
        double x, y;
        std::string text;
      };
      std::vector<Spot> spots;
      for (size_t i : keep[s]) {
        if (i >= se.point_labels.size() || se.point_labels[i].empty()) continue;
        const double px = sx(se.x[i]), py = sy(se.y[i]);
        if (!std::isfinite(px) || !std::isfinite(py)) continue;
        occupied.Add(px - 3.5, py - 3.5, px + 3.5, py + 3.5);
        bool joined = false;
        for (Spot& sp : spots) {
          if (std::fabs(sp.x - px) < 3 && std::fabs(sp.y - py) < 3) {
            sp.text += ", " + Truncate(se.point_labels[i], 16);
            joined = true;
            break;
          }
        }
        if (!joined) spots.push_back({px, py, Truncate(se.point_labels[i], 16)});
      }
      body += "<g class=\"point-labels\" font-size=\"9.5\" fill=\"" + std::string(kMuted) + "\">";
      for (const Spot& sp : spots) {
        const std::string text = Truncate(sp.text, 40);
        const double w = EstimateTextWidth(text, kLabelCharWidth), h = 10;
        // Baseline-left corners of the candidate places: NE, SE, NW, SW, E, W, N, S, then the
        // same farther out.
        bool placed = false;
        for (double r : {1.0, 2.2}) {
          const double c[8][2] = {{5 * r, -5 * r},         {5 * r, 5 * r + 8}, {-5 * r - w, -5 * r},
                                  {-5 * r - w, 5 * r + 8}, {7 * r, 3.5},       {-7 * r - w, 3.5},
                                  {-w / 2, -7 * r},        {-w / 2, 7 * r + 8}};
          for (const auto& d : c) {
            const double x = sp.x + d[0], y = sp.y + d[1];
            if (x < f.px0() || x + w > f.px1() || y - h + 2 < f.py1() || y + 2 > f.py0()) {
              continue;
            }
            if (occupied.Overlaps(x, y - h + 2, x + w, y + 2)) continue;
            occupied.Add(x, y - h + 2, x + w, y + 2);
            body += "<text x=\"" + N(x) + "\" y=\"" + N(y) + "\">" + EscapeText(text) + "</text>";
            placed = true;
            break;
          }
          if (placed) break;
        }
        if (!placed) ++labels_left_out;
      }
      body += "</g>";
    }
    body += "</g>";
  }

  if (labels_left_out > 0) {
    notes.push_back(
        PluralNote(labels_left_out, "point label(s) left out where they would overlap."));
  }
  const std::string clip = ClipId(o, body);
  std::string out = SvgOpen(o, "");
  out += "<defs><clipPath id=\"" + clip + "\"><rect x=\"" + N(f.px0() - 4) + "\" y=\"" +
         N(f.py1() - 4) + "\" width=\"" + N(f.px1() - f.px0() + 8) + "\" height=\"" +
         N(f.py0() - f.py1() + 8) + "\"/></clipPath></defs>";
  out += TitleSvg(o, f);
  out += legend_svg;
  out += AxesSvg(o, f, sx, sy, xt, yt, true);
  out += "<g class=\"data\" clip-path=\"url(#" + clip + ")\">" + body + "</g>";
  if (empty) {
    out += "<text class=\"no-data\" x=\"" + N((f.px0() + f.px1()) / 2) + "\" y=\"" +
           N((f.py0() + f.py1()) / 2) + "\" text-anchor=\"middle\" fill=\"" + kMuted +
           "\">no data</text>";
  }
  out += NotesSvg(notes, f);
  out += "</svg>";
  return out;
}

std::string RenderBarChart(const PlotOptions& o, const std::vector<std::string>& categories,
                           const std::vector<BarSeries>& series) {
  std::vector<std::string> notes = o.notes;
  const ScaleType ty = o.y.type;
  Extent ey;
  size_t skipped = 0, non_finite = 0;
  for (const auto& s : series) {
    for (size_t i = 0; i < s.values.size() && i < categories.size(); ++i) {
      const double v = s.values[i];
      if (!std::isfinite(v)) {
        if (!std::isnan(v)) ++non_finite;
        continue;
      }
      if (!Usable(v, ty)) {
        ++skipped;
        continue;
      }
      ey.Add(v);
      if (i < s.errors.size() && std::isfinite(s.errors[i])) {
        const double e = std::fabs(s.errors[i]);
        ey.Add(v + e);
        if (Usable(v - e, ty)) ey.Add(v - e);
      }
    }
  }
  for (const auto& r : o.ref_lines) {
    if (!r.vertical && Usable(r.at, ty)) ey.Add(r.at);
  }
  if (non_finite > 0) notes.push_back(PluralNote(non_finite, "non-finite value(s) not shown."));
  if (skipped > 0) {
    notes.push_back(PluralNote(skipped, "zero or negative value(s) not shown on the log axis."));
  }
  const bool empty = categories.empty() || ey.empty();
  if (empty) notes.push_back("No data to plot.");
  AxisOptions yopt = o.y;
  if (ty == ScaleType::kLinear) yopt.include_zero = true;
  // Log bars start at the axis bottom: keep the smallest bar visibly tall.
  if (ty == ScaleType::kLog10 && !ey.empty()) ey.Add(ey.lo / 3);
  const auto dy = AxisDomain(yopt, ey);

  std::vector<LegendEntry> legend;
  if (o.legend && series.size() > 1) {
    for (size_t s = 0; s < series.size(); ++s) {
      if (series[s].label.empty()) continue;
      const size_t ci = series[s].color >= 0 ? static_cast<size_t>(series[s].color) : s;
      legend.push_back({series[s].label, PaletteColor(ci), "", Marker::kNone, false, true});
    }
  }

  // Category labels: rotate when they do not fit side by side; thin out when very many.
  const size_t nc = categories.size();
  double max_label = 0;
  for (const auto& c : categories)
    max_label = std::max(max_label, EstimateTextWidth(Truncate(c, 24)));
  Frame f;
  AxisTicks yt = MakeTicks(yopt, dy.first, dy.second);
  LayoutFrame(o, yt, legend.size(), 0, notes.size(), &f);
  const double plot_w = f.px1() - f.px0();
  const double band = nc > 0 ? plot_w / static_cast<double>(nc) : plot_w;
  const bool rotate = nc > 0 && max_label + 6 > band;
  size_t label_every = 1;
  if (rotate && band < 12) label_every = static_cast<size_t>(std::ceil(12 / band));
  const double extra_bottom = rotate ? std::min(max_label * 0.7, 90.0) : 0;
  LayoutFrame(o, yt, legend.size(), extra_bottom, notes.size(), &f);
  double legend_h = 0;
  const std::string legend_svg = LegendSvg(legend, f.px0(), f.px1(), f.top, &legend_h);
  f.top += legend_h + (legend_h > 0 ? 6 : 0);
  const Scale sy(ty, dy.first, dy.second, f.py0(), f.py1());
  const Scale sx(ScaleType::kLinear, 0, 1, f.px0(), f.px1());

  std::string body;
  const double base = ty == ScaleType::kLog10 ? f.py0() : sy(std::max(0.0, dy.first));
  const double group = band * 0.78;
  const double bar_w = series.empty() ? group : group / static_cast<double>(series.size());
  for (size_t s = 0; s < series.size(); ++s) {
    const size_t ci = series[s].color >= 0 ? static_cast<size_t>(series[s].color) : s;
    const std::string color = PaletteColor(ci);
    std::string bars, errs;
    for (size_t i = 0; i < nc && i < series[s].values.size(); ++i) {
      const double v = series[s].values[i];
      if (!Usable(v, ty)) continue;
      const double x = f.px0() + band * (static_cast<double>(i) + 0.11) + bar_w * s;
      const double y = sy(v);
      bars += "<rect x=\"" + N(x) + "\" y=\"" + N(std::min(y, base)) + "\" width=\"" +
              N(std::max(bar_w - 1, 0.8)) + "\" height=\"" + N(std::fabs(base - y)) + "\"/>";
      if (i < series[s].errors.size() && std::isfinite(series[s].errors[i])) {
        const double e = std::fabs(series[s].errors[i]);
        double a = sy(v - e);
        const double b = sy(v + e), cx = x + bar_w / 2;
        if (!std::isfinite(a)) a = f.py0();
        errs += "M" + N(cx) + " " + N(a) + "V" + N(b) + "M" + N(cx - 3) + " " + N(b) + "h6M" +
                N(cx - 3) + " " + N(a) + "h6";
      }
    }
    body += "<g class=\"series series-" + std::to_string(s) + " bars\" fill=\"" + color +
            "\" fill-opacity=\"0.85\">" + bars + "</g>";
    if (!errs.empty()) {
      body += "<path class=\"error-bars\" d=\"" + errs +
              "\" stroke=\"#1c232b\" stroke-width=\"1\" fill=\"none\"/>";
    }
  }
  // Horizontal reference lines (e.g. the noise level).
  for (const auto& r : o.ref_lines) {
    if (r.vertical || !Usable(r.at, ty)) continue;
    const double y = sy(r.at);
    body += "<g class=\"ref-line\"><line x1=\"" + N(f.px0()) + "\" y1=\"" + N(y) + "\" x2=\"" +
            N(f.px1()) + "\" y2=\"" + N(y) + "\" stroke=\"#6b7580\" stroke-width=\"1.2\"" +
            std::string(r.dashed ? " stroke-dasharray=\"5 4\"" : "") + "/>";
    if (!r.label.empty()) {
      body += "<text x=\"" + N(f.px1() - 4) + "\" y=\"" + N(y - 4) +
              "\" text-anchor=\"end\" fill=\"" + kMuted + "\">" + EscapeText(r.label) + "</text>";
    }
    body += "</g>";
  }
  // Category labels.
  std::string labels = "<g class=\"category-labels\">";
  for (size_t i = 0; i < nc; i += label_every) {
    const double cx = f.px0() + band * (static_cast<double>(i) + 0.5);
    const std::string text = EscapeText(Truncate(categories[i], 24));
    if (rotate) {
      const double y = f.py0() + 10;
      labels += "<text x=\"" + N(cx) + "\" y=\"" + N(y) + "\" text-anchor=\"end\" transform=\"" +
                "rotate(-40 " + N(cx) + " " + N(y) + ")\">" + text + "</text>";
    } else {
      labels += "<text x=\"" + N(cx) + "\" y=\"" + N(f.py0() + 16) + "\" text-anchor=\"middle\">" +
                text + "</text>";
    }
  }
  labels += "</g>";

  PlotOptions axes_opts = o;
  axes_opts.y = yopt;
  std::string out = SvgOpen(o, "");
  out += TitleSvg(o, f);
  out += legend_svg;
  // The x title goes below rotated labels: draw it here rather than in AxesSvg.
  std::string x_title = o.x.title;
  axes_opts.x.title.clear();
  out += AxesSvg(axes_opts, f, sx, sy, AxisTicks{}, yt, false);
  out += "<g class=\"data\">" + body + "</g>";
  out += labels;
  if (!x_title.empty()) {
    out += "<text class=\"axis-title axis-title-x\" x=\"" + N((f.px0() + f.px1()) / 2) + "\" y=\"" +
           N(f.py0() + 32 + extra_bottom) + "\" text-anchor=\"middle\" font-size=\"11.5\">" +
           EscapeText(x_title) + "</text>";
  }
  if (empty) {
    out += "<text class=\"no-data\" x=\"" + N((f.px0() + f.px1()) / 2) + "\" y=\"" +
           N((f.py0() + f.py1()) / 2) + "\" text-anchor=\"middle\" fill=\"" + kMuted +
           "\">no data</text>";
  }
  out += NotesSvg(notes, f);
  out += "</svg>";
  return out;
}

Histogram MakeHistogram(const std::vector<double>& values, int bins, std::string label) {
  Histogram h;
  h.label = std::move(label);
  Extent e;
  for (double v : values) e.Add(v);
  if (e.empty() || bins < 1 || !std::isfinite(e.hi - e.lo)) return h;
  double lo = e.lo, hi = e.hi;
  if (!(hi > lo)) {
    const double pad = lo == 0 ? 0.5 : std::fabs(lo) * 0.05;
    lo -= pad;
    hi += pad;
  }
  h.edges.resize(static_cast<size_t>(bins) + 1);
  for (int i = 0; i <= bins; ++i) h.edges[static_cast<size_t>(i)] = lo + (hi - lo) * i / bins;
  h.counts.assign(static_cast<size_t>(bins), 0);
  for (double v : values) {
    if (!std::isfinite(v)) continue;
    double pos = std::floor((v - lo) / (hi - lo) * bins);
    if (!std::isfinite(pos)) continue;
    pos = std::max(0.0, std::min(static_cast<double>(bins - 1), pos));
    const auto k = static_cast<int64_t>(pos);
    h.counts[static_cast<size_t>(k)] += 1;
  }
  return h;
}

std::string RenderHistogram(const PlotOptions& o, const std::vector<Histogram>& histograms) {
  std::vector<std::string> notes = o.notes;
  Extent ex, ey;
  ey.Add(0);
  bool any = false;
  for (const auto& h : histograms) {
    if (h.edges.size() != h.counts.size() + 1 || h.counts.empty()) continue;
    for (size_t i = 0; i < h.counts.size(); ++i) {
      if (!std::isfinite(h.edges[i]) || !std::isfinite(h.edges[i + 1]) ||
          !std::isfinite(h.counts[i])) {
        continue;
      }
      ex.Add(h.edges[i]);
      ex.Add(h.edges[i + 1]);
      ey.Add(h.counts[i]);
      any = true;
    }
  }
  if (!any) notes.push_back("No data to plot.");
  AxisOptions yopt = o.y;
  yopt.type = ScaleType::kLinear;
  yopt.include_zero = true;
  AxisOptions xopt = o.x;
  xopt.type = ScaleType::kLinear;
  const auto dx = AxisDomain(xopt, ex);
  const auto dy = AxisDomain(yopt, ey);

  std::vector<LegendEntry> legend;
  if (o.legend) {
    for (size_t s = 0; s < histograms.size(); ++s) {
      if (histograms[s].label.empty()) continue;
      const size_t ci = histograms[s].color >= 0 ? static_cast<size_t>(histograms[s].color) : s;
      legend.push_back({histograms[s].label, PaletteColor(ci), "", Marker::kNone, false, true});
    }
  }
  Frame f;
  const AxisTicks yt = MakeTicks(yopt, dy.first, dy.second);
  LayoutFrame(o, yt, legend.size(), 0, notes.size(), &f);
  double legend_h = 0;
  const std::string legend_svg = LegendSvg(legend, f.px0(), f.px1(), f.top, &legend_h);
  f.top += legend_h + (legend_h > 0 ? 6 : 0);
  const AxisTicks xt = MakeTicks(xopt, dx.first, dx.second);
  const Scale sx(ScaleType::kLinear, dx.first, dx.second, f.px0(), f.px1());
  const Scale sy(ScaleType::kLinear, dy.first, dy.second, f.py0(), f.py1());

  std::string body;
  for (size_t s = 0; s < histograms.size(); ++s) {
    const Histogram& h = histograms[s];
    if (h.edges.size() != h.counts.size() + 1 || h.counts.empty()) continue;
    const size_t ci = h.color >= 0 ? static_cast<size_t>(h.color) : s;
    const std::string color = PaletteColor(ci);
    std::string d;
    const double base = sy(0);
    bool open = false;
    for (size_t i = 0; i < h.counts.size(); ++i) {
      const double c = h.counts[i];
      if (!std::isfinite(h.edges[i]) || !std::isfinite(h.edges[i + 1]) || !std::isfinite(c)) {
        if (open) d += "V" + N(base);
        open = false;
        continue;
      }
      const double x0 = sx(h.edges[i]), x1 = sx(h.edges[i + 1]), y = sy(c);
      if (!open) d += "M" + N(x0) + " " + N(base);
      d += "V" + N(y) + "H" + N(x1);
      open = true;
    }
    if (open) d += "V" + N(base) + "Z";
    body += "<path class=\"series series-" + std::to_string(s) + " histogram\" d=\"" + d +
            "\" fill=\"" + color + "\" fill-opacity=\"0.22\" stroke=\"" + color +
            "\" stroke-width=\"1.4\"/>";
  }
  PlotOptions axes_opts = o;
  axes_opts.y = yopt;
  std::string out = SvgOpen(o, "");
  out += TitleSvg(o, f);
  out += legend_svg;
  out += AxesSvg(axes_opts, f, sx, sy, xt, yt, true);
  out += "<g class=\"data\">" + body + "</g>";
  if (!any) {
    out += "<text class=\"no-data\" x=\"" + N((f.px0() + f.px1()) / 2) + "\" y=\"" +
           N((f.py0() + f.py1()) / 2) + "\" text-anchor=\"middle\" fill=\"" + kMuted +
           "\">no data</text>";
  }
  out += NotesSvg(notes, f);
  out += "</svg>";
  return out;
}

}  // namespace calibd::web
