// The thermal report section (methods/thermal/thermal_report.h), read from the result JSON; a
// result of an unexpected shape shows "not available" (web::Guard).
#include "methods/thermal/thermal_report.h"

#include <string>
#include <vector>

#include "methods/thermal/thermal_drift.h"
#include "web/html.h"
#include "web/report_common.h"
#include "web/svg_plot.h"

namespace calibd::web::internal {

namespace {

// One channel's plot: the curve ± 1σ on the grid, the window means (heating and cooling in two
// colours, steady in a third).
std::string ChannelPlot(const json& pimu, const json& uimu, const json& ch, int c) {
  const char* sensor = c < 3 ? "accelerometer" : "gyroscope";
  const json& unc = uimu.at(sensor).at("bias");
  const std::vector<double> grid = unc.at("temperatures").get<std::vector<double>>();
  const std::vector<double> curve = ch.at("curve").get<std::vector<double>>();
  const std::vector<double> sd =
      unc.at("std").at(static_cast<size_t>(c % 3)).get<std::vector<double>>();
  // A series of the curve's points with `label` (members set one by one: the struct's later
  // members keep their defaults).
  auto curve_series = [&](const char* label) {
    Series s;
    s.label = label;
    s.x = grid;
    s.y = curve;
    return s;
  };
  Series mid = curve_series("curve");
  Series hi = curve_series("curve + 1 sigma"), lo = curve_series("");
  hi.dashed = lo.dashed = true;
  hi.color = lo.color = mid.color = 0;
  for (size_t i = 0; i < grid.size(); ++i) {
    hi.y[i] += sd[i];
    lo.y[i] -= sd[i];
  }
  const json& pts = ch.at("points");
  Series phases[3];
  const char* const kPhaseNames[3] = {"cooling", "steady", "heating"};
  for (int p = 0; p < 3; ++p) phases[p].label = kPhaseNames[p];
  for (size_t i = 0; i < pts.at("temperature").size(); ++i) {
    Series& s = phases[pts.at("phase")[i].get<int>() + 1];
    s.x.push_back(pts.at("temperature")[i].get<double>());
    s.y.push_back(pts.at("deviation")[i].get<double>());
    s.y_err.push_back(pts.at("std")[i].get<double>());
  }
  std::vector<Series> series = {mid, hi, lo};
  for (int k = 0; k < 3; ++k) {
    phases[k].line = false;
    phases[k].marker = Marker::kCircle;
    phases[k].color = k + 1;
    if (!phases[k].x.empty()) series.push_back(phases[k]);
  }
  PlotOptions o;
  o.name = "thermal";
  o.title = "IMU " + pimu.at("name").get<std::string>() + " " + ch.at("name").get<std::string>();
  o.x.title = "temperature (degC)";
  o.y.title = std::string("bias - bias(t_ref) (") + (c < 3 ? "m/s^2" : "rad/s") + ")";
  return Figure(RenderXYPlot(o, series), o.title + ": order " +
                                             std::to_string(ch.at("order").get<int>()) +
                                             ", basis " + ch.at("basis").get<std::string>());
}

// Accelerometer axis a's scale curve d(T) (the gain's relative change from t_ref) ± 1σ, where the
// result has one; else a line with the reason it is null.
std::string ScalePlot(const json& pimu, const json& uimu, int a) {
  const json& scale = pimu.at("accelerometer").at("scale");
  if (scale.is_null()) return "";
  const json& coefficients = scale.at("coefficients").at(static_cast<size_t>(a));
  const std::string axis(1, "xyz"[a]);
  if (coefficients.is_null()) {
    return "<p>Scale curve of accelerometer " + axis + " not estimated: " +
           E(scale.at("not_estimated").at(static_cast<size_t>(a)).get<std::string>()) + "</p>";
  }
  const json& unc = uimu.at("accelerometer").at("scale");
  const std::vector<double> grid = unc.at("temperatures").get<std::vector<double>>();
  const std::vector<double> sd =
      unc.at("std").at(static_cast<size_t>(a)).get<std::vector<double>>();
  const double t_ref = pimu.at("t_ref").get<double>();
  Series mid, hi, lo;
  mid.label = "scale curve";
  hi.label = "curve + 1 sigma";
  for (Series* s : {&mid, &hi, &lo}) {
    s->x = grid;
    s->color = 0;
  }
  hi.dashed = lo.dashed = true;
  for (size_t i = 0; i < grid.size(); ++i) {
    double value = 0, power = 1;  // sum_k d_k (T - t_ref)^k
    for (const json& d : coefficients) {
      power *= grid[i] - t_ref;
      value += d.get<double>() * power;
    }
    mid.y.push_back(value);
    hi.y.push_back(value + sd[i]);
    lo.y.push_back(value - sd[i]);
  }
  PlotOptions o;
  o.x.title = "temperature (degC)";
  o.name = "thermal_scale";
  o.title = "IMU " + pimu.at("name").get<std::string>() + " accelerometer." + axis + " scale";
  o.y.title = "gain / gain(t_ref) - 1";
  return Figure(RenderXYPlot(o, {mid, hi, lo}),
                o.title + ": order " +
                    std::to_string(scale.at("orders").at(static_cast<size_t>(a)).get<int>()));
}

std::string OrderTable(const json& d) {
  std::string h =
      "<table><tr><th>channel</th><th>order</th><th>chi2/dof</th><th>residual RMS</th>"
      "<th>noise RMS</th><th>BIC weight by order (curve / band)</th><th>hysteresis max "
      "|z|</th></tr>";
  for (const json& ch : d.at("channels")) {
    std::string weights;
    for (const json& row : ch.at("order_table")) {
      // Results stored before the band weights have none.
      weights +=
          std::to_string(row.at("order").get<int>()) + ": " +
          FormatSig(row.at("weight").get<double>(), 2) +
          (row.contains("band_weight") ? " / " + FormatSig(row.at("band_weight").get<double>(), 2)
                                       : std::string()) +
          " ";
    }
    const json& hy = ch.at("hysteresis");
    const std::string z = hy.at("tested").get<bool>()
                              ? FormatSig(hy.at("max_abs_z").get<double>(), 3) +
                                    (hy.at("flagged").get<bool>() ? " (flagged)" : "")
                              : "not tested";
    h += "<tr><td>" + E(ch.at("name").get<std::string>()) + "</td>" +
         NumCell(std::to_string(ch.at("order").get<int>())) +
         NumCell(ScalarText(&ch.at("chi2_per_dof"), 3)) +
         NumCell(ScalarText(&ch.at("residual_rms"), 3)) +
         NumCell(ScalarText(&ch.at("noise_rms"), 3)) + "<td class=\"small\">" + E(weights) +
         "</td><td>" + E(z) + "</td></tr>";
  }
  return h + "</table><p class=\"muted small\">Hysteresis flagged above |z| " +
         E(FormatSig(d.at("hysteresis_critical_z").get<double>(), 3)) +
         " (Bonferroni over 6 channels and the grid).</p>";
}

// The lag line: τ with its σ where estimated, as given, or none (a result stored before the lag
// existed has no diagnostics.imus[].lag: none).
std::string LagLine(const json& uimu, const json& d) {
  const json none = {{"mode", "none"}};
  const json& lag = d.contains("lag") ? d.at("lag") : none;
  const std::string mode = lag.at("mode").get<std::string>();
  if (mode == "none") {
    return "<p>Lag: none (the temperature reading is taken as the sensor's).</p>";
  }
  std::string text = "Lag between the temperature reading and the sensor: &tau; = " +
                     E(FormatSig(lag.at("tau").get<double>(), 3));
  if (mode == "estimate") text += " &plusmn; " + E(FormatSig(uimu.at("lag_std").get<double>(), 2));
  return "<p>" + text + " s (" + E(mode == "estimate" ? "estimated" : "given") + ").</p>";
}

class ThermalReport : public MethodReport {
 public:
  const char* method() const override { return "thermal"; }
  std::string Section(const JobView& view) const override {
    return Guard("thermal curves", [&] {
      const json& r = view.job.result;
      const json& p = r.at("parameters").at("imus");
      const json& u = r.at("uncertainty").at("imus");
      const json& d = r.at("diagnostics").at("imus");
      std::string body;
      for (size_t i = 0; i < p.size(); ++i) {
        body += "<h3>IMU " + E(p[i].at("name").get<std::string>()) + ": " +
                E(FormatSig(p[i].at("t_min").get<double>(), 4)) + " to " +
                E(FormatSig(p[i].at("t_max").get<double>(), 4)) + " degC, t_ref " +
                E(FormatSig(p[i].at("t_ref").get<double>(), 4)) + "</h3>";
        body += LagLine(u[i], d[i]) + OrderTable(d[i]);
        for (int c = 0; c < 6; ++c) {
          body += ChannelPlot(p[i], u[i], d[i].at("channels").at(static_cast<size_t>(c)), c);
        }
        for (int a = 0; a < 3; ++a) body += ScalePlot(p[i], u[i], a);
      }
      return internal::Section("thermal", "Bias against temperature", body);
    });
  }
  std::string Drift(const std::vector<const JobSummary*>& jobs) const override {
    return ThermalDriftHtml(jobs);  // methods/thermal/thermal_drift.h
  }
};

}  // namespace

const MethodReport& ThermalMethodReport() {
  static const ThermalReport& report = *new ThermalReport;
  return report;
}

}  // namespace calibd::web::internal
