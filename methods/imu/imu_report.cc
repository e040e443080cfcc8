// The imu report section (methods/imu/imu_report.h): reads the result once as results::ImuResult
// (methods/imu/imu_result.h); a result that does not read shows "not available" with the reason.
#include "methods/imu/imu_report.h"

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

#include "methods/imu/imu_drift.h"
#include "methods/imu/imu_result.h"
#include "web/html.h"
#include "web/report_common.h"
#include "web/svg_plot.h"

namespace calibd::web::internal {

namespace {

// A result that does not read as results::ImuResult: the "not available" text with the reader's
// message (which names the path of the problem).
std::string Unreadable(const std::string& what, const Status& s) {
  return NotAvailable(what) + "<p class=\"muted small\">" + E(s.message()) + "</p>";
}

// A number as the diagnostics table shows it (integral values without decimals; NaN a dash).
// A text member, or a dash when it is empty (absent from a result of an earlier calibd).
std::string TextOrDash(const std::string& s) { return s.empty() ? std::string(kDash) : s; }

std::string Scalar(double v, int sig) {
  const json j = results::Num(v);
  return ScalarText(&j, sig);
}

std::string Vec3Cell(const Eigen::Vector3d& v, int sig = 6) {
  std::string text;
  for (int k = 0; k < 3; ++k) {
    text += (k ? "<br>" : "") + FormatSig(v(k), sig);  // x, y, z stacked: fits 1280 px
  }
  return NumCell(text);
}

// One figure per item of `items` (1-based index on x): `before(item)` and `after(item)` as open
// and filled circles; "" when there are no items.
template <class T, class Before, class After>
std::string BeforeAfterPlot(const std::vector<T>& items, Before before_of, After after_of,
                            PlotOptions options, const std::string& caption) {
  if (items.empty()) return "";
  Series before, after;
  before.label = "nominal conversion";
  after.label = "calibrated";
  before.marker = Marker::kOpenCircle;
  after.marker = Marker::kCircle;
  before.line = after.line = false;
  for (size_t j = 0; j < items.size(); ++j) {
    before.x.push_back(static_cast<double>(j + 1));
    after.x.push_back(static_cast<double>(j + 1));
    before.y.push_back(before_of(items[j]));
    after.y.push_back(after_of(items[j]));
  }
  options.y.include_zero = true;
  return Figure(RenderXYPlot(options, {before, after}), caption);
}

}  // namespace

std::string ImuReport(const JobView& view) {
  results::ImuResult r;
  if (Status st = results::FromJson(view.job.result, &r); !st.ok()) {
    return Unreadable("The imu result", st);
  }
  const results::ImuDiagnostics& diag = r.diagnostics;
  std::string out;
  out += Guard("Parameters", [&] {
    if (!r.parameters) return NotAvailable("Parameters");
    const results::ImuParameters& params = *r.parameters;
    std::string s = "<dl class=\"kv\"><dt>gravity</dt><dd>" + E(Scalar(params.gravity, 7)) +
                    " m/s\xC2\xB2</dd><dt>gyroscope bias</dt><dd>" +
                    E(TextOrDash(params.gyro_bias)) + "</dd><dt>static intervals</dt><dd>";
    s += std::to_string(diag.statics.size()) + " (" + E(TextOrDash(diag.threshold_choice)) +
         ")</dd></dl>";
    if (params.imus.empty()) {
      return Section("parameters", "Parameters", s + NotAvailable("IMUs"));
    }
    s += "<div class=\"table-wrap\"><table class=\"table-imu-parameters\"><thead><tr>"
         "<th>IMU</th><th>sensor</th><th>bias b, x y z<br>(reading units)</th>"
         "<th>\xCF\x83(b)<br>(reading units)</th><th>scale K, x y z<br>(SI per reading unit)</th>"
         "<th>\xCF\x83(K)<br>(SI per reading unit)</th><th>misalignment T<br>(3 rows, unitless)"
         "</th></tr></thead><tbody>";
    for (size_t i = 0; i < params.imus.size(); ++i) {
      const results::ImuTriads& imu = params.imus[i];
      const results::ImuTriadsStd& u = r.uncertainty->imus[i];
      for (int t = 0; t < 2; ++t) {
        const results::SensorTriad& p = t == 0 ? imu.accelerometer : imu.gyroscope;
        const results::SensorTriadStd& ps = t == 0 ? u.accelerometer : u.gyroscope;
        std::string rows;
        for (int row = 0; row < 3; ++row) {
          std::string cells;
          for (int k = 0; k < 3; ++k)
            cells += (k ? " " : "") + FormatFixed(p.misalignment(row, k), 5);
          rows += (row ? "<br>" : "") + cells;
        }
        s += "<tr><td>" + E(imu.name) + "</td><td>" + (t == 0 ? "accelerometer" : "gyroscope") +
             "</td>" + Vec3Cell(p.bias) + Vec3Cell(ps.bias_std, 2) + Vec3Cell(p.scale) +
             Vec3Cell(ps.scale_std, 2) + "<td class=\"num small\">" + rows + "</td></tr>";
      }
    }
    s += "</tbody></table></div><p class=\"muted small\">The parameters of the model above. T_a "
         "is upper triangular: the body frame is the accelerometer's (x along its x axis, y in its "
         "x-y plane). \xCF\x83 is one standard deviation from the Fisher information at the "
         "estimate.</p>";
    return Section("parameters", "Parameters", s);
  });
  out += Guard("Fit", [&] {
    if (diag.imus.empty()) return std::string();
    std::string s, figs;
    for (const results::ImuFitDiagnostics& imu : diag.imus) {
      s += "<h3>IMU " + E(imu.name) + "</h3><dl class=\"kv\">";
      s += "<dt>|a| \xE2\x88\x92 g over the statics (RMS)</dt><dd>" +
           FormatSI(imu.accel_norm_rms_before, "m/s\xC2\xB2") + " before, " +
           FormatSI(imu.accel_norm_rms_after, "m/s\xC2\xB2") + " after</dd>";
      s += "<dt>gravity direction after each rotation (RMS)</dt><dd>" +
           FormatSI(imu.gyro_direction_rms_before, "rad") + " before, " +
           FormatSI(imu.gyro_direction_rms_after, "rad") + " after</dd>";
      s += "<dt>\xCF\x87\xC2\xB2 / degrees of freedom</dt><dd>" + E(Scalar(imu.chi2_per_dof, 3)) +
           "</dd>";
      s += "<dt>orientation coverage</dt><dd>" + E(imu.coverage.verdict) +
           " (smallest eigenvalue " + E(Scalar(imu.coverage.min_eigenvalue, 3)) +
           ", 1 = evenly spread)</dd></dl>";
      PlotOptions o;
      o.name = "imu-gravity-norm";
      o.title = "|a| \xE2\x88\x92 g per static interval";
      o.x.title = "static interval";
      o.y.title = "|a| \xE2\x88\x92 g (m/s\xC2\xB2)";
      figs += BeforeAfterPlot(
          imu.statics, [](const results::ImuStatic& x) { return x.norm_residual_before; },
          [](const results::ImuStatic& x) { return x.norm_residual_after; }, o,
          "Each static's specific force should have the magnitude of gravity.");
      o.name = "imu-rotation-error";
      o.title = "Gravity direction error after each rotation";
      o.x.title = "rotation (between statics j and j+1)";
      o.y.title = "angle (rad)";
      figs += BeforeAfterPlot(
          imu.rotations, [](const results::ImuRotation& x) { return x.direction_error_before; },
          [](const results::ImuRotation& x) { return x.direction_error_after; }, o,
          "The integrated gyroscope must carry gravity's direction from one static to the next.");
    }
    return Section("fit", "Fit", s + "<div class=\"plots\">" + figs + "</div>");
  });
  return out;
}

// A failed imu job: the statics found on the timeline, and per IMU its coverage and rotations.
std::string ImuPartial(const JobView& view) {
  results::ImuResult r;
  if (Status st = results::FromJson(view.job.error_detail, &r); !st.ok()) {
    return Unreadable("The partial diagnostics", st);
  }
  const results::ImuDiagnostics& diag = r.diagnostics;
  const size_t n = diag.statics.size();
  std::string s = "<dl class=\"kv partial-imu\"><dt>static intervals found</dt><dd>" +
                  std::to_string(n) + "</dd><dt>sample rate</dt><dd>" +
                  FormatSI(diag.rate.value_or(kNaN), "Hz") + "</dd><dt>threshold</dt><dd>" +
                  E(TextOrDash(diag.threshold_choice)) + "</dd></dl>";
  if (n > 0) {
    PlotOptions o;
    o.name = "imu-statics-found";
    o.title = "Static intervals found";
    o.x.title = "time t (s)";
    o.y.title = "duration (s)";
    o.width = 900;
    o.height = 260;
    o.y.include_zero = true;
    Series mid;
    mid.label = "static interval";
    mid.line = false;
    mid.marker = Marker::kCircle;
    size_t k = 0;
    for (const results::ImuInterval& iv : diag.statics) {
      const double a = iv.start, b = iv.end;
      ++k;
      if (!std::isfinite(a) || !std::isfinite(b)) continue;
      o.bands.push_back({a, b, std::to_string(k)});
      mid.x.push_back(0.5 * (a + b));
      mid.y.push_back(b - a);
    }
    s += Figure(RenderXYPlot(o, {mid}),
                "Shaded and numbered: the static intervals the detector found on the log's "
                "timeline (marker: each one's duration).");
  }
  for (const results::ImuFitDiagnostics& imu : diag.imus) {
    std::string missing_text;
    for (const std::string& m : imu.coverage.missing_up) {
      missing_text += (missing_text.empty() ? "" : ", ") + m;
    }
    s += "<h3>IMU " + E(imu.name) + "</h3><dl class=\"kv\">";
    s += "<dt>termination</dt><dd>" + E(TextOrDash(imu.termination)) + "</dd>";
    s += "<dt>rotations between statics</dt><dd>" + std::to_string(imu.rotations.size()) + "</dd>";
    s += "<dt>orientation coverage</dt><dd class=\"coverage-verdict\">" +
         E(TextOrDash(imu.coverage.verdict)) + "</dd>";
    if (!missing_text.empty()) {
      s += "<dt>orientations missing (up)</dt><dd>" + E(missing_text) + "</dd>";
    }
    s += "</dl>";
  }
  return s;
}

namespace {

class ImuReportImpl : public MethodReport {
 public:
  const char* method() const override { return "imu"; }
  std::string Section(const JobView& view) const override { return ImuReport(view); }
  std::string Partial(const JobView& view) const override { return ImuPartial(view); }
  // "|a|−g RMS ≤ 1.2 mm/s² · χ²/ν ≤ 1.03 · 24 statics": the worst IMU's accelerometer residual
  // over the statics and its fit quality, and the statics found.
  std::string KeyFigures(const json& result) const override {
    results::ImuResult r;
    const Status read = results::FromJson(result, &r);
    if (!read.ok()) return "not available: " + read.message();
    double norm = kNaN, chi2 = kNaN;
    for (const results::ImuFitDiagnostics& imu : r.diagnostics.imus) {
      if (std::isfinite(imu.accel_norm_rms_after) && !(norm >= imu.accel_norm_rms_after))
        norm = imu.accel_norm_rms_after;
      if (std::isfinite(imu.chi2_per_dof) && !(chi2 >= imu.chi2_per_dof)) chi2 = imu.chi2_per_dof;
    }
    if (!std::isfinite(norm) && !std::isfinite(chi2)) return "";
    const std::string le = r.diagnostics.imus.size() > 1 ? " \xE2\x89\xA4 " : " ";
    return "|a|\xE2\x88\x92g RMS" + le + FormatSI(norm, "m/s\xC2\xB2", 2) +
           " \xC2\xB7 \xCF\x87\xC2\xB2/\xCE\xBD" + le + FormatSig(chi2, 3) + " \xC2\xB7 " +
           std::to_string(r.diagnostics.statics.size()) + " statics";
  }
  std::string Drift(const std::vector<const JobSummary*>& jobs) const override {
    return ImuDriftHtml(jobs);  // methods/imu/imu_drift.h
  }
};

}  // namespace

const MethodReport& ImuMethodReport() {
  static const ImuReportImpl& report = *new ImuReportImpl();
  return report;
}

}  // namespace calibd::web::internal
