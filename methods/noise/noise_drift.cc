// The noise method's drift on the device page (methods/noise/noise_drift.h).
#include "methods/noise/noise_drift.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "methods/noise/noise_result.h"
#include "web/drift_table.h"
#include "web/html.h"
#include "web/svg_plot.h"

namespace calibd::web {
namespace {

using json = nlohmann::json;
using namespace drift;  // NOLINT: the shared drift pieces

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

}  // namespace calibd::web
