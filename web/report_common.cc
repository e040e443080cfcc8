// Shared helpers of the HTML pages (web/report_common.h).
#include "web/report_common.h"

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
#include "web/svg_plot.h"

namespace calibd::web::internal {

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
std::string ScalarText(const json* j, int sig) {
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
std::string TimeHtml(const std::string& stored, bool seconds) {
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

double Norm3(const double* v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

// A badge for a result the gate rejected or a person revoked, with the reason in words ("" for
// an accepted result: the usual case needs no mark).
std::string VerdictBadge(const JobSummary& job) {
  const ServeState gate = GateState(job);
  if (gate == ServeState::kAccepted) {
    // Accepted by a person (an accept decision, or a result the gate rejected that is served
    // anyway): marked, with the person's reason; accepted by the gate: no mark.
    const JobEventSummary* accept = nullptr;
    for (const auto& e : job.events) {
      if (e.action == "accept") accept = &e;
    }
    const bool overridden = Str(Get(Get(job.result, "verdict"), "status")) == "rejected";
    if (accept == nullptr && !overridden) return "";
    const std::string reason = accept != nullptr ? accept->reason : "";
    std::string shown = reason;
    if (shown.size() > 140) shown = shown.substr(0, 140) + "\xE2\x80\xA6";
    return " <span class=\"badge badge-accepted badge-accepted-by-person\" title=\"" +
           E("accepted by a person" + (reason.empty() ? std::string() : ": " + reason)) +
           "\">accepted by a person</span>" +
           (shown.empty()
                ? ""
                : "<span class=\"verdict-reason verdict-reason-accepted\">" + E(shown) + "</span>");
  }
  if (gate != ServeState::kRejected && gate != ServeState::kRevoked) return "";
  const std::string state = Name(gate);
  std::string reason;
  if (gate == ServeState::kRevoked) {
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

std::string WarningsCell(const JobSummary& j) {
  const size_t w = WarningCount(j.result);
  if (w == 0)
    return "<td class=\"num muted\" data-label=\"warnings\">" + std::string(kDash) + "</td>";
  return "<td class=\"num\" data-label=\"warnings\"><span class=\"flag-warn\" "
         "title=\"warnings\">\xE2\x9A\xA0 " +
         std::to_string(w) + "</span></td>";
}

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

size_t FirstDriftPair(size_t n) { return n > kMaxDriftPairs + 1 ? n - kMaxDriftPairs : 1; }
std::string OmittedPairsNote(size_t n) {
  if (n <= kMaxDriftPairs + 1) return "";
  return "<p class=\"muted small\">" + std::to_string(n - 1 - kMaxDriftPairs) +
         " older pairs not listed; the plots show every calibration.</p>";
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

}  // namespace calibd::web::internal

namespace calibd::web {

using namespace internal;  // NOLINT: Str and Get

ServeState GateState(const JobSummary& job) {
  if (job.status != JobStatus::kSucceeded) return ServeState::kNone;
  if (job.state != ServeState::kNone) return job.state;
  return Str(Get(Get(job.result, "verdict"), "status")) == "rejected" ? ServeState::kRejected
                                                                      : ServeState::kAccepted;
}

}  // namespace calibd::web
