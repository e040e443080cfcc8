#include "web/pages.h"

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

#include "web/device_drift.h"
#include "web/html.h"
#include "web/svg_plot.h"

namespace calibd::web {
namespace {

using json = nlohmann::json;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kPi = 3.14159265358979323846;
constexpr const char* kDash = "\xE2\x80\x93";  // –
constexpr const char* kSigma = "\xCF\x83";     // σ
constexpr const char* kTimes = "\xC3\x97";     // ×

// ---------------------------------------------------------------------------------------------
// Defensive JSON access: never throws, wrong types read as "absent".

const json* Get(const json* j, const char* key) {
  if (j == nullptr || !j->is_object()) return nullptr;
  const auto it = j->find(key);
  return it == j->end() ? nullptr : &*it;
}
const json* Get(const json& j, const char* key) { return Get(&j, key); }

double Num(const json* j) {
  if (j == nullptr || !j->is_number()) return kNaN;
  return j->get<double>();
}

std::string Str(const json* j) {
  if (j == nullptr) return "";
  if (j->is_string()) return j->get<std::string>();
  return "";
}

// A scalar of any type as text (numbers with `sig` digits).
std::string ScalarText(const json* j, int sig = 6) {
  if (j == nullptr || j->is_null()) return kDash;
  if (j->is_boolean()) return j->get<bool>() ? "yes" : "no";
  if (j->is_number_integer()) return j->dump();
  if (j->is_number()) {
    const double v = j->get<double>();
    if (std::isfinite(v) && v == std::round(v) && std::fabs(v) < 1e15) {
      return std::to_string(static_cast<long long>(v));
    }
    return FormatSig(v, sig);
  }
  if (j->is_string()) return j->get<std::string>();
  return j->dump(-1, ' ', false, json::error_handler_t::replace);
}

std::vector<double> NumArray(const json* j) {
  std::vector<double> out;
  if (j == nullptr || !j->is_array()) return out;
  out.reserve(j->size());
  for (const auto& v : *j) out.push_back(v.is_number() ? v.get<double>() : kNaN);
  return out;
}

const json* Array(const json* j) { return (j != nullptr && j->is_array()) ? j : nullptr; }

bool HasNumbers(const std::vector<double>& v) {
  for (double x : v) {
    if (std::isfinite(x)) return true;
  }
  return false;
}

// Pretty JSON with arrays of scalars kept on one line (configs hold long numeric lists).
void CompactPretty(const json& j, int depth, std::string* out) {
  const std::string pad(static_cast<size_t>(2 * (depth + 1)), ' ');
  const std::string pad_end(static_cast<size_t>(2 * depth), ' ');
  if (j.is_object() && !j.empty()) {
    *out += "{\n";
    size_t i = 0;
    for (auto it = j.begin(); it != j.end(); ++it, ++i) {
      *out += pad + json(it.key()).dump(-1, ' ', false, json::error_handler_t::replace) + ": ";
      CompactPretty(it.value(), depth + 1, out);
      *out += i + 1 < j.size() ? ",\n" : "\n";
    }
    *out += pad_end + "}";
    return;
  }
  if (j.is_array() && !j.empty()) {
    bool flat = true;
    for (const auto& v : j) flat = flat && !v.is_structured();
    bool rows = true;  // an array of flat arrays: one row per line
    for (const auto& v : j) {
      rows = rows && v.is_array();
      if (rows) {
        for (const auto& w : v) rows = rows && !w.is_structured();
      }
    }
    if (flat) {
      *out += j.dump(-1, ' ', false, json::error_handler_t::replace);
      return;
    }
    *out += "[\n";
    for (size_t i = 0; i < j.size(); ++i) {
      *out += pad;
      if (rows) {
        *out += j[i].dump(-1, ' ', false, json::error_handler_t::replace);
      } else {
        CompactPretty(j[i], depth + 1, out);
      }
      *out += i + 1 < j.size() ? ",\n" : "\n";
    }
    *out += pad_end + "]";
    return;
  }
  *out += j.dump(-1, ' ', false, json::error_handler_t::replace);
}

std::string PrettyJson(const json& j) {
  try {
    std::string out;
    CompactPretty(j, 0, &out);
    return out;
  } catch (const std::exception&) {
    return "(not available)";
  }
}

std::string Dump(const json& j, int indent) {
  try {
    return j.dump(indent, ' ', false, json::error_handler_t::replace);
  } catch (const std::exception&) {
    return "(not available)";
  }
}

// ---------------------------------------------------------------------------------------------
// Small HTML helpers.

std::string E(const std::string& s) { return EscapeText(s); }
std::string A(const std::string& s) { return EscapeAttr(s); }

std::string NumCell(const std::string& text) { return "<td class=\"num\">" + text + "</td>"; }
std::string NumCell(double v, int sig = 4) { return NumCell(FormatSig(v, sig)); }

std::string DeviceLink(const std::string& serial) {
  if (serial.empty()) return "<span class=\"muted\">(none)</span>";
  return "<a href=\"/devices/" + A(UrlEncode(serial)) + "\">" + E(serial) + "</a>";
}

std::string JobLink(int64_t id) {
  return "<a href=\"/jobs/" + std::to_string(id) + "\">#" + std::to_string(id) + "</a>";
}

std::string FormatUnixTime(double t, bool seconds) {
  if (!std::isfinite(t) || std::fabs(t) > 1e12) return kDash;
  const auto tt = static_cast<time_t>(std::floor(t));
  std::tm tm{};
  if (gmtime_r(&tt, &tm) == nullptr) return kDash;
  char buf[64];
  std::strftime(buf, sizeof(buf), seconds ? "%Y-%m-%d %H:%M:%S" : "%Y-%m-%d %H:%M", &tm);
  return std::string(buf) + " UTC";
}

// A stored timestamp shown uniformly; unparseable ones are shown as stored (escaped).
std::string TimeHtml(const std::string& stored, bool seconds = false) {
  if (stored.empty()) return "<span class=\"muted\">" + std::string(kDash) + "</span>";
  double t;
  if (ParseTimestamp(stored, &t)) {
    return "<time datetime=\"" + A(stored) + "\">" + FormatUnixTime(t, seconds) + "</time>";
  }
  return E(stored);
}

double Seconds(const std::string& stored) {
  double t;
  return ParseTimestamp(stored, &t) ? t : kNaN;
}

std::string Section(const std::string& id, const std::string& title, const std::string& body) {
  return "<section id=\"" + id + "\"><h2>" + E(title) + "</h2>" + body + "</section>";
}

std::string Figure(const std::string& svg, const std::string& caption) {
  return "<figure>" + svg + (caption.empty() ? "" : "<figcaption>" + E(caption) + "</figcaption>") +
         "</figure>";
}

std::string NotAvailable(const std::string& what) {
  return "<p class=\"muted not-available\">" + E(what) + ": not available.</p>";
}

// Runs a section renderer; a failure there (an unexpected JSON shape, a bug) costs that section
// only.
template <typename F>
std::string Guard(const std::string& what, F&& f) {
  try {
    return f();
  } catch (const std::exception&) {
    return NotAvailable(what);
  } catch (...) {
    return NotAvailable(what);
  }
}

// Largest 1-2-5 number <= v (>= 1).
double NiceFactorBelow(double v) {
  if (!std::isfinite(v) || v <= 1) return 1;
  const double mag = std::pow(10.0, std::floor(std::log10(v)));
  const double n = v / mag;
  const double nice = n >= 5 ? 5 : (n >= 2 ? 2 : 1);
  return nice * mag;
}

std::string FactorText(double k) {
  if (std::isfinite(k) && k >= 1 && k < 1e15 && k == std::round(k)) {
    return kTimes + std::to_string(static_cast<long long>(k));
  }
  return kTimes + FormatSig(k, 3);
}

std::string Warnings(const json& result) {
  const json* w = Array(Get(result, "warnings"));
  if (w == nullptr || w->empty()) return "";
  std::string out = "<div class=\"callout callout-warn\"><p><strong>" + std::to_string(w->size()) +
                    (w->size() == 1 ? " warning" : " warnings") +
                    "</strong></p><ul class=\"warnings\">";
  for (const auto& item : *w)
    out += "<li>" + E(item.is_string() ? item.get<std::string>() : Dump(item, -1)) + "</li>";
  return out + "</ul></div>";
}

size_t WarningCount(const json& result) {
  const json* w = Array(Get(result, "warnings"));
  return w == nullptr ? 0 : w->size();
}

// ---------------------------------------------------------------------------------------------
// Key figures.

struct PcaFigures {
  double worst_rel_scale_std = kNaN;  // max σ(scale)/scale
  double worst_scale_std = kNaN;
  double rank_gap = kNaN;
};

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

struct ArrayFigures {
  double rms_offset = kNaN;   // metres, over the non-reference triads
  double worst_sigma = kNaN;  // metres, max over all coordinates
};

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

std::string Percent(double rel) {
  if (!std::isfinite(rel)) return kDash;
  if (rel < 1e-3) return FormatSig(rel * 1e6, 2) + " ppm";
  return FormatSig(rel * 100, 2) + " %";
}

// ---------------------------------------------------------------------------------------------
// Diagnostics table (in the spirit of Ceres' FullReport).

const char* DiagnosticMeaning(const std::string& key) {
  static const std::map<std::string, const char*>& kMeaning =
      *new std::map<std::string, const char*>{
          {"singular_values", "all singular values of the m\xC3\x97n reading matrix"},
          {"rank_gap",
           "\xCF\x83_d / \xCF\x83_{d+1}: a large gap means the readings span exactly d directions"},
          {"positions", "static positions used (n)"},
          {"min_positions", "the minimum n = d(d+1)/2"},
          {"g_eigenvalues", "eigenvalues of g; all must be positive"},
          {"residual_rms", "RMS of the model residual (per sensor, or per sensor type)"},
          {"magnitude_error", "field magnitude error per position"},
          {"solver", "joint Gauss-Newton (Schur complement) or block coordinate descent"},
          {"iterations", "iterations (joint) or sweeps (bcd) run"},
          {"converged", "the cost change fell below the tolerance"},
          {"cost", "cost per iteration"},
          {"samples", "samples used"},
          {"samples_dropped", "samples dropped (saturation, non-finite)"},
          {"noise_estimate", "noise level estimated from the residuals"},
          {"termination", "why the solver stopped"},
          {"usable", "whether the preconditions of the method hold"},
          {"reason", "why the result is not usable"},
          {"noise_std", "reading noise \xCF\x83 used for the uncertainties"},
          {"noise_std_estimated", "reading noise \xCF\x83 estimated from the residuals"},
          {"degrees_of_freedom", "residual degrees of freedom"},
          {"refined", "maximum-likelihood refinement ran after the closed form"},
          {"reflection",
           "true: the estimated axes match the nominal ones as a mirror image (the Procrustes "
           "fit has determinant \xE2\x88\x92"
           "1). The readings cannot tell left- from "
           "right-handed axes (the paper's Remark 1), so either value is normal and the "
           "parameters are valid; only a nominal whose handedness differs from the wiring "
           "would hide behind it"},
          {"noise_configured.accelerometer", "\xCF\x83_a from the config"},
          {"noise_configured.gyroscope", "\xCF\x83_g from the config"},
          {"excitation.verdict", "whether the motion determines every position direction"},
          {"excitation.min_eigenvalue",
           "smallest eigenvalue of \xCE\xA3 A\xE2\x82\x99\xE1\xB5\x80"
           "A\xE2\x82\x99"},
          {"excitation.noise_floor", "eigenvalues below this are not determined"},
          {"excitation.weakest_direction", "direction of the smallest eigenvalue"},
          {"motion.stride", "every stride-th sample kept for the excitation plots"},
          {"parallel_fraction", "share of the work run in parallel"},
          {"gyro_triads", "gyroscope triads used"},
          {"excitation",
           "smallest eigenvalue of \xCE\xA3 A\xE2\x82\x99\xE1\xB5\x80"
           "A\xE2\x82\x99 and a verdict"},
      };
  const auto it = kMeaning.find(key);
  return it == kMeaning.end() ? "" : it->second;
}

std::string SummariseArray(const json& arr) {
  if (arr.empty()) return "(empty)";
  bool all_numbers = true;
  for (const auto& v : arr) all_numbers = all_numbers && v.is_number();
  bool all_strings = true;
  for (const auto& v : arr) all_strings = all_strings && v.is_string();
  if (all_strings && arr.size() > 8) {
    std::string s = std::to_string(arr.size()) + " labels: ";
    for (size_t i = 0; i < 5; ++i) s += arr[i].get<std::string>() + ", ";
    return E(s + "\xE2\x80\xA6, " + arr.back().get<std::string>());
  }
  if (!all_numbers) {
    std::string s = Dump(arr, -1);
    if (s.size() > 300) s = s.substr(0, 300) + "\xE2\x80\xA6";
    return E(s);
  }
  std::vector<double> v = NumArray(&arr);
  if (v.size() <= 8) {
    std::string s;
    for (size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + FormatSig(v[i], 5);
    return "<span class=\"mono\">[" + s + "]</span>";
  }
  std::vector<double> sorted;
  for (double x : v) {
    if (std::isfinite(x)) sorted.push_back(x);
  }
  std::sort(sorted.begin(), sorted.end());
  std::string s = std::to_string(v.size()) + " values";
  if (!sorted.empty()) {
    s += ": min " + FormatSig(sorted.front(), 4) + ", median " +
         FormatSig(sorted[sorted.size() / 2], 4) + ", max " + FormatSig(sorted.back(), 4) +
         "; first " + FormatSig(v.front(), 4) + ", last " + FormatSig(v.back(), 4);
  }
  return E(s);
}

void DiagnosticRows(const std::string& prefix, const json& obj, int depth, std::string* rows) {
  for (auto it = obj.begin(); it != obj.end(); ++it) {
    const std::string key = prefix.empty() ? it.key() : prefix + "." + it.key();
    const json& v = it.value();
    if (v.is_object() && depth < 3 && !v.empty()) {
      DiagnosticRows(key, v, depth + 1, rows);
      continue;
    }
    std::string value;
    if (v.is_array()) {
      value = SummariseArray(v);
    } else if (v.is_object()) {
      std::string s = Dump(v, -1);
      if (s.size() > 300) s = s.substr(0, 300) + "\xE2\x80\xA6";
      value = E(s);
    } else {
      value = E(ScalarText(&v, 6));
    }
    const std::string top = prefix.empty() ? it.key() : prefix.substr(0, prefix.find('.'));
    *rows += "<tr><th scope=\"row\" class=\"mono\">" + E(key) + "</th><td>" + value +
             "</td><td class=\"muted small\">" + E(DiagnosticMeaning(key)) + "</td></tr>";
  }
}

std::string DiagnosticsSection(const json& result) {
  const json* d = Get(result, "diagnostics");
  std::string body;
  if (d == nullptr || !d->is_object() || d->empty()) {
    body = NotAvailable("Diagnostics");
  } else {
    std::string rows;
    DiagnosticRows("", *d, 0, &rows);
    body =
        "<div class=\"table-wrap\"><table class=\"table-diagnostics\"><thead><tr><th>key</th>"
        "<th>value</th><th>meaning</th></tr></thead><tbody>" +
        rows + "</tbody></table></div>";
  }
  std::string warnings = Warnings(result);
  if (warnings.empty()) warnings = "<p class=\"muted\">No warnings.</p>";
  return Section("diagnostics", "Diagnostics and warnings", warnings + body);
}

// ---------------------------------------------------------------------------------------------
// pca report.

// Unit vector of the first min(d,3) components (NaN when not available).
std::vector<double> Unit(const std::vector<double>& a) {
  double n = 0;
  for (double x : a) n += x * x;
  n = std::sqrt(n);
  std::vector<double> out(a.size(), kNaN);
  if (!(n > 0) || !std::isfinite(n)) return out;
  for (size_t i = 0; i < a.size(); ++i) out[i] = a[i] / n;
  return out;
}

double AngleBetween(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.size() != b.size() || a.empty()) return kNaN;
  const auto ua = Unit(a), ub = Unit(b);
  double dot = 0;
  for (size_t i = 0; i < a.size(); ++i) dot += ua[i] * ub[i];
  if (!std::isfinite(dot)) return kNaN;
  dot = std::max(-1.0, std::min(1.0, dot));
  // acos is ill-conditioned near 1: use the cross-product norm via the difference.
  double diff = 0;
  for (size_t i = 0; i < a.size(); ++i) diff += (ua[i] - ub[i]) * (ua[i] - ub[i]);
  const double chord = std::sqrt(diff);
  return 2 * std::asin(std::min(1.0, chord / 2));
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

// ---------------------------------------------------------------------------------------------
// array report.

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

double Norm3(const double* v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

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
    figs += Figure(ArrayResidualPlot(dj, view.config),
                   "Residual RMS close to the noise level means the model fits.");
    figs += ResidualHistograms(dj);
    figs += ExcitationPlots(dj);
    return Section("plots", "Plots", "<div class=\"plots\">" + figs + "</div>");
  });
  return out;
}

// ---------------------------------------------------------------------------------------------
// noise and imu reports.

std::vector<double> Doubles(const json* j) {
  std::vector<double> out;
  if (j == nullptr || !j->is_array()) return out;
  for (const json& v : *j) out.push_back(v.is_number() ? v.get<double>() : kNaN);
  return out;
}

// "1.23e-4 ± 2.1e-6" or "not visible" for a null term.
std::string TermCell(const json* value, const json* std) {
  const double v = Num(value), s = Num(std);
  if (!std::isfinite(v)) return "<td class=\"num muted\">not visible</td>";
  return NumCell(FormatSig(v, 4) + (std::isfinite(s) ? " \xC2\xB1 " + FormatSig(s, 2) : ""));
}

// Log-log Allan deviation of the channels of one sensor type, with their confidence bands and
// the fitted model.
std::string AllanPlot(const json* diag, char kind, const std::string& unit) {
  const json* allan = Get(diag, "allan");
  if (allan == nullptr || !allan->is_array()) return "";
  std::vector<Series> series;
  int color = 0;
  for (const json& c : *allan) {
    const std::string name = Str(Get(c, "name"));
    if (name.empty() || name[0] != kind) continue;
    Series data;
    data.label = name;
    data.x = Doubles(Get(c, "tau"));
    data.y = Doubles(Get(c, "adev"));
    data.marker = Marker::kCircle;
    data.color = color;
    for (const char* bound : {"adev_lower", "adev_upper"}) {
      Series b;
      b.x = data.x;
      b.y = Doubles(Get(c, bound));
      b.color = color;
      b.dashed = true;
      b.line_width = 0.8;
      if (b.y.size() == b.x.size()) series.push_back(b);
    }
    Series fit;
    fit.x = data.x;
    fit.y = Doubles(Get(c, "fitted_adev"));
    fit.color = color;
    fit.line_width = 2.4;
    series.push_back(std::move(data));
    if (fit.y.size() == fit.x.size()) series.push_back(std::move(fit));
    ++color;
  }
  if (series.empty()) return "";
  PlotOptions o;
  o.name = std::string("allan-") + (kind == 'a' ? "accel" : "gyro");
  o.title = std::string(kind == 'a' ? "Accelerometers" : "Gyroscopes") + ": Allan deviation";
  o.x.title = "cluster time \xCF\x84 (s)";
  o.x.type = ScaleType::kLog10;
  o.y.title = "Allan deviation \xCF\x83(\xCF\x84) (" + unit + ")";
  o.y.type = ScaleType::kLog10;
  o.ref_lines.push_back({true, 1.0, "\xCF\x84 = 1 s: N", true});
  o.ref_lines.push_back({true, 3.0, "\xCF\x84 = 3 s: K", true});
  return Figure(RenderXYPlot(o, series),
                "Circles: overlapping Allan deviation; dashed: its confidence interval; thick: "
                "the fitted model N\xC2\xB2/\xCF\x84 + (0.664 B)\xC2\xB2 + K\xC2\xB2\xCF\x84/3. "
                "Slope \xE2\x88\x92\xC2\xBD: white noise (read at 1 s), flat: bias instability, "
                "+\xC2\xBD: random walk (read at 3 s).");
}

std::string NoiseReport(const JobView& view) {
  const json& result = view.job.result;
  const json* params = Get(result, "parameters");
  const json* unc = Get(result, "uncertainty");
  const json* diag = Get(result, "diagnostics");
  std::string out;
  out += Guard("Parameters", [&] {
    std::string s = "<dl class=\"kv\">";
    s += "<dt>sample rate</dt><dd>" + E(ScalarText(Get(diag, "rate"), 6)) + " Hz</dd>";
    s += "<dt>samples</dt><dd>" + E(ScalarText(Get(diag, "samples"))) + " (" +
         FormatDuration(Num(Get(diag, "duration"))) + ")</dd>";
    const json* st = Get(diag, "stationary");
    s += "<dt>stationary</dt><dd>" +
         std::string(st != nullptr && st->is_boolean() && st->get<bool>()
                         ? "yes"
                         : "no: the sensor moved, the Allan curve is meaningless") +
         "</dd></dl>";
    const json* channels = Get(params, "channels");
    const json* uch = Get(unc, "channels");
    if (channels == nullptr || !channels->is_array() || channels->empty()) {
      return Section("parameters", "Parameters", s + NotAvailable("Channels"));
    }
    s += "<div class=\"table-wrap\"><table class=\"table-noise-parameters\"><thead><tr>"
         "<th>channel</th><th>unit</th><th>white noise N (unit/\xE2\x88\x9AHz)</th>"
         "<th>bias instability B (unit)</th><th>at \xCF\x84 (s)</th>"
         "<th>random walk K (unit/s/\xE2\x88\x9AHz)</th></tr></thead><tbody>";
    for (size_t i = 0; i < channels->size(); ++i) {
      const json& c = (*channels)[i];
      const json* u = uch != nullptr && uch->is_array() && i < uch->size() ? &(*uch)[i] : nullptr;
      s += "<tr><td>" + E(Str(Get(c, "name"))) + "</td><td>" + E(Str(Get(c, "unit"))) + "</td>" +
           TermCell(Get(c, "white_noise"), Get(u, "white_noise_std")) +
           TermCell(Get(c, "bias_instability"), Get(u, "bias_instability_std")) +
           NumCell(Num(Get(c, "bias_instability_tau")), 3) +
           TermCell(Get(c, "random_walk"), Get(u, "random_walk_std")) + "</tr>";
    }
    s += "</tbody></table></div><p class=\"muted small\">\xC2\xB1 is one standard deviation. "
         "N and K are Kalibr's noise_density and random_walk "
         "(<a href=\"/api/v1/devices/" +
         A(UrlEncode(view.job.device)) +
         "/calibration?method=noise&amp;format=yaml\">imu.yaml</a>). A term the log is too short "
         "to show is \"not visible\"; the warnings say how long a log would show it.</p>";
    return Section("parameters", "Parameters", s);
  });
  out += Guard("Plots", [&] {
    std::string figs = AllanPlot(diag, 'a', "m/s\xC2\xB2") + AllanPlot(diag, 'g', "rad/s");
    if (figs.empty()) return NotAvailable("The Allan deviation plots");
    return Section("plots", "Plots", "<div class=\"plots\">" + figs + "</div>");
  });
  return out;
}

std::string Vec3Cell(const json* v, int sig = 6) {
  std::string text;
  for (size_t k = 0; k < 3; ++k) {
    const json* x = v != nullptr && v->is_array() && k < v->size() ? &(*v)[k] : nullptr;
    text += (k ? "<br>" : "") + FormatSig(Num(x), sig);  // x, y, z stacked: fits 1280 px
  }
  return NumCell(text);
}

// One figure per item of `items` (1-based index on x): `before` and `after` (keys of each item)
// as open and filled circles; "" when there are no items.
std::string BeforeAfterPlot(const json* items, const char* before_key, const char* after_key,
                            PlotOptions options, const std::string& caption) {
  if (items == nullptr || !items->is_array() || items->empty()) return "";
  Series before, after;
  before.label = "nominal conversion";
  after.label = "calibrated";
  before.marker = Marker::kOpenCircle;
  after.marker = Marker::kCircle;
  before.line = after.line = false;
  for (size_t j = 0; j < items->size(); ++j) {
    before.x.push_back(static_cast<double>(j + 1));
    after.x.push_back(static_cast<double>(j + 1));
    before.y.push_back(Num(Get((*items)[j], before_key)));
    after.y.push_back(Num(Get((*items)[j], after_key)));
  }
  options.y.include_zero = true;
  return Figure(RenderXYPlot(options, {before, after}), caption);
}

std::string ImuReport(const JobView& view) {
  const json& result = view.job.result;
  const json* params = Get(result, "parameters");
  const json* unc = Get(result, "uncertainty");
  const json* diag = Get(result, "diagnostics");
  const json* imus = Get(params, "imus");
  std::string out;
  out += Guard("Parameters", [&] {
    std::string s = "<dl class=\"kv\"><dt>gravity</dt><dd>" +
                    E(ScalarText(Get(params, "gravity"), 7)) +
                    " m/s\xC2\xB2</dd><dt>gyroscope bias</dt><dd>" +
                    E(ScalarText(Get(params, "gyro_bias"))) + "</dd><dt>static intervals</dt><dd>";
    const json* statics = Get(diag, "statics");
    s += std::to_string(statics != nullptr && statics->is_array() ? statics->size() : 0) + " (" +
         E(Str(Get(diag, "threshold_choice"))) + ")</dd></dl>";
    if (imus == nullptr || !imus->is_array() || imus->empty()) {
      return Section("parameters", "Parameters", s + NotAvailable("IMUs"));
    }
    s += "<div class=\"table-wrap\"><table class=\"table-imu-parameters\"><thead><tr>"
         "<th>IMU</th><th>sensor</th><th>bias b, x y z<br>(reading units)</th>"
         "<th>\xCF\x83(b)<br>(reading units)</th><th>scale K, x y z<br>(SI per reading unit)</th>"
         "<th>\xCF\x83(K)<br>(SI per reading unit)</th><th>misalignment T<br>(3 rows, unitless)"
         "</th></tr></thead><tbody>";
    const json* uimus = Get(unc, "imus");
    for (size_t i = 0; i < imus->size(); ++i) {
      const json& imu = (*imus)[i];
      const json* u =
          uimus != nullptr && uimus->is_array() && i < uimus->size() ? &(*uimus)[i] : nullptr;
      for (const char* sensor : {"accelerometer", "gyroscope"}) {
        const json* p = Get(imu, sensor);
        const json* ps = Get(u, sensor);
        const json* t = Get(p, "misalignment");
        std::string rows;
        for (size_t r = 0; r < 3; ++r) {
          const json* row = t != nullptr && t->is_array() && r < t->size() ? &(*t)[r] : nullptr;
          std::string cells;
          for (size_t k = 0; k < 3; ++k) {
            const json* x =
                row != nullptr && row->is_array() && k < row->size() ? &(*row)[k] : nullptr;
            cells += (k ? " " : "") + FormatFixed(Num(x), 5);
          }
          rows += (r ? "<br>" : "") + cells;
        }
        s += "<tr><td>" + E(Str(Get(imu, "name"))) + "</td><td>" + sensor + "</td>" +
             Vec3Cell(Get(p, "bias")) + Vec3Cell(Get(ps, "bias_std"), 2) +
             Vec3Cell(Get(p, "scale")) + Vec3Cell(Get(ps, "scale_std"), 2) +
             "<td class=\"num small\">" + rows + "</td></tr>";
      }
    }
    s += "</tbody></table></div><p class=\"muted small\">The parameters of the model above. T_a "
         "is upper triangular: the body frame is the accelerometer's (x along its x axis, y in its "
         "x-y plane). \xCF\x83 is one standard deviation from the Fisher information at the "
         "estimate.</p>";
    return Section("parameters", "Parameters", s);
  });
  out += Guard("Fit", [&] {
    const json* d = Get(diag, "imus");
    if (d == nullptr || !d->is_array()) return std::string();
    std::string s, figs;
    for (const json& imu : *d) {
      const json* res = Get(imu, "residuals");
      const json* cov = Get(imu, "coverage");
      s += "<h3>IMU " + E(Str(Get(imu, "name"))) + "</h3><dl class=\"kv\">";
      s += "<dt>|a| \xE2\x88\x92 g over the statics (RMS)</dt><dd>" +
           FormatSI(Num(Get(res, "accel_norm_rms_before")), "m/s\xC2\xB2") + " before, " +
           FormatSI(Num(Get(res, "accel_norm_rms_after")), "m/s\xC2\xB2") + " after</dd>";
      s += "<dt>gravity direction after each rotation (RMS)</dt><dd>" +
           FormatSI(Num(Get(res, "gyro_direction_rms_before")), "rad") + " before, " +
           FormatSI(Num(Get(res, "gyro_direction_rms_after")), "rad") + " after</dd>";
      s += "<dt>\xCF\x87\xC2\xB2 / degrees of freedom</dt><dd>" +
           E(ScalarText(Get(imu, "chi2_per_dof"), 3)) + "</dd>";
      s += "<dt>orientation coverage</dt><dd>" + E(Str(Get(cov, "verdict"))) +
           " (smallest eigenvalue " + E(ScalarText(Get(cov, "min_eigenvalue"), 3)) +
           ", 1 = evenly spread)</dd></dl>";
      PlotOptions o;
      o.name = "imu-gravity-norm";
      o.title = "|a| \xE2\x88\x92 g per static interval";
      o.x.title = "static interval";
      o.y.title = "|a| \xE2\x88\x92 g (m/s\xC2\xB2)";
      figs += BeforeAfterPlot(Get(imu, "statics"), "norm_residual_before", "norm_residual_after", o,
                              "Each static's specific force should have the magnitude of gravity.");
      o.name = "imu-rotation-error";
      o.title = "Gravity direction error after each rotation";
      o.x.title = "rotation (between statics j and j+1)";
      o.y.title = "angle (rad)";
      figs += BeforeAfterPlot(Get(imu, "rotations"), "direction_error_before",
                              "direction_error_after", o,
                              "The integrated gyroscope must carry gravity's direction from one "
                              "static to the next.");
    }
    return Section("fit", "Fit", s + "<div class=\"plots\">" + figs + "</div>");
  });
  return out;
}

// ---------------------------------------------------------------------------------------------
// Job page pieces.

std::string TimingsHtml(const JobSummary& job) {
  const double c = Seconds(job.created_at), s = Seconds(job.started_at),
               f = Seconds(job.finished_at);
  std::string out = "<dt>created</dt><dd>" + TimeHtml(job.created_at, true) + "</dd>";
  out += "<dt>started</dt><dd>" + TimeHtml(job.started_at, true);
  if (std::isfinite(c) && std::isfinite(s)) out += " (waited " + FormatDuration(s - c) + ")";
  out += "</dd><dt>finished</dt><dd>" + TimeHtml(job.finished_at, true);
  if (std::isfinite(s) && std::isfinite(f)) out += " (ran " + FormatDuration(f - s) + ")";
  out += "</dd><dt>attempts</dt><dd>" + std::to_string(job.attempts) + "</dd>";
  return out;
}

// The export formats of a method's calibration (GET .../calibration?format=).
std::string ExportLinks(const std::string& base, const std::string& method) {
  std::string out = "<a href=\"" + A(base + "json") + "\">JSON</a> \xC2\xB7 <a href=\"" +
                    A(base + "csv") + "\">CSV</a>";
  out += " \xC2\xB7 <a href=\"" + A(base + "h") + "\">C header</a>";
  if (method == "noise") {
    out += " \xC2\xB7 <a href=\"" + A(base + "yaml") + "\">Kalibr imu.yaml</a>";
  }
  return out;
}

std::string DownloadsHtml(const JobView& view) {
  const JobSummary& job = view.job;
  std::string out = "<ul class=\"downloads\">";
  out += "<li><a href=\"/api/v1/jobs/" + std::to_string(job.id) +
         "\">This job and its result (JSON)</a></li>";
  if (view.recording_id > 0) {
    out += "<li><a href=\"/api/v1/recordings/" + std::to_string(view.recording_id) +
           "/data\">Recording (original CSV)</a></li>";
  }
  if (!job.device.empty() && !job.method.empty()) {
    const std::string base = "/api/v1/devices/" + UrlEncode(job.device) +
                             "/calibration?method=" + UrlEncode(job.method) + "&format=";
    out += "<li>Latest " + E(job.method) + " calibration of " + E(job.device) +
           " (may be newer than this report): " + ExportLinks(base, job.method) + "</li>";
  }
  return out + "</ul>";
}

std::string StatusCallout(const JobView& view) {
  const JobSummary& job = view.job;
  if (job.status == "failed") {
    std::string out =
        "<div class=\"callout callout-error\"><p><strong>The calibration failed."
        "</strong></p><p class=\"failure-reason\">" +
        (job.error.empty() ? std::string("No reason was recorded.") : E(job.error)) + "</p>";
    // The method's message is the one source of what was wrong and what to record or set
    // instead (it knows the configuration it ran with); the page adds nothing that could repeat
    // or contradict it.
    if (!job.error.empty()) {
      out +=
          "<p class=\"muted small\">This is the method's own account: what it needed, what it "
          "found, and what to record or change instead.</p>";
    }
    return out + "</div>";
  }
  if (job.status == "queued" || job.status == "running") {
    return "<div class=\"callout\"><p>This job is " + E(job.status) +
           ". Reload the page to see the result when it has finished.</p></div>";
  }
  if (job.status == "succeeded") {
    // A pca result whose preconditions failed (diagnostics.usable == false) says why.
    const json* usable = Get(Get(job.result, "diagnostics"), "usable");
    if (usable != nullptr && usable->is_boolean() && !usable->get<bool>()) {
      const std::string reason = Str(Get(Get(job.result, "diagnostics"), "reason"));
      return "<div class=\"callout callout-error\"><p><strong>The result is not usable.</strong>"
             "</p><p class=\"failure-reason\">" +
             E(reason.empty() ? std::string("The method's preconditions do not hold.") : reason) +
             "</p></div>";
    }
    const size_t w = WarningCount(job.result);
    if (w > 0) {
      return "<div class=\"callout callout-warn\"><p><strong>Succeeded with " + std::to_string(w) +
             (w == 1 ? " warning" : " warnings") +
             "</strong>: read them under <a href=\"#diagnostics\">Diagnostics</a> before using "
             "these parameters.</p></div>";
    }
    return "<div class=\"callout callout-ok\"><p><strong>Succeeded</strong> without warnings."
           "</p></div>";
  }
  return "";
}

// A badge for a result the gate rejected or a person revoked, with the reason in words ("" for
// an accepted result: the usual case needs no mark).
std::string VerdictBadge(const JobSummary& job) {
  const std::string state = GateState(job);
  if (state != "rejected" && state != "revoked") return "";
  std::string reason;
  if (state == "revoked") {
    for (const auto& e : job.events) {
      if (e.action == "revoke") reason = e.reason;
    }
  } else if (const json* reasons = Array(Get(Get(job.result, "verdict"), "reasons"))) {
    if (!reasons->empty() && (*reasons)[0].is_string()) reason = (*reasons)[0].get<std::string>();
    if (reasons->size() > 1) reason += " (+" + std::to_string(reasons->size() - 1) + " more)";
  }
  std::string shown = reason;
  if (shown.size() > 140) shown = shown.substr(0, 140) + "\xE2\x80\xA6";
  return " <span class=\"badge badge-" + state + "\" title=\"" + E(reason) + "\">" + state +
         "</span>" +
         (shown.empty() ? "" : "<span class=\"verdict-reason\">" + E(shown) + "</span>");
}

// The report's verdict block: what the gate decided and why, and every decision since.
std::string VerdictSection(const JobSummary& job) {
  const std::string state = GateState(job);
  if (state.empty()) return "";
  const json* verdict = Get(job.result, "verdict");
  std::string out;
  const json* reasons = Array(Get(verdict, "reasons"));
  const std::string gate = Str(Get(verdict, "status"));
  if (state == "accepted") {
    out += "<div class=\"callout callout-ok verdict\"><p><strong>Accepted</strong>" +
           std::string(gate == "rejected" ? " by a person, overriding the acceptance gate"
                                          : " by the acceptance gate") +
           ": this result is served as the device's calibration when it is the latest "
           "accepted one.</p>";
  } else if (state == "rejected") {
    out +=
        "<div class=\"callout callout-error verdict\"><p><strong>Rejected by the acceptance "
        "gate</strong>: this result is never served to production tooling. Record again "
        "as advised, or accept it with a reason (POST /api/v1/jobs/" +
        std::to_string(job.id) + "/accept).</p>";
  } else {
    out +=
        "<div class=\"callout callout-warn verdict\"><p><strong>Revoked</strong>: withdrawn "
        "by a person; the device's calibration fell back to its previous accepted one.</p>";
  }
  if (reasons != nullptr && !reasons->empty()) {
    out += "<p>The gate's reasons:</p><ul class=\"verdict-reasons\">";
    for (const auto& r : *reasons)
      out += "<li>" + E(r.is_string() ? r.get<std::string>() : r.dump()) + "</li>";
    out += "</ul>";
  }
  out += "</div>";
  if (!job.events.empty()) {
    out +=
        "<div class=\"table-wrap\"><table class=\"table-events\"><thead><tr><th>when</th>"
        "<th>decision</th><th>by</th><th>reason</th></tr></thead><tbody>";
    for (const auto& e : job.events) {
      out += "<tr><td class=\"time\">" + TimeHtml(e.at) + "</td><td>" + E(e.action) + "</td><td>" +
             E(e.actor) + "</td><td>" + E(e.reason) + "</td></tr>";
    }
    out += "</tbody></table></div>";
  }
  return out;
}

std::string JobBody(const JobView& view) {
  const JobSummary& job = view.job;
  std::string out;
  out += "<h1>Calibration #" + std::to_string(job.id) + " \xC2\xB7 " +
         E(job.method.empty() ? std::string("?") : job.method) +
         (job.device.empty() ? "" : " \xC2\xB7 " + E(job.device)) + " " + StatusBadge(job.status) +
         (GateState(job) == "rejected" || GateState(job) == "revoked"
              ? " <span class=\"badge badge-" + GateState(job) + "\">" + GateState(job) + "</span>"
              : std::string()) +
         "</h1>";
  out += VerdictSection(job);
  out += StatusCallout(view);
  // Header facts.
  std::string kv = "<dl class=\"kv job-header\"><dt>device</dt><dd>" + DeviceLink(job.device) +
                   "</dd><dt>method</dt><dd>" + E(job.method) + "</dd><dt>status</dt><dd>" +
                   StatusBadge(job.status) + "</dd><dt>recording</dt><dd>";
  if (view.recording_id > 0) {
    kv += "<a href=\"/api/v1/recordings/" + std::to_string(view.recording_id) + "/data\">#" +
          std::to_string(view.recording_id) + " (download CSV)</a>";
    if (view.recording_bytes >= 0)
      kv += ", " + FormatSI(static_cast<double>(view.recording_bytes), "B");
    if (view.recording_rows >= 0) kv += ", " + std::to_string(view.recording_rows) + " rows";
    if (!view.recording_sha256.empty()) {
      kv += ", <span class=\"mono small\">sha256 " + E(view.recording_sha256.substr(0, 16)) +
            "\xE2\x80\xA6</span>";
    }
    kv += " \xC2\xB7 <a href=\"/recordings/" + std::to_string(view.recording_id) +
          "\">recording page</a>";
  } else {
    kv += kDash;
  }
  kv += "</dd>";
  // An array job that used a pca calibration of its accelerometers links to it (issue #8).
  const json* accel_cal = Get(Get(job.result, "diagnostics"), "accelerometer_calibration");
  if (accel_cal != nullptr && accel_cal->is_object()) {
    kv += "<dt>accelerometers</dt><dd class=\"accelerometer-calibration\">";
    const json* cal_job = Get(accel_cal, "job");
    if (cal_job != nullptr && cal_job->is_number_integer()) {
      const std::string id = std::to_string(cal_job->get<int64_t>());
      kv +=
          "corrected with the pca calibration of <a href=\"/jobs/" + id + "\">job #" + id + "</a>";
    } else {
      kv += "corrected with a pca calibration given inline";
    }
    const json* sensors = Get(accel_cal, "sensors");
    if (sensors != nullptr && sensors->is_number_integer()) {
      kv += " (" + std::to_string(sensors->get<int64_t>()) + " sensors)";
    }
    kv += "</dd>";
  }
  // Noise levels taken from noise jobs ({"job": ID} in the config) link to them (SPEC §7).
  const json* noise_jobs = Get(Get(job.result, "diagnostics"), "noise_jobs");
  if (noise_jobs != nullptr && noise_jobs->is_object()) {
    std::string links;
    for (const char* sensor : {"accelerometer", "gyroscope"}) {
      const json* id = Get(noise_jobs, sensor);
      if (id == nullptr || !id->is_number_integer()) continue;
      const std::string n = std::to_string(id->get<int64_t>());
      links += std::string(links.empty() ? "" : "; ") + sensor + " from <a href=\"/jobs/" + n +
               "\">noise job #" + n + "</a>";
    }
    if (!links.empty()) kv += "<dt>noise levels</dt><dd class=\"noise-jobs\">" + links + "</dd>";
  }
  kv += TimingsHtml(job) + "</dl>";
  out += kv;
  if (!view.config.is_null()) {
    const std::string pretty = PrettyJson(view.config);
    const bool short_config = std::count(pretty.begin(), pretty.end(), '\n') <= 24;
    out += std::string("<details") + (short_config ? " open" : "") +
           "><summary>Configuration</summary><pre class=\"config\">" + E(pretty) +
           "</pre></details>";
  }
  out += Section("downloads", "Downloads", DownloadsHtml(view));
  const bool has_result = job.result.is_object() && !job.result.empty();
  if (has_result) {
    std::string method = Str(Get(job.result, "method"));
    if (method.empty()) method = job.method;
    // The equation that applies the parameters to a raw reading (result key `model`).
    const std::string model = Str(Get(job.result, "model"));
    out += Section("model", "Model",
                   model.empty() ? NotAvailable("The model statement")
                                 : "<p class=\"model\">" + E(model) + "</p>");
    if (method == "pca") {
      out += PcaReport(view);
    } else if (method == "array") {
      out += ArrayReport(view);
    } else if (method == "noise") {
      out += NoiseReport(view);
    } else if (method == "imu") {
      out += ImuReport(view);
    } else {
      out += NotAvailable("A report for method \"" + method + "\"");
    }
    out += Guard("Diagnostics", [&] { return DiagnosticsSection(job.result); });
  } else if (job.status == "succeeded") {
    out += NotAvailable("The result");
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// History.

std::string Option(const std::string& value, const std::string& label, const std::string& current) {
  return "<option value=\"" + A(value) + "\"" + (value == current ? " selected" : "") + ">" +
         E(label) + "</option>";
}

std::string FilterQuery(const HistoryFilter& f) {
  std::string q;
  if (!f.device.empty()) q += "&device=" + UrlEncode(f.device);
  if (!f.method.empty()) q += "&method=" + UrlEncode(f.method);
  if (!f.status.empty()) q += "&status=" + UrlEncode(f.status);
  if (!f.verdict.empty()) q += "&verdict=" + UrlEncode(f.verdict);
  return q;
}

std::string WarningsCell(const JobSummary& j) {
  const size_t w = WarningCount(j.result);
  if (w == 0) return "<td class=\"num muted\">" + std::string(kDash) + "</td>";
  return "<td class=\"num\"><span class=\"flag-warn\" title=\"warnings\">\xE2\x9A\xA0 " +
         std::to_string(w) + "</span></td>";
}

std::string HistoryBody(const HistoryView& v) {
  std::string out = "<h1>Calibration history</h1>";
  out += "<form class=\"filters\" method=\"get\" action=\"/\">";
  out += "<label>device<input type=\"text\" name=\"device\" value=\"" + A(v.filter.device) +
         "\" list=\"devices\" size=\"18\"></label>";
  if (!v.devices.empty()) {
    out += "<datalist id=\"devices\">";
    for (const auto& d : v.devices) out += "<option value=\"" + A(d) + "\">";
    out += "</datalist>";
  }
  out += "<label>method<select name=\"method\">" + Option("", "any", v.filter.method);
  for (const std::string& m : v.methods) out += Option(m, m, v.filter.method);
  if (!v.filter.method.empty() &&
      std::find(v.methods.begin(), v.methods.end(), v.filter.method) == v.methods.end()) {
    out += Option(v.filter.method, v.filter.method, v.filter.method);
  }
  out +=
      "</select></label><label>status<select name=\"status\">" + Option("", "any", v.filter.status);
  for (const char* s : {"succeeded", "failed", "running", "queued"}) {
    out += Option(s, s, v.filter.status);
  }
  if (!v.filter.status.empty() && v.filter.status != "succeeded" && v.filter.status != "failed" &&
      v.filter.status != "running" && v.filter.status != "queued") {
    out += Option(v.filter.status, v.filter.status, v.filter.status);
  }
  out += "</select></label><label>verdict<select name=\"verdict\">" +
         Option("", "any", v.filter.verdict);
  for (const char* s : {"accepted", "rejected", "revoked"}) out += Option(s, s, v.filter.verdict);
  out += "</select></label><button type=\"submit\">Filter</button>";
  out += "<a href=\"/\">clear</a></form>";
  if (v.total >= 0) {
    out += "<p class=\"muted small\">" + std::to_string(v.total) + " matching calibrations.</p>";
  }
  if (v.jobs.empty()) {
    out += "<p class=\"empty\">No calibrations match.</p>";
  } else {
    out +=
        "<div class=\"table-wrap\"><table class=\"table-history\"><thead><tr><th>job</th>"
        "<th>device</th><th>method</th><th>status</th><th>created</th><th>key figures</th>"
        "<th class=\"num\">warnings</th></tr></thead><tbody>";
    for (const auto& j : v.jobs) {
      std::string figures;
      if (j.status == "failed") {
        std::string e = j.error;
        if (e.size() > 90) e = e.substr(0, 90) + "\xE2\x80\xA6";
        figures = "<span class=\"muted\">" + E(e.empty() ? std::string("failed") : e) + "</span>";
      } else {
        figures = E(Guard("figures", [&] { return KeyFigures(j.method, j.result); }));
      }
      out += "<tr><td>" + JobLink(j.id) + "</td><td class=\"name\">" + DeviceLink(j.device) +
             "</td><td>" + E(j.method) + "</td><td>" + StatusBadge(j.status) + VerdictBadge(j) +
             "</td><td class=\"time\">" + TimeHtml(j.created_at) + "</td><td>" + figures + "</td>" +
             WarningsCell(j) + "</tr>";
    }
    out += "</tbody></table></div>";
  }
  out += "<nav class=\"pager\">";
  if (!v.next_before.empty()) {
    out += "<a class=\"older\" rel=\"next\" href=\"" +
           A("/?before=" + UrlEncode(v.next_before) + FilterQuery(v.filter)) +
           "\">Older calibrations \xE2\x86\x92</a>";
  }
  out += "</nav>";
  return out;
}

// ---------------------------------------------------------------------------------------------
// Device page.

double JobTime(const JobSummary& j) {
  double t = Seconds(j.created_at);
  if (!std::isfinite(t)) t = Seconds(j.finished_at);
  return t;
}

bool OlderFirst(const JobSummary& a, const JobSummary& b) {
  const double ta = JobTime(a), tb = JobTime(b);
  if (std::isfinite(ta) && std::isfinite(tb) && ta != tb) return ta < tb;
  return a.id < b.id;
}

struct TimeAxis {
  std::string title;
  std::vector<double> x;  // per job, in the chosen unit
};

TimeAxis MakeTimeAxis(const std::vector<const JobSummary*>& jobs) {
  TimeAxis ax;
  std::vector<double> t;
  bool all = true;
  for (const auto* j : jobs) {
    t.push_back(JobTime(*j));
    all = all && std::isfinite(t.back());
  }
  if (!all || t.empty()) {
    for (size_t i = 0; i < jobs.size(); ++i) ax.x.push_back(static_cast<double>(i + 1));
    ax.title = "calibration number";
    return ax;
  }
  const double t0 = t.front(), span = t.back() - t.front();
  double unit = 86400;
  std::string name = "days";
  if (span < 2 * 3600) {
    unit = 60;
    name = "minutes";
  } else if (span < 2 * 86400) {
    unit = 3600;
    name = "hours";
  }
  for (double v : t) ax.x.push_back((v - t0) / unit);
  ax.title = name + " since " + FormatUnixTime(t0, false);
  return ax;
}

std::string PairLabel(const JobSummary& a, const JobSummary& b) {
  return JobLink(a.id) + " \xE2\x86\x92 " + JobLink(b.id);
}

std::string PairTimeCell(const JobSummary& a, const JobSummary& b) {
  const double ta = JobTime(a), tb = JobTime(b);
  std::string s = TimeHtml(b.created_at);
  if (std::isfinite(ta) && std::isfinite(tb))
    s += " <span class=\"muted small\">(+" + FormatDuration(tb - ta) + ")</span>";
  return "<td>" + s + "</td>";
}

// Drift tables list at most the newest kMaxDriftPairs pairs (the plots show all calibrations).
constexpr size_t kMaxDriftPairs = 60;
size_t FirstDriftPair(size_t n) { return n > kMaxDriftPairs + 1 ? n - kMaxDriftPairs : 1; }
std::string OmittedPairsNote(size_t n) {
  if (n <= kMaxDriftPairs + 1) return "";
  return "<p class=\"muted small\">" + std::to_string(n - 1 - kMaxDriftPairs) +
         " older pairs not listed; the plots show every calibration.</p>";
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

std::string DeviceBody(const DeviceView& v) {
  std::vector<JobSummary> jobs = v.jobs;
  std::sort(jobs.begin(), jobs.end(), OlderFirst);
  std::string out = "<h1>Device " + E(v.serial) + "</h1>";
  std::vector<std::string> methods;
  for (const auto& j : jobs) {
    if (j.status == "succeeded" &&
        std::find(methods.begin(), methods.end(), j.method) == methods.end()) {
      methods.push_back(j.method);
    }
  }
  if (!methods.empty()) {
    out += "<ul class=\"downloads\">";
    for (const auto& m : methods) {
      const std::string base = "/api/v1/devices/" + UrlEncode(v.serial) +
                               "/calibration?method=" + UrlEncode(m) + "&format=";
      out += "<li>Latest " + E(m) + " calibration: " + ExportLinks(base, m) + "</li>";
    }
    out += "</ul>";
  }
  std::string table;
  if (jobs.empty()) {
    table = "<p class=\"empty\">No calibrations for this device.</p>";
  } else {
    table =
        "<div class=\"table-wrap\"><table class=\"table-calibrations\"><thead><tr>"
        "<th class=\"num\">#</th><th>job</th><th>method</th><th>status</th><th>created</th>"
        "<th>key figures</th><th class=\"num\">warnings</th></tr></thead><tbody>";
    for (size_t i = jobs.size(); i-- > 0;) {  // newest first
      const auto& j = jobs[i];
      std::string figures;
      if (j.status == "failed") {
        std::string e = j.error;
        if (e.size() > 90) e = e.substr(0, 90) + "\xE2\x80\xA6";
        figures = "<span class=\"muted\">" + E(e.empty() ? std::string("failed") : e) + "</span>";
      } else {
        figures = E(Guard("figures", [&] { return KeyFigures(j.method, j.result); }));
      }
      table += "<tr>" + NumCell(std::to_string(i + 1)) + "<td>" + JobLink(j.id) + "</td><td>" +
               E(j.method) + "</td><td>" + StatusBadge(j.status) + VerdictBadge(j) +
               "</td><td class=\"time\">" + TimeHtml(j.created_at) + "</td><td>" + figures +
               "</td>" + WarningsCell(j) + "</tr>";
    }
    table += "</tbody></table></div>";
  }
  out += Section("calibrations", "Calibrations", table);
  std::string drift;
  for (const char* method : {"pca", "array", "imu", "noise"}) {
    const std::string m = method;
    std::vector<const JobSummary*> ok;
    for (const auto& j : jobs) {
      // Only what production tooling could have fetched: accepted, not revoked.
      if (GateState(j) == "accepted" && j.method == m && j.result.is_object()) ok.push_back(&j);
    }
    if (ok.size() < 2) continue;
    drift += "<h3>" + m + " (" + std::to_string(ok.size()) +
             " accepted calibrations; rejected and revoked ones are not compared)</h3>";
    drift += Guard("Drift", [&] {
      return m == "pca" ? PcaDrift(ok) : m == "array" ? ArrayDrift(ok) : RawLogDriftHtml(m, ok);
    });
  }
  if (drift.empty()) {
    drift =
        "<p class=\"muted\">Drift needs at least two accepted (not revoked) calibrations of the "
        "same method.</p>";
  }
  out += Section("drift", "Drift between successive calibrations", drift);
  return out;
}

std::string SafePage(const std::string& title, const std::string& cls,
                     const std::function<std::string()>& body) {
  std::string b;
  try {
    b = body();
  } catch (...) {
    b = "<h1>" + E(title) +
        "</h1><div class=\"callout callout-error\"><p>This page could not "
        "be rendered completely.</p></div>";
  }
  return RenderPage(title, cls, b);
}

}  // namespace

std::string KeyFigures(const std::string& method, const json& result) {
  if (!result.is_object()) return kDash;
  std::string m = Str(Get(result, "method"));
  if (m.empty()) m = method;
  if (m == "pca") {
    const PcaFigures f = ComputePcaFigures(result);
    if (!std::isfinite(f.worst_rel_scale_std) && !std::isfinite(f.rank_gap)) return kDash;
    return std::string(kSigma) + "(scale) \xE2\x89\xA4 " + Percent(f.worst_rel_scale_std) +
           " \xC2\xB7 gap " + FormatSig(f.rank_gap, 3);
  }
  if (m == "array") {
    const ArrayFigures f = ComputeArrayFigures(result);
    if (!std::isfinite(f.rms_offset) && !std::isfinite(f.worst_sigma)) return kDash;
    return "offset RMS " + FormatMicrometres(f.rms_offset) + " \xC2\xB7 " + kSigma +
           " \xE2\x89\xA4 " + FormatMicrometres(f.worst_sigma, 2);
  }
  return kDash;
}

std::string GateState(const JobSummary& job) {
  if (job.status != "succeeded") return "";
  if (!job.state.empty()) return job.state;
  return Str(Get(Get(job.result, "verdict"), "status")) == "rejected" ? "rejected" : "accepted";
}

std::string RenderHistoryPage(const HistoryView& view) {
  return SafePage("Calibration history", "page-history", [&] { return HistoryBody(view); });
}

std::string RenderJobPage(const JobView& view) {
  const std::string title = "Calibration #" + std::to_string(view.job.id) +
                            (view.job.device.empty() ? "" : " \xC2\xB7 " + view.job.device);
  return SafePage(title, "page-job", [&] { return JobBody(view); });
}

std::string RenderDevicePage(const DeviceView& view) {
  return SafePage("Device " + view.serial, "page-device", [&] { return DeviceBody(view); });
}

std::string RenderErrorPage(int status, const std::string& message) {
  std::string reason;
  switch (status) {
    case 400:
      reason = "Bad request";
      break;
    case 401:
      reason = "Unauthorized";
      break;
    case 404:
      reason = "Not found";
      break;
    case 405:
      reason = "Method not allowed";
      break;
    case 422:
      reason = "Cannot be calibrated";
      break;
    case 500:
      reason = "Internal error";
      break;
    case 503:
      reason = "Overloaded";
      break;
    default:
      reason = "Error";
  }
  try {
    const std::string body =
        "<h1>" + std::to_string(status) + " \xC2\xB7 " + reason +
        "</h1><div class=\"callout callout-error\"><p class=\"error-message\">" + E(message) +
        "</p></div><p><a href=\"/\">Back to the calibration "
        "history</a></p>";
    return RenderPage(std::to_string(status) + " " + reason, "page-error", body);
  } catch (...) {
    return "<!doctype html><title>Error</title><p>Error</p>";
  }
}

std::string RenderDevicesPage(const DevicesView& view) {
  return SafePage("Devices", "page-devices", [&] {
    std::string out = "<h1>Devices</h1>";
    if (view.devices.empty()) {
      return out +
             "<p>No device has a calibration yet. Upload a recording with "
             "<code>?device=SERIAL</code> (see the README's walkthrough).</p>";
    }
    out += "<p class=\"muted small\">" + std::to_string(view.devices.size()) +
           (view.devices.size() == 1 ? " device" : " devices") +
           ". Each method's column shows its latest calibration: the time links to its report, "
           "JSON to the parameters that production tooling fetches.</p>";
    out +=
        "<div class=\"table-wrap\"><table class=\"table-devices\"><thead><tr>"
        "<th>device (serial)</th><th>first seen (UTC)</th>";
    for (const auto& m : view.methods) out += "<th>latest " + E(m) + " (UTC)</th>";
    out += "</tr></thead><tbody>";
    for (const auto& d : view.devices) {
      out += "<tr><td>" + DeviceLink(d.serial) + "</td><td class=\"time\">" +
             TimeHtml(d.first_seen) + "</td>";
      for (const auto& m : view.methods) {
        const DevicesView::Latest* latest = nullptr;
        for (const auto& l : d.latest) {
          if (l.method == m) latest = &l;
        }
        if (latest == nullptr) {
          out += "<td class=\"muted\">" + std::string(kDash) + "</td>";
          continue;
        }
        out += "<td><a class=\"time\" href=\"/jobs/" + std::to_string(latest->job_id) + "\">" +
               TimeHtml(latest->calibrated_at) + "</a> (report #" + std::to_string(latest->job_id) +
               ") \xC2\xB7 <a href=\"" +
               A("/api/v1/devices/" + UrlEncode(d.serial) + "/calibration?method=" + UrlEncode(m)) +
               "\">JSON</a></td>";
      }
      out += "</tr>";
    }
    return out + "</tbody></table></div>";
  });
}

}  // namespace calibd::web
