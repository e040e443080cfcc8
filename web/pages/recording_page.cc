#include "web/recording_page.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "web/html.h"
#include "web/svg_plot.h"

namespace calibd::web {

using nlohmann::json;

namespace {

std::string E(std::string_view s) { return EscapeText(s); }

double NumberOr(const json& j, const char* key, double fallback) {
  if (!j.is_object()) return fallback;
  auto it = j.find(key);
  return it != j.end() && it->is_number() ? it->get<double>() : fallback;
}

std::string Dd(const std::string& term, const std::string& value_html) {
  return "<dt>" + E(term) + "</dt><dd>" + value_html + "</dd>";
}

// The timeline of one sensor kind: the norm of every triad against time, statics shaded.
std::string Timeline(const std::vector<RecordingPageView::Trace>& traces, const json& intervals,
                     const std::string& name, const std::string& title,
                     const std::string& y_title) {
  PlotOptions o;
  o.name = name;
  o.title = title;
  o.x.title = "time t (s)";
  o.y.title = y_title;
  o.width = 900;
  o.height = 300;
  o.max_points = 4000;
  if (intervals.is_array()) {
    for (const json& iv : intervals) {
      o.bands.push_back({NumberOr(iv, "start", NAN), NumberOr(iv, "end", NAN),
                         std::to_string(static_cast<long long>(NumberOr(iv, "number", 0)))});
    }
  }
  std::vector<Series> series;
  for (const auto& tr : traces) {
    Series s;
    s.label = "|" + tr.name + "|";
    s.x = tr.t;
    s.y = tr.norm;
    s.line_width = 1.0;
    series.push_back(std::move(s));
  }
  return RenderXYPlot(o, series);
}

std::string JobsSection(const RecordingPageView& v) {
  std::string s = "<section id=\"jobs\"><h2>Jobs on this recording</h2>";
  if (v.jobs.empty()) {
    return s +
           "<p class=\"muted\">No job has used this recording yet (POST /api/v1/jobs with its "
           "recording_id runs one).</p></section>";
  }
  s += "<div class=\"table-wrap\"><table class=\"table-recording-jobs\"><thead><tr><th>job</th>"
       "<th>method</th><th>device</th><th>status</th><th>created</th></tr></thead><tbody>";
  for (const JobSummary& j : v.jobs) {
    const std::string id = std::to_string(j.id);
    s += "<tr><td><a href=\"/jobs/" + id + "\">#" + id + "</a></td><td>" + E(j.method) +
         "</td><td>" +
         (j.device.empty() ? std::string("<span class=\"muted\">none</span>")
                           : "<a href=\"/devices/" + EscapeAttr(UrlEncode(j.device)) + "\">" +
                                 E(j.device) + "</a>") +
         "</td><td>" + StatusBadge(j.status) + "</td><td>" + E(j.created_at) + "</td></tr>";
  }
  return s + "</tbody></table></div></section>";
}

// What the timelines' norms are in: SI when the units were given or the accelerometer norm at
// rest is within 20 % of 1 g; else reading units (a log of counts: |a| of 54 000 at rest). A
// given accel_unit that does not make the rest norm about 1 g is trusted but questioned.
struct Units {
  bool accel_si = true, gyro_si = true;
  std::string note;  // "" when both are SI and the rest norm is about 1 g
};

Units JudgeUnits(const RecordingPageView& v) {
  constexpr double kG = 9.80665;
  Units u;
  const double rest = RestNorm(v);
  const bool looks_si = std::isfinite(rest) && rest > 0.8 * kG && rest < 1.2 * kG;
  u.accel_si = v.accel_unit_given || looks_si;
  u.gyro_si = v.gyro_unit_given || (!v.accel_unit_given && looks_si);
  if (v.accel_unit_given && !looks_si && std::isfinite(rest)) {
    u.note = "With the accel_unit given, the accelerometer norm at rest is " + FormatSig(rest, 4) +
             " m/s\xC2\xB2, not about 9.81: check accel_unit.";
  }
  if (u.accel_si && u.gyro_si) return u;
  if (!u.accel_si) {
    u.note = "The accelerometer norm at rest is " + FormatSig(rest, 4) +
             ", not about 9.81 m/s\xC2\xB2: this log is not in m/s\xC2\xB2, so the timeline shows "
             "reading units. Give accel_unit (m/s\xC2\xB2 per reading unit";
    if (std::isfinite(rest) && rest > 0) {
      const std::string unit = FormatSig(kG / rest, 4);
      u.note += "; about " + unit + " here: ?accel_unit=" + unit;
    }
    u.note += ") to see SI.";
  }
  if (!u.gyro_si) {
    u.note += std::string(u.note.empty() ? "" : " ") +
              "The gyroscope norm is shown in reading units: give gyro_unit (rad/s per reading "
              "unit) to see rad/s.";
  }
  return u;
}

std::string SegmentsSection(const RecordingPageView& v) {
  std::string s = "<section id=\"segments\"><h2>Static intervals</h2>";
  const json& seg = v.segments;
  if (!seg.is_object()) {
    return s + "<p class=\"muted not-available\">" + E(v.segments_note) + "</p></section>";
  }
  const json& intervals = seg.contains("intervals") ? seg["intervals"] : json::array();
  const std::string id = std::to_string(v.id);
  s += "<p>" + std::to_string(intervals.size()) +
       " static interval(s) found from the log's own noise floor (window " +
       E(FormatSig(NumberOr(seg, "static_window", NAN), 3)) + " s, at least " +
       E(FormatSig(NumberOr(seg, "min_static", NAN), 3)) + " s, threshold " +
       E(FormatSig(NumberOr(seg, "threshold_multiplier", NAN), 3)) +
       " \xC3\x97 the noise floor unless overridden" +
       (v.query.empty() ? std::string() : "; options: " + E(v.query)) +
       "). The same as JSON: <a href=\"/api/v1/recordings/" + id + "/segments" +
       (v.query.empty() ? std::string() : "?" + EscapeAttr(v.query)) +
       "\">segments</a>. Try other options with <code>?static_window=&amp;min_static=&amp;"
       "static_threshold={\"accelerometer\":x,\"gyroscope\":y}</code>.</p>";
  const Units units = JudgeUnits(v);
  if (!units.note.empty()) s += "<p class=\"callout units-note\">" + E(units.note) + "</p>";
  s += "<div class=\"timelines\">";  // one under the other, full width: a shared time axis
  s += "<figure>" +
       Timeline(v.accel, intervals, "timeline-accel", "Accelerometer norm",
                units.accel_si ? "|a| (m/s\xC2\xB2)" : "|a| (reading units)") +
       "<figcaption>Shaded and numbered: the static intervals.</figcaption></figure>";
  s += "<figure>" +
       Timeline(v.gyro, intervals, "timeline-gyro", "Gyroscope norm",
                units.gyro_si ? "|\xCF\x89| (rad/s)" : "|\xCF\x89| (reading units)") +
       "<figcaption>Between two statics the board was turned; the rotations the imu method "
       "integrates.</figcaption></figure>";
  s += "</div>";
  // Thresholds per triad.
  if (seg.contains("triads") && seg["triads"].is_array()) {
    s += "<div class=\"table-wrap\"><table class=\"table-thresholds\"><thead><tr><th>triad</th>"
         "<th>kind</th><th>noise floor (reading units)</th><th>threshold (reading units)</th>"
         "<th>" +
         std::string(units.accel_si && units.gyro_si ? "threshold (SI)"
                                                     : "threshold \xC3\x97 unit (no unit given)") +
         "</th><th>saturated samples</th></tr></thead><tbody>";
    for (const json& t : seg["triads"]) {
      s += "<tr><td>" + E(t.value("name", "")) + "</td><td>" + E(t.value("kind", "")) +
           "</td><td>" + E(FormatSig(NumberOr(t, "noise_floor", NAN))) + "</td><td>" +
           E(FormatSig(NumberOr(t, "threshold", NAN))) +
           (t.value("overridden", false) ? " (given)" : "") + "</td><td>" +
           E(FormatSig(NumberOr(t, "threshold_si", NAN))) + "</td><td>" +
           std::to_string(static_cast<long long>(NumberOr(t, "saturated_samples", 0))) +
           "</td></tr>";
    }
    s += "</tbody></table></div>";
  }
  if (seg.contains("gaps") && seg["gaps"].is_array() && !seg["gaps"].empty()) {
    s += "<p class=\"warning\">" + std::to_string(seg["gaps"].size()) +
         " gap(s) in the sample times (no static window spans one):";
    size_t shown = 0;
    for (const json& g : seg["gaps"]) {
      if (++shown > 20) {
        s += " \xE2\x80\xA6";
        break;
      }
      s += " " + E(FormatSig(NumberOr(g, "start", NAN), 6)) + "\xE2\x80\x93" +
           E(FormatSig(NumberOr(g, "end", NAN), 6)) + " s;";
    }
    s += "</p>";
  }
  if (!intervals.empty()) {
    s += "<div class=\"table-wrap\"><table class=\"table-intervals\"><thead><tr><th>#</th>"
         "<th>start (s)</th><th>end (s)</th><th>duration</th><th>samples</th>"
         "<th>mean per triad (reading units)</th></tr></thead><tbody>";
    for (const json& iv : intervals) {
      std::string means;
      if (iv.contains("mean") && iv["mean"].is_object()) {
        for (const auto& [name, m] : iv["mean"].items()) {
          means += E(name) + " (";
          for (size_t i = 0; i < 3 && m.is_array() && i < m.size(); ++i) {
            means += (i ? ", " : "") + E(FormatSig(m[i].is_number() ? m[i].get<double>() : NAN));
          }
          means += ") ";
        }
      }
      const double a = NumberOr(iv, "start", NAN), b = NumberOr(iv, "end", NAN);
      s += "<tr><td>" + std::to_string(static_cast<long long>(NumberOr(iv, "number", 0))) +
           "</td><td>" + E(FormatSig(a, 6)) + "</td><td>" + E(FormatSig(b, 6)) + "</td><td>" +
           E(FormatDuration(b - a)) + "</td><td>" +
           std::to_string(static_cast<long long>(NumberOr(iv, "samples", 0))) + "</td><td>" +
           means + "</td></tr>";
    }
    s += "</tbody></table></div>";
  }
  return s + "</section>";
}

std::string Cell(const json& j, const char* key, int digits = 6) {
  if (!j.is_object() || !j.contains(key) || j[key].is_null()) {
    return "<span class=\"muted\">\xE2\x80\x94</span>";
  }
  const json& v = j[key];
  if (v.is_number_integer()) return std::to_string(v.get<long long>());
  if (v.is_number()) return E(FormatSig(v.get<double>(), digits));
  if (v.is_string()) return E(v.get<std::string>());
  return E(v.dump());
}

// SPEC §9 "What was read": the log's streams, the IMUs formed from them, its warnings.
std::string LogSection(const json& log) {
  std::string s = "<section id=\"log\"><h2>What was read</h2><p>A " +
                  E(log.value("format", std::string("sensor"))) +
                  " log. Time base: " + E(log.value("time_base", std::string("?"))) +
                  ". Values in SI (magnetic field in \xC2\xB5T) as the format defines them.</p>";
  if (log.contains("warnings") && log["warnings"].is_array()) {
    for (const json& w : log["warnings"]) {
      if (w.is_string()) s += "<p class=\"warning\">" + E(w.get<std::string>()) + "</p>";
    }
  }
  if (log.contains("streams") && log["streams"].is_array()) {
    s += "<div class=\"table-wrap\"><table class=\"table-streams\"><thead><tr><th>stream</th>"
         "<th>kind</th><th>device id</th><th>samples</th><th>rate (Hz)</th><th>start (s)</th>"
         "<th>end (s)</th><th>gaps</th><th>unit in the log</th><th>time</th><th>note</th>"
         "</tr></thead><tbody>";
    for (const json& st : log["streams"]) {
      s += "<tr><td>" + Cell(st, "name") + "</td><td>" + Cell(st, "kind") + "</td><td>" +
           Cell(st, "device_id") + "</td><td>" + Cell(st, "samples") + "</td><td>" +
           Cell(st, "rate", 5) + "</td><td>" + Cell(st, "start", 9) + "</td><td>" +
           Cell(st, "end", 9) + "</td><td>" + Cell(st, "gaps") + "</td><td>" + Cell(st, "unit") +
           "</td><td>" + Cell(st, "time_source") + "</td><td>" + Cell(st, "note") + "</td></tr>";
    }
    s += "</tbody></table></div>";
  }
  if (log.contains("imus") && log["imus"].is_array()) {
    s += "<div class=\"table-wrap\"><table class=\"table-log-imus\"><thead><tr><th>IMU</th>"
         "<th>accelerometer</th><th>gyroscope</th><th>temperature</th><th>samples</th>"
         "<th>dropped</th><th>resampled</th></tr></thead><tbody>";
    for (const json& imu : log["imus"]) {
      const json resampled = imu.value("resampled", json::array());
      s += "<tr><td>" + Cell(imu, "index") + "</td><td>" + Cell(imu, "accel") + "</td><td>" +
           Cell(imu, "gyro") + "</td><td>" + Cell(imu, "temp") + "</td><td>" +
           Cell(imu, "samples") + "</td><td>" + Cell(imu, "dropped") + "</td><td>" +
           (resampled.empty() ? std::string("none") : E(resampled.dump())) + "</td></tr>";
    }
    s += "</tbody></table></div><p class=\"muted\">Choose other streams with the config key "
         "<code>streams</code>, e.g. <code>{\"imus\": [{\"accel\": \"sensor_accel:1\", "
         "\"gyro\": \"sensor_gyro:1\"}]}</code>.</p>";
  }
  return s + "</section>";
}

}  // namespace

double RestNorm(const RecordingPageView& view) {
  std::vector<std::pair<double, double>> statics;
  const json* intervals = view.segments.is_object() && view.segments.contains("intervals")
                              ? &view.segments["intervals"]
                              : nullptr;
  if (intervals != nullptr && intervals->is_array()) {
    for (const json& iv : *intervals) {
      const double a = NumberOr(iv, "start", NAN), b = NumberOr(iv, "end", NAN);
      if (std::isfinite(a) && std::isfinite(b)) statics.push_back({a, b});
    }
  }
  std::vector<double> norms;
  for (const auto& tr : view.accel) {
    for (size_t i = 0; i < tr.t.size() && i < tr.norm.size(); ++i) {
      if (!std::isfinite(tr.norm[i])) continue;
      bool inside = statics.empty();
      for (const auto& [a, b] : statics) inside = inside || (tr.t[i] >= a && tr.t[i] <= b);
      if (inside) norms.push_back(tr.norm[i]);
    }
  }
  if (norms.empty()) return NAN;
  std::nth_element(norms.begin(), norms.begin() + norms.size() / 2, norms.end());
  return norms[norms.size() / 2];
}

std::string RenderRecordingPage(const RecordingPageView& v) {
  const std::string id = std::to_string(v.id);
  std::string body = "<h1>Recording " + id + "</h1>";
  std::string columns;
  for (size_t i = 0; i < v.columns.size(); ++i) {
    if (i == 40) {
      columns += ", \xE2\x80\xA6 (" + std::to_string(v.columns.size()) + " in all)";
      break;
    }
    columns += (i ? ", " : "") + E(v.columns[i]);
  }
  body += "<section id=\"metadata\"><h2>Metadata</h2><dl class=\"kv\">" +
          Dd("layout", E(v.layout)) + Dd("rows", std::to_string(v.rows)) +
          Dd("bytes", std::to_string(v.bytes) + " (" +
                          E(FormatSI(static_cast<double>(v.bytes), "B")) + ")") +
          Dd("SHA-256", "<code>" + E(v.sha256) + "</code>") +
          Dd("device", v.device.empty() ? std::string("<span class=\"muted\">none</span>")
                                        : "<a href=\"/devices/" + EscapeAttr(UrlEncode(v.device)) +
                                              "\">" + E(v.device) + "</a>") +
          Dd("file name", v.file_name.empty() ? std::string("<span class=\"muted\">none</span>")
                                              : E(v.file_name)) +
          Dd("uploaded", E(v.created_at)) + Dd("columns", columns) +
          Dd("data", "<a href=\"/api/v1/recordings/" + id + "/data\">" +
                         (v.log.is_object() ? "the log as uploaded" : "the CSV") +
                         "</a> \xC2\xB7 <a href=\"/api/v1/recordings/" + id +
                         "\">metadata as JSON</a>") +
          "</dl></section>";
  if (v.log.is_object()) body += LogSection(v.log);
  body += SegmentsSection(v);
  body += CheckSection(v);
  body += JobsSection(v);
  return RenderPage("Recording " + id, "page-recording", body);
}

}  // namespace calibd::web
