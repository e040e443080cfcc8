// The thermal method's drift on the device page (methods/thermal/thermal_drift.h).
#include "methods/thermal/thermal_drift.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "web/drift_table.h"
#include "web/html.h"
#include "web/svg_plot.h"

namespace calibd::web {
namespace {

using json = nlohmann::json;
using namespace drift;  // NOLINT: the shared drift pieces

constexpr int kGrid = 21;             // points across the common range
constexpr double kMinOverlap = 1.0;   // °C of common range below which curves are not compared
constexpr double kSameTref = 0.05;    // °C: t_ref "the same" for the absolute gyroscope bias
constexpr size_t kMaxPlotted = 8;     // newest calibrations drawn per plot
constexpr const char* kAxes = "xyz";  // channel c: sensor c / 3, axis c % 3

// One channel's curve d(T) = Σ_{k=1..p} c_k (T − t_ref)^k and the covariance of c.
struct Curve {
  Eigen::VectorXd c;
  Eigen::MatrixXd cov;
};

struct ThermalImu {
  std::string name;
  double t_ref = kNaN, t_min = kNaN, t_max = kNaN;
  std::array<Curve, 6> channels;                        // accelerometer x y z, gyroscope x y z (SI)
  std::optional<Eigen::Vector3d> gyro_at, gyro_at_std;  // absolute gyroscope bias at t_ref
};

Eigen::VectorXd ReadVector(const json& j) {
  Eigen::VectorXd v(static_cast<Eigen::Index>(j.size()));
  for (size_t i = 0; i < j.size(); ++i) v(static_cast<Eigen::Index>(i)) = j.at(i).get<double>();
  if (!v.allFinite()) throw std::runtime_error("a value is not finite");
  return v;
}

// One sensor's three curves of a thermal result's IMU.
void ReadSensor(const json& p, const json& u, int first, ThermalImu* imu) {
  const json& coefficients = p.at("bias").at("coefficients");
  const json& covariance = u.at("bias").at("covariance");
  if (coefficients.size() != 3 || covariance.size() != 3)
    throw std::runtime_error("bias curves of " + std::to_string(coefficients.size()) + " axes");
  for (size_t a = 0; a < 3; ++a) {
    Curve& curve = imu->channels[static_cast<size_t>(first) + a];
    curve.c = ReadVector(coefficients.at(a));
    const auto p_order = curve.c.size();
    const json& rows = covariance.at(a);
    if (static_cast<Eigen::Index>(rows.size()) != p_order)
      throw std::runtime_error("a curve's covariance does not match its coefficients");
    curve.cov.resize(p_order, p_order);
    for (Eigen::Index r = 0; r < p_order; ++r) {
      const Eigen::VectorXd row = ReadVector(rows.at(static_cast<size_t>(r)));
      if (row.size() != p_order)
        throw std::runtime_error("a curve's covariance does not match its coefficients");
      curve.cov.row(r) = row.transpose();
    }
  }
}

// The IMUs of a thermal result; none, with *problem set, when it does not read.
std::vector<ThermalImu> ReadThermal(const json& result, std::string* problem) {
  std::vector<ThermalImu> out;
  try {
    const json& p = result.at("parameters").at("imus");
    const json& u = result.at("uncertainty").at("imus");
    if (p.size() != u.size()) throw std::runtime_error("parameters and uncertainty differ in IMUs");
    for (size_t i = 0; i < p.size(); ++i) {
      ThermalImu imu;
      imu.name = p[i].at("name").get<std::string>();
      imu.t_ref = p[i].at("t_ref").get<double>();
      imu.t_min = p[i].at("t_min").get<double>();
      imu.t_max = p[i].at("t_max").get<double>();
      if (!std::isfinite(imu.t_ref) || !(imu.t_min <= imu.t_max))
        throw std::runtime_error("no valid temperature range");
      ReadSensor(p[i].at("accelerometer"), u[i].at("accelerometer"), 0, &imu);
      ReadSensor(p[i].at("gyroscope"), u[i].at("gyroscope"), 3, &imu);
      const json& at = p[i].at("gyroscope").at("bias").at("at_t_ref");
      const json& at_std = u[i].at("gyroscope").at("bias").at("at_t_ref_std");
      if (at.is_array() && at_std.is_array() && at.size() == 3 && at_std.size() == 3) {
        imu.gyro_at = ReadVector(at);
        imu.gyro_at_std = ReadVector(at_std);
      }
      out.push_back(std::move(imu));
    }
  } catch (const std::exception& e) {
    // json's own messages name the key; this is shown escaped under the table.
    *problem = std::string("not a thermal result of the expected shape: ") + e.what();
    out.clear();
  }
  return out;
}

const ThermalImu* FindImu(const std::vector<ThermalImu>& list, const std::string& name) {
  for (const ThermalImu& imu : list) {
    if (imu.name == name) return &imu;
  }
  return nullptr;
}

// g_k = (T − t_ref)^k − (T0 − t_ref)^k, k = 1..p: D(T) = gᵀc, var D(T) = gᵀCg.
Eigen::VectorXd ShapeBasis(Eigen::Index p, double t, double t0, double t_ref) {
  Eigen::VectorXd g(p);
  double x = 1, x0 = 1;
  for (Eigen::Index k = 0; k < p; ++k) {
    x *= t - t_ref;
    x0 *= t0 - t_ref;
    g(k) = x - x0;
  }
  return g;
}

// The common range of two IMUs' logs, [lo, hi]; hi − lo < kMinOverlap: not comparable.
std::pair<double, double> Common(const ThermalImu& a, const ThermalImu& b) {
  return {std::max(a.t_min, b.t_min), std::min(a.t_max, b.t_max)};
}

// The change of channel c's shape between `before` and `now` where it is largest in σ of the
// difference: Δ, its z and the temperature.
struct ShapeChange {
  double delta = kNaN, z = kNaN, at = kNaN;
};

ShapeChange CompareShape(const ThermalImu& before, const ThermalImu& now, int c, double lo,
                         double hi) {
  const Curve& a = before.channels[static_cast<size_t>(c)];
  const Curve& b = now.channels[static_cast<size_t>(c)];
  const double t0 = 0.5 * (lo + hi);
  ShapeChange best;
  for (int i = 0; i < kGrid; ++i) {
    const double t = lo + (hi - lo) * i / (kGrid - 1);
    const Eigen::VectorXd ga = ShapeBasis(a.c.size(), t, t0, before.t_ref);
    const Eigen::VectorXd gb = ShapeBasis(b.c.size(), t, t0, now.t_ref);
    const double delta = gb.dot(b.c) - ga.dot(a.c);
    const double var = ga.dot(a.cov * ga) + gb.dot(b.cov * gb);
    const double z = var > 0 ? delta / std::sqrt(var) : (delta == 0 ? 0.0 : kNaN);
    const bool better =
        !std::isfinite(best.delta) || (std::isfinite(z) ? !(std::fabs(z) <= std::fabs(best.z))
                                                        : std::fabs(delta) > std::fabs(best.delta));
    if (better) best = {delta, z, t};
  }
  return best;
}

std::string ShapeCell(const ThermalImu& before, const ThermalImu& now, int first,
                      std::array<double, 6>* worst_z) {
  const auto [lo, hi] = Common(before, now);
  if (!(hi - lo >= kMinOverlap))
    return NoChangeCell(
        "ranges overlap by less than 1 \xC2\xB0"
        "C");
  std::vector<std::pair<std::string, double>> lines;
  for (int a = 0; a < 3; ++a) {
    const ShapeChange s = CompareShape(before, now, first + a, lo, hi);
    double& w = (*worst_z)[static_cast<size_t>(first + a)];
    if (std::isfinite(s.z)) w = std::max(w, std::fabs(s.z));
    lines.emplace_back(
        std::string(1, kAxes[a]) + " " + Signed(s.delta, 3) + " at " + FormatSig(s.at, 2), s.z);
  }
  return ChangeCell(lines);
}

std::string GyroAtRefCell(const ThermalImu& before, const ThermalImu& now) {
  if (!before.gyro_at || !now.gyro_at) return NoChangeCell(kDash);
  if (!(std::fabs(before.t_ref - now.t_ref) <= kSameTref))
    return NoChangeCell("t_ref differs");  // both are in the range column
  std::vector<std::pair<std::string, double>> lines;
  for (int a = 0; a < 3; ++a) {
    auto line = ChangeLine((*before.gyro_at)(a), (*before.gyro_at_std)(a), (*now.gyro_at)(a),
                           (*now.gyro_at_std)(a), 0, "");
    line.first = std::string(1, kAxes[a]) + " " + line.first;
    lines.push_back(std::move(line));
  }
  return ChangeCell(lines);
}

std::string RangeCell(const ThermalImu& imu) {
  return "<td class=\"num\">" + FormatSig(imu.t_min, 3) + " to " + FormatSig(imu.t_max, 3) +
         "<br><span class=\"muted small\">t_ref " + FormatSig(imu.t_ref, 4) + "</span></td>";
}

// The table; `worst_z[imu name][channel]` collects the largest |z| of each channel's shape change.
std::string DriftTable(const std::vector<const JobSummary*>& jobs,
                       const std::vector<std::vector<ThermalImu>>& data,
                       std::map<std::string, std::array<double, 6>>* worst_z) {
  std::string rows;
  const size_t first =
      jobs.size() > kMaxDriftCalibrations ? jobs.size() - kMaxDriftCalibrations : 0;
  for (size_t k = 0; k < jobs.size(); ++k) {
    for (size_t i = 0; i < data[k].size(); ++i) {
      const ThermalImu& now = data[k][i];
      const ThermalImu* before = nullptr;
      for (size_t p = k; p-- > 0 && before == nullptr;) before = FindImu(data[p], now.name);
      auto& w = worst_z->try_emplace(now.name).first->second;  // zeros when new
      std::string cells;
      if (before == nullptr) {
        cells = NoChangeCell("first") + NoChangeCell("first") + NoChangeCell("first");
      } else {
        cells = ShapeCell(*before, now, 0, &w) + ShapeCell(*before, now, 3, &w) +
                GyroAtRefCell(*before, now);
      }
      if (k < first) continue;  // counted for the plots, not listed
      rows += "<tr>" + (i == 0 ? CalibrationCell(*jobs[k], data[k].size()) : std::string()) +
              "<td class=\"name\">" + E(now.name) + "</td>" + RangeCell(now) + cells + "</tr>";
    }
  }
  if (rows.empty()) return "";
  return "<div class=\"table-wrap\"><table class=\"table-drift-thermal\"><thead><tr>"
         "<th>calibration</th><th>IMU</th><th class=\"num\">range (\xC2\xB0"
         "C)</th>"
         "<th class=\"num\">accelerometer curve change (m/s\xC2\xB2) at T (\xC2\xB0"
         "C)</th>"
         "<th class=\"num\">gyroscope curve change (rad/s) at T (\xC2\xB0"
         "C)</th>"
         "<th class=\"num\">gyroscope bias at t_ref change (rad/s)</th>"
         "</tr></thead><tbody>" +
         rows + "</tbody></table></div>";
}

// Channel c's D(T) of every plotted calibration of IMU `name`.
std::string ShapePlot(const std::vector<const JobSummary*>& jobs,
                      const std::vector<std::vector<ThermalImu>>& data, const std::string& name,
                      int c) {
  std::vector<std::pair<size_t, const ThermalImu*>> drawn;
  for (size_t k = jobs.size(); k-- > 0 && drawn.size() < kMaxPlotted;) {
    if (const ThermalImu* imu = FindImu(data[k], name)) drawn.emplace_back(k, imu);
  }
  if (drawn.size() < 2) return "";
  std::reverse(drawn.begin(), drawn.end());
  double lo = -INFINITY, hi = INFINITY;
  for (const auto& [k, imu] : drawn) {
    lo = std::max(lo, imu->t_min);
    hi = std::min(hi, imu->t_max);
  }
  const bool common = hi - lo >= kMinOverlap;
  std::vector<Series> series;
  for (size_t n = 0; n < drawn.size(); ++n) {
    const ThermalImu& imu = *drawn[n].second;
    const Curve& curve = imu.channels[static_cast<size_t>(c)];
    const double a = common ? lo : imu.t_min, b = common ? hi : imu.t_max;
    const double t0 = common ? 0.5 * (lo + hi) : imu.t_ref;
    Series s;
    s.label = "#" + std::to_string(jobs[drawn[n].first]->id) + " " +
              UtcDate(JobTime(*jobs[drawn[n].first])).substr(0, 10);
    s.color = static_cast<int>(n);
    for (int i = 0; i < kGrid; ++i) {
      const double t = a + (b - a) * i / (kGrid - 1);
      s.x.push_back(t);
      s.y.push_back(ShapeBasis(curve.c.size(), t, t0, imu.t_ref).dot(curve.c));
    }
    series.push_back(std::move(s));
  }
  PlotOptions o;
  o.name = std::string("drift-thermal-") + (c < 3 ? "accel" : "gyro");
  o.title = "IMU " + name + " " + (c < 3 ? "accelerometer " : "gyroscope ") + kAxes[c % 3] +
            ": curve of each calibration";
  o.x.title = "temperature (degC)";
  o.y.title = std::string(common ? "bias(T) - bias(middle of the common range) ("
                                 : "bias(T) - bias(t_ref) (") +
              (c < 3 ? "m/s^2" : "rad/s") + ")";
  if (!common) o.notes.push_back("the calibrations share no temperature range");
  return "<figure>" + RenderXYPlot(o, series) + "</figure>";
}

}  // namespace

std::string ThermalDriftHtml(const std::vector<const JobSummary*>& jobs) {
  if (jobs.empty()) return "";
  std::vector<std::vector<ThermalImu>> data;
  std::vector<std::string> problems(jobs.size());
  for (size_t k = 0; k < jobs.size(); ++k)
    data.push_back(ReadThermal(jobs[k]->result, &problems[k]));
  const std::string unreadable = UnreadableNote(jobs, problems);
  std::map<std::string, std::array<double, 6>> worst_z;
  const std::string table = DriftTable(jobs, data, &worst_z);
  if (table.empty())
    return "<p class=\"muted\">No thermal curves in these results.</p>" + unreadable;
  std::string figs;
  for (const auto& [name, z] : worst_z) {
    for (int first : {0, 3}) {  // per sensor, the axis that moved most
      int c = first;
      for (int a = 1; a < 3; ++a) {
        if (z[static_cast<size_t>(first + a)] > z[static_cast<size_t>(c)]) c = first + a;
      }
      figs += ShapePlot(jobs, data, name, c);
    }
  }
  return table + OmittedNote(jobs.size()) + unreadable +
         "<p class=\"muted small\">The curves are relative to bias(t_ref), which differs between "
         "calibrations, so their shapes are compared over the range both logs covered: bias(T) "
         "\xE2\x88\x92 bias(T\xE2\x82\x80), T\xE2\x82\x80 the middle of that range. Each axis "
         "gives the change where it is largest in standard deviations of the difference, the "
         "temperature and that size; from 3 on it is marked. The gyroscope's bias at t_ref is "
         "compared only where both used the same t_ref (set t_ref in the config to make it "
         "comparable).</p>" +
         (figs.empty() ? std::string() : "<div class=\"plots\">" + figs + "</div>");
}

}  // namespace calibd::web
