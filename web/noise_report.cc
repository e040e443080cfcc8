// The noise report section (web/reports.h).
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
#include "web/report_common.h"
#include "web/reports.h"
#include "web/svg_plot.h"

namespace calibd::web::internal {

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

namespace {

// A failed noise job: what was found (rate, duration, per channel its status and reason) and
// the Allan curves as far as they were computed.
std::string NoisePartialReport(const JobView& view) {
  const json* diag = Get(view.job.error_detail, "diagnostics");
  std::string s = "<dl class=\"kv partial-noise\"><dt>samples</dt><dd>" +
                  E(ScalarText(Get(diag, "samples"))) + "</dd><dt>rate</dt><dd>" +
                  FormatSI(Num(Get(diag, "rate")), "Hz") + "</dd><dt>duration</dt><dd>" +
                  FormatSI(Num(Get(diag, "duration")), "s") + "</dd></dl>";
  const json* channels = Array(Get(diag, "channels"));
  if (channels != nullptr && !channels->empty()) {
    s += "<div class=\"table-wrap\"><table class=\"table-noise-channels\"><thead><tr>"
         "<th>channel</th><th>status</th><th>reason</th></tr></thead><tbody>";
    for (const json& c : *channels) {
      s += "<tr><td>" + E(Str(Get(&c, "name"))) + "</td><td>" + E(Str(Get(&c, "status"))) +
           "</td><td>" + E(Str(Get(&c, "reason"))) + "</td></tr>";
    }
    s += "</tbody></table></div>";
  }
  const std::string figs = AllanPlot(diag, 'a', "m/s\xC2\xB2") + AllanPlot(diag, 'g', "rad/s");
  if (!figs.empty()) s += "<div class=\"plots\">" + figs + "</div>";
  return s;
}

class NoiseReportImpl : public MethodReport {
 public:
  const char* method() const override { return "noise"; }
  std::string Section(const JobView& view) const override { return NoiseReport(view); }
  std::string Partial(const JobView& view) const override { return NoisePartialReport(view); }
  std::string Drift(const std::vector<const JobSummary*>& jobs) const override {
    return NoiseDriftHtml(jobs);  // web/device_drift.h
  }
  std::vector<Download> Downloads() const override {
    return {{"csv", "CSV"}, {"h", "C header"}, {"yaml", "Kalibr imu.yaml"}};
  }
};

}  // namespace

const MethodReport& NoiseMethodReport() {
  static const NoiseReportImpl& report = *new NoiseReportImpl();
  return report;
}

}  // namespace calibd::web::internal
