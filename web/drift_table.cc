// The pieces the methods' drift tables on the device page share (web/drift_table.h).
#include "web/drift_table.h"

#include <algorithm>
#include <cmath>
#include <ctime>

#include "web/html.h"

namespace calibd::web::drift {

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

std::string ValueCell(double v, double s, int sig) {
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

}  // namespace calibd::web::drift
