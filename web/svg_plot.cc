// Line and scatter plots (web/svg_plot.h), on the frame of svg_plot_parts.h. RenderXYPlot runs
// in stages: the drawable points and their extent (CollectPoints), the layout of frame, legend
// and scales (LayoutXY), then the layers of the plot area from back to front (bands, reference
// lines, segments, each series) and the document around them.
#include "web/svg_plot.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "web/html.h"
#include "web/svg_plot_parts.h"

namespace calibd::web {

using namespace svg_parts;  // NOLINT(build/namespaces): this file draws with the parts

namespace {

constexpr double kPi = 3.14159265358979323846;
// Dash patterns cycle with a different period, so series stay distinct in grey print.
constexpr const char* kDashes[] = {"", "6 3", "2 2", "8 3 2 3"};
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
  const size_t ci = ColorIndex(se.color, index);
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

// The drawable points of every series and the data extent they cover, with what was left out.
struct XYPoints {
  std::vector<std::vector<size_t>> keep;  // per series: indices of the points drawn, ascending
  Extent ex, ey;
  size_t non_finite = 0;      // points with a NaN or Inf coordinate
  size_t non_positive = 0;    // points at zero or below on a log axis
  size_t decimated_from = 0;  // the largest series that was decimated (points), or 0
};

// Widens the extents by the error bars and 1σ ellipse of point i of `se` (at xv, yv).
void AddPointExtent(const Series& se, size_t i, double xv, double yv, ScaleType tx, ScaleType ty,
                    XYPoints* pts) {
  auto add_err = [&](const std::vector<double>& err, Extent* e, double c, ScaleType t) {
    if (i < err.size() && std::isfinite(err[i])) {
      const double a = c - std::fabs(err[i]), b = c + std::fabs(err[i]);
      if (Usable(a, t)) e->Add(a);
      if (Usable(b, t)) e->Add(b);
    }
  };
  add_err(se.y_err, &pts->ey, yv, ty);
  add_err(se.x_err, &pts->ex, xv, tx);
  if (i < se.ellipses.size() && tx == ScaleType::kLinear && ty == ScaleType::kLinear) {
    const Cov2& c = se.ellipses[i];
    if (std::isfinite(c[0]) && std::isfinite(c[2]) && c[0] >= 0 && c[2] >= 0) {
      pts->ex.Add(xv - std::sqrt(c[0]));
      pts->ex.Add(xv + std::sqrt(c[0]));
      pts->ey.Add(yv - std::sqrt(c[2]));
      pts->ey.Add(yv + std::sqrt(c[2]));
    }
  }
}

// Adds series `se`: its drawable points (decimated to max_points) and their extent.
void AddSeriesPoints(const Series& se, ScaleType tx, ScaleType ty, size_t max_points,
                     std::vector<size_t>* keep, XYPoints* pts) {
  const size_t n = std::min(se.x.size(), se.y.size());
  std::vector<double> xs(n), ys(n);
  for (size_t i = 0; i < n; ++i) {
    const double xv = se.x[i], yv = se.y[i];
    if (!std::isfinite(xv) || !std::isfinite(yv)) {
      ++pts->non_finite;
      xs[i] = ys[i] = std::numeric_limits<double>::quiet_NaN();
    } else if (!Usable(xv, tx) || !Usable(yv, ty)) {
      ++pts->non_positive;
      xs[i] = ys[i] = std::numeric_limits<double>::quiet_NaN();
    } else {
      xs[i] = xv;
      ys[i] = yv;
    }
  }
  *keep = DecimateMinMax(xs, ys, max_points);
  size_t usable = 0;
  for (size_t i = 0; i < n; ++i) usable += std::isfinite(xs[i]) ? 1 : 0;
  if (keep->size() < usable) pts->decimated_from = std::max(pts->decimated_from, usable);
  for (size_t i : *keep) {
    pts->ex.Add(xs[i]);
    pts->ey.Add(ys[i]);
    AddPointExtent(se, i, xs[i], ys[i], tx, ty, pts);
  }
}

// The points of every series, and the extent of them, the segments and the reference lines
// (bands are added later: they widen the x axis but do not count as data).
XYPoints CollectPoints(const PlotOptions& o, const std::vector<Series>& series) {
  const ScaleType tx = o.x.type, ty = o.y.type;
  XYPoints pts;
  pts.keep.resize(series.size());
  for (size_t s = 0; s < series.size(); ++s) {
    AddSeriesPoints(series[s], tx, ty, o.max_points, &pts.keep[s], &pts);
  }
  for (const auto& seg : o.segments) {
    if (Usable(seg.x0, tx) && Usable(seg.y0, ty) && Usable(seg.x1, tx) && Usable(seg.y1, ty)) {
      pts.ex.Add(seg.x0);
      pts.ex.Add(seg.x1);
      pts.ey.Add(seg.y0);
      pts.ey.Add(seg.y1);
    }
  }
  for (const auto& r : o.ref_lines) {
    if (Usable(r.at, r.vertical ? tx : ty)) (r.vertical ? pts.ex : pts.ey).Add(r.at);
  }
  return pts;
}

// The notes saying which points were left out or thinned.
void AddPointNotes(const XYPoints& pts, std::vector<std::string>* notes) {
  if (pts.non_finite > 0) {
    notes->push_back(PluralNote(pts.non_finite, "non-finite point(s) not shown."));
  }
  if (pts.non_positive > 0) {
    notes->push_back(
        PluralNote(pts.non_positive, "zero or negative value(s) not shown on the log axis."));
  }
  if (pts.decimated_from > 0) {
    notes->push_back("Large series decimated (" + std::to_string(pts.decimated_from) +
                     " points \xE2\x86\x92 min/max per bucket; peaks kept).");
  }
}

// Where everything goes: the frame (with the legend above the plot area), the ticks and the
// scales from data to pixels.
struct XYLayout {
  Frame f;
  AxisTicks xt, yt;
  Scale sx, sy;
  std::string legend_svg;
};

// `dx`, `dy`: the axes' domains from the data; `note_lines`: the lines of notes under the plot.
XYLayout LayoutXY(const PlotOptions& o, const std::vector<Series>& series,
                  const std::vector<SeriesStyle>& styles, std::pair<double, double> dx,
                  std::pair<double, double> dy, size_t note_lines) {
  std::vector<LegendEntry> legend;
  if (o.legend) {
    for (size_t s = 0; s < series.size(); ++s) {
      const Series& se = series[s];
      if (se.label.empty()) continue;
      legend.push_back(
          {se.label, styles[s].color, styles[s].dash, styles[s].marker, se.line, false});
    }
  }
  XYLayout l;
  l.yt = MakeTicks(o.y, dy.first, dy.second);
  // A plot with point labels keeps a line for the note on labels left out.
  bool point_labels = false;
  for (const Series& se : series) point_labels = point_labels || !se.point_labels.empty();
  LayoutFrame(o, l.yt, 0, note_lines + (point_labels ? 1 : 0), &l.f);
  l.legend_svg = LegendAbove(legend, &l.f);
  if (o.equal_aspect && o.x.type == ScaleType::kLinear && o.y.type == ScaleType::kLinear) {
    EqualAspect(l.f, &dx, &dy);
    l.yt = MakeTicks(o.y, dy.first, dy.second);
  }
  l.xt = MakeTicks(o.x, dx.first, dx.second);
  l.sx = Scale(o.x.type, dx.first, dx.second, l.f.px0(), l.f.px1());
  l.sy = Scale(o.y.type, dy.first, dy.second, l.f.py0(), l.f.py1());
  return l;
}

// Shaded bands, behind everything else; labels at the top of the plot area (a label that would
// overlap its neighbour's goes one row lower).
std::string BandsSvg(const std::vector<Band>& bands, const XYLayout& l, Occupancy* occupied) {
  if (bands.empty()) return "";
  const Frame& f = l.f;
  std::string body = "<g class=\"bands\">";
  for (const auto& b : bands) {
    double a = l.sx(b.x0), c = l.sx(b.x1);
    if (!std::isfinite(a) || !std::isfinite(c)) continue;
    if (a > c) std::swap(a, c);
    a = std::max(a, f.px0());
    c = std::min(c, f.px1());
    if (c < a) continue;
    body += "<rect x=\"" + N(a) + "\" y=\"" + N(f.py1()) + "\" width=\"" + N(std::max(c - a, 0.6)) +
            "\" height=\"" + N(f.py0() - f.py1()) + "\" fill=\"#cfe3f3\" fill-opacity=\"0.75\"/>";
    if (!b.label.empty()) {
      const double w = EstimateTextWidth(b.label, kBandCharWidth), mid = (a + c) / 2;
      double y = f.py1() + 10;
      for (int row = 0; row < 3 && occupied->Overlaps(mid - w / 2, y - 8, mid + w / 2, y + 1);
           ++row) {
        y += 10;
      }
      occupied->Add(mid - w / 2, y - 8, mid + w / 2, y + 1);
      body += "<text x=\"" + N(mid) + "\" y=\"" + N(y) +
              "\" text-anchor=\"middle\" font-size=\"9\" fill=\"" + kMuted + "\">" +
              EscapeText(b.label) + "</text>";
    }
  }
  return body + "</g>";
}

// The label of reference line `r` drawn at pixel `p`: next to its line, at the top (vertical)
// or the right (horizontal); a label that would overlap one placed before moves a row down
// (vertical) or to the other side of its line.
std::string RefLineLabelSvg(const RefLine& r, double p, const Frame& f, Occupancy* occupied) {
  const double w = EstimateTextWidth(r.label);
  if (r.vertical) {
    const bool right_half = p > (f.px0() + f.px1()) / 2;
    const double x0 = right_half ? p - 4 - w : p + 4;
    double y = f.py1() + 12;
    for (int row = 0; row < 6 && occupied->Overlaps(x0, y - 9, x0 + w, y + 2); ++row) y += 13;
    occupied->Add(x0, y - 9, x0 + w, y + 2);
    return "<text x=\"" + N(right_half ? p - 4 : p + 4) + "\" y=\"" + N(y) + "\" text-anchor=\"" +
           (right_half ? "end" : "start") + "\" fill=\"" + kMuted + "\">" + EscapeText(r.label) +
           "</text>";
  }
  const double x1 = f.px1() - 4;
  double y = p - 4;
  if (occupied->Overlaps(x1 - w, y - 9, x1, y + 2)) y = p + 13;
  occupied->Add(x1 - w, y - 9, x1, y + 2);
  return "<text x=\"" + N(x1) + "\" y=\"" + N(y) + "\" text-anchor=\"end\" fill=\"" + kMuted +
         "\">" + EscapeText(r.label) + "</text>";
}

std::string RefLinesSvg(const std::vector<RefLine>& ref_lines, const XYLayout& l,
                        Occupancy* occupied) {
  const Frame& f = l.f;
  std::string body;
  for (const auto& r : ref_lines) {
    const double p = r.vertical ? l.sx(r.at) : l.sy(r.at);
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
    if (!r.label.empty()) body += RefLineLabelSvg(r, p, f, occupied);
    body += "</g>";
  }
  return body;
}

std::string SegmentsSvg(const std::vector<Segment>& segments, const XYLayout& l) {
  if (segments.empty()) return "";
  std::string grey, coloured;
  for (const auto& seg : segments) {
    const double a = l.sx(seg.x0), b = l.sy(seg.y0), c = l.sx(seg.x1), d = l.sy(seg.y1);
    if (!std::isfinite(a) || !std::isfinite(b) || !std::isfinite(c) || !std::isfinite(d)) {
      continue;
    }
    const std::string p = "M" + N(a) + " " + N(b) + "L" + N(c) + " " + N(d);
    if (seg.color < 0) {
      grey += p;
    } else {
      coloured += "<path d=\"" + p + "\" stroke=\"" + PaletteColor(static_cast<size_t>(seg.color)) +
                  "\" stroke-width=\"1.2\"/>";
    }
  }
  std::string body = "<g class=\"segments\" fill=\"none\">";
  if (!grey.empty()) body += "<path d=\"" + grey + "\" stroke=\"#8a949e\" stroke-width=\"1\"/>";
  return body + coloured + "</g>";
}

// One series' points to draw (`keep`), how it is drawn, and where.
struct SeriesDrawing {
  const Series& se;
  const std::vector<size_t>& keep;
  const SeriesStyle& style;
  const XYLayout& l;
};

// The 1σ ellipses, under the markers (linear axes only).
std::string EllipsesSvg(const SeriesDrawing& sd) {
  const Series& se = sd.se;
  std::string d;
  for (size_t i : sd.keep) {
    if (i >= se.ellipses.size()) continue;
    const Cov2& c = se.ellipses[i];
    if (!std::isfinite(c[0]) || !std::isfinite(c[1]) || !std::isfinite(c[2])) continue;
    const double tr = (c[0] + c[2]) / 2,
                 disc = std::sqrt(std::max(0.0, (c[0] - c[2]) * (c[0] - c[2]) / 4 + c[1] * c[1]));
    const double l1 = std::max(0.0, tr + disc), l2 = std::max(0.0, tr - disc);
    const double th = 0.5 * std::atan2(2 * c[1], c[0] - c[2]);
    const double r1 = std::sqrt(l1), r2 = std::sqrt(l2);
    const double ct = std::cos(th), st = std::sin(th);
    for (int k = 0; k <= 36; ++k) {
      const double t = 2 * kPi * k / 36;
      const double u = r1 * std::cos(t), v = r2 * std::sin(t);
      const double px = sd.l.sx(se.x[i] + ct * u - st * v), py = sd.l.sy(se.y[i] + st * u + ct * v);
      d += (k == 0 ? "M" : "L") + N(px) + " " + N(py);
    }
    d += "Z";
  }
  if (d.empty()) return "";
  const std::string& color = sd.style.color;
  return "<path class=\"ellipses\" d=\"" + d + "\" fill=\"" + color +
         "\" fill-opacity=\"0.12\" stroke=\"" + color + "\" stroke-width=\"1\"/>";
}

std::string ErrorBarsSvg(const SeriesDrawing& sd) {
  const Series& se = sd.se;
  const XYLayout& l = sd.l;
  std::string d;
  for (size_t i : sd.keep) {
    const double px = l.sx(se.x[i]), py = l.sy(se.y[i]);
    if (i < se.y_err.size() && std::isfinite(se.y_err[i])) {
      const double e = std::fabs(se.y_err[i]);
      double a = l.sy(se.y[i] - e), b = l.sy(se.y[i] + e);
      if (!std::isfinite(a)) a = l.f.py0();
      if (std::isfinite(b)) {
        d += "M" + N(px) + " " + N(a) + "V" + N(b) + "M" + N(px - 3) + " " + N(a) + "h6M" +
             N(px - 3) + " " + N(b) + "h6";
      }
    }
    if (i < se.x_err.size() && std::isfinite(se.x_err[i])) {
      const double e = std::fabs(se.x_err[i]);
      double a = l.sx(se.x[i] - e), b = l.sx(se.x[i] + e);
      if (!std::isfinite(a)) a = l.f.px0();
      if (std::isfinite(b)) {
        d += "M" + N(a) + " " + N(py) + "H" + N(b) + "M" + N(a) + " " + N(py - 3) + "v6M" + N(b) +
             " " + N(py - 3) + "v6";
      }
    }
  }
  if (d.empty()) return "";
  return "<path class=\"error-bars\" d=\"" + d + "\" stroke=\"" + sd.style.color +
         "\" stroke-width=\"1\" fill=\"none\"/>";
}

std::string LineSvg(const SeriesDrawing& sd) {
  std::string d;
  for (size_t k = 0; k < sd.keep.size(); ++k) {
    const size_t i = sd.keep[k];
    d += (k == 0 ? "M" : "L") + N(sd.l.sx(sd.se.x[i])) + " " + N(sd.l.sy(sd.se.y[i]));
  }
  const std::string& dash = sd.style.dash;
  return "<path class=\"line\" d=\"" + d + "\" fill=\"none\" stroke=\"" + sd.style.color +
         "\" stroke-width=\"" + N(sd.se.line_width) + "\" stroke-linejoin=\"round\"" +
         (dash.empty() ? std::string() : " stroke-dasharray=\"" + dash + "\"") + "/>";
}

// Markers (one path for crosses, keeps the SVG small).
std::string MarkersSvg(const SeriesDrawing& sd) {
  const Marker m = sd.style.marker == Marker::kNone ? Marker::kCircle : sd.style.marker;
  const std::string& color = sd.style.color;
  std::string d;
  for (size_t i : sd.keep) {
    const double px = sd.l.sx(sd.se.x[i]), py = sd.l.sy(sd.se.y[i]);
    if (m == Marker::kCross) {
      d += "M" + N(px - 3.2) + " " + N(py - 3.2) + "l6.4 6.4m-6.4 0l6.4-6.4";
    } else {
      d += MarkerSvg(m, px, py, color);
    }
  }
  if (m == Marker::kCross) {
    return "<path class=\"markers\" d=\"" + d + "\" stroke=\"" + color +
           "\" stroke-width=\"1.6\" fill=\"none\"/>";
  }
  return "<g class=\"markers\">" + d + "</g>";
}

// A point label's anchor: the labelled point (pixels) and its text.
struct LabelSpot {
  double x, y;
  std::string text;
};

// The labelled points of a series: the labels of points drawn on the same spot are joined
// ("s1, s4"). Every labelled point is marked occupied.
std::vector<LabelSpot> LabelSpots(const SeriesDrawing& sd, Occupancy* occupied) {
  const Series& se = sd.se;
  std::vector<LabelSpot> spots;
  for (size_t i : sd.keep) {
    if (i >= se.point_labels.size() || se.point_labels[i].empty()) continue;
    const double px = sd.l.sx(se.x[i]), py = sd.l.sy(se.y[i]);
    if (!std::isfinite(px) || !std::isfinite(py)) continue;
    occupied->Add(px - 3.5, py - 3.5, px + 3.5, py + 3.5);
    bool joined = false;
    for (LabelSpot& sp : spots) {
      if (std::fabs(sp.x - px) < 3 && std::fabs(sp.y - py) < 3) {
        sp.text += ", " + Truncate(se.point_labels[i], 16);
        joined = true;
        break;
      }
    }
    if (!joined) spots.push_back({px, py, Truncate(se.point_labels[i], 16)});
  }
  return spots;
}

// The label of `sp` at the first of several places around its point where it stays inside the
// plot area and overlaps nothing placed before; empty (nothing occupied) when there is none.
std::string PlaceLabel(const LabelSpot& sp, const Frame& f, Occupancy* occupied) {
  const std::string text = Truncate(sp.text, 40);
  const double w = EstimateTextWidth(text, kLabelCharWidth), h = 10;
  // Baseline-left corners of the candidate places: NE, SE, NW, SW, E, W, N, S, then the same
  // farther out.
  for (double r : {1.0, 2.2}) {
    const double c[8][2] = {{5 * r, -5 * r},         {5 * r, 5 * r + 8}, {-5 * r - w, -5 * r},
                            {-5 * r - w, 5 * r + 8}, {7 * r, 3.5},       {-7 * r - w, 3.5},
                            {-w / 2, -7 * r},        {-w / 2, 7 * r + 8}};
    for (const auto& d : c) {
      const double x = sp.x + d[0], y = sp.y + d[1];
      if (x < f.px0() || x + w > f.px1() || y - h + 2 < f.py1() || y + 2 > f.py0()) continue;
      if (occupied->Overlaps(x, y - h + 2, x + w, y + 2)) continue;
      occupied->Add(x, y - h + 2, x + w, y + 2);
      return "<text x=\"" + N(x) + "\" y=\"" + N(y) + "\">" + EscapeText(text) + "</text>";
    }
  }
  return "";
}

// Point labels: each goes to the first free place around its point (no label, labelled point
// or reference-line label placed before it there); one with no free place is left out and
// counted in *left_out.
std::string PointLabelsSvg(const SeriesDrawing& sd, Occupancy* occupied, size_t* left_out) {
  std::string body =
      "<g class=\"point-labels\" font-size=\"9.5\" fill=\"" + std::string(kMuted) + "\">";
  for (const LabelSpot& sp : LabelSpots(sd, occupied)) {
    const std::string label = PlaceLabel(sp, sd.l.f, occupied);
    if (label.empty()) ++*left_out;
    body += label;
  }
  return body + "</g>";
}

// Series number `s`: ellipses, error bars, line, markers and point labels, back to front.
std::string SeriesSvg(const SeriesDrawing& sd, size_t s, ScaleType tx, ScaleType ty,
                      Occupancy* occupied, size_t* labels_left_out) {
  const Series& se = sd.se;
  std::string body = "<g class=\"series series-" + std::to_string(s) + "\">";
  if (!se.ellipses.empty() && tx == ScaleType::kLinear && ty == ScaleType::kLinear) {
    body += EllipsesSvg(sd);
  }
  if (!se.y_err.empty() || !se.x_err.empty()) body += ErrorBarsSvg(sd);
  if (se.line && sd.keep.size() >= 2) body += LineSvg(sd);
  if (se.marker != Marker::kNone || (!se.line && !sd.keep.empty()) || sd.keep.size() == 1) {
    body += MarkersSvg(sd);
  }
  if (!se.point_labels.empty()) body += PointLabelsSvg(sd, occupied, labels_left_out);
  return body + "</g>";
}

}  // namespace

std::string RenderXYPlot(const PlotOptions& o, const std::vector<Series>& series) {
  std::vector<std::string> notes = o.notes;
  const ScaleType tx = o.x.type, ty = o.y.type;

  XYPoints pts = CollectPoints(o, series);
  AddPointNotes(pts, &notes);
  const bool empty = pts.ex.empty();
  if (empty) notes.push_back("No data to plot.");
  // The x axis covers every band (a static interval far from the plotted points stays visible).
  for (const auto& b : o.bands) {
    if (Usable(b.x0, tx) && Usable(b.x1, tx)) {
      pts.ex.Add(b.x0);
      pts.ex.Add(b.x1);
    }
  }

  std::vector<SeriesStyle> styles;
  for (size_t s = 0; s < series.size(); ++s) styles.push_back(StyleOf(series[s], s));
  const XYLayout l =
      LayoutXY(o, series, styles, AxisDomain(o.x, pts.ex), AxisDomain(o.y, pts.ey), notes.size());

  // Text placed inside the plot area (band, reference-line and point labels): each avoids what
  // was placed before it.
  Occupancy occupied;
  std::string body = BandsSvg(o.bands, l, &occupied);
  body += RefLinesSvg(o.ref_lines, l, &occupied);
  body += SegmentsSvg(o.segments, l);
  size_t labels_left_out = 0;
  for (size_t s = 0; s < series.size(); ++s) {
    const SeriesDrawing sd{series[s], pts.keep[s], styles[s], l};
    body += SeriesSvg(sd, s, tx, ty, &occupied, &labels_left_out);
  }
  if (labels_left_out > 0) {
    notes.push_back(
        PluralNote(labels_left_out, "point label(s) left out where they would overlap."));
  }

  const Frame& f = l.f;
  const std::string clip = ClipId(o, body);
  std::string out = SvgOpen(o, "");
  out += "<defs><clipPath id=\"" + clip + "\"><rect x=\"" + N(f.px0() - 4) + "\" y=\"" +
         N(f.py1() - 4) + "\" width=\"" + N(f.px1() - f.px0() + 8) + "\" height=\"" +
         N(f.py0() - f.py1() + 8) + "\"/></clipPath></defs>";
  out += TitleSvg(o, f);
  out += l.legend_svg;
  out += AxesSvg(o, f, l.sx, l.sy, l.xt, l.yt, true);
  out += "<g class=\"data\" clip-path=\"url(#" + clip + ")\">" + body + "</g>";
  if (empty) out += NoDataSvg(f);
  out += NotesSvg(notes, f);
  out += "</svg>";
  return out;
}

}  // namespace calibd::web
