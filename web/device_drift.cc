#include "web/device_drift.h"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <limits>
#include <nlohmann/json.hpp>

#include "results/imu_result.h"
#include "results/noise_result.h"
#include "web/html.h"
#include "web/svg_plot.h"

namespace calibd::web {
namespace {

using json = nlohmann::json;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
const char kDash[] = "\xE2\x80\x93";
const char kPlusMinus[] = " \xC2\xB1 ";
const char kSigma[] = "\xCF\x83";
constexpr double kSignificant = 3;  // a change of this many σ of the difference is marked

// ----- Formatting.

std::string E(const std::string& s) { return EscapeText(s); }

std::string JobLink(int64_t id) {
  return "<a href=\"/jobs/" + std::to_string(id) + "\">#" + std::to_string(id) + "</a>";
}

double JobTime(const JobSummary& j) {
  double t;
  if (ParseTimestamp(j.created_at, &t)) return t;
  if (ParseTimestamp(j.finished_at, &t)) return t;
  return kNaN;
}

std::string UtcDate(double t) {
  if (!std::isfinite(t) || std::fabs(t) > 1e12) return kDash;
  const auto tt = static_cast<time_t>(std::floor(t));
  std::tm tm{};
  if (gmtime_r(&tt, &tm) == nullptr) return kDash;
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M UTC", &tm);
  return buf;
}

std::string Signed(double v, int sig) { return (v > 0 ? "+" : "") + FormatSig(v, sig); }

// "m/s^2" -> "m/s²" for headings.
std::string PrettyUnit(const std::string& unit) {
  std::string u = unit;
  const auto p = u.find("^2");
  if (p != std::string::npos) u.replace(p, 2, "\xC2\xB2");
  return u;
}

std::string ValueCell(double v, double s, int sig = 4) {
  if (!std::isfinite(v)) return "<td class=\"num muted\">not visible</td>";
  return "<td class=\"num\">" + FormatSig(v, sig) +
         (std::isfinite(s) ? kPlusMinus + FormatSig(s, 2) : std::string()) + "</td>";
}

// z = Δ / √(σ_before² + σ_now²); NaN when a σ is missing.
double ZScore(double delta, double s_before, double s_now) {
  const double s = std::sqrt(s_before * s_before + s_now * s_now);
  return std::isfinite(delta) && s > 0 ? delta / s : kNaN;
}

std::string ZText(double z) {
  return std::isfinite(z) ? FormatSig(std::fabs(z), 2) + " " + kSigma
                          : std::string(kDash) + " " + kSigma;
}

// A change cell: lines of "Δ (zσ)"; a single change has its (zσ) on a line of its own, which
// keeps the column narrow. Marked when any |z| reaches kSignificant.
std::string ChangeCell(const std::vector<std::pair<std::string, double>>& lines) {
  bool significant = false;
  std::string text;
  const char* const gap = lines.size() == 1 ? "<br>" : " ";
  for (size_t i = 0; i < lines.size(); ++i) {
    significant = significant || std::fabs(lines[i].second) >= kSignificant;
    text += (i ? "<br>" : "") + lines[i].first + gap + "<span class=\"muted small\">(" +
            ZText(lines[i].second) + ")</span>";
  }
  return std::string("<td class=\"num") + (significant ? " drift-significant" : "") + "\">" +
         (significant ? "<strong>" + text + "</strong>" : text) + "</td>";
}

// One line of a change cell: now − before, relative to |before| times `per` (100: %, 1e6: ppm)
// or absolute when `per` is 0, followed by `unit`; with the change in σ of the difference.
std::pair<std::string, double> ChangeLine(double before, double s_before, double now, double s_now,
                                          double per, const std::string& unit) {
  const double delta = now - before;
  const double shown = per == 0 ? delta : before != 0 ? delta / std::fabs(before) * per : kNaN;
  return {Signed(shown, 3) + unit, ZScore(delta, s_before, s_now)};
}

std::string NoChangeCell(const std::string& why) {
  return "<td class=\"num muted small\">" + why + "</td>";
}

// x of each job for the plots: days since the first calibration (hours when they span less than
// two days), or the calibration number when a time is missing.
struct TimeAxis {
  std::string title;
  std::vector<double> x;
};

TimeAxis MakeTimeAxis(const std::vector<const JobSummary*>& jobs) {
  TimeAxis ax;
  std::vector<double> t;
  bool all = !jobs.empty();
  for (const JobSummary* j : jobs) {
    t.push_back(JobTime(*j));
    all = all && std::isfinite(t.back());
  }
  if (!all) {
    for (size_t i = 0; i < jobs.size(); ++i) ax.x.push_back(static_cast<double>(i + 1));
    ax.title = "calibration number";
    return ax;
  }
  const double span = t.back() - t.front();
  const double unit = span < 2 * 86400 ? 3600 : 86400;
  for (double v : t) ax.x.push_back((v - t.front()) / unit);
  ax.title = std::string(unit == 3600 ? "hours" : "days") + " since " + UtcDate(t.front());
  return ax;
}

std::string OmittedNote(size_t n) {
  if (n <= kMaxDriftCalibrations) return "";
  return "<p class=\"muted small\">" + std::to_string(n - kMaxDriftCalibrations) +
         " older calibrations not listed; the plots show every calibration.</p>";
}

// The calibration cell spanning a job's rows: its link, and below it its date and time (two short
// lines instead of a wide "when" column, so the drift tables fit 1280 px).
std::string CalibrationCell(const JobSummary& j, size_t rows) {
  const std::string span = rows > 1 ? " rowspan=\"" + std::to_string(rows) + "\"" : "";
  std::string when = E(UtcDate(JobTime(j)));
  const size_t space = when.find(' ');
  if (space != std::string::npos) when.replace(space, 1, "<br>");
  return "<td class=\"time\"" + span + ">" + JobLink(j.id) + "<br><span class=\"muted small\">" +
         when + "</span></td>";
}

// The change columns' heading: the note under each table says against what and in which units.
const char kChangeHeading[] = "<th class=\"num\">change</th>";

// ----- noise

struct Term {
  double value = kNaN, std = kNaN;  // value NaN: not visible
};

struct NoiseChannel {
  std::string name, unit;
  Term n, b, k;
  double b_tau = kNaN;
};

// The channels of a noise result (results::NoiseResult); a result that does not read has none and
// `*problem` says why.
std::vector<NoiseChannel> ReadNoise(const json& result, std::string* problem) {
  std::vector<NoiseChannel> out;
  results::NoiseResult r;
  const Status s = results::FromJson(result, &r);
  if (!s.ok()) {
    *problem = s.message();
    return out;
  }
  for (size_t i = 0; i < r.channels.size(); ++i) {
    const results::NoiseChannelParameters& c = r.channels[i];
    const results::NoiseChannelUncertainty& u = r.channel_stds[i];
    if (c.name.empty()) continue;
    NoiseChannel ch;
    ch.name = c.name;
    ch.unit = c.unit;
    ch.n = {c.white_noise, u.white_noise_std};
    ch.b = {c.bias_instability, u.bias_instability_std};
    ch.k = {c.random_walk, u.random_walk_std};
    ch.b_tau = c.bias_instability_tau;
    out.push_back(std::move(ch));
  }
  return out;
}

// The calibrations whose result does not read, one line each ("" when every one reads).
std::string UnreadableNote(const std::vector<const JobSummary*>& jobs,
                           const std::vector<std::string>& problems) {
  std::string lines;
  for (size_t k = 0; k < jobs.size(); ++k) {
    if (problems[k].empty()) continue;
    lines += "<li>" + JobLink(jobs[k]->id) + ": not available (" + E(problems[k]) + ")</li>";
  }
  return lines.empty() ? "" : "<ul class=\"muted small drift-unreadable\">" + lines + "</ul>";
}

const NoiseChannel* FindChannel(const std::vector<NoiseChannel>& list, const std::string& name) {
  for (const NoiseChannel& c : list) {
    if (c.name == name) return &c;
  }
  return nullptr;
}

std::string TermChange(const Term& before, const Term& now) {
  const bool was = std::isfinite(before.value), is = std::isfinite(now.value);
  if (!was && !is) return NoChangeCell(kDash);
  if (!was) return NoChangeCell("now visible");
  if (!is) return NoChangeCell("no longer visible");
  return ChangeCell({ChangeLine(before.value, before.std, now.value, now.std, 100, " %")});
}

std::string NoiseTable(const std::vector<const JobSummary*>& jobs,
                       const std::vector<std::vector<NoiseChannel>>& data, char kind) {
  const std::string sensor = kind == 'a' ? "accelerometer" : "gyroscope";
  std::string unit = kind == 'a' ? "m/s^2" : "rad/s";
  for (const auto& list : data) {
    for (const NoiseChannel& c : list) {
      if (c.name[0] == kind && !c.unit.empty()) unit = c.unit;
    }
  }
  unit = E(PrettyUnit(unit));
  std::string rows;
  const size_t first =
      jobs.size() > kMaxDriftCalibrations ? jobs.size() - kMaxDriftCalibrations : 0;
  for (size_t k = first; k < jobs.size(); ++k) {
    std::vector<const NoiseChannel*> mine;
    for (const NoiseChannel& c : data[k]) {
      if (c.name[0] == kind) mine.push_back(&c);
    }
    for (size_t i = 0; i < mine.size(); ++i) {
      const NoiseChannel& c = *mine[i];
      const NoiseChannel* prev = nullptr;
      for (size_t p = k; p-- > 0 && prev == nullptr;) prev = FindChannel(data[p], c.name);
      rows += "<tr>" + (i == 0 ? CalibrationCell(*jobs[k], mine.size()) : std::string()) +
              "<td class=\"name\">" + E(c.name) + "</td>";
      const std::string first_cell = NoChangeCell("first");
      rows += ValueCell(c.n.value, c.n.std) + (prev ? TermChange(prev->n, c.n) : first_cell) +
              ValueCell(c.b.value, c.b.std) + "<td class=\"num\">" +
              (std::isfinite(c.b.value) ? FormatSig(c.b_tau, 3) : std::string(kDash)) + "</td>" +
              (prev ? TermChange(prev->b, c.b) : first_cell) + ValueCell(c.k.value, c.k.std) +
              (prev ? TermChange(prev->k, c.k) : first_cell) + "</tr>";
    }
  }
  if (rows.empty()) return "";
  const std::string change = kChangeHeading;
  return "<h4>" + std::string(kind == 'a' ? "Accelerometers" : "Gyroscopes") +
         "</h4><div class=\"table-wrap\"><table class=\"table-drift-noise\" data-sensor=\"" +
         sensor +
         "\"><thead><tr><th>calibration</th><th>channel</th>"
         "<th class=\"num\">white noise N (" +
         unit + "/\xE2\x88\x9AHz)</th>" + change + "<th class=\"num\">bias instability B (" + unit +
         ")</th><th class=\"num\">at \xCF\x84 (s)</th>" + change +
         "<th class=\"num\">random walk K (" + unit + "/s/\xE2\x88\x9AHz)</th>" + change +
         "</tr></thead><tbody>" + rows + "</tbody></table></div>";
}

std::string NoisePlot(const TimeAxis& ax, const std::vector<std::vector<NoiseChannel>>& data,
                      char kind) {
  std::vector<std::string> names;
  std::string unit = kind == 'a' ? "m/s^2" : "rad/s";
  for (const auto& list : data) {
    for (const NoiseChannel& c : list) {
      if (c.name[0] != kind) continue;
      if (!c.unit.empty()) unit = c.unit;
      if (std::find(names.begin(), names.end(), c.name) == names.end()) names.push_back(c.name);
    }
  }
  std::vector<Series> series;
  for (const std::string& name : names) {
    Series s;
    s.label = name;
    s.marker = Marker::kCircle;
    for (size_t k = 0; k < data.size(); ++k) {
      const NoiseChannel* c = FindChannel(data[k], name);
      if (c == nullptr || !std::isfinite(c->n.value)) continue;
      s.x.push_back(ax.x[k]);
      s.y.push_back(c->n.value);
      s.y_err.push_back(std::isfinite(c->n.std) ? c->n.std : 0.0);
    }
    if (!s.x.empty()) series.push_back(std::move(s));
  }
  if (series.empty()) return "";
  PlotOptions o;
  o.name = std::string("drift-noise-") + (kind == 'a' ? "accel" : "gyro");
  o.title = std::string(kind == 'a' ? "Accelerometers" : "Gyroscopes") +
            ": white noise density over time";
  o.x.title = ax.title;
  o.y.title = "N (" + PrettyUnit(unit) + "/\xE2\x88\x9AHz)";
  o.y.include_zero = true;
  return "<figure>" + RenderXYPlot(o, series) +
         "<figcaption>Bars: \xC2\xB1"
         "1\xCF\x83 of each calibration.</figcaption></figure>";
}

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

std::string NoiseDriftHtml(const std::vector<const JobSummary*>& jobs) {
  if (jobs.empty()) return "";
  std::vector<std::vector<NoiseChannel>> data;
  std::vector<std::string> problems(jobs.size());
  for (size_t k = 0; k < jobs.size(); ++k) data.push_back(ReadNoise(jobs[k]->result, &problems[k]));
  const std::string unreadable = UnreadableNote(jobs, problems);
  const TimeAxis ax = MakeTimeAxis(jobs);
  std::string tables = NoiseTable(jobs, data, 'a') + NoiseTable(jobs, data, 'g');
  if (tables.empty()) {
    return "<p class=\"muted\">No noise terms in these results.</p>" + unreadable;
  }
  const std::string figs = NoisePlot(ax, data, 'a') + NoisePlot(ax, data, 'g');
  return tables + OmittedNote(jobs.size()) + unreadable +
         "<p class=\"muted small\">\xC2\xB1 is one standard deviation. A change is given "
         "relative to the previous calibration and in standard deviations of the difference, "
         "\xE2\x88\x9A(\xCF\x83\xE2\x82\x81\xC2\xB2 + \xCF\x83\xE2\x82\x82\xC2\xB2); from 3 on "
         "it is marked: more than the two logs' own uncertainty explains (the sensor, its "
         "temperature or its mounting changed).</p>" +
         (figs.empty() ? std::string() : "<div class=\"plots\">" + figs + "</div>");
}

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
