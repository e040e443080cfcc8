// The pca report section, key figures and drift (methods/pca/pca_report.h).
#include "methods/pca/pca_report.h"

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

#include "methods/pca/pca_result.h"
#include "web/html.h"
#include "web/report_common.h"
#include "web/svg_plot.h"

namespace calibd::web::internal {

namespace {

// What a report shows for a result that does not read (results::FromJson's message).
std::string Unreadable(const std::string& what, const Status& s) {
  return NotAvailable(what) + "<p class=\"muted small unreadable\">" + E(s.message()) + "</p>";
}

PcaFigures ComputeFigures(const results::PcaResult& result) {
  PcaFigures f;
  f.rank_gap = result.diagnostics.rank_gap;
  if (!result.parameters || !result.uncertainty) return f;
  const auto& sensors = result.parameters->sensors;
  const auto& stds = result.uncertainty->sensors;  // FromJson: one per sensor, same order
  for (size_t i = 0; i < stds.size() && i < sensors.size(); ++i) {
    const double sd = stds[i].scale_std;
    const double scale = sensors[i].scale;
    if (!std::isfinite(sd)) continue;
    if (!(f.worst_scale_std >= sd)) f.worst_scale_std = sd;
    if (std::isfinite(scale) && scale != 0) {
      const double rel = sd / std::fabs(scale);
      if (!(f.worst_rel_scale_std >= rel)) f.worst_rel_scale_std = rel;
    }
  }
  return f;
}

}  // namespace

PcaFigures ComputePcaFigures(const json& result) {
  results::PcaResult typed;
  if (!results::FromJson(result, &typed).ok()) return PcaFigures();
  return ComputeFigures(typed);
}

struct PcaSensor {
  std::string name;
  double scale = kNaN, scale_std = kNaN, axis_std = kNaN, bias = kNaN, bias_std = kNaN;
  double residual_rms = kNaN;
  std::vector<double> axis;     // unit, d components
  std::vector<double> nominal;  // unit nominal axis, d components (empty when none)
};

// The sensors of a usable result (none for a partial document), with the nominal axes of the
// config (its "nominal", m rows of d numbers, matched by index; absent or of another shape: none).
std::vector<PcaSensor> ReadPcaSensors(const results::PcaResult& result, const json& config,
                                      size_t d) {
  std::vector<PcaSensor> out;
  if (!result.parameters || !result.uncertainty) return out;
  const auto& stds = result.uncertainty->sensors;  // FromJson: one per sensor, same order
  const auto& rms = result.diagnostics.residual_rms;
  for (size_t i = 0; i < result.parameters->sensors.size(); ++i) {
    const results::PcaSensor& s = result.parameters->sensors[i];
    PcaSensor p;
    p.name = s.name;
    p.scale = s.scale;
    p.bias = s.bias;
    p.axis = s.axis;
    if (!HasNumbers(p.axis)) p.axis = Unit(s.sensitivity);
    if (!std::isfinite(p.scale) && HasNumbers(s.sensitivity)) {
      double n = 0;
      for (double x : s.sensitivity) n += x * x;
      p.scale = std::sqrt(n);
    }
    if (i < stds.size()) {
      p.scale_std = stds[i].scale_std;
      p.axis_std = stds[i].axis_std_rad;
      p.bias_std = stds[i].bias_std;
    }
    if (i < rms.size()) p.residual_rms = rms[i];
    out.push_back(std::move(p));
  }
  // Nominal axes: the config's (not the result's) nominal.
  if (const json* nominal = Array(Get(config, "nominal"))) {
    for (size_t i = 0; i < out.size() && i < nominal->size(); ++i) {
      auto row = NumArray(&(*nominal)[i]);
      if (row.size() == d && HasNumbers(row)) out[i].nominal = Unit(row);
    }
  }
  return out;
}

// Which σ the tables show (the σ convention, SPEC §7), in words.
std::string PcaSigmaBasisText(const results::PcaUncertainty& u) {
  const std::string chi2 = std::isfinite(u.chi2_per_dof)
                               ? ", \xCF\x87\xC2\xB2/dof " + FormatSig(u.chi2_per_dof, 3)
                               : std::string();
  if (u.basis == "chi2_scaled" && std::isfinite(u.chi2_per_dof))
    return "the Cram\xC3\xA9r\xE2\x80\x93Rao bound scaled by the residuals (they exceed the "
           "given noise_std" +
           chi2 + "; the bound itself is in uncertainty.sensors[].crb of the JSON)";
  if (u.basis == "chi2_scaled")
    return "the Cram\xC3\xA9r\xE2\x80\x93Rao bound at the noise the residuals estimate "
           "(noise_std not given)";
  if (u.basis == "crb")
    return "the Cram\xC3\xA9r\xE2\x80\x93Rao bound at the given noise_std (the residuals match "
           "it" +
           chi2 + ")";
  return "the Cram\xC3\xA9r\xE2\x80\x93Rao bound at the estimate (stored by an earlier calibd)";
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

std::string SingularValuePlot(const results::PcaDiagnostics& diag, size_t d) {
  const std::vector<double>& sv = diag.singular_values;
  const double gap = diag.rank_gap;
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

std::string MagnitudeErrorPlot(const results::PcaDiagnostics& diag, bool magnitude_known) {
  const std::vector<double>& me = diag.magnitude_error;
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

// A count of the diagnostics (-1: not computed).
std::string CountText(int n) { return n >= 0 ? std::to_string(n) : std::string(kDash); }

std::string PcaReport(const JobView& view) {
  results::PcaResult result;
  const Status read = results::FromJson(view.job.result, &result);
  if (!read.ok()) {
    return Section("parameters", "Parameters", Unreadable("The pca report", read));
  }
  if (!result.parameters) {
    return Section("parameters", "Parameters",
                   NotAvailable("The parameters (the result holds a failed run's diagnostics)"));
  }
  const results::PcaParameters& params = *result.parameters;
  const results::PcaDiagnostics& diag = result.diagnostics;
  const size_t d = static_cast<size_t>(params.dimension);  // FromJson: >= 1
  const auto sensors = ReadPcaSensors(result, view.config, d);
  std::string out;

  out += Guard("Parameters", [&] {
    std::string s;
    const bool known = params.magnitude_known;
    s += "<dl class=\"kv\"><dt>dimension d</dt><dd>" + std::to_string(d) + "</dd>";
    const json magnitude = results::Num(params.magnitude);
    s += "<dt>field magnitude c</dt><dd>" +
         (known ? E(ScalarText(&magnitude)) + " (known)"
                : std::string("unknown: scale factors are relative (the paper's Remark 2)")) +
         "</dd>";
    s += "<dt>frame</dt><dd>" +
         std::string(params.frame == results::PcaFrame::kNominal
                         ? "nominal body frame (orthogonal Procrustes fit)"
                         : "canonical frame of the paper's Eq. 19") +
         "</dd>";
    s += "<dt>sensors m</dt><dd>" + std::to_string(sensors.size()) + "</dd>";
    s += "<dt>positions n</dt><dd>" + CountText(diag.positions) + " (minimum " +
         CountText(diag.min_positions) + ")</dd></dl>";
    bool has_bias = false;
    for (const auto& p : sensors) {
      has_bias = has_bias || (std::isfinite(p.bias) && p.bias != 0) ||
                 (std::isfinite(p.bias_std) && p.bias_std > 0);
    }
    if (sensors.empty()) {
      s += NotAvailable("Sensor parameters");
    } else {
      s += PcaParametersTable(sensors, d, has_bias);
      s += "<p class=\"muted small\">Uncertainties are one standard deviation: " +
           PcaSigmaBasisText(*result.uncertainty) +
           ". Scale factors and angles do not depend on the frame.</p>";
    }
    return Section("parameters", "Parameters", s);
  });

  out += Guard("Plots", [&] {
    std::string figs;
    figs += Figure(SingularValuePlot(diag, d),
                   "A clear drop after index d means the readings determine the d-dimensional "
                   "sensitivities.");
    figs += Figure(MagnitudeErrorPlot(diag, params.magnitude_known),
                   "Should scatter around zero at the noise level; outliers are bad positions.");
    figs += Figure(ResidualRmsPlot(sensors, diag.noise_std),
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
  results::PcaResult result;
  const Status read = results::FromJson(view.job.error_detail, &result);
  if (!read.ok()) return Unreadable("The partial pca diagnostics", read);
  const results::PcaDiagnostics& diag = result.diagnostics;
  // d: the result's (a partial document has no parameters), else the config's, else 3.
  double dd = result.parameters ? result.parameters->dimension : Num(Get(view.config, "dimension"));
  const size_t d = std::isfinite(dd) && dd >= 1 && dd <= 32 ? static_cast<size_t>(dd) : 3;
  const double gap = diag.rank_gap;
  std::string s = "<dl class=\"kv partial-pca\"><dt>positions n</dt><dd>" +
                  CountText(diag.positions) + " (minimum " + CountText(diag.min_positions) +
                  ")</dd><dt>rank gap " + kSigma + std::to_string(d) + "/" + kSigma +
                  std::to_string(d + 1) + "</dt><dd>" +
                  (std::isfinite(gap) ? E(FormatSig(gap, 3)) : std::string(kDash)) + "</dd>";
  // Absent (an earlier calibd's document, or left out over the size cap) or not computed: no row.
  if (diag.coverage && diag.coverage->verdict != results::PcaCoverageVerdict::kUnknown) {
    const results::PcaCoverage& cov = *diag.coverage;
    s += "<dt>orientation coverage</dt><dd class=\"coverage-verdict\">" +
         E(results::Name(cov.verdict)) +
         (cov.advice.empty() ? std::string() : ": " + E(cov.advice)) + "</dd>";
  }
  s += "</dl>";
  if (!diag.singular_values.empty()) {
    s += Figure(SingularValuePlot(diag, d),
                "The singular values of the readings: without a clear drop after index d the "
                "readings do not determine d-dimensional sensitivities.");
  }
  return s;
}

std::string PcaDrift(const std::vector<const JobSummary*>& jobs) {
  // Each result read once; one that does not read has no sensors here (and is named below).
  std::vector<std::vector<PcaSensor>> sensors;
  std::vector<std::string> frames;
  std::string unreadable;
  for (const auto* j : jobs) {
    results::PcaResult typed;
    const Status read = results::FromJson(j->result, &typed);
    if (!read.ok()) {
      unreadable += Unreadable("Calibration " + std::to_string(j->id), read);
      sensors.emplace_back();
      frames.push_back("unknown");
      continue;
    }
    sensors.push_back(ReadPcaSensors(typed, json(), 3));
    std::string f = typed.parameters ? results::Name(typed.parameters->frame) : "unknown";
    if (typed.parameters && typed.diagnostics.reflection) f += " (reflected)";
    frames.push_back(f);
  }
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
  auto frame_of = [&](size_t k) { return frames[k]; };
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
      rows + "</tbody></table></div>" + unreadable + OmittedPairsNote(jobs.size()) +
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
    results::PcaResult typed;
    const Status read = results::FromJson(result, &typed);
    if (!read.ok()) return "not available: " + read.message();
    const PcaFigures f = ComputeFigures(typed);
    if (!std::isfinite(f.worst_rel_scale_std) && !std::isfinite(f.rank_gap)) return "";
    return std::string(kSigma) + "(scale) \xE2\x89\xA4 " + Percent(f.worst_rel_scale_std) +
           " \xC2\xB7 gap " + FormatSig(f.rank_gap, 3);
  }
  std::string Drift(const std::vector<const JobSummary*>& jobs) const override {
    return PcaDrift(jobs);
  }
};

}  // namespace

const MethodReport& PcaMethodReport() {
  static const PcaReportImpl& report = *new PcaReportImpl();
  return report;
}

}  // namespace calibd::web::internal
