// The recording page's "Check before fitting" section (web/recording_page.h CheckSection).
#include <cmath>
#include <string>
#include <vector>

#include "web/html.h"
#include "web/recording_page.h"
#include "web/svg_plot.h"

namespace calibd::web {

using nlohmann::json;

namespace {

std::string E(std::string_view s) { return EscapeText(s); }

std::string Number(const json& j, int sig = 4) {
  return j.is_number() ? E(FormatSig(j.get<double>(), sig)) : std::string("&mdash;");
}

// One hemisphere of the statics' gravity directions (z >= 0 seen from +z, or z < 0 seen from -z)
// in the Lambert azimuthal equal-area projection (radius sqrt(2) at the equator), points
// numbered as the statics; the equator drawn.
std::string Hemisphere(const json& statics, bool upper) {
  PlotOptions o;
  o.name = upper ? "check-upper" : "check-lower";
  o.title = upper ? "z up (seen from +z)" : "z down (seen from -z)";
  o.x.title = "x";
  o.y.title = "y";
  o.x.min = o.y.min = -1.5;
  o.x.max = o.y.max = 1.5;
  o.width = o.height = 340;
  o.equal_aspect = true;
  o.legend = false;
  Series equator;
  for (int i = 0; i <= 96; ++i) {
    const double a = 2 * M_PI * i / 96;
    equator.x.push_back(std::sqrt(2.0) * std::cos(a));
    equator.y.push_back(std::sqrt(2.0) * std::sin(a));
  }
  equator.color = 7;
  equator.line_width = 1;
  Series points;
  points.line = false;
  points.marker = Marker::kCircle;
  points.color = 0;
  for (size_t i = 0; i < statics.size(); ++i) {
    const json& up = statics[i].value("up", json());
    if (!up.is_array() || up.size() != 3 || !up[2].is_number()) continue;
    const double x = up[0].get<double>(), y = up[1].get<double>(), z = up[2].get<double>();
    if ((z >= 0) != upper) continue;
    const double k = std::sqrt(2 / (1 + std::abs(z)));  // equal-area
    points.x.push_back(k * x);
    points.y.push_back(upper ? k * y : -k * y);  // seen from below: y mirrored
    points.point_labels.push_back(std::to_string(i + 1));
  }
  return RenderXYPlot(o, {equator, points});
}

std::string Form(const RecordingPageView& v) {
  std::string s = "<form method=\"get\" action=\"/recordings/" + std::to_string(v.id) +
                  "\"><label>Method <select name=\"check\">";
  for (const std::string& m : v.check_methods) {
    s += "<option" + std::string(m == v.check_method ? " selected" : "") + ">" + E(m) + "</option>";
  }
  return s + "</select></label> <button type=\"submit\">Check</button></form>";
}

std::string Verdicts(const json& c) {
  std::string s = "<ul class=\"check-verdicts\">";
  if (c.contains("job_would_fail")) {
    s += "<li><strong>The job would fail:</strong> " + E(c["job_would_fail"].get<std::string>()) +
         "</li>";
  }
  for (const json& u : c.value("units", json::array())) {
    s += "<li><strong>Units (" + E(u.value("quantity", "")) + "):</strong> " +
         E(u.value("message", "")) + "</li>";
  }
  const json& t = c.value("timing", json::object());
  s += "<li>Timing: " + Number(t.value("rate", json())) + " Hz, jitter " +
       Number(t.value("jitter_rms", json()), 3) + " s RMS (largest " +
       Number(t.value("jitter_max", json()), 3) + " s), " +
       std::to_string(t.value("gap_count", 0)) + " gap(s)</li>";
  const json& sat = c.value("saturation", json());
  if (sat.is_object()) {
    std::string channels;
    for (const json& ch : sat.value("channels", json::array())) {
      channels += (channels.empty() ? "" : ", ") + E(ch.value("name", "")) + " " +
                  std::to_string(ch.value("pinned_low", 0) + ch.value("pinned_high", 0));
    }
    s += "<li>Saturation: " + std::to_string(sat.value("samples", 0)) + " sample(s) pinned" +
         (channels.empty() ? std::string() : " (" + channels + ")") + "</li>";
  }
  for (const json& cov : c.value("coverage", json::array())) {
    s += "<li>Coverage of IMU " + E(cov.value("name", "")) + ": " +
         (cov.value("sufficient", false) ? "sufficient" : "insufficient") + " &mdash; " +
         E(cov.value("verdict", "")) + "</li>";
  }
  for (const json& tr : c.value("temperature", json::array())) {
    s += "<li>Temperature " + E(tr.value("name", "")) + ": " + Number(tr.value("min", json())) +
         " to " + Number(tr.value("max", json())) + " &deg;C</li>";
  }
  for (const json& n : c.value("notes", json::array()))
    s += "<li class=\"muted\">" + E(n.get<std::string>()) + "</li>";
  return s + "</ul>";
}

// The largest of the numbers in `j` (nested arrays); NaN when there are none.
double Largest(const json& j) {
  double worst = std::nan("");
  if (j.is_number()) return j.get<double>();
  if (j.is_array()) {
    for (const json& v : j) {
      const double x = Largest(v);
      if (!std::isnan(x) && (std::isnan(worst) || x > worst)) worst = x;
    }
  }
  return worst;
}

// Rows "where | largest 1σ" for every σ in a result's uncertainty shape (keys named "std" or
// ending in "_std"; covariances and grids left out), per IMU.
void SigmaRows(const json& node, const std::string& where, std::string* rows) {
  if (!node.is_object()) return;
  for (const auto& [key, value] : node.items()) {
    const bool is_std =
        key == "std" || (key.size() > 4 && key.compare(key.size() - 4, 4, "_std") == 0);
    if (is_std && value.is_array()) {
      const double worst = Largest(value);
      if (std::isnan(worst)) continue;
      *rows += "<tr><td>" + E(where + key) + "</td><td class=\"num\">" + E(FormatSig(worst, 3)) +
               "</td></tr>";
    } else if (value.is_object() && key != "crb") {
      SigmaRows(value, where + key + ".", rows);
    }
  }
}

// The job's σ predicted by the method's check (its `predicted`), or why there is none.
std::string Predicted(const json& c) {
  const json& p = c.value("predicted", json());
  if (!p.is_object()) return "";
  std::string s = "<h3>Predicted &sigma;</h3>";
  if (p.contains("how") && p["how"].is_string()) {
    s += "<p class=\"muted\">" + E(p["how"].get<std::string>()) + "</p>";
  }
  const json& u = p.value("uncertainty", json());
  if (!u.is_object()) {
    return s + "<p>No prediction: " + E(p.value("reason", std::string("not given"))) + "</p>";
  }
  std::string rows;
  for (const json& imu : u.value("imus", json::array())) {
    SigmaRows(imu, "IMU " + imu.value("name", std::string("?")) + " ", &rows);
  }
  return s +
         "<table class=\"check-predicted\"><thead><tr><th>quantity (SI)</th><th>largest "
         "1&sigma;</th></tr></thead><tbody>" +
         rows + "</tbody></table>";
}

}  // namespace

std::string CheckSection(const RecordingPageView& v) {
  if (v.check_methods.empty()) return "";
  std::string s =
      "<section id=\"check\"><h2>Check before fitting</h2><p>What a job would find "
      "before fitting: timing, units, saturation, statics and their orientations "
      "(the same stages the job runs; <a href=\"/api/v1/recordings/" +
      std::to_string(v.id) + "/check?method=" +
      EscapeAttr(UrlEncode(v.check_method.empty() ? v.check_methods.front() : v.check_method)) +
      "\">as JSON</a>).</p>" + Form(v);
  if (!v.check_note.empty()) s += "<p class=\"muted\">" + E(v.check_note) + "</p>";
  if (v.check.is_object()) {
    s += Verdicts(v.check) + Predicted(v.check);
    const json& statics = v.check.value("statics", json());
    if (statics.is_array()) {
      s += "<p>" + std::to_string(statics.size()) +
           " static interval(s); their gravity directions on the two hemispheres (equal-area "
           "projection, nominal units, numbered in time order):</p><div class=\"plots\">" +
           Hemisphere(statics, true) + Hemisphere(statics, false) + "</div>";
    }
  }
  return s + "</section>";
}

}  // namespace calibd::web
