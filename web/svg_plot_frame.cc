// The frame around a plot's data: margins, axes, legend, title and notes (svg_plot_parts.h).
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "web/html.h"
#include "web/svg_plot.h"
#include "web/svg_plot_parts.h"

namespace calibd::web {

const char* PaletteColor(size_t i) { return svg_parts::kPalette[i % svg_parts::kPaletteSize]; }

namespace svg_parts {
namespace {

uint64_t Fnv1a(const std::string& s, uint64_t h = 1469598103934665603ULL) {
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ULL;
  }
  return h;
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

}  // namespace

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

double EstimateTextWidth(const std::string& s, double char_width) {
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

std::string MarkerSvg(Marker m, double x, double y, const std::string& color, double r) {
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

std::string LegendAbove(const std::vector<LegendEntry>& entries, Frame* f) {
  double legend_h = 0;
  std::string legend_svg = LegendSvg(entries, f->px0(), f->px1(), f->top, &legend_h);
  f->top += legend_h + (legend_h > 0 ? 6 : 0);
  return legend_svg;
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

void LayoutFrame(const PlotOptions& o, const AxisTicks& yt, double extra_bottom, size_t notes,
                 Frame* f) {
  f->width = std::max(o.width, 160);
  f->height = std::max(o.height, 120);
  double label_w = 0;
  for (const auto& l : yt.labels) label_w = std::max(label_w, EstimateTextWidth(l));
  f->left = std::min(12 + label_w + (o.y.title.empty() ? 6 : 22), f->width * 0.4);
  f->right = 26;
  f->top = o.title.empty() ? 10 : 28;
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

std::string NoDataSvg(const Frame& f) {
  return "<text class=\"no-data\" x=\"" + N((f.px0() + f.px1()) / 2) + "\" y=\"" +
         N((f.py0() + f.py1()) / 2) + "\" text-anchor=\"middle\" fill=\"" + kMuted +
         "\">no data</text>";
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

}  // namespace svg_parts
}  // namespace calibd::web
