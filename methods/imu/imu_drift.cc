// The imu method's drift on the device page (methods/imu/imu_drift.h).
#include "methods/imu/imu_drift.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "methods/imu/imu_result.h"
#include "web/drift_table.h"
#include "web/html.h"
#include "web/svg_plot.h"

namespace calibd::web {
namespace {

using json = nlohmann::json;
using namespace drift;  // NOLINT: the shared drift pieces

// ----- imu

struct ImuSensor {
  double scale[3], scale_std[3], bias[3], bias_std[3], t[9], t_std[9];
};

struct ImuEntry {
  std::string name;
  ImuSensor sensor[2];  // accelerometer, gyroscope
};

const char* const kSensors[2] = {"accelerometer", "gyroscope"};

void CopyVec(const Eigen::Vector3d& v, double* out) {
  for (int i = 0; i < 3; ++i) out[i] = v(i);
}
void CopyMat(const Eigen::Matrix3d& m, double* out) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out[3 * r + c] = m(r, c);
}

// The IMUs of an imu result (results::ImuResult); a result that does not read has none and
// `*problem` says why.
std::vector<ImuEntry> ReadImus(const json& result, std::string* problem) {
  std::vector<ImuEntry> out;
  results::ImuResult r;
  const Status s = results::FromJson(result, &r);
  if (!s.ok()) {
    *problem = s.message();
    return out;
  }
  if (!r.parameters) return out;
  for (size_t i = 0; i < r.parameters->imus.size(); ++i) {
    const results::ImuTriads& p = r.parameters->imus[i];
    const results::ImuTriadsStd& u = r.uncertainty->imus[i];
    ImuEntry e;
    e.name = p.name.empty() ? std::to_string(i) : p.name;
    for (int k = 0; k < 2; ++k) {
      const results::SensorTriad& ps = k == 0 ? p.accelerometer : p.gyroscope;
      const results::SensorTriadStd& us = k == 0 ? u.accelerometer : u.gyroscope;
      ImuSensor& x = e.sensor[k];
      CopyVec(ps.scale, x.scale);
      CopyVec(us.scale_std, x.scale_std);
      CopyVec(ps.bias, x.bias);
      CopyVec(us.bias_std, x.bias_std);
      CopyMat(ps.misalignment, x.t);
      CopyMat(us.misalignment_std, x.t_std);
    }
    out.push_back(std::move(e));
  }
  return out;
}

const ImuEntry* FindImu(const std::vector<ImuEntry>& list, const std::string& name) {
  for (const ImuEntry& e : list) {
    if (e.name == name) return &e;
  }
  return nullptr;
}

std::string Vec3Cell(const double* v, const double* s, int sig) {
  std::string text;
  for (int k = 0; k < 3; ++k) {
    text += (k ? "<br>" : "") + FormatSig(v[k], sig) +
            (std::isfinite(s[k]) ? kPlusMinus + FormatSig(s[k], 2) : std::string());
  }
  return "<td class=\"num\">" + text + "</td>";
}

// T − I in mrad: its largest |entry| shown, the three rows collapsed beneath it (a <details>
// the reader opens), so the column stays narrow.
std::string MisalignmentCell(const double* t) {
  std::string text;
  double largest = kNaN;
  for (int r = 0; r < 3; ++r) {
    text += r ? "<br>" : "";
    for (int c = 0; c < 3; ++c) {
      const double mrad = (t[3 * r + c] - (r == c ? 1.0 : 0.0)) * 1e3;
      text += (c ? " " : "") + FormatFixed(mrad, 2);
      if (std::isfinite(mrad) && !(std::fabs(mrad) <= largest)) largest = std::fabs(mrad);
    }
  }
  return "<td class=\"num small\"><details><summary>" +
         (std::isfinite(largest) ? "max " + FormatFixed(largest, 2) : std::string(kDash)) +
         "</summary>" + text + "</details></td>";
}

const char* const kEntry[9] = {"xx", "xy", "xz", "yx", "yy", "yz", "zx", "zy", "zz"};

// The change of a vector's x, y and z (scale factors, biases) against the previous calibration,
// as ChangeLine.
std::string Vec3Change(const double* before, const double* s_before, const double* now,
                       const double* s_now, double per, const std::string& unit) {
  std::vector<std::pair<std::string, double>> lines;
  for (int k = 0; k < 3; ++k) {
    lines.push_back(ChangeLine(before[k], s_before[k], now[k], s_now[k], per, unit));
  }
  return ChangeCell(lines);
}

// The largest change of an entry of T against the previous calibration, in mrad, naming it.
std::string MisalignmentChange(const ImuSensor& before, const ImuSensor& now) {
  int worst = -1;
  for (int i = 0; i < 9; ++i) {
    const double d = std::fabs(now.t[i] - before.t[i]);
    if (std::isfinite(d) && (worst < 0 || d > std::fabs(now.t[worst] - before.t[worst]))) {
      worst = i;
    }
  }
  if (worst < 0) return NoChangeCell(kDash);
  const double d = now.t[worst] - before.t[worst];
  return ChangeCell({{Signed(d * 1e3, 3) + " mrad (" + kEntry[worst] + ")",
                      ZScore(d, before.t_std[worst], now.t_std[worst])}});
}

std::string ImuRows(const JobSummary& job, const ImuEntry& e, const ImuEntry* prev,
                    bool first_of_job, size_t job_rows) {
  const std::string first = NoChangeCell("first");
  std::string rows;
  for (int s = 0; s < 2; ++s) {
    const ImuSensor& x = e.sensor[s];
    const ImuSensor* y = prev != nullptr ? &prev->sensor[s] : nullptr;
    rows += "<tr>" + (first_of_job && s == 0 ? CalibrationCell(job, job_rows) : std::string()) +
            (s == 0 ? "<td class=\"name\" rowspan=\"2\">" + E(e.name) + "</td>" : std::string()) +
            "<td>" + kSensors[s] + "</td>" + Vec3Cell(x.scale, x.scale_std, 7) +
            (y ? Vec3Change(y->scale, y->scale_std, x.scale, x.scale_std, 1e6, " ppm") : first) +
            MisalignmentCell(x.t) + (y ? MisalignmentChange(*y, x) : first) +
            Vec3Cell(x.bias, x.bias_std, 6) +
            (y ? Vec3Change(y->bias, y->bias_std, x.bias, x.bias_std, 0, "") : first) + "</tr>";
  }
  return rows;
}

std::string ImuScalePlot(const TimeAxis& ax, const std::vector<std::vector<ImuEntry>>& data) {
  std::vector<std::string> names;
  for (const auto& list : data) {
    for (const ImuEntry& e : list) {
      if (std::find(names.begin(), names.end(), e.name) == names.end()) names.push_back(e.name);
    }
  }
  std::vector<Series> series;
  for (const std::string& name : names) {
    for (int s = 0; s < 2; ++s) {
      for (int k = 0; k < 3; ++k) {
        Series line;
        line.label = name + " " + (s == 0 ? "a" : "g") + "_" + "xyz"[k];
        line.marker = Marker::kCircle;
        line.dashed = s == 1;
        double first = kNaN;
        for (size_t j = 0; j < data.size(); ++j) {
          const ImuEntry* e = FindImu(data[j], name);
          if (e == nullptr || !std::isfinite(e->sensor[s].scale[k])) continue;
          if (!std::isfinite(first)) first = e->sensor[s].scale[k];
          line.x.push_back(ax.x[j]);
          line.y.push_back(first != 0 ? (e->sensor[s].scale[k] - first) / std::fabs(first) * 1e6
                                      : kNaN);
        }
        if (!line.x.empty()) series.push_back(std::move(line));
      }
    }
  }
  if (series.empty()) return "";
  PlotOptions o;
  o.name = "drift-imu-scale";
  o.title = "IMU scale factor change since the first calibration";
  o.x.title = ax.title;
  o.y.title = "\xCE\x94scale / scale (ppm)";
  o.y.include_zero = true;
  return "<figure>" + RenderXYPlot(o, series) +
         "<figcaption>Solid: accelerometer axes; dashed: gyroscope axes.</figcaption></figure>";
}

}  // namespace

std::string ImuDriftHtml(const std::vector<const JobSummary*>& jobs) {
  if (jobs.empty()) return "";
  std::vector<std::vector<ImuEntry>> data;
  std::vector<std::string> problems(jobs.size());
  for (size_t k = 0; k < jobs.size(); ++k) data.push_back(ReadImus(jobs[k]->result, &problems[k]));
  const std::string unreadable = UnreadableNote(jobs, problems);
  std::string rows;
  const size_t first =
      jobs.size() > kMaxDriftCalibrations ? jobs.size() - kMaxDriftCalibrations : 0;
  for (size_t k = first; k < jobs.size(); ++k) {
    for (size_t i = 0; i < data[k].size(); ++i) {
      const ImuEntry& e = data[k][i];
      const ImuEntry* prev = nullptr;
      for (size_t p = k; p-- > 0 && prev == nullptr;) prev = FindImu(data[p], e.name);
      rows += ImuRows(*jobs[k], e, prev, i == 0, 2 * data[k].size());
    }
  }
  if (rows.empty()) {
    return "<p class=\"muted\">No IMU parameters in these results.</p>" + unreadable;
  }
  const std::string change = kChangeHeading;
  const std::string figs = ImuScalePlot(MakeTimeAxis(jobs), data);
  return "<div class=\"table-wrap\"><table class=\"table-drift-imu\"><thead><tr>"
         "<th>calibration</th><th>IMU</th><th>sensor</th>"
         "<th class=\"num\">scale K, x y z (SI per reading unit)</th>" +
         change +
         "<th class=\"num\">misalignment T \xE2\x88\x92 I (mrad)</th>"
         "<th class=\"num\">largest \xCE\x94T (mrad)</th>"
         "<th class=\"num\">bias b, x y z (reading units)</th>" +
         change + "</tr></thead><tbody>" + rows + "</tbody></table></div>" +
         OmittedNote(jobs.size()) + unreadable +
         "<p class=\"muted small\">\xC2\xB1 is one standard deviation. Changes are against the "
         "previous calibration of the same IMU, with their size in standard deviations of the "
         "difference; from 3 on they are marked. The misalignment column shows the largest "
         "|T \xE2\x88\x92 I| entry: open it for the three rows. T compares between calibrations: "
         "the body frame is the accelerometer's by convention (SPEC \xC2\xA7"
         "7).</p>" +
         (figs.empty() ? std::string() : "<div class=\"plots\">" + figs + "</div>");
}

}  // namespace calibd::web
