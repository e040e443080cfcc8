// The pca report section, key figures and drift (web/reports.h).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <exception>
#include <functional>
#include <limits>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "web/html.h"
#include "web/report_common.h"
#include "web/reports.h"
#include "web/svg_plot.h"

namespace calibd::web::internal {

PcaFigures ComputePcaFigures(const json& result) {
  PcaFigures f;
  std::map<std::string, double> scale_by_name;
  std::vector<double> scales;
  if (const json* sensors = Array(Get(Get(result, "parameters"), "sensors"))) {
    for (const auto& s : *sensors) {
      scales.push_back(Num(Get(s, "scale")));
      scale_by_name[Str(Get(s, "name"))] = scales.back();
    }
  }
  if (const json* us = Array(Get(Get(result, "uncertainty"), "sensors"))) {
    size_t i = 0;
    for (const auto& u : *us) {
      const double sd = Num(Get(u, "scale_std"));
      double scale = i < scales.size() ? scales[i] : kNaN;
      const auto it = scale_by_name.find(Str(Get(u, "name")));
      if (it != scale_by_name.end()) scale = it->second;
      ++i;
      if (!std::isfinite(sd)) continue;
      if (!(f.worst_scale_std >= sd)) f.worst_scale_std = sd;
      if (std::isfinite(scale) && scale != 0) {
        const double rel = sd / std::fabs(scale);
        if (!(f.worst_rel_scale_std >= rel)) f.worst_rel_scale_std = rel;
      }
    }
  }
  f.rank_gap = Num(Get(Get(result, "diagnostics"), "rank_gap"));
  return f;
}

struct PcaSensor {
  std::string name;
  double scale = kNaN, scale_std = kNaN, axis_std = kNaN, bias = kNaN, bias_std = kNaN;
  double residual_rms = kNaN;
  std::vector<double> axis;     // unit, d components
  std::vector<double> nominal;  // unit nominal axis, d components (empty when none)
};

std::vector<PcaSensor> ReadPcaSensors(const json& result, const json& config, size_t d) {
  std::vector<PcaSensor> out;
  const json* sensors = Array(Get(Get(result, "parameters"), "sensors"));
  if (sensors == nullptr) return out;
  for (const auto& s : *sensors) {
    PcaSensor p;
    p.name = Str(Get(s, "name"));
    p.scale = Num(Get(s, "scale"));
    p.bias = Num(Get(s, "bias"));
    p.axis = NumArray(Get(s, "axis"));
    if (p.axis.empty() || !HasNumbers(p.axis)) p.axis = Unit(NumArray(Get(s, "sensitivity")));
    if (!std::isfinite(p.scale)) {
      const auto sens = NumArray(Get(s, "sensitivity"));
      if (HasNumbers(sens)) {
        double n = 0;
        for (double x : sens) n += x * x;
        p.scale = std::sqrt(n);
      }
    }
    out.push_back(std::move(p));
  }
  std::map<std::string, size_t> by_name;
  for (size_t i = 0; i < out.size(); ++i) by_name[out[i].name] = i;
  if (const json* us = Array(Get(Get(result, "uncertainty"), "sensors"))) {
    for (size_t i = 0; i < us->size(); ++i) {
      const json& u = (*us)[i];
      const auto it = by_name.find(Str(Get(u, "name")));
      const size_t k = it != by_name.end() ? it->second : i;
      if (k >= out.size()) continue;
      out[k].scale_std = Num(Get(u, "scale_std"));
      out[k].axis_std = Num(Get(u, "axis_std_rad"));
      out[k].bias_std = Num(Get(u, "bias_std"));
    }
  }
  const auto rms = NumArray(Array(Get(Get(result, "diagnostics"), "residual_rms")));
  for (size_t i = 0; i < out.size() && i < rms.size(); ++i) out[i].residual_rms = rms[i];
  // Nominal axes: config.nominal, m rows of d numbers, matched by index.
  if (const json* nominal = Array(Get(config, "nominal"))) {
    for (size_t i = 0; i < out.size() && i < nominal->size(); ++i) {
      auto row = NumArray(&(*nominal)[i]);
      if (row.size() == d && HasNumbers(row)) out[i].nominal = Unit(row);
    }
  }
  return out;
}

std::string PcaParametersTable(const std::vector<PcaSensor>& sensors, size_t d, bool has_bias) {
  bool any_nominal = false;
  for (const auto& s : sensors) any_nominal = any_nominal || !s.nominal.empty();
  static const char* kAxisNames[] = {"x", "y", "z"};
  // Every head names its unit (on further lines), the axis is one column and σ(scale) shares one
  // with its relative value, so the table fits 1280 px even with biases and nominal axes.
  std::string axis_names;
  for (size_t k = 0; k < d; ++k) {
    axis_names += (k ? ", " : "") + (k < 3 ? std::string(kAxisNames[k]) : std::to_string(k + 1));
  }
  std::string head =
      "<tr><th>sensor</th><th class=\"num\">scale<br>(reading per<br>field "
      "unit)</th><th class=\"num\">" +
      std::string(kSigma) + "(scale)<br>(same unit,<br>relative)</th>" + "<th class=\"num\">axis " +
      axis_names + "<br>(unitless)</th>";
  head += "<th class=\"num\">" + std::string(kSigma) + "(axis)<br>(mrad)</th>";
  if (any_nominal) head += "<th class=\"num\">angle to<br>nominal<br>(mrad)</th>";
  if (has_bias) {
    head += "<th class=\"num\">bias<br>(reading<br>units)</th><th class=\"num\">" +
            std::string(kSigma) + "(bias)<br>(reading<br>units)</th>";
  }
  head += "<th class=\"num\">residual<br>RMS (reading<br>units)</th></tr>";
  std::string rows;
  for (const auto& s : sensors) {
    rows +=
        "<tr><td class=\"name\">" + E(s.name) + "</td>" + NumCell(s.scale, 6) +
        NumCell(FormatSig(s.scale_std, 3) + " (" +
                Percent(std::isfinite(s.scale) && s.scale != 0 ? s.scale_std / std::fabs(s.scale)
                                                               : kNaN) +
                ")");
    std::string axis;
    for (size_t k = 0; k < d; ++k) {
      axis += (k ? "&nbsp; " : "") + FormatFixed(k < s.axis.size() ? s.axis[k] : kNaN, 5);
    }
    rows += NumCell(axis);
    rows += NumCell(s.axis_std * 1e3, 3);
    if (any_nominal) {
      rows += NumCell(s.nominal.empty() ? kNaN : AngleBetween(s.axis, s.nominal) * 1e3, 3);
    }
    if (has_bias) rows += NumCell(s.bias, 4) + NumCell(s.bias_std, 3);
    rows += NumCell(s.residual_rms, 3) + "</tr>";
  }
  return "<div class=\"table-wrap\"><table class=\"table-pca-parameters\"><thead>" + head +
         "</thead><tbody>" + rows + "</tbody></table></div>";
}

std::string SingularValuePlot(const json& diag, size_t d) {
  const auto sv = NumArray(Get(diag, "singular_values"));
  const double gap = Num(Get(diag, "rank_gap"));
  Series signal, noise, all;
  all.line = true;
  all.color = 6;
  all.line_width = 0.8;
  signal.label = "signal (1\xE2\x80\xA6" + std::to_string(d) + ")";
  signal.line = false;
  signal.marker = Marker::kCircle;
  signal.color = 0;
  noise.label = "noise (" + std::to_string(d + 1) + "\xE2\x80\xA6)";
  noise.line = false;
  noise.marker = Marker::kOpenCircle;
  noise.color = 1;
  for (size_t i = 0; i < sv.size(); ++i) {
    const double x = static_cast<double>(i + 1);
    all.x.push_back(x);
    all.y.push_back(sv[i]);
    (i < d ? signal : noise).x.push_back(x);
    (i < d ? signal : noise).y.push_back(sv[i]);
  }
  PlotOptions o;
  o.name = "singular-values";
  o.title = "Singular value spectrum";
  o.x.title = "index i";
  o.y.title = "singular value (reading units)";
  o.y.type = ScaleType::kLog10;
  o.x.min = 0.5;
  o.x.max = static_cast<double>(std::max<size_t>(sv.size(), d + 1)) + 0.5;
  o.x.target_ticks = std::min<int>(10, static_cast<int>(std::max<size_t>(sv.size(), 2)));
  o.description = "Singular values of the reading matrix on a log scale; the gap between index " +
                  std::to_string(d) + " and " + std::to_string(d + 1) +
                  " separates the field from the noise.";
  o.ref_lines.push_back({true, static_cast<double>(d) + 0.5,
                         "gap " + std::string(kSigma) + std::to_string(d) + "/" + kSigma +
                             std::to_string(d + 1) + " = " + FormatSig(gap, 3),
                         true});
  return RenderXYPlot(o, {all, signal, noise});
}

std::string MagnitudeErrorPlot(const json& diag, bool magnitude_known) {
  const auto me = NumArray(Get(diag, "magnitude_error"));
  Series s;
  s.label = "";
  s.line = me.size() > 150;
  s.marker = me.size() > 150 ? Marker::kNone : Marker::kCircle;
  for (size_t i = 0; i < me.size(); ++i) {
    s.x.push_back(static_cast<double>(i + 1));
    s.y.push_back(me[i]);
  }
  PlotOptions o;
  o.name = "magnitude-error";
  o.title = "Field magnitude error per position";
  o.x.title = "position j";
  o.y.title =
      magnitude_known ? "magnitude error (field units)" : "magnitude error (relative units)";
  o.ref_lines.push_back({false, 0.0, "", false});
  return RenderXYPlot(o, {s});
}

std::string ResidualRmsPlot(const std::vector<PcaSensor>& sensors, double noise_std) {
  std::vector<std::string> names;
  BarSeries b;
  b.label = "residual RMS";
  for (const auto& s : sensors) {
    names.push_back(s.name);
    b.values.push_back(s.residual_rms);
  }
  PlotOptions o;
  o.name = "residual-rms";
  o.title = "Residual RMS per sensor";
  o.x.title = "sensor";
  o.y.title = "residual RMS (reading units)";
  o.legend = false;
  if (std::isfinite(noise_std) && noise_std > 0) {
    o.ref_lines.push_back({false, noise_std, "noise \xCF\x83 = " + FormatSig(noise_std, 3), true});
  }
  return RenderBarChart(o, names, {b});
}

// Sensitivity axes projected onto two coordinates (a, b: 0=x, 1=y, 2=z), with nominal axes when
// known (deviations magnified by `k`).
std::string AxesPlot(const std::vector<PcaSensor>& sensors, int a, int b, double k,
                     bool have_nominal) {
  static const char* kName[] = {"x", "y", "z"};
  const std::string plane = std::string(kName[a]) + kName[b];
  Series circle;
  circle.line = true;
  circle.color = 6;
  circle.line_width = 0.6;
  for (int i = 0; i <= 72; ++i) {
    circle.x.push_back(std::cos(2 * kPi * i / 72));
    circle.y.push_back(std::sin(2 * kPi * i / 72));
  }
  Series nominal, est;
  nominal.label = "nominal";
  nominal.line = false;
  nominal.marker = Marker::kOpenCircle;
  nominal.color = 6;
  est.label = have_nominal && k > 1 ? "estimated (deviation " + FactorText(k) + ")" : "estimated";
  est.line = false;
  est.marker = Marker::kCross;
  est.color = 1;
  PlotOptions o;
  o.name = "axes-" + plane;
  o.title = "Sensitivity axes, " + plane + " projection";
  o.x.title = std::string(kName[a]) + " component of the unit axis";
  o.y.title = std::string(kName[b]) + " component";
  o.x.min = o.y.min = -1.25;
  o.x.max = o.y.max = 1.25;
  o.equal_aspect = true;
  o.height = 520;
  const bool labels = sensors.size() <= 16;
  for (const auto& s : sensors) {
    if (s.axis.size() <= static_cast<size_t>(std::max(a, b))) continue;
    const double ea = s.axis[a], eb = s.axis[b];
    if (have_nominal && s.nominal.size() == s.axis.size()) {
      const double na = s.nominal[a], nb = s.nominal[b];
      nominal.x.push_back(na);
      nominal.y.push_back(nb);
      const double pa = na + k * (ea - na), pb = nb + k * (eb - nb);
      est.x.push_back(pa);
      est.y.push_back(pb);
      o.segments.push_back({0, 0, na, nb, -1});
      o.segments.push_back({na, nb, pa, pb, 1});
    } else {
      est.x.push_back(ea);
      est.y.push_back(eb);
      o.segments.push_back({0, 0, ea, eb, 1});
    }
    if (labels) est.point_labels.push_back(s.name);
  }
  if (have_nominal && k > 1) {
    o.notes.push_back("Deviations from the nominal axes magnified " + FactorText(k) + ".");
  }
  std::vector<Series> series{circle};
  if (have_nominal) series.push_back(nominal);
  series.push_back(est);
  return RenderXYPlot(o, series);
}

std::string PcaReport(const JobView& view) {
  const json& result = view.job.result;
  const json* params = Get(result, "parameters");
  const json* diag = Get(result, "diagnostics");
  double dd = Num(Get(params, "dimension"));
  if (!std::isfinite(dd)) dd = Num(Get(view.config, "dimension"));
  const size_t d = std::isfinite(dd) && dd >= 1 && dd <= 10 ? static_cast<size_t>(dd) : 3;
  const auto sensors = ReadPcaSensors(result, view.config, d);
  std::string out;

  out += Guard("Parameters", [&] {
    std::string s;
    const json* mk = Get(params, "magnitude_known");
    const bool known = mk != nullptr && mk->is_boolean() && mk->get<bool>();
    s += "<dl class=\"kv\"><dt>dimension d</dt><dd>" + std::to_string(d) + "</dd>";
    s += "<dt>field magnitude c</dt><dd>" +
         (known ? E(ScalarText(Get(params, "magnitude"))) + " (known)"
                : std::string("unknown: scale factors are relative (the paper's Remark 2)")) +
         "</dd>";
    const std::string frame = Str(Get(params, "frame"));
    s += "<dt>frame</dt><dd>" +
         (frame == "nominal"     ? std::string("nominal body frame (orthogonal Procrustes fit)")
          : frame == "canonical" ? std::string("canonical frame of the paper's Eq. 19")
          : frame.empty()        ? std::string(kDash)
                                 : E(frame)) +
         "</dd>";
    s += "<dt>sensors m</dt><dd>" + std::to_string(sensors.size()) + "</dd>";
    s += "<dt>positions n</dt><dd>" + E(ScalarText(Get(diag, "positions"))) + " (minimum " +
         E(ScalarText(Get(diag, "min_positions"))) + ")</dd></dl>";
    bool has_bias = false;
    for (const auto& p : sensors) {
      has_bias = has_bias || (std::isfinite(p.bias) && p.bias != 0) ||
                 (std::isfinite(p.bias_std) && p.bias_std > 0);
    }
    if (sensors.empty()) {
      s += NotAvailable("Sensor parameters");
    } else {
      s += PcaParametersTable(sensors, d, has_bias);
      s += "<p class=\"muted small\">Uncertainties are one standard deviation from the Fisher "
           "information at the estimate. Scale factors and angles do not depend on the frame.</p>";
    }
    return Section("parameters", "Parameters", s);
  });

  out += Guard("Plots", [&] {
    std::string figs;
    figs += Figure(SingularValuePlot(diag ? *diag : json(), d),
                   "A clear drop after index d means the readings determine the d-dimensional "
                   "sensitivities.");
    const json* mk = Get(params, "magnitude_known");
    figs += Figure(MagnitudeErrorPlot(diag ? *diag : json(),
                                      mk != nullptr && mk->is_boolean() && mk->get<bool>()),
                   "Should scatter around zero at the noise level; outliers are bad positions.");
    figs += Figure(ResidualRmsPlot(sensors, Num(Get(diag, "noise_std"))),
                   "Should be near each sensor's noise level.");
    bool have_nominal = false;
    double max_dev = 0;
    for (const auto& s : sensors) {
      if (s.nominal.size() == s.axis.size() && !s.nominal.empty()) {
        have_nominal = true;
        double dev = 0;
        for (size_t i = 0; i < s.axis.size(); ++i) {
          dev += (s.axis[i] - s.nominal[i]) * (s.axis[i] - s.nominal[i]);
        }
        if (std::isfinite(dev)) max_dev = std::max(max_dev, std::sqrt(dev));
      }
    }
    const double k = have_nominal && max_dev > 0 ? NiceFactorBelow(0.15 / max_dev) : 1;
    if (d >= 2) {
      figs += Figure(AxesPlot(sensors, 0, 1, k, have_nominal),
                     have_nominal ? "Nominal axes (circles) and estimated axes (crosses)."
                                  : "Estimated unit axes (no nominal axes in the config).");
    }
    if (d >= 3) figs += Figure(AxesPlot(sensors, 0, 2, k, have_nominal), "");
    return Section("plots", "Plots", "<div class=\"plots\">" + figs + "</div>");
  });
  return out;
}

// A failed pca job: positions against the minimum, the singular values and rank gap, and the
// coverage with its advice when the fit got that far.
std::string PcaPartial(const JobView& view) {
  const json* diag = Get(view.job.error_detail, "diagnostics");
  double dd = Num(Get(view.config, "dimension"));
  const size_t d = std::isfinite(dd) && dd >= 1 && dd <= 10 ? static_cast<size_t>(dd) : 3;
  const double gap = Num(Get(diag, "rank_gap"));
  std::string s = "<dl class=\"kv partial-pca\"><dt>positions n</dt><dd>" +
                  E(ScalarText(Get(diag, "positions"))) + " (minimum " +
                  E(ScalarText(Get(diag, "min_positions"))) + ")</dd><dt>rank gap " + kSigma +
                  std::to_string(d) + "/" + kSigma + std::to_string(d + 1) + "</dt><dd>" +
                  (std::isfinite(gap) ? E(FormatSig(gap, 3)) : std::string(kDash)) + "</dd>";
  const json* cov = Get(diag, "coverage");
  const std::string verdict = Str(Get(cov, "verdict"));
  const std::string advice = Str(Get(cov, "advice"));
  if (!verdict.empty() && verdict != "unknown") {
    s += "<dt>orientation coverage</dt><dd class=\"coverage-verdict\">" + E(verdict) +
         (advice.empty() ? std::string() : ": " + E(advice)) + "</dd>";
  }
  s += "</dl>";
  const auto sv = NumArray(Get(diag, "singular_values"));
  if (!sv.empty()) {
    s += Figure(SingularValuePlot(*diag, d),
                "The singular values of the readings: without a clear drop after index d the "
                "readings do not determine d-dimensional sensitivities.");
  }
  return s;
}

std::string PcaDrift(const std::vector<const JobSummary*>& jobs) {
  std::vector<std::vector<PcaSensor>> sensors;
  for (const auto* j : jobs) sensors.push_back(ReadPcaSensors(j->result, json(), 3));
  // Sensor names in the order of the first calibration that has them.
  std::vector<std::string> names;
  for (const auto& ss : sensors) {
    for (const auto& s : ss) {
      if (std::find(names.begin(), names.end(), s.name) == names.end()) names.push_back(s.name);
    }
  }
  auto find = [&](size_t k, const std::string& name) -> const PcaSensor* {
    for (const auto& s : sensors[k]) {
      if (s.name == name) return &s;
    }
    return nullptr;
  };
  auto frame_of = [&](size_t k) {
    std::string f = Str(Get(Get(jobs[k]->result, "parameters"), "frame"));
    const json* reflection = Get(Get(jobs[k]->result, "diagnostics"), "reflection");
    if (reflection != nullptr && reflection->is_boolean() && reflection->get<bool>()) {
      f += " (reflected)";
    }
    return f.empty() ? std::string("unknown") : f;
  };
  // Frame-free: the largest change of an angle between two sensors' axes (what a change of frame
  // cannot move), named by the pair.
  auto axis_pair_change = [&](size_t k, std::string* pair) {
    double worst = kNaN;
    for (size_t i = 0; i < names.size(); ++i) {
      for (size_t j = i + 1; j < names.size(); ++j) {
        const PcaSensor *a0 = find(k - 1, names[i]), *b0 = find(k - 1, names[j]);
        const PcaSensor *a1 = find(k, names[i]), *b1 = find(k, names[j]);
        if (!a0 || !b0 || !a1 || !b1) continue;
        const double d =
            std::fabs(AngleBetween(a1->axis, b1->axis) - AngleBetween(a0->axis, b0->axis));
        if (std::isfinite(d) && !(worst >= d)) {
          worst = d;
          *pair = names[i] + "/" + names[j];
        }
      }
    }
    return worst;
  };
  auto named = [](const std::string& who) {
    return who.empty() ? std::string()
                       : "<br><span class=\"name small muted\">" + E(who) + "</span>";
  };
  std::string rows;
  for (size_t k = FirstDriftPair(jobs.size()); k < jobs.size(); ++k) {
    double worst_scale = kNaN, worst_bias = kNaN;
    std::string ws, wb, detail, pair;
    const bool same_frame = frame_of(k - 1) == frame_of(k);
    const double pair_change = axis_pair_change(k, &pair);
    for (const auto& n : names) {
      const PcaSensor *a = find(k - 1, n), *b = find(k, n);
      if (a == nullptr || b == nullptr) continue;
      const double ds = b->scale - a->scale;
      const double rel = a->scale != 0 ? ds / std::fabs(a->scale) : kNaN;
      // Axis directions only compare within one frame; across frames the change is the frame's.
      const double ang = same_frame ? AngleBetween(a->axis, b->axis) : kNaN;
      const double db = b->bias - a->bias;
      if (std::isfinite(rel) && !(std::fabs(worst_scale) >= std::fabs(rel))) {
        worst_scale = rel;
        ws = n;
      }
      if (std::isfinite(db) && !(std::fabs(worst_bias) >= std::fabs(db))) {
        worst_bias = db;
        wb = n;
      }
      detail += "<tr><td class=\"name\">" + E(n) + "</td>" + NumCell(ds, 3) +
                NumCell(FormatSig(rel * 1e6, 3)) + NumCell(db, 3) + NumCell(ang * 1e3, 3) + "</tr>";
    }
    const std::string frames =
        same_frame
            ? std::string()
            : "<br><span class=\"frames-differ muted small\">frames differ (" + E(frame_of(k - 1)) +
                  " \xE2\x86\x92 " + E(frame_of(k)) + "): axis directions not compared</span>";
    rows += "<tr><td>" + PairLabel(*jobs[k - 1], *jobs[k]) + frames + "</td>" +
            PairTimeCell(*jobs[k - 1], *jobs[k]) +
            NumCell(FormatSig(worst_scale * 1e6, 3) + named(ws)) +
            NumCell(FormatSig(pair_change * 1e3, 3) + named(pair)) +
            NumCell(FormatSig(worst_bias, 3) + named(wb)) + "<td><details><summary>" +
            std::to_string(names.size()) +
            " sensors</summary><table class=\"table-drift-detail\"><thead><tr><th>sensor</th>"
            "<th class=\"num\">\xCE\x94scale (reading units per field unit)</th>"
            "<th class=\"num\">\xCE\x94scale (ppm)</th>"
            "<th class=\"num\">\xCE\x94"
            "bias (reading units)</th><th class=\"num\">\xCE\x94"
            "axis (mrad)</th></tr></thead><tbody>" +
            detail + "</tbody></table></details></td></tr>";
  }
  std::string out =
      "<div class=\"table-wrap\"><table class=\"table-drift-pca\"><thead><tr><th>calibrations</th>"
      "<th>when</th><th class=\"num\">largest \xCE\x94scale (ppm)</th>"
      "<th class=\"num\" title=\"largest change of an angle between two sensors' axes\">"
      "largest change of an angle between axes (mrad)</th>"
      "<th class=\"num\">largest \xCE\x94"
      "bias (reading units)</th>"
      "<th>per sensor (axis change: same frame only)</th></tr>"
      "</thead><tbody>" +
      rows + "</tbody></table></div>" + OmittedPairsNote(jobs.size()) +
      "<p class=\"muted small\">Scale factors, biases and the angles between axes do not depend "
      "on the frame; an axis direction does, so it is compared only between results in the same "
      "frame.</p>";
  // Plots over time, relative to the first calibration.
  const TimeAxis ax = MakeTimeAxis(jobs);
  std::vector<Series> scale_series, axis_series;
  for (size_t n = 0; n < names.size(); ++n) {
    Series s, t;
    s.label = t.label = names[n];
    s.marker = t.marker = Marker::kCircle;
    const PcaSensor* first = nullptr;
    for (size_t k = 0; k < jobs.size(); ++k) {
      const PcaSensor* p = find(k, names[n]);
      if (p == nullptr) continue;
      if (first == nullptr) first = p;
      s.x.push_back(ax.x[k]);
      s.y.push_back(first->scale != 0 ? (p->scale - first->scale) / std::fabs(first->scale) * 1e6
                                      : kNaN);
      t.x.push_back(ax.x[k]);
      t.y.push_back(AngleBetween(first->axis, p->axis) * 1e3);
    }
    scale_series.push_back(std::move(s));
    axis_series.push_back(std::move(t));
  }
  PlotOptions o;
  o.name = "drift-scale";
  o.title = "Scale factor change since the first calibration";
  o.x.title = ax.title;
  o.y.title = "\xCE\x94scale / scale (ppm)";
  std::string figs = Figure(RenderXYPlot(o, scale_series), "");
  o.name = "drift-axis";
  o.title = "Axis direction change since the first calibration";
  o.y.title = "angle to the first axis (mrad)";
  o.y.include_zero = true;
  figs += Figure(RenderXYPlot(o, axis_series),
                 "Axis angles compare frames: meaningful when results are in the nominal frame.");
  return out + "<div class=\"plots\">" + figs + "</div>";
}

namespace {

class PcaReportImpl : public MethodReport {
 public:
  const char* method() const override { return "pca"; }
  std::string Section(const JobView& view) const override { return PcaReport(view); }
  std::string Partial(const JobView& view) const override { return PcaPartial(view); }
  std::string KeyFigures(const json& result) const override {
    const PcaFigures f = ComputePcaFigures(result);
    if (!std::isfinite(f.worst_rel_scale_std) && !std::isfinite(f.rank_gap)) return "";
    return std::string(kSigma) + "(scale) \xE2\x89\xA4 " + Percent(f.worst_rel_scale_std) +
           " \xC2\xB7 gap " + FormatSig(f.rank_gap, 3);
  }
  std::string Drift(const std::vector<const JobSummary*>& jobs) const override {
    return PcaDrift(jobs);
  }
  std::vector<Download> Downloads() const override { return {{"csv", "CSV"}, {"h", "C header"}}; }
};

}  // namespace

const MethodReport& PcaMethodReport() {
  static const PcaReportImpl& report = *new PcaReportImpl();
  return report;
}

}  // namespace calibd::web::internal
