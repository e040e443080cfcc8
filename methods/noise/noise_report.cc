// The noise report section (methods/noise/noise_report.h): reads the result once as
// results::NoiseResult (methods/noise/noise_result.h); a result that does not read shows "not
// available" with the reason.
#include "methods/noise/noise_report.h"

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

#include "methods/noise/noise_drift.h"
#include "methods/noise/noise_result.h"
#include "web/html.h"
#include "web/report_common.h"
#include "web/svg_plot.h"

namespace calibd::web::internal {

namespace {

// A result that does not read as results::NoiseResult: the "not available" text with the reader's
// message (which names the path of the problem).
std::string Unreadable(const std::string& what, const Status& s) {
  return NotAvailable(what) + "<p class=\"muted small\">" + E(s.message()) + "</p>";
}

// A number as the diagnostics table shows it (integral values without decimals; NaN a dash).
std::string Scalar(double v, int sig = 6) {
  const json j = results::Num(v);
  return ScalarText(&j, sig);
}

// "1.23e-4 ± 2.1e-6" or "not visible" for a term the log does not show (NaN).
std::string TermCell(double v, double s) {
  if (!std::isfinite(v)) return "<td class=\"num muted\">not visible</td>";
  return NumCell(FormatSig(v, 4) + (std::isfinite(s) ? " \xC2\xB1 " + FormatSig(s, 2) : ""));
}

// Log-log Allan deviation of the channels of one sensor type, with their confidence bands and
// the fitted model.
std::string AllanPlot(const std::vector<results::NoiseAllanCurve>& allan, char kind,
                      const std::string& unit) {
  std::vector<Series> series;
  int color = 0;
  for (const results::NoiseAllanCurve& c : allan) {
    if (c.name.empty() || c.name[0] != kind) continue;
    Series data;
    data.label = c.name;
    data.x = c.tau;
    data.y = c.adev;
    data.marker = Marker::kCircle;
    data.color = color;
    for (const std::vector<double>* bound : {&c.adev_lower, &c.adev_upper}) {
      Series b;
      b.x = data.x;
      b.y = *bound;
      b.color = color;
      b.dashed = true;
      b.line_width = 0.8;
      if (b.y.size() == b.x.size()) series.push_back(b);
    }
    Series fit;
    fit.x = data.x;
    fit.y = c.fitted_adev;
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

// Which σ the table shows (the σ convention, issue 28), in words.
std::string NoiseSigmaBasisText(const results::NoiseResult& r) {
  std::string scaled;
  for (const results::NoiseChannelUncertainty& u : r.channel_stds) {
    if (u.basis != "chi2_scaled") continue;
    scaled += (scaled.empty() ? "" : ", ") + u.name + " \xC3\x97" +
              FormatSig(std::sqrt(u.chi2_per_dof), 3);
  }
  if (r.basis == "chi2_scaled")
    return "the noise model's \xCF\x83 where the Allan curve follows it, scaled by "
           "\xE2\x88\x9A(\xCF\x87\xC2\xB2 / expected \xCF\x87\xC2\xB2) where it does not (" +
           scaled + "; the model's own in uncertainty.channels[].crb of the JSON)";
  if (r.basis == "crb")
    return "the noise model's \xCF\x83 (the Allan curve follows N/B/K within its intervals, "
           "largest \xCF\x87\xC2\xB2 / expected " +
           FormatSig(r.chi2_per_dof, 3) + ")";
  return "the noise model's \xCF\x83, whatever the fit (stored by an earlier calibd)";
}

}  // namespace

std::string NoiseReport(const JobView& view) {
  results::NoiseResult r;
  if (Status st = results::FromJson(view.job.result, &r); !st.ok()) {
    return Unreadable("The noise result", st);
  }
  const results::NoiseDiagnostics& d = r.diagnostics;
  std::string out;
  out += Guard("Parameters", [&] {
    std::string s = "<dl class=\"kv\">";
    s += "<dt>sample rate</dt><dd>" + E(Scalar(d.rate)) + " Hz</dd>";
    s += "<dt>samples</dt><dd>" + E(std::to_string(d.samples)) + " (" + FormatDuration(d.duration) +
         ")</dd>";
    s +=
        "<dt>stationary</dt><dd>" +
        std::string(d.stationary ? "yes" : "no: the sensor moved, the Allan curve is meaningless") +
        "</dd></dl>";
    if (r.channels.empty())
      return Section("parameters", "Parameters", s + NotAvailable("Channels"));
    s += "<div class=\"table-wrap\"><table class=\"table-noise-parameters\"><thead><tr>"
         "<th>channel</th><th>unit</th><th>white noise N (unit/\xE2\x88\x9AHz)</th>"
         "<th>bias instability B (unit)</th><th>at \xCF\x84 (s)</th>"
         "<th>random walk K (unit/s/\xE2\x88\x9AHz)</th></tr></thead><tbody>";
    for (size_t i = 0; i < r.channels.size(); ++i) {
      const results::NoiseChannelParameters& c = r.channels[i];
      const results::NoiseChannelUncertainty& u = r.channel_stds[i];
      s += "<tr><td>" + E(c.name) + "</td><td>" + E(c.unit) + "</td>" +
           TermCell(c.white_noise, u.white_noise_std) +
           TermCell(c.bias_instability, u.bias_instability_std) +
           NumCell(c.bias_instability_tau, 3) + TermCell(c.random_walk, u.random_walk_std) +
           "</tr>";
    }
    s += "</tbody></table></div><p class=\"muted small\">\xC2\xB1 is one standard deviation: " +
         E(NoiseSigmaBasisText(r)) +
         ". N and K are Kalibr's noise_density and random_walk "
         "(<a href=\"/api/v1/devices/" +
         A(UrlEncode(view.job.device)) +
         "/calibration?method=noise&amp;format=yaml\">imu.yaml</a>). A term the log is too short "
         "to show is \"not visible\"; the warnings say how long a log would show it.</p>";
    return Section("parameters", "Parameters", s);
  });
  out += Guard("Plots", [&] {
    std::string figs = AllanPlot(d.allan, 'a', "m/s\xC2\xB2") + AllanPlot(d.allan, 'g', "rad/s");
    if (figs.empty()) return NotAvailable("The Allan deviation plots");
    return Section("plots", "Plots", "<div class=\"plots\">" + figs + "</div>");
  });
  return out;
}

namespace {

// A failed noise job: what was found (rate, duration, per channel its status and reason) and
// the Allan curves as far as they were computed.
std::string NoisePartialReport(const JobView& view) {
  results::NoiseResult r;
  if (Status st = results::FromJson(view.job.error_detail, &r); !st.ok()) {
    return Unreadable("The partial diagnostics", st);
  }
  const results::NoiseDiagnostics& d = r.diagnostics;
  // No samples counted: the diagnostics left it out (or the log had none): a dash.
  std::string s = "<dl class=\"kv partial-noise\"><dt>samples</dt><dd>" +
                  E(d.samples > 0 ? std::to_string(d.samples) : std::string(kDash)) +
                  "</dd><dt>rate</dt><dd>" + FormatSI(d.rate, "Hz") + "</dd><dt>duration</dt><dd>" +
                  FormatSI(d.duration, "s") + "</dd></dl>";
  if (!d.channels.empty()) {
    s += "<div class=\"table-wrap\"><table class=\"table-noise-channels\"><thead><tr>"
         "<th>channel</th><th>status</th><th>reason</th></tr></thead><tbody>";
    for (const results::NoiseChannelDiagnostics& c : d.channels) {
      s += "<tr><td>" + E(c.name) + "</td><td>" + E(c.status) + "</td><td>" + E(c.reason) +
           "</td></tr>";
    }
    s += "</tbody></table></div>";
  }
  const std::string figs =
      AllanPlot(d.allan, 'a', "m/s\xC2\xB2") + AllanPlot(d.allan, 'g', "rad/s");
  if (!figs.empty()) s += "<div class=\"plots\">" + figs + "</div>";
  return s;
}

class NoiseReportImpl : public MethodReport {
 public:
  const char* method() const override { return "noise"; }
  std::string Section(const JobView& view) const override { return NoiseReport(view); }
  std::string Partial(const JobView& view) const override { return NoisePartialReport(view); }
  // "accel N ≤ 2 mm/s²/√Hz · gyro N ≤ 120 µrad/s/√Hz": the largest white noise density per
  // sensor type ("not visible" when no channel of that type shows it), led by "not stationary"
  // when the sensor moved.
  std::string KeyFigures(const json& result) const override {
    results::NoiseResult r;
    const Status read = results::FromJson(result, &r);
    if (!read.ok()) return "not available: " + read.message();
    if (r.channels.empty()) return "";
    std::string out = r.diagnostics.stationary ? "" : "not stationary \xC2\xB7 ";
    bool first = true;
    for (const char kind : {'a', 'g'}) {
      double worst = kNaN;
      bool any = false;
      for (const results::NoiseChannelParameters& c : r.channels) {
        if (c.name.empty() || c.name[0] != kind) continue;
        any = true;
        if (std::isfinite(c.white_noise) && !(worst >= c.white_noise)) worst = c.white_noise;
      }
      if (!any) continue;
      out += std::string(first ? "" : " \xC2\xB7 ") + (kind == 'a' ? "accel" : "gyro") + " N ";
      out +=
          std::isfinite(worst)
              ? "\xE2\x89\xA4 " +
                    FormatSI(worst,
                             kind == 'a' ? "m/s\xC2\xB2/\xE2\x88\x9AHz" : "rad/s/\xE2\x88\x9AHz", 2)
              : std::string("not visible");
      first = false;
    }
    return out;
  }
  std::string Drift(const std::vector<const JobSummary*>& jobs) const override {
    return NoiseDriftHtml(jobs);  // methods/noise/noise_drift.h
  }
};

}  // namespace

const MethodReport& NoiseMethodReport() {
  static const NoiseReportImpl& report = *new NoiseReportImpl();
  return report;
}

}  // namespace calibd::web::internal
