// The imu report section (web/reports.h).
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

// A failed imu job: the statics found on the timeline, and per IMU its coverage and rotations.
std::string ImuPartial(const JobView& view) {
  const json* diag = Get(view.job.error_detail, "diagnostics");
  const json* statics = Array(Get(diag, "statics"));
  const size_t n = statics != nullptr ? statics->size() : 0;
  std::string s = "<dl class=\"kv partial-imu\"><dt>static intervals found</dt><dd>" +
                  std::to_string(n) + "</dd><dt>sample rate</dt><dd>" +
                  FormatSI(Num(Get(diag, "rate")), "Hz") + "</dd><dt>threshold</dt><dd>" +
                  E(Str(Get(diag, "threshold_choice"))) + "</dd></dl>";
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
    for (const json& iv : *statics) {
      const double a = Num(Get(&iv, "start")), b = Num(Get(&iv, "end"));
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
  const json* imus = Array(Get(diag, "imus"));
  if (imus != nullptr) {
    for (const json& imu : *imus) {
      const json* cov = Get(&imu, "coverage");
      const json* missing = Array(Get(cov, "missing_up"));
      std::string missing_text;
      if (missing != nullptr) {
        for (const json& m : *missing) {
          if (m.is_string())
            missing_text += (missing_text.empty() ? "" : ", ") + m.get<std::string>();
        }
      }
      const json* rotations = Array(Get(&imu, "rotations"));
      s += "<h3>IMU " + E(Str(Get(&imu, "name"))) + "</h3><dl class=\"kv\">";
      s += "<dt>termination</dt><dd>" + E(Str(Get(&imu, "termination"))) + "</dd>";
      s += "<dt>rotations between statics</dt><dd>" +
           std::to_string(rotations != nullptr ? rotations->size() : 0) + "</dd>";
      s += "<dt>orientation coverage</dt><dd class=\"coverage-verdict\">" +
           E(Str(Get(cov, "verdict")).empty() ? std::string(kDash) : Str(Get(cov, "verdict"))) +
           "</dd>";
      if (!missing_text.empty()) {
        s += "<dt>orientations missing (up)</dt><dd>" + E(missing_text) + "</dd>";
      }
      s += "</dl>";
    }
  }
  return s;
}

namespace {

class ImuReportImpl : public MethodReport {
 public:
  const char* method() const override { return "imu"; }
  std::string Section(const JobView& view) const override { return ImuReport(view); }
  std::string Partial(const JobView& view) const override { return ImuPartial(view); }
  std::string Drift(const std::vector<const JobSummary*>& jobs) const override {
    return ImuDriftHtml(jobs);  // web/device_drift.h
  }
  std::vector<Download> Downloads() const override {
    return {{"csv", "CSV"}, {"h", "C header"}, {"yaml", "OpenVINS kalibr_imu_chain.yaml"}};
  }
};

}  // namespace

const MethodReport& ImuMethodReport() {
  static const ImuReportImpl& report = *new ImuReportImpl();
  return report;
}

}  // namespace calibd::web::internal
