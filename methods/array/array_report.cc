// The array report section, key figures and drift (methods/array/array_report.h).
#include "methods/array/array_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <exception>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "methods/array/array_full_report.h"
#include "methods/array/array_result.h"
#include "web/html.h"
#include "web/report_common.h"
#include "web/svg_plot.h"

namespace calibd::web::internal {

namespace {

// Reads an array result typed (methods/array/array_result.h); false with *message when it does not
// read.
bool ReadResult(const json& doc, results::ArrayResult* r, std::string* message) {
  const Status s = results::FromJson(doc, r);
  if (!s.ok()) *message = s.message();
  return s.ok();
}

// A value as the generic tables show it (web/report_common.h ScalarText): NaN as a dash.
std::string Text(double v, int sig = 6) {
  const json j = results::Num(v);
  return ScalarText(&j, sig);
}
template <typename T>
std::string Text(const T& v) {
  const json j = v;
  return ScalarText(&j);
}
// A count a result may lack (a partial document, a result of an earlier calibd): a dash then.
template <typename T>
std::string Text(const std::optional<T>& v) {
  return v ? Text(*v) : std::string(kDash);
}
// A verdict a result may lack: a dash then.
std::string VerdictText(const std::string& verdict) {
  return verdict.empty() ? std::string(kDash) : E(verdict);
}

ArrayFigures Figures(const results::ArrayResult& r) {
  ArrayFigures f;
  if (!r.parameters || !r.uncertainty) return f;
  double sum = 0;
  size_t n = 0;
  for (size_t i = 0; i < r.parameters->positions.size(); ++i) {
    if (static_cast<int>(i) == r.parameters->reference) continue;
    const Eigen::Vector3d& off = r.parameters->positions[i].offset;
    if (!off.array().isFinite().any()) continue;
    double s2 = 0;
    for (int k = 0; k < 3; ++k) s2 += std::isfinite(off(k)) ? off(k) * off(k) : 0;
    sum += s2;
    ++n;
  }
  if (n > 0) f.rms_offset = std::sqrt(sum / static_cast<double>(n));
  for (const auto& u : r.uncertainty->positions) {
    for (int k = 0; k < 3; ++k) {
      const double s = u.std(k);
      if (std::isfinite(s) && !(f.worst_sigma >= s)) f.worst_sigma = s;
    }
  }
  return f;
}

}  // namespace

ArrayFigures ComputeArrayFigures(const json& result) {
  results::ArrayResult r;
  std::string message;
  return ReadResult(result, &r, &message) ? Figures(r) : ArrayFigures();
}

struct Triad {
  std::string name;
  double p[3] = {kNaN, kNaN, kNaN};    // estimated position (m)
  double off[3] = {kNaN, kNaN, kNaN};  // offset from nominal (m)
  double sd[3] = {kNaN, kNaN, kNaN};   // 1σ (m)
  double nom[3] = {kNaN, kNaN, kNaN};  // nominal (m)
  bool reference = false;
};

// The triads of a result; the nominal positions from the config's geometry (when given), else
// position − offset.
std::vector<Triad> ReadTriads(const results::ArrayResult& result, const json& config) {
  std::vector<Triad> out;
  if (!result.parameters) return out;
  const results::ArrayParameters& params = *result.parameters;
  const json* cfg_pos = Array(Get(Get(config, "geometry"), "positions"));
  for (size_t i = 0; i < params.positions.size(); ++i) {
    const results::ArrayPosition& t = params.positions[i];
    Triad tr;
    tr.name = t.name;
    if (tr.name.empty()) tr.name = "a" + std::to_string(i);
    std::vector<double> nom;
    if (cfg_pos != nullptr && i < cfg_pos->size()) nom = NumArray(&(*cfg_pos)[i]);
    for (size_t k = 0; k < 3; ++k) {
      tr.p[k] = t.position(k);
      tr.off[k] = t.offset(k);
      if (k < nom.size()) tr.nom[k] = nom[k];
      if (!std::isfinite(tr.nom[k])) tr.nom[k] = tr.p[k] - tr.off[k];
      if (!std::isfinite(tr.off[k])) tr.off[k] = tr.p[k] - tr.nom[k];
    }
    tr.reference = static_cast<int>(i) == params.reference;
    out.push_back(tr);
  }
  std::map<std::string, size_t> by_name;
  for (size_t i = 0; i < out.size(); ++i) by_name[out[i].name] = i;
  if (result.uncertainty) {
    const auto& us = result.uncertainty->positions;
    for (size_t i = 0; i < us.size(); ++i) {
      const auto it = by_name.find(us[i].name);
      const size_t k = it != by_name.end() ? it->second : i;
      if (k >= out.size()) continue;
      for (int c = 0; c < 3; ++c) out[k].sd[c] = us[i].std(c);
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

std::string CostPlot(const std::vector<double>& cost) {
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

// Unit of the gyroscope figures of an array result: diagnostics.gyro_unit.
std::string GyroUnit(const std::string& gyro_unit) {
  return gyro_unit == "deg/s" ? "\xC2\xB0/s" : "rad/s";
}

// The positions model's residual RMS against the noise estimate and the configured σ.
std::string ArrayResidualPlot(const results::ArrayPositionsDiagnostics& d) {
  const std::string gu = GyroUnit(d.gyro_unit);
  BarSeries r{"residual RMS", {d.residual_rms.accelerometer, d.residual_rms.gyroscope}, {}, 0};
  BarSeries n{
      "noise estimate", {d.noise_estimate.accelerometer, d.noise_estimate.gyroscope}, {}, 1};
  std::vector<BarSeries> series{r, n};
  const double cfg_a = d.noise_configured.accelerometer, cfg_g = d.noise_configured.gyroscope;
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

// |ω| and |ω̇| of the positions model's usable samples (diagnostics.motion, every stride-th).
std::string ExcitationPlots(const results::ArrayMotion& motion) {
  std::string out;
  struct Item {
    const std::vector<double>* y;
    const char* name;
    const char* title;
    const char* unit;
  };
  const Item items[] = {{&motion.omega_norm, "excitation-omega",
                         "Angular rate \xE2\x80\x96\xCF\x89\xE2\x80\x96 per sample",
                         "\xE2\x80\x96\xCF\x89\xE2\x80\x96 (rad/s)"},
                        {&motion.omega_dot_norm, "excitation-omega-dot",
                         "Angular acceleration \xE2\x80\x96\xCF\x89\xCC\x87\xE2\x80\x96 per sample",
                         "\xE2\x80\x96\xCF\x89\xCC\x87\xE2\x80\x96 (rad/s\xC2\xB2)"}};
  const double stride = motion.stride >= 1 ? static_cast<double>(motion.stride) : 1;
  for (const auto& it : items) {
    if (it.y->empty()) continue;
    Series s;
    s.y = *it.y;
    s.line_width = 1;
    s.x.resize(s.y.size());
    for (size_t i = 0; i < s.y.size(); ++i) s.x[i] = static_cast<double>(i) * stride;
    PlotOptions o;
    o.name = it.name;
    o.title = it.title;
    o.x.title = "sample";
    o.y.title = it.unit;
    o.y.include_zero = true;
    o.legend = false;
    o.max_points = 1600;
    out += Figure(RenderXYPlot(o, {s}), "");
  }
  return out;
}

std::string ArrayReport(const JobView& view) {
  results::ArrayResult result;
  std::string message;
  if (!ReadResult(view.job.result, &result, &message))
    return Section("parameters", "Parameters", NotAvailable("The array result (" + message + ")"));
  if (!result.parameters)
    return Section("parameters", "Parameters",
                   NotAvailable("The array result (a failed run's partial diagnostics)"));
  // A result without diagnostics.gyro_unit (one stored by an earlier calibd): the config's.
  std::string& unit =
      result.full ? result.full_diagnostics.gyro_unit : result.diagnostics.gyro_unit;
  if (unit.empty()) {
    const json* configured = Get(view.config, "gyro_unit");
    if (configured != nullptr && configured->is_string()) unit = configured->get<std::string>();
  }
  const auto triads = ReadTriads(result, view.config);
  // Offsets the result does not give (a full-model result stored without parameters.positions)
  // as the table shows them: against the config's geometry.
  for (size_t i = 0; i < triads.size(); ++i) {
    Eigen::Vector3d& offset = result.parameters->positions[i].offset;
    if (!offset.allFinite()) offset = {triads[i].off[0], triads[i].off[1], triads[i].off[2]};
  }
  const results::ArrayPositionsDiagnostics& d = result.diagnostics;
  const results::ArrayFullDiagnostics& fd = result.full_diagnostics;
  std::string out;
  out += Guard("Parameters", [&] {
    std::string s = "<dl class=\"kv\">";
    std::string ref_name = kDash;
    for (const auto& t : triads) {
      if (t.reference) ref_name = t.name;
    }
    s += "<dt>triads K</dt><dd>" + std::to_string(triads.size()) + "</dd>";
    s += "<dt>reference triad</dt><dd>" + E(ref_name) + " (held at its nominal position)</dd>";
    const std::string solver = result.full ? fd.solver : d.solver;
    const std::optional<int> iterations = result.full ? fd.iterations : d.iterations;
    const bool converged = result.full ? fd.converged : d.converged;
    const std::string termination = result.full ? fd.termination : d.termination;
    s += "<dt>solver</dt><dd>" + E(solver) + ", " + Text(iterations) +
         " iterations, converged: " + Text(converged) +
         (termination.empty() ? std::string() : " (" + E(termination) + ")") + "</dd>";
    if (result.full) {
      // The full model: the motion's samples, and the rotation excitation of the whole log.
      const results::ArrayRotationExcitation& x = fd.rotation_excitation;
      s += "<dt>samples</dt><dd>" + Text(fd.dynamic_samples) + " used in motion, " +
           Text(fd.samples_dropped) + " dropped</dd>";
      s += "<dt>rotation excitation</dt><dd>" + VerdictText(x.verdict) + " (smallest eigenvalue " +
           E(Text(x.eigenvalues.minCoeff(), 4)) + ", noise floor " + E(Text(x.noise_floor, 4)) +
           ")</dd>";
    } else {
      s += "<dt>samples</dt><dd>" + Text(d.samples) + " used, " + Text(d.samples_dropped) +
           " dropped</dd>";
      s += "<dt>excitation</dt><dd>" + VerdictText(d.excitation.verdict) +
           " (smallest eigenvalue " + E(Text(d.excitation.min_eigenvalue, 4)) + ", noise floor " +
           E(Text(d.excitation.noise_floor, 4)) + ")</dd>";
    }
    const ArrayFigures f = Figures(result);
    s += "<dt>RMS offset from nominal</dt><dd>" + FormatMicrometres(f.rms_offset) + "</dd>";
    s += "<dt>worst position " + std::string(kSigma) + "</dt><dd>" +
         FormatMicrometres(f.worst_sigma) + "</dd>";
    s += "<dt>" + std::string(kSigma) + " shown</dt><dd class=\"sigma-basis\">" +
         ArraySigmaBasisText(result.uncertainty ? *result.uncertainty
                                                : results::ArrayUncertainty()) +
         "</dd></dl>";
    if (triads.empty()) {
      s += NotAvailable("Triad positions");
    } else {
      s += ArrayParametersTable(triads);
      s += "<p class=\"muted small\">Positions in the nominal geometry's frame; \xCE\x94 is the "
           "offset from the nominal position; \xCF\x83 is one standard deviation: " +
           ArraySigmaBasisText(result.uncertainty ? *result.uncertainty
                                                  : results::ArrayUncertainty()) +
           ".</p>";
    }
    return Section("parameters", "Parameters", s);
  });
  if (result.full) out += ArrayFullSections(result);  // methods/array/array_full_report.h
  out += Guard("Plots", [&] {
    std::string figs;
    figs += Figure(CostPlot(result.full ? fd.cost : d.cost),
                   "Joint Gauss-Newton converges in a handful of iterations; "
                   "block coordinate descent needs hundreds.");
    if (!triads.empty()) {
      figs += Figure(PositionsPlot(triads, 0, 1), "Circles: nominal; crosses: estimated.");
      figs += Figure(PositionsPlot(triads, 0, 2), "");
      figs += Figure(PositionSigmaPlot(triads), "");
    }
    if (!result.full) {  // model full: per triad in ArrayFullSections
      figs += Figure(ArrayResidualPlot(d),
                     "Residual RMS close to the noise level means the model fits.");
      figs += ExcitationPlots(d.motion);
    }
    return Section("plots", "Plots", "<div class=\"plots\">" + figs + "</div>");
  });
  return out;
}

std::string ArrayDrift(const std::vector<const JobSummary*>& jobs) {
  std::vector<std::vector<Triad>> triads;
  std::string unread;  // the jobs whose result does not read, with the reader's message
  for (const auto* j : jobs) {
    results::ArrayResult r;
    std::string message;
    if (ReadResult(j->result, &r, &message)) {
      triads.push_back(ReadTriads(r, json()));
    } else {
      triads.emplace_back();
      unread += NotAvailable("Job #" + std::to_string(j->id) + "'s result (" + message + ")");
    }
  }
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
      rows + "</tbody></table></div>" + OmittedPairsNote(jobs.size()) + unread;
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
  results::ArrayResult r;
  std::string message;
  if (!ReadResult(view.job.error_detail, &r, &message))
    return NotAvailable("The partial diagnostics (" + message + ")");
  std::string s = "<dl class=\"kv partial-array\">";
  if (r.full) {
    const results::ArrayFullDiagnostics& d = r.full_diagnostics;
    s += "<dt>statics</dt><dd>" + Text(d.statics) + " (" + Text(d.static_samples) +
         " samples)</dd><dt>dynamic samples</dt><dd>" + Text(d.dynamic_samples) +
         "</dd><dt>rotation excitation</dt><dd>" + VerdictText(d.rotation_excitation.verdict) +
         "</dd>";
  } else {
    const results::ArrayPositionsDiagnostics& d = r.diagnostics;
    const std::string& verdict = d.excitation.verdict;
    s += "<dt>usable samples</dt><dd>" + Text(d.samples) + " (" + Text(d.samples_dropped) +
         " dropped for gyroscope saturation)</dd><dt>gyroscope triads</dt><dd>" +
         Text(d.gyro_triads) + "</dd><dt>excitation</dt><dd>" +
         (verdict.empty()
              ? std::string("not reached")
              : E(verdict) + " (smallest eigenvalue " + E(Text(d.excitation.min_eigenvalue, 3)) +
                    ", noise floor " + E(Text(d.excitation.noise_floor, 3)) + ")") +
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
};

}  // namespace

const MethodReport& ArrayMethodReport() {
  static const ArrayReportImpl& report = *new ArrayReportImpl();
  return report;
}

}  // namespace calibd::web::internal
