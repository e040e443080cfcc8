// The mag report section (methods/mag/mag_report.h), read from the result JSON; a result of an
// unexpected shape shows "not available" (web::Guard).
#include "methods/mag/mag_report.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "web/html.h"
#include "web/report_common.h"
#include "web/svg_plot.h"

namespace calibd::web::internal {

namespace {

const char kAxisNames[3] = {'x', 'y', 'z'};

std::vector<double> Row(const json& m, size_t r) { return m.at(r).get<std::vector<double>>(); }

// µT per unit of the calibrated output S (y − h): 1 with a field, else the field estimate.
double CalibratedScale(const json& p) {
  return p.at("field").is_number() ? 1.0 : p.at("field_estimate").get<double>();
}

// The three projections of the raw (converted to µT, centred on the hard iron shown as a cross)
// and the calibrated samples, with the circle of radius F.
std::string SphereProjections(const json& p, const json& plot) {
  const double per_unit = p.at("microtesla_per_unit").get<double>();
  const double scale = CalibratedScale(p);
  const double f = p.at("field").is_number() ? p.at("field").get<double>()
                                             : p.at("field_estimate").get<double>();
  std::string figs;
  for (int k = 0; k < 3; ++k) {
    const size_t a = static_cast<size_t>(k), b = static_cast<size_t>((k + 1) % 3);
    Series raw, cal, circle;
    raw.label = "raw";
    cal.label = "calibrated";
    circle.label = "|m| = field";
    for (Series* s : {&raw, &cal}) {
      const json& src = plot.at(s == &raw ? "raw" : "calibrated");
      const double c = s == &raw ? per_unit : scale;
      s->x = Row(src, a);
      s->y = Row(src, b);
      for (double& v : s->x) v *= c;
      for (double& v : s->y) v *= c;
      s->line = false;
      s->marker = Marker::kCircle;
    }
    for (int i = 0; i <= 96; ++i) {
      circle.x.push_back(f * std::cos(2 * kPi * i / 96));
      circle.y.push_back(f * std::sin(2 * kPi * i / 96));
    }
    circle.dashed = true;
    PlotOptions o;
    o.name = "mag-sphere";
    o.title = p.at("name").get<std::string>() + ": " + kAxisNames[a] + "-" + kAxisNames[b];
    o.x.title = std::string(1, kAxisNames[a]) + " (uT)";
    o.y.title = std::string(1, kAxisNames[b]) + " (uT)";
    o.equal_aspect = true;
    o.width = o.height = 360;
    figs += Figure(RenderXYPlot(o, {raw, cal, circle}),
                   o.title + " projection: raw readings and calibrated field");
  }
  return figs;
}

// |m| − F over time, the disturbed spans as bands.
std::string ResidualPlot(const json& p, const json& d) {
  const json& plot = d.at("plot");
  Series r;
  r.label = "|m| - field";
  r.x = plot.at("t").get<std::vector<double>>();
  r.y = plot.at("residual").get<std::vector<double>>();
  for (double& v : r.y) v *= CalibratedScale(p);
  PlotOptions o;
  o.name = "mag-residuals";
  o.title = p.at("name").get<std::string>() + ": |m| residual over time";
  o.x.title = "time (s)";
  o.y.title = "|m| - field (uT)";
  for (const json& s : d.at("disturbed_spans")) {
    o.bands.push_back({s.at("start").get<double>(), s.at("end").get<double>(), "disturbed"});
  }
  return Figure(RenderXYPlot(o, {r}), o.title + " (shaded: disturbed spans, down-weighted)");
}

// The field's direction in the magnetometer frame (P (y − h), i.e. Rᵀ m) as azimuth and
// elevation: where the samples went; the missing axes named under the plot.
std::string CoverageMap(const json& p, const json& d) {
  const json& plot = d.at("plot");
  Eigen::Matrix3d rt = Eigen::Matrix3d::Identity();
  if (p.contains("alignment") && p.at("alignment").is_array()) {
    for (size_t r = 0; r < 3; ++r) {
      for (size_t c = 0; c < 3; ++c) rt(c, r) = p.at("alignment").at(r).at(c).get<double>();
    }
  }
  Series s;
  s.label = "field direction";
  const json& cal = plot.at("calibrated");
  for (size_t i = 0; i < cal.at(0).size(); ++i) {
    const Eigen::Vector3d m = rt * Eigen::Vector3d(cal[0][i].get<double>(), cal[1][i].get<double>(),
                                                   cal[2][i].get<double>());
    if (!(m.norm() > 0)) continue;
    s.x.push_back(std::atan2(m(1), m(0)) * 180 / kPi);
    s.y.push_back(std::asin(std::clamp(m(2) / m.norm(), -1.0, 1.0)) * 180 / kPi);
  }
  s.line = false;
  s.marker = Marker::kCircle;
  PlotOptions o;
  o.name = "mag-coverage";
  o.title = p.value("name", "") + ": coverage of field directions";
  o.x.title = "azimuth in the magnetometer frame (deg)";
  o.y.title = "elevation (deg)";
  o.x.min = -180;
  o.x.max = 180;
  o.y.min = -90;
  o.y.max = 90;
  const json& c = d.at("coverage");
  o.notes.push_back("verdict: " + c.at("verdict").get<std::string>());
  return Figure(RenderXYPlot(o, {s}), o.title);
}

std::string ParameterTable(const json& p, const json& u, const json& d) {
  auto pm = [](const json& v, const json& s, int sig) {
    return NumCell(ScalarText(&v, sig) + " \xC2\xB1 " + ScalarText(&s, 2));
  };
  std::string h = "<table><tr><th></th><th>x</th><th>y</th><th>z</th></tr><tr><td>hard iron (" +
                  E(p.at("mag_unit").get<std::string>()) + ")</td>";
  for (size_t a = 0; a < 3; ++a) h += pm(p.at("hard_iron").at(a), u.at("hard_iron_std").at(a), 5);
  h += "</tr>";
  for (size_t r = 0; r < 3; ++r) {
    h += "<tr><td>soft iron S row " + std::string(1, kAxisNames[r]) + "</td>";
    for (size_t c = 0; c < 3; ++c) {
      h += pm(p.at("soft_iron").at(r).at(c), u.at("soft_iron_std").at(r).at(c), 5);
    }
    h += "</tr>";
  }
  if (u.at("alignment_std").is_array()) {
    h += "<tr><td>alignment 1" + std::string(kSigma) + " (rad)</td>";
    for (size_t a = 0; a < 3; ++a) h += NumCell(ScalarText(&u.at("alignment_std").at(a), 3));
    h += "</tr>";
  }
  h += "</table><p>field estimate " + E(ScalarText(&p.at("field_estimate"), 4)) + " uT";
  if (p.at("dip").is_number()) {
    h += ", dip " + E(ScalarText(&p.at("dip"), 4)) + " \xC2\xB1 " +
         E(ScalarText(&u.at("dip_std"), 2)) + " deg";
  }
  h += "; alignment " + E(d.at("alignment_note").get<std::string>()) + "; |m| residual RMS " +
       E(ScalarText(&d.at("residual_rms_before"), 3)) + " uT before, " +
       E(ScalarText(&d.at("residual_rms_clean"), 3)) + " uT after (undisturbed samples); " +
       std::to_string(d.at("disturbed_samples").get<int64_t>()) + " of " +
       std::to_string(d.at("samples").get<int64_t>()) + " samples disturbed.</p>";
  // What σ holds where the offsets wander (core/mag.h step 3c; absent from results of calibd
  // before it).
  const json* wander = d.contains("wander") ? &d.at("wander") : nullptr;
  if (wander != nullptr && wander->value("included", false) && wander->at("rate").is_array()) {
    const json& rate = wander->at("rate");
    h += "<p class=\"wander\">The offsets wander (the sandwich's blocking reaches no plateau): " +
         std::string(kSigma) + " above predicts the next log as long as this one: the sensor's " +
         "sample-to-sample noise plus the hard iron's random walk of " +
         E(ScalarText(&rate.at(0), 3)) + ", " + E(ScalarText(&rate.at(1), 3)) + ", " +
         E(ScalarText(&rate.at(2), 3)) + " " + E(wander->value("rate_unit", std::string())) +
         " (x, y, z) from " + std::to_string(wander->value("segments", 0)) + " segments.</p>";
  }
  return h;
}

class MagReport : public MethodReport {
 public:
  const char* method() const override { return "mag"; }
  std::string Section(const JobView& view) const override {
    return Guard("magnetometer calibration", [&] {
      const json& r = view.job.result;
      const json& p = r.at("parameters").at("mags");
      const json& u = r.at("uncertainty").at("mags");
      const json& d = r.at("diagnostics").at("mags");
      std::string body;
      for (size_t i = 0; i < p.size(); ++i) {
        body += "<h3>Magnetometer " + E(p[i].at("name").get<std::string>()) + "</h3>" +
                ParameterTable(p[i], u[i], d[i]) + "<div class=\"plots\">" +
                SphereProjections(p[i], d[i].at("plot")) + ResidualPlot(p[i], d[i]) +
                CoverageMap(p[i], d[i]) + "</div>";
      }
      return internal::Section("mag", "Hard and soft iron", body);
    });
  }
  std::string Partial(const JobView& view) const override {
    return Guard("what the magnetometer fit found", [&] {
      std::string body;
      for (const json& d : view.job.error_detail.at("diagnostics").at("mags")) {
        if (!d.contains("plot")) continue;
        const json p = {{"name", d.at("name")}, {"alignment", nullptr}};
        body += "<p>" + E(d.at("coverage").at("verdict").get<std::string>()) + "</p>" +
                CoverageMap(p, d);
      }
      return body.empty() ? std::string() : internal::Section("partial-mag", "Coverage", body);
    });
  }
  // "field 48.2 uT · |m| RMS 0.31 uT" (the worst magnetometer's residual).
  std::string KeyFigures(const json& result) const override {
    try {
      const json& p = result.at("parameters").at("mags");
      const json& d = result.at("diagnostics").at("mags");
      if (p.empty()) return "";
      double worst = 0;
      for (const json& m : d) worst = std::max(worst, m.at("residual_rms_clean").get<double>());
      return "field " + FormatSig(p[0].at("field_estimate").get<double>(), 3) +
             " uT \xC2\xB7 |m| RMS " + FormatSig(worst, 2) + " uT";
    } catch (const std::exception&) {
      return "";
    }
  }
  std::string Drift(const std::vector<const JobSummary*>& jobs) const override;
};

// The index of magnetometer `name` in a result's parameters.mags, or -1.
int FindMag(const json& result, const std::string& name) {
  const json& mags = result.at("parameters").at("mags");
  for (size_t i = 0; i < mags.size(); ++i) {
    if (mags[i].at("name") == name) return static_cast<int>(i);
  }
  return -1;
}

// The hard iron (µT) and its σ of magnetometer i of a result.
void HardIronMicrotesla(const json& result, size_t i, Eigen::Vector3d* h, Eigen::Vector3d* s) {
  const json& p = result.at("parameters").at("mags").at(i);
  const json& u = result.at("uncertainty").at("mags").at(i);
  const double per_unit = p.at("microtesla_per_unit").get<double>();
  for (size_t x = 0; x < 3; ++x) {
    (*h)(x) = p.at("hard_iron").at(x).get<double>() * per_unit;
    (*s)(x) = u.at("hard_iron_std").at(x).get<double>() * per_unit;
  }
}

// The hard iron's change between successive results, per magnetometer, in µT, with |Δ| over
// the σ of the difference.
std::string MagReport::Drift(const std::vector<const JobSummary*>& jobs) const {
  return Guard("hard-iron drift", [&] {
    std::string rows;
    for (size_t k = FirstDriftPair(jobs.size()); k < jobs.size(); ++k) {
      const json& a = jobs[k - 1]->result;
      const json& b = jobs[k]->result;
      std::string cells;
      const json& mags = b.at("parameters").at("mags");
      for (size_t ib = 0; ib < mags.size(); ++ib) {
        const std::string name = mags[ib].at("name").get<std::string>();
        const int ia = FindMag(a, name);
        if (ia < 0) continue;
        Eigen::Vector3d ha, sa, hb, sb;
        HardIronMicrotesla(a, static_cast<size_t>(ia), &ha, &sa);
        HardIronMicrotesla(b, ib, &hb, &sb);
        const double change = (hb - ha).norm();
        const double sigma = std::sqrt(sa.squaredNorm() + sb.squaredNorm());
        cells += name + ": " + FormatSig(change, 3) + " uT (" + FormatSig(change / sigma, 2) + " " +
                 kSigma + ") ";
      }
      rows += "<tr>" + PairTimeCell(*jobs[k - 1], *jobs[k]) + "<td>" +
              PairLabel(*jobs[k - 1], *jobs[k]) + "</td><td>" + E(cells) + "</td></tr>";
    }
    return "<h3>mag: hard-iron drift</h3>" + OmittedPairsNote(jobs.size()) +
           "<table><tr><th>time</th><th>pair</th><th>|change of h| per magnetometer</th></tr>" +
           rows + "</table>";
  });
}

}  // namespace

const MethodReport& MagMethodReport() {
  static const MagReport& report = *new MagReport;
  return report;
}

}  // namespace calibd::web::internal
