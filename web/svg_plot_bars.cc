// Bar charts and histograms (web/svg_plot.h), on the frame of svg_plot_parts.h.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "web/html.h"
#include "web/svg_plot.h"
#include "web/svg_plot_parts.h"

namespace calibd::web {

using namespace svg_parts;  // NOLINT(build/namespaces): this file draws with the parts

namespace {

// The extent of the bars (with their error bars) and of the horizontal reference lines, and
// what is left out of it.
struct BarValues {
  Extent ey;
  size_t skipped = 0;     // zero or negative values on a log axis
  size_t non_finite = 0;  // ±Inf (NaN means "no bar" and is not counted)
};

BarValues CollectBarValues(const PlotOptions& o, const std::vector<std::string>& categories,
                           const std::vector<BarSeries>& series) {
  const ScaleType ty = o.y.type;
  BarValues b;
  for (const auto& s : series) {
    for (size_t i = 0; i < s.values.size() && i < categories.size(); ++i) {
      const double v = s.values[i];
      if (!std::isfinite(v)) {
        if (!std::isnan(v)) ++b.non_finite;
        continue;
      }
      if (!Usable(v, ty)) {
        ++b.skipped;
        continue;
      }
      b.ey.Add(v);
      if (i < s.errors.size() && std::isfinite(s.errors[i])) {
        const double e = std::fabs(s.errors[i]);
        b.ey.Add(v + e);
        if (Usable(v - e, ty)) b.ey.Add(v - e);
      }
    }
  }
  for (const auto& r : o.ref_lines) {
    if (!r.vertical && Usable(r.at, ty)) b.ey.Add(r.at);
  }
  return b;
}

// Where the categories go along x: the width of each one's band, and whether their labels are
// rotated (and only every label_every-th shown) because they do not fit side by side.
struct CategoryAxis {
  double band = 0;  // pixels per category
  bool rotate = false;
  size_t label_every = 1;
  double extra_bottom = 0;  // room below the x axis for rotated labels
};

// Lays out the frame of a bar chart (margins, then the category axis that depends on them).
CategoryAxis LayoutBars(const PlotOptions& o, const std::vector<std::string>& categories,
                        const AxisTicks& yt, size_t notes, Frame* f) {
  const size_t nc = categories.size();
  double max_label = 0;
  for (const auto& c : categories)
    max_label = std::max(max_label, EstimateTextWidth(Truncate(c, 24)));
  LayoutFrame(o, yt, 0, notes, f);
  const double plot_w = f->px1() - f->px0();
  CategoryAxis axis;
  axis.band = nc > 0 ? plot_w / static_cast<double>(nc) : plot_w;
  axis.rotate = nc > 0 && max_label + 6 > axis.band;
  if (axis.rotate && axis.band < 12) {
    axis.label_every = static_cast<size_t>(std::ceil(12 / axis.band));
  }
  axis.extra_bottom = axis.rotate ? std::min(max_label * 0.7, 90.0) : 0;
  LayoutFrame(o, yt, axis.extra_bottom, notes, f);
  return axis;
}

// The bars of every series, grouped by category, with their error bars.
std::string BarsSvg(const std::vector<BarSeries>& series, size_t categories, ScaleType ty,
                    const CategoryAxis& axis, const Frame& f, const Scale& sy, double base) {
  std::string body;
  const double group = axis.band * 0.78;
  const double bar_w = series.empty() ? group : group / static_cast<double>(series.size());
  for (size_t s = 0; s < series.size(); ++s) {
    const std::string color = PaletteColor(ColorIndex(series[s].color, s));
    std::string bars, errs;
    for (size_t i = 0; i < categories && i < series[s].values.size(); ++i) {
      const double v = series[s].values[i];
      if (!Usable(v, ty)) continue;
      const double x = f.px0() + axis.band * (static_cast<double>(i) + 0.11) + bar_w * s;
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
  return body;
}

// Horizontal reference lines (e.g. the noise level), labelled at the right end.
std::string BarRefLinesSvg(const std::vector<RefLine>& ref_lines, ScaleType ty, const Frame& f,
                           const Scale& sy) {
  std::string body;
  for (const auto& r : ref_lines) {
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
  return body;
}

std::string CategoryLabelsSvg(const std::vector<std::string>& categories, const CategoryAxis& axis,
                              const Frame& f) {
  std::string labels = "<g class=\"category-labels\">";
  for (size_t i = 0; i < categories.size(); i += axis.label_every) {
    const double cx = f.px0() + axis.band * (static_cast<double>(i) + 0.5);
    const std::string text = EscapeText(Truncate(categories[i], 24));
    if (axis.rotate) {
      const double y = f.py0() + 10;
      labels += "<text x=\"" + N(cx) + "\" y=\"" + N(y) + "\" text-anchor=\"end\" transform=\"" +
                "rotate(-40 " + N(cx) + " " + N(y) + ")\">" + text + "</text>";
    } else {
      labels += "<text x=\"" + N(cx) + "\" y=\"" + N(f.py0() + 16) + "\" text-anchor=\"middle\">" +
                text + "</text>";
    }
  }
  labels += "</g>";
  return labels;
}

// Legend of boxes, one per labelled series (bars, histograms).
template <typename Item>
std::vector<LegendEntry> BoxLegend(const std::vector<Item>& items) {
  std::vector<LegendEntry> legend;
  for (size_t s = 0; s < items.size(); ++s) {
    if (items[s].label.empty()) continue;
    legend.push_back({items[s].label, PaletteColor(ColorIndex(items[s].color, s)), "",
                      Marker::kNone, false, true});
  }
  return legend;
}

}  // namespace

std::string RenderBarChart(const PlotOptions& o, const std::vector<std::string>& categories,
                           const std::vector<BarSeries>& series) {
  std::vector<std::string> notes = o.notes;
  const ScaleType ty = o.y.type;
  BarValues values = CollectBarValues(o, categories, series);
  Extent& ey = values.ey;
  if (values.non_finite > 0) {
    notes.push_back(PluralNote(values.non_finite, "non-finite value(s) not shown."));
  }
  if (values.skipped > 0) {
    notes.push_back(
        PluralNote(values.skipped, "zero or negative value(s) not shown on the log axis."));
  }
  const bool empty = categories.empty() || ey.empty();
  if (empty) notes.push_back("No data to plot.");
  AxisOptions yopt = o.y;
  if (ty == ScaleType::kLinear) yopt.include_zero = true;
  // Log bars start at the axis bottom: keep the smallest bar visibly tall.
  if (ty == ScaleType::kLog10 && !ey.empty()) ey.Add(ey.lo / 3);
  const auto dy = AxisDomain(yopt, ey);

  std::vector<LegendEntry> legend;
  if (o.legend && series.size() > 1) legend = BoxLegend(series);

  Frame f;
  const AxisTicks yt = MakeTicks(yopt, dy.first, dy.second);
  const CategoryAxis axis = LayoutBars(o, categories, yt, notes.size(), &f);
  const std::string legend_svg = LegendAbove(legend, &f);
  const Scale sy(ty, dy.first, dy.second, f.py0(), f.py1());
  const Scale sx(ScaleType::kLinear, 0, 1, f.px0(), f.px1());

  const double base = ty == ScaleType::kLog10 ? f.py0() : sy(std::max(0.0, dy.first));
  const std::string body = BarsSvg(series, categories.size(), ty, axis, f, sy, base) +
                           BarRefLinesSvg(o.ref_lines, ty, f, sy);

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
  out += CategoryLabelsSvg(categories, axis, f);
  if (!x_title.empty()) {
    out += "<text class=\"axis-title axis-title-x\" x=\"" + N((f.px0() + f.px1()) / 2) + "\" y=\"" +
           N(f.py0() + 32 + axis.extra_bottom) + "\" text-anchor=\"middle\" font-size=\"11.5\">" +
           EscapeText(x_title) + "</text>";
  }
  if (empty) out += NoDataSvg(f);
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
  if (o.legend) legend = BoxLegend(histograms);
  Frame f;
  const AxisTicks yt = MakeTicks(yopt, dy.first, dy.second);
  LayoutFrame(o, yt, 0, notes.size(), &f);
  const std::string legend_svg = LegendAbove(legend, &f);
  const AxisTicks xt = MakeTicks(xopt, dx.first, dx.second);
  const Scale sx(ScaleType::kLinear, dx.first, dx.second, f.px0(), f.px1());
  const Scale sy(ScaleType::kLinear, dy.first, dy.second, f.py0(), f.py1());

  std::string body;
  for (size_t s = 0; s < histograms.size(); ++s) {
    const Histogram& h = histograms[s];
    if (h.edges.size() != h.counts.size() + 1 || h.counts.empty()) continue;
    const std::string color = PaletteColor(ColorIndex(h.color, s));
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
  if (!any) out += NoDataSvg(f);
  out += NotesSvg(notes, f);
  out += "</svg>";
  return out;
}

}  // namespace calibd::web
