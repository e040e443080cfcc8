// The array report section, key figures and drift (web/reports.h).
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

#include "web/array_full_report.h"
#include "web/html.h"
#include "web/report_common.h"
#include "web/reports.h"
#include "web/svg_plot.h"

namespace calibd::web::internal {

ArrayFigures ComputeArrayFigures(const json& result) {
  ArrayFigures f;
  const json* params = Get(result, "parameters");
  const double ref = Num(Get(params, "reference"));
  if (const json* pos = Array(Get(params, "positions"))) {
    double sum = 0;
    size_t n = 0;
    for (size_t i = 0; i < pos->size(); ++i) {
      if (std::isfinite(ref) && static_cast<double>(i) == ref) continue;
      const auto off = NumArray(Get((*pos)[i], "offset"));
      if (off.size() < 3 || !HasNumbers(off)) continue;
      double s2 = 0;
      for (size_t k = 0; k < 3; ++k) s2 += std::isfinite(off[k]) ? off[k] * off[k] : 0;
      sum += s2;
      ++n;
    }
    if (n > 0) f.rms_offset = std::sqrt(sum / static_cast<double>(n));
  }
  if (const json* us = Array(Get(Get(result, "uncertainty"), "positions"))) {
    for (const auto& u : *us) {
      for (double s : NumArray(Get(u, "std"))) {
        if (std::isfinite(s) && !(f.worst_sigma >= s)) f.worst_sigma = s;
      }
    }
  }
  return f;
}

struct Triad {
  std::string name;
  double p[3] = {kNaN, kNaN, kNaN};    // estimated position (m)
  double off[3] = {kNaN, kNaN, kNaN};  // offset from nominal (m)
  double sd[3] = {kNaN, kNaN, kNaN};   // 1σ (m)
  double nom[3] = {kNaN, kNaN, kNaN};  // nominal (m)
  bool reference = false;
};

std::vector<Triad> ReadTriads(const json& result, const json& config) {
  std::vector<Triad> out;
  const json* params = Get(result, "parameters");
  const double ref = Num(Get(params, "reference"));
  const json* pos = Array(Get(params, "positions"));
  const json* cfg_pos = Array(Get(Get(config, "geometry"), "positions"));
  if (pos == nullptr) return out;
  for (size_t i = 0; i < pos->size(); ++i) {
    const json& t = (*pos)[i];
    Triad tr;
    tr.name = Str(Get(t, "name"));
    if (tr.name.empty()) tr.name = "a" + std::to_string(i);
    const auto p = NumArray(Get(t, "position"));
    const auto o = NumArray(Get(t, "offset"));
    std::vector<double> nom;
    if (cfg_pos != nullptr && i < cfg_pos->size()) nom = NumArray(&(*cfg_pos)[i]);
    for (size_t k = 0; k < 3; ++k) {
      if (k < p.size()) tr.p[k] = p[k];
      if (k < o.size()) tr.off[k] = o[k];
      if (k < nom.size()) tr.nom[k] = nom[k];
      if (!std::isfinite(tr.nom[k])) tr.nom[k] = tr.p[k] - tr.off[k];
      if (!std::isfinite(tr.off[k])) tr.off[k] = tr.p[k] - tr.nom[k];
    }
    tr.reference = std::isfinite(ref) && static_cast<double>(i) == ref;
    out.push_back(tr);
  }
  std::map<std::string, size_t> by_name;
  for (size_t i = 0; i < out.size(); ++i) by_name[out[i].name] = i;
  if (const json* us = Array(Get(Get(result, "uncertainty"), "positions"))) {
    for (size_t i = 0; i < us->size(); ++i) {
      const auto it = by_name.find(Str(Get((*us)[i], "name")));
      const size_t k = it != by_name.end() ? it->second : i;
      if (k >= out.size()) continue;
      const auto sd = NumArray(Get((*us)[i], "std"));
      for (size_t c = 0; c < 3 && c < sd.size(); ++c) out[k].sd[c] = sd[c];
    }
  }
  return out;
}

std::string ArrayParametersTable(const std::vector<Triad>& triads) {
  std::string head =
      "<tr><th>triad</th><th class=\"num\">x (mm)</th><th class=\"num\">y (mm)</th>"
      "<th class=\"num\">z (mm)</th><th class=\"num\">\xCE\x94x (\xC2\xB5m)</th>"
      "<th class=\"num\">\xCE\x94y (\xC2\xB5m)</th><th class=\"num\">\xCE\x94z (\xC2\xB5m)</th>"
      "<th class=\"num\">|\xCE\x94| (\xC2\xB5m)</th><th class=\"num\">\xCF\x83x (\xC2\xB5m)</th>"
      "<th class=\"num\">\xCF\x83y (\xC2\xB5m)</th><th class=\"num\">\xCF\x83z "
      "(\xC2\xB5m)</th></tr>";
  std::string rows;
  for (const auto& t : triads) {
    rows += "<tr><td class=\"name\">" + E(t.name) +
            (t.reference ? " <span class=\"muted small\">(reference, fixed)</span>" : "") + "</td>";
    for (double v : t.p) rows += NumCell(FormatFixed(v * 1e3, 4));
    for (double v : t.off) rows += NumCell(FormatFixed(v * 1e6, 1));
    rows += NumCell(FormatFixed(Norm3(t.off) * 1e6, 1));
    for (double v : t.sd)
      rows +=
          NumCell(t.reference && !std::isfinite(v) ? std::string(kDash) : FormatSig(v * 1e6, 3));
    rows += "</tr>";
  }
  return "<div class=\"table-wrap\"><table class=\"table-array-parameters\"><thead>" + head +
         "</thead><tbody>" + rows + "</tbody></table></div>";
}

std::string CostPlot(const json& diag) {
  const auto cost = NumArray(Get(diag, "cost"));
  Series s;
  s.marker = cost.size() <= 60 ? Marker::kCircle : Marker::kNone;
  for (size_t i = 0; i < cost.size(); ++i) {
    s.x.push_back(static_cast<double>(i));
    s.y.push_back(cost[i]);
  }
  PlotOptions o;
  o.name = "cost";
  o.title = "Cost per iteration";
  o.x.title = "iteration";
  o.y.title = "cost (weighted squared residuals)";
  o.y.type = ScaleType::kLog10;
  o.legend = false;
  return RenderXYPlot(o, {s});
}

// Nominal vs estimated positions in one projection (a, b), in mm, offsets magnified by k and
// 1σ ellipses magnified by ke.
std::string PositionsPlot(const std::vector<Triad>& triads, int a, int b) {
  static const char* kName[] = {"x", "y", "z"};
  const std::string plane = std::string(kName[a]) + kName[b];
  // Pitch: smallest distance between distinct nominal points in this projection.
  double pitch = kNaN, max_off = 0, max_sd = 0;
  for (size_t i = 0; i < triads.size(); ++i) {
    const auto& t = triads[i];
    const double oa = t.off[a], ob = t.off[b];
    if (std::isfinite(oa) && std::isfinite(ob)) max_off = std::max(max_off, std::hypot(oa, ob));
    if (std::isfinite(t.sd[a])) max_sd = std::max(max_sd, t.sd[a]);
    if (std::isfinite(t.sd[b])) max_sd = std::max(max_sd, t.sd[b]);
    for (size_t j = i + 1; j < triads.size(); ++j) {
      const double dist = std::hypot(t.nom[a] - triads[j].nom[a], t.nom[b] - triads[j].nom[b]);
      if (std::isfinite(dist) && dist > 1e-9 && !(pitch <= dist)) pitch = dist;
    }
  }
  if (!std::isfinite(pitch)) pitch = max_off > 0 ? max_off * 10 : 1e-3;
  const double k = max_off > 0 ? NiceFactorBelow(0.3 * pitch / max_off) : 1;
  // Ellipses at the offsets' magnification when visible, else their own (stated) factor.
  double ke = k;
  if (max_sd > 0 && k * max_sd < 0.03 * pitch) ke = NiceFactorBelow(0.12 * pitch / max_sd);
  Series nominal, est;
  nominal.label = "nominal";
  nominal.line = false;
  nominal.marker = Marker::kOpenCircle;
  nominal.color = 6;
  est.label = "estimated (offset " + FactorText(k) + ")";
  if (max_sd > 0) est.label += ", 1\xCF\x83 ellipse " + FactorText(ke);
  est.line = false;
  est.marker = Marker::kCross;
  est.color = 1;
  PlotOptions o;
  o.name = "positions-" + plane;
  o.title = "Triad positions, " + plane + " view";
  o.x.title = std::string(kName[a]) + " (mm)";
  o.y.title = std::string(kName[b]) + " (mm)";
  o.equal_aspect = true;
  o.height = 420;
  const bool labels = triads.size() <= 16;
  for (const auto& t : triads) {
    const double na = t.nom[a] * 1e3, nb = t.nom[b] * 1e3;
    const double pa = na + k * t.off[a] * 1e3, pb = nb + k * t.off[b] * 1e3;
    if (!std::isfinite(na) || !std::isfinite(nb)) continue;
    nominal.x.push_back(na);
    nominal.y.push_back(nb);
    est.x.push_back(pa);
    est.y.push_back(pb);
    const double sa = t.sd[a] * 1e3 * ke, sb = t.sd[b] * 1e3 * ke;
    est.ellipses.push_back(
        {std::isfinite(sa) ? sa * sa : kNaN, 0.0, std::isfinite(sb) ? sb * sb : kNaN});
    if (labels) est.point_labels.push_back(t.name);
    o.segments.push_back({na, nb, pa, pb, 1});
  }
  o.notes.push_back("Offsets from nominal magnified " + FactorText(k) +
                    (max_sd > 0 ? "; 1\xCF\x83 ellipses magnified " + FactorText(ke) : "") + ".");
  return RenderXYPlot(o, {nominal, est});
}

std::string PositionSigmaPlot(const std::vector<Triad>& triads) {
  std::vector<std::string> names;
  BarSeries sx{"\xCF\x83x", {}, {}, 0}, sy{"\xCF\x83y", {}, {}, 1}, sz{"\xCF\x83z", {}, {}, 2};
  for (const auto& t : triads) {
    names.push_back(t.name);
    sx.values.push_back(t.sd[0] * 1e6);
    sy.values.push_back(t.sd[1] * 1e6);
    sz.values.push_back(t.sd[2] * 1e6);
  }
  PlotOptions o;
  o.name = "position-sigma";
  o.title = "Position uncertainty (1\xCF\x83) per triad";
  o.x.title = "triad";
  o.y.title = "1\xCF\x83 (\xC2\xB5m)";
  return RenderBarChart(o, names, {sx, sy, sz});
}

// Unit of the gyroscope figures of an array result: diagnostics.gyro_unit, else the config's.
std::string GyroUnit(const json& diag, const json& config) {
  std::string u = Str(Get(diag, "gyro_unit"));
  if (u.empty()) u = Str(Get(config, "gyro_unit"));
  return u == "deg/s" ? "\xC2\xB0/s" : "rad/s";
}

std::string ArrayResidualPlot(const json& diag, const json& config) {
  const json* rms = Get(diag, "residual_rms");
  const json* noise = Get(diag, "noise_estimate");
  const json* configured = Get(diag, "noise_configured");
  // Configured σ: from the result (in the gyro unit), else from the config (same unit).
  double cfg_a = Num(Get(configured, "accelerometer"));
  double cfg_g = Num(Get(configured, "gyroscope"));
  if (configured == nullptr) {
    cfg_a = Num(Get(config, "accel_noise"));
    cfg_g = Num(Get(config, "gyro_noise"));
  }
  const std::string gu = GyroUnit(diag, config);
  BarSeries r{"residual RMS", {Num(Get(rms, "accelerometer")), Num(Get(rms, "gyroscope"))}, {}, 0};
  BarSeries n{
      "noise estimate", {Num(Get(noise, "accelerometer")), Num(Get(noise, "gyroscope"))}, {}, 1};
  std::vector<BarSeries> series{r, n};
  if (std::isfinite(cfg_a) || std::isfinite(cfg_g)) {
    series.push_back({"configured \xCF\x83", {cfg_a, cfg_g}, {}, 2});
  }
  PlotOptions o;
  o.name = "residual-rms";
  o.title = "Residual RMS per sensor type";
  o.y.title = "RMS (m/s\xC2\xB2 | " + gu + ")";
  o.y.type = ScaleType::kLog10;
  return RenderBarChart(o, {"accelerometer (m/s\xC2\xB2)", "gyroscope (" + gu + ")"}, series);
}

// Residual histograms, when the result carries them: diagnostics.residual_histogram.TYPE as
// {"edges": [...], "counts": [...]} (or "bin_edges"), or raw diagnostics.residuals.TYPE arrays.
std::string ResidualHistograms(const json& diag) {
  std::string out;
  for (const char* type : {"accelerometer", "gyroscope"}) {
    Histogram h;
    const json* hj = Get(Get(diag, "residual_histogram"), type);
    if (hj != nullptr) {
      h.edges = NumArray(Get(hj, "edges"));
      if (h.edges.empty()) h.edges = NumArray(Get(hj, "bin_edges"));
      h.counts = NumArray(Get(hj, "counts"));
    } else if (const json* raw = Array(Get(Get(diag, "residuals"), type))) {
      h = MakeHistogram(NumArray(raw), 40);
    } else {
      continue;
    }
    if (h.edges.size() != h.counts.size() + 1) continue;
    h.color = std::string(type) == "accelerometer" ? 0 : 1;
    PlotOptions o;
    o.name = std::string("residual-histogram-") + type;
    o.title = std::string("Residual histogram, ") + type;
    o.x.title = std::string("residual (") +
                (std::string(type) == "accelerometer" ? "m/s\xC2\xB2" : "rad/s") + ")";
    o.y.title = "count";
    o.legend = false;
    out += Figure(RenderHistogram(o, {h}), "Should look Gaussian and centred on zero.");
  }
  return out;
}

std::string ExcitationPlots(const json& diag) {
  std::string out;
  struct Item {
    const char* key;
    const char* name;
    const char* title;
    const char* unit;
  };
  const Item items[] = {
      {"omega_norm", "excitation-omega", "Angular rate \xE2\x80\x96\xCF\x89\xE2\x80\x96 per sample",
       "\xE2\x80\x96\xCF\x89\xE2\x80\x96 (rad/s)"},
      {"omega_dot_norm", "excitation-omega-dot",
       "Angular acceleration \xE2\x80\x96\xCF\x89\xCC\x87\xE2\x80\x96 per sample",
       "\xE2\x80\x96\xCF\x89\xCC\x87\xE2\x80\x96 (rad/s\xC2\xB2)"}};
  const json* exc = Get(diag, "excitation");
  const json* motion = Get(diag, "motion");
  for (const auto& it : items) {
    // diagnostics.motion.KEY (every stride-th sample), or diagnostics.KEY / excitation.KEY.
    double stride = 1;
    const json* arr = Array(Get(motion, it.key));
    if (arr != nullptr) {
      const double st = Num(Get(motion, "stride"));
      if (std::isfinite(st) && st >= 1) stride = st;
    }
    if (arr == nullptr) arr = Array(Get(diag, it.key));
    if (arr == nullptr) arr = Array(Get(exc, it.key));
    if (arr == nullptr) continue;
    const auto y = NumArray(arr);
    std::vector<double> t = NumArray(Get(diag, "t"));
    if (t.size() != y.size()) t = NumArray(Get(diag, "time"));
    const bool have_t = t.size() == y.size() && HasNumbers(t);
    Series s;
    s.y = y;
    s.line_width = 1;
    if (have_t) {
      s.x = t;
    } else {
      s.x.resize(y.size());
      for (size_t i = 0; i < y.size(); ++i) s.x[i] = static_cast<double>(i) * stride;
    }
    PlotOptions o;
    o.name = it.name;
    o.title = it.title;
    o.x.title = have_t ? "time (s)" : "sample";
    o.y.title = it.unit;
    o.y.include_zero = true;
    o.legend = false;
    o.max_points = 1600;
    out += Figure(RenderXYPlot(o, {s}), "");
  }
  return out;
}

std::string ArrayReport(const JobView& view) {
  const json& result = view.job.result;
  const json* diag = Get(result, "diagnostics");
  const auto triads = ReadTriads(result, view.config);
  std::string out;
  out += Guard("Parameters", [&] {
    std::string s = "<dl class=\"kv\">";
    std::string ref_name = kDash;
    for (const auto& t : triads) {
      if (t.reference) ref_name = t.name;
    }
    s += "<dt>triads K</dt><dd>" + std::to_string(triads.size()) + "</dd>";
    s += "<dt>reference triad</dt><dd>" + E(ref_name) + " (held at its nominal position)</dd>";
    s += "<dt>solver</dt><dd>" + E(ScalarText(Get(diag, "solver"))) + ", " +
         E(ScalarText(Get(diag, "iterations"))) +
         " iterations, converged: " + E(ScalarText(Get(diag, "converged"))) +
         (Get(diag, "termination") != nullptr ? " (" + E(ScalarText(Get(diag, "termination"))) + ")"
                                              : std::string()) +
         "</dd>";
    s += "<dt>samples</dt><dd>" + E(ScalarText(Get(diag, "samples"))) + " used, " +
         E(ScalarText(Get(diag, "samples_dropped"))) + " dropped</dd>";
    const json* exc = Get(diag, "excitation");
    s += "<dt>excitation</dt><dd>" + E(ScalarText(Get(exc, "verdict"))) + " (smallest eigenvalue " +
         E(ScalarText(Get(exc, "min_eigenvalue"), 4)) +
         (Get(exc, "noise_floor") != nullptr
              ? ", noise floor " + E(ScalarText(Get(exc, "noise_floor"), 4))
              : std::string()) +
         ")</dd>";
    const ArrayFigures f = ComputeArrayFigures(result);
    s += "<dt>RMS offset from nominal</dt><dd>" + FormatMicrometres(f.rms_offset) + "</dd>";
    s += "<dt>worst position " + std::string(kSigma) + "</dt><dd>" +
         FormatMicrometres(f.worst_sigma) + "</dd></dl>";
    if (triads.empty()) {
      s += NotAvailable("Triad positions");
    } else {
      s += ArrayParametersTable(triads);
      s += "<p class=\"muted small\">Positions in the nominal geometry's frame; \xCE\x94 is the "
           "offset from the nominal position; \xCF\x83 is one standard deviation (Cram\xC3\xA9r"
           "\xE2\x80\x93Rao bound at the estimate).</p>";
    }
    return Section("parameters", "Parameters", s);
  });
  if (IsArrayFullResult(result)) out += ArrayFullSections(result);  // web/array_full_report.h
  out += Guard("Plots", [&] {
    const json dj = diag ? *diag : json();
    std::string figs;
    figs += Figure(CostPlot(dj),
                   "Joint Gauss-Newton converges in a handful of iterations; "
                   "block coordinate descent needs hundreds.");
    if (!triads.empty()) {
      figs += Figure(PositionsPlot(triads, 0, 1), "Circles: nominal; crosses: estimated.");
      figs += Figure(PositionsPlot(triads, 0, 2), "");
      figs += Figure(PositionSigmaPlot(triads), "");
    }
    if (!IsArrayFullResult(result))  // model full: per triad in ArrayFullSections
      figs += Figure(ArrayResidualPlot(dj, view.config),
                     "Residual RMS close to the noise level means the model fits.");
    figs += ResidualHistograms(dj);
    figs += ExcitationPlots(dj);
    return Section("plots", "Plots", "<div class=\"plots\">" + figs + "</div>");
  });
  return out;
}

std::string ArrayDrift(const std::vector<const JobSummary*>& jobs) {
  std::vector<std::vector<Triad>> triads;
  for (const auto* j : jobs) triads.push_back(ReadTriads(j->result, json()));
  std::vector<std::string> names;
  for (const auto& ts : triads) {
    for (const auto& t : ts) {
      if (std::find(names.begin(), names.end(), t.name) == names.end()) names.push_back(t.name);
    }
  }
  auto find = [&](size_t k, const std::string& name) -> const Triad* {
    for (const auto& t : triads[k]) {
      if (t.name == name) return &t;
    }
    return nullptr;
  };
  std::string rows;
  for (size_t k = FirstDriftPair(jobs.size()); k < jobs.size(); ++k) {
    double worst = kNaN, sum = 0;
    size_t n_used = 0;
    std::string wn, detail;
    for (const auto& n : names) {
      const Triad *a = find(k - 1, n), *b = find(k, n);
      if (a == nullptr || b == nullptr) continue;
      const double dv[3] = {b->p[0] - a->p[0], b->p[1] - a->p[1], b->p[2] - a->p[2]};
      const double norm = Norm3(dv);
      if (std::isfinite(norm)) {
        sum += norm * norm;
        ++n_used;
        if (!(worst >= norm)) {
          worst = norm;
          wn = n;
        }
      }
      detail += "<tr><td class=\"name\">" + E(n) + "</td>" + NumCell(FormatFixed(dv[0] * 1e6, 1)) +
                NumCell(FormatFixed(dv[1] * 1e6, 1)) + NumCell(FormatFixed(dv[2] * 1e6, 1)) +
                NumCell(FormatFixed(norm * 1e6, 1)) + "</tr>";
    }
    const double rms = n_used > 0 ? std::sqrt(sum / static_cast<double>(n_used)) : kNaN;
    rows += "<tr><td>" + PairLabel(*jobs[k - 1], *jobs[k]) + "</td>" +
            PairTimeCell(*jobs[k - 1], *jobs[k]) + NumCell(FormatFixed(rms * 1e6, 1)) +
            NumCell(FormatFixed(worst * 1e6, 1)) + "<td class=\"name\">" + E(wn) +
            "</td><td><details><summary>" + std::to_string(names.size()) +
            " triads</summary><table class=\"table-drift-detail\"><thead><tr><th>triad</th>"
            "<th class=\"num\">\xCE\x94x (\xC2\xB5m)</th><th class=\"num\">\xCE\x94y (\xC2\xB5m)"
            "</th><th class=\"num\">\xCE\x94z (\xC2\xB5m)</th><th class=\"num\">|\xCE\x94| "
            "(\xC2\xB5m)</th></tr></thead><tbody>" +
            detail + "</tbody></table></details></td></tr>";
  }
  std::string out =
      "<div class=\"table-wrap\"><table class=\"table-drift-array\"><thead><tr><th>calibrations"
      "</th><th>when</th><th class=\"num\">RMS |\xCE\x94position| (\xC2\xB5m)</th>"
      "<th class=\"num\">largest |\xCE\x94position| (\xC2\xB5m)</th><th>triad</th>"
      "<th>per triad</th></tr></thead><tbody>" +
      rows + "</tbody></table></div>" + OmittedPairsNote(jobs.size());
  const TimeAxis ax = MakeTimeAxis(jobs);
  std::vector<Series> series;
  for (const auto& n : names) {
    Series s;
    s.label = n;
    s.marker = Marker::kCircle;
    const Triad* first = nullptr;
    for (size_t k = 0; k < jobs.size(); ++k) {
      const Triad* t = find(k, n);
      if (t == nullptr) continue;
      if (first == nullptr) first = t;
      const double dv[3] = {t->p[0] - first->p[0], t->p[1] - first->p[1], t->p[2] - first->p[2]};
      s.x.push_back(ax.x[k]);
      s.y.push_back(Norm3(dv) * 1e6);
    }
    series.push_back(std::move(s));
  }
  PlotOptions o;
  o.name = "drift-position";
  o.title = "Triad position change since the first calibration";
  o.x.title = ax.title;
  o.y.title = "|\xCE\x94position| (\xC2\xB5m)";
  o.y.include_zero = true;
  return out + "<div class=\"plots\">" + Figure(RenderXYPlot(o, series), "") + "</div>";
}

namespace {

// A failed array job: the samples used and dropped, and the excitation when the solver got
// that far (the full model: statics, dynamic samples and the rotation excitation).
std::string ArrayPartialReport(const JobView& view) {
  const json* diag = Get(view.job.error_detail, "diagnostics");
  std::string s = "<dl class=\"kv partial-array\">";
  if (Str(Get(diag, "model")) == "full") {
    const json* rot = Get(diag, "rotation");
    s += "<dt>statics</dt><dd>" + E(ScalarText(Get(diag, "statics"))) + " (" +
         E(ScalarText(Get(diag, "static_samples"))) + " samples)</dd><dt>dynamic samples</dt><dd>" +
         E(ScalarText(Get(diag, "dynamic_samples"))) + "</dd><dt>rotation excitation</dt><dd>" +
         E(Str(Get(rot, "verdict"))) + "</dd>";
  } else {
    const json* ex = Get(diag, "excitation");
    const std::string verdict = Str(Get(ex, "verdict"));
    s += "<dt>usable samples</dt><dd>" + E(ScalarText(Get(diag, "samples"))) + " (" +
         E(ScalarText(Get(diag, "samples_dropped"))) +
         " dropped for gyroscope saturation)</dd><dt>gyroscope triads</dt><dd>" +
         E(ScalarText(Get(diag, "gyro_triads"))) + "</dd><dt>excitation</dt><dd>" +
         (verdict.empty() ? std::string("not reached")
                          : E(verdict) + " (smallest eigenvalue " +
                                E(ScalarText(Get(ex, "min_eigenvalue"), 3)) + ", noise floor " +
                                E(ScalarText(Get(ex, "noise_floor"), 3)) + ")") +
         "</dd>";
  }
  return s + "</dl>";
}

class ArrayReportImpl : public MethodReport {
 public:
  const char* method() const override { return "array"; }
  std::string Section(const JobView& view) const override { return ArrayReport(view); }
  std::string Partial(const JobView& view) const override { return ArrayPartialReport(view); }
  std::string KeyFigures(const json& result) const override {
    const ArrayFigures f = ComputeArrayFigures(result);
    if (!std::isfinite(f.rms_offset) && !std::isfinite(f.worst_sigma)) return "";
    return "offset RMS " + FormatMicrometres(f.rms_offset) + " \xC2\xB7 " + kSigma +
           " \xE2\x89\xA4 " + FormatMicrometres(f.worst_sigma, 2);
  }
  std::string Drift(const std::vector<const JobSummary*>& jobs) const override {
    return ArrayDrift(jobs);
  }
  std::vector<Download> Downloads() const override { return {{"csv", "CSV"}, {"h", "C header"}}; }
};

}  // namespace

const MethodReport& ArrayMethodReport() {
  static const ArrayReportImpl& report = *new ArrayReportImpl();
  return report;
}

}  // namespace calibd::web::internal
