#include "methods/array/array_full_report.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "methods/array/array_result.h"
#include "web/html.h"
#include "web/report_common.h"
#include "web/svg_plot.h"

namespace calibd::web {
namespace {

using json = nlohmann::json;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kPi = 3.14159265358979323846;
constexpr const char* kPm = "\xC2\xB1";  // ±

std::string E(const std::string& s) { return EscapeText(s); }
std::string A(const std::string& s) { return EscapeAttr(s); }

std::string Section(const std::string& id, const std::string& title, const std::string& body) {
  return "<section id=\"" + id + "\"><h2>" + title + "</h2>" + body + "</section>";
}
std::string Figure(const std::string& svg, const std::string& caption) {
  return "<figure>" + svg + (caption.empty() ? "" : "<figcaption>" + caption + "</figcaption>") +
         "</figure>";
}

// Digits after the point that show a value to the precision of its typical σ (two significant
// digits of σ), within [0, 6].
int Decimals(double typical_sigma) {
  if (!(typical_sigma > 0) || !std::isfinite(typical_sigma)) return 3;
  return std::clamp(static_cast<int>(std::ceil(-std::log10(typical_sigma))) + 1, 0, 6);
}

// A count a result may lack (one stored by an earlier calibd): a dash when absent.
std::string Count(const std::optional<int64_t>& n) {
  return FormatFixed(n ? static_cast<double>(*n) : kNaN, 0);
}

double Median(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return !std::isfinite(x); }), v.end());
  if (v.empty()) return kNaN;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// The σ the tables show of one entry of uncertainty.imus: the primary (uncertainty.basis).
// `k` beyond the entries: every σ undefined.
struct Shown {
  const results::SensorTriadStd* accelerometer;
  const results::SensorTriadStd* gyroscope;
  const Eigen::Vector3d* position_std;
  const results::SensorTriadStd& Of(bool accel) const {
    return accel ? *accelerometer : *gyroscope;
  }
};
Shown ShownSigma(const results::ArrayUncertainty& u, size_t k) {
  static const results::SensorTriadStd kUndefined;
  static const Eigen::Vector3d kUndefined3 = Eigen::Vector3d::Constant(kNaN);
  if (k >= u.imus.size()) return {&kUndefined, &kUndefined, &kUndefined3};
  const results::ArrayImuStd& s = u.imus[k];
  return {&s.triads.accelerometer, &s.triads.gyroscope, &s.position_std};
}

// A value cell with its σ in small print beside it; `beyond` (non-empty: why) marks it.
std::string ValueCell(double v, int decimals, double sd, const std::string& beyond,
                      bool group_start = false, bool sign = true) {
  std::string cls = "num";
  if (group_start) cls += " gs";
  if (!beyond.empty()) cls += " beyond";
  std::string text = FormatFixed(v, decimals);
  if (sign && std::isfinite(v) && v > 0 && text != FormatFixed(0, decimals)) text = "+" + text;
  std::string out = "<td class=\"" + cls + "\"" +
                    (beyond.empty() ? "" : " title=\"" + A(beyond) + "\"") + ">" + text;
  if (std::isfinite(sd))
    out += "<span class=\"sd\">" + std::string(kPm) + FormatSig(sd, 2) + "</span>";
  return out + "</td>";
}

// The acceptance limits the result was judged against (verdict.limits); NaN when absent/null.
struct Limits {
  double scale_range = kNaN, scale_std = kNaN, implausible = kNaN, axis_std = kNaN;
  double accel_bias = kNaN, accel_bias_std = kNaN, gyro_bias = kNaN, gyro_bias_std = kNaN;
};
Limits ReadLimits(const results::ArrayResult& result) {
  Limits o;
  if (!result.envelope.verdict) return o;
  const auto& l = result.envelope.verdict->limits;
  auto get = [&](const char* key) {
    const auto it = l.find(key);
    return it != l.end() && it->second ? *it->second : kNaN;
  };
  o.scale_range = get("scale_range");
  o.scale_std = get("max_scale_std");
  o.implausible = get("implausible_factor");
  o.axis_std = get("max_axis_std");
  o.accel_bias = get("max_accel_bias");
  o.accel_bias_std = get("max_accel_bias_std");
  o.gyro_bias = get("max_gyro_bias");
  o.gyro_bias_std = get("max_gyro_bias_std");
  return o;
}

struct Kind {
  const char* key;        // "accelerometer" | "gyroscope"
  bool accel;             // the accelerometers
  std::string bias_unit;  // reading units, for headers
  double unit = 1;        // SI per reading unit (the nominal: 1 for m/s^2, pi/180 for deg/s)
  double bias_limit = kNaN, bias_std_limit = kNaN;  // SI
};

// The per-axis misalignment angle of axis j: the angle between the sensor's axis j (column j of
// the unit-diagonal misalignment matrix) and the body axis j, and its σ to first order from the
// entries' σ (entries taken as uncorrelated; for an angle near 0 the entries' rms σ).
void AxisAngle(const Eigen::Matrix3d& m, const Eigen::Matrix3d& m_std, int j, double* angle,
               double* sd) {
  double off2 = 0, var = 0, s2 = 0;
  int n = 0;
  for (int i = 0; i < 3; ++i) {
    if (i == j) continue;
    off2 += m(i, j) * m(i, j);
    s2 += m_std(i, j) * m_std(i, j);
    ++n;
  }
  const double r = std::sqrt(off2);
  *angle = std::atan2(r, m(j, j));
  for (int i = 0; i < 3; ++i) {
    if (i == j) continue;
    const double w = r > 0 ? m(i, j) / r : 1 / std::sqrt(static_cast<double>(n));
    var += w * w * m_std(i, j) * m_std(i, j);
  }
  *sd = std::sqrt(r > 0 ? var : s2 / n);
}

// The triad of IMU k of the kind's sensor type.
const results::SensorTriad& TriadOf(const results::ArrayImu& imu, const Kind& kind) {
  return kind.accel ? imu.triads.accelerometer : imu.triads.gyroscope;
}

std::string SensorTable(const results::ArrayResult& result, const Kind& kind, const Limits& lim) {
  const std::vector<results::ArrayImu>& imus = result.parameters->imus;
  const results::ArrayUncertainty& stds = *result.uncertainty;
  const int ref = result.parameters->reference;
  const size_t K = imus.size();
  // Precision per column group from the median σ.
  std::vector<double> g_sd, a_sd, b_sd;
  for (size_t k = 0; k < K; ++k) {
    const results::SensorTriad& p = TriadOf(imus[k], kind);
    const results::SensorTriadStd& s = ShownSigma(stds, k).Of(kind.accel);
    for (int c = 0; c < 3; ++c) {
      g_sd.push_back(100 * s.scale_std(c) / std::abs(p.scale(c)));
      double ang, sd;
      AxisAngle(p.misalignment, s.misalignment_std, c, &ang, &sd);
      a_sd.push_back(1e3 * sd);
      b_sd.push_back(s.bias_std(c));
    }
  }
  const int gd = Decimals(Median(g_sd)), ad = Decimals(Median(a_sd)), bd = Decimals(Median(b_sd));
  const std::string sub =
      "<th class=\"num gs\">x</th><th class=\"num\">y</th><th class=\"num\">z</th>";
  std::string head =
      "<tr><th rowspan=\"2\">triad</th><th class=\"group gs\" colspan=\"3\">gain "
      "\xE2\x88\x92 1 (%)</th><th class=\"group gs\" colspan=\"3\">axis "
      "misalignment (mrad)</th><th class=\"group gs\" colspan=\"3\">bias (" +
      E(kind.bias_unit) + ")</th></tr><tr>" + sub + sub + sub + "</tr>";
  std::string rows;
  int marked = 0;
  for (size_t k = 0; k < K; ++k) {
    const results::SensorTriad& p = TriadOf(imus[k], kind);
    const results::SensorTriadStd& s = ShownSigma(stds, k).Of(kind.accel);
    std::string name = imus[k].triads.name;
    if (name.empty()) name = std::to_string(k);
    const bool is_ref = static_cast<int>(k) == ref;
    std::string row = "<tr><td class=\"name\">" + E(name) +
                      (is_ref ? " <span class=\"muted small\">(ref.)</span>" : "") + "</td>";
    for (int c = 0; c < 3; ++c) {
      const double scale = p.scale(c);
      const double ratio = scale / kind.unit;
      const double rel_sd = s.scale_std(c) / std::abs(scale);
      std::string why;
      if (std::isfinite(lim.implausible) && std::isfinite(ratio) &&
          (ratio > lim.implausible || ratio < 1 / lim.implausible)) {
        why = "physically implausible: " + FormatSig(ratio, 3) + " times the nominal (units?)";
      } else if (std::isfinite(lim.scale_range) && std::abs(ratio - 1) > lim.scale_range) {
        why = "beyond scale_range " + FormatSig(100 * lim.scale_range, 3) + " %";
      } else if (std::isfinite(lim.scale_std) && rel_sd > lim.scale_std) {
        why = "\xCF\x83 beyond max_scale_std " + FormatSig(100 * lim.scale_std, 3) + " %";
      }
      marked += !why.empty();
      row += ValueCell(100 * (ratio - 1), gd, 100 * rel_sd, why, c == 0);
    }
    for (int c = 0; c < 3; ++c) {
      double ang, sd;
      AxisAngle(p.misalignment, s.misalignment_std, c, &ang, &sd);
      double worst = 0;
      for (int i = 0; i < 3; ++i)
        if (i != c) worst = std::max(worst, s.misalignment_std(i, c));
      std::string why;
      if (std::isfinite(lim.axis_std) && worst > lim.axis_std)
        why =
            "an entry's \xCF\x83 beyond max_axis_std " + FormatSig(1e3 * lim.axis_std, 3) + " mrad";
      marked += !why.empty();
      row += ValueCell(1e3 * ang, ad, 1e3 * sd, why, c == 0, false);
    }
    for (int c = 0; c < 3; ++c) {
      const double b = p.bias(c), sd = s.bias_std(c);
      std::string why;
      if (std::isfinite(kind.bias_limit) && std::abs(b * kind.unit) > kind.bias_limit) {
        why = "beyond the bias limit " + FormatSig(kind.bias_limit / kind.unit, 3) + " " +
              kind.bias_unit;
      } else if (std::isfinite(kind.bias_std_limit) && sd * kind.unit > kind.bias_std_limit) {
        why = "\xCF\x83 beyond the limit " + FormatSig(kind.bias_std_limit / kind.unit, 3) + " " +
              kind.bias_unit;
      }
      marked += !why.empty();
      row += ValueCell(b, bd, sd, why, c == 0);
    }
    rows += row + "</tr>";
  }
  std::string out =
      "<h3>" +
      std::string(kind.key == std::string("accelerometer") ? "Accelerometers" : "Gyroscopes") +
      "</h3>";
  out += "<div class=\"table-wrap\"><table class=\"table-array-full table-array-full-" +
         std::string(kind.key) + "\"><thead>" + head + "</thead><tbody>" + rows +
         "</tbody></table></div>";
  if (marked > 0)
    out += "<p class=\"flag-warn small\">" + std::to_string(marked) +
           " value(s) beyond the acceptance limits, marked (the cell's tooltip names the "
           "limit).</p>";
  return out;
}

// The off-diagonal misalignment entries of every triad and sensor, in mrad, with σ.
std::string MisalignmentTable(const results::ArrayResult& result, double axis_std_limit) {
  const std::vector<results::ArrayImu>& imus = result.parameters->imus;
  static const int kEntries[6][2] = {{0, 1}, {0, 2}, {1, 0}, {1, 2}, {2, 0}, {2, 1}};
  std::string head = "<tr><th>triad</th><th>sensor</th>";
  for (const auto& e : kEntries)
    head += "<th class=\"num\">T[" + std::to_string(e[0]) + "][" + std::to_string(e[1]) + "]</th>";
  head += "</tr>";
  std::string rows;
  for (size_t k = 0; k < imus.size(); ++k) {
    std::string name = imus[k].triads.name;
    if (name.empty()) name = std::to_string(k);
    for (const bool accel : {true, false}) {
      const char* sensor = accel ? "accelerometer" : "gyroscope";
      const Eigen::Matrix3d& m =
          (accel ? imus[k].triads.accelerometer : imus[k].triads.gyroscope).misalignment;
      const Eigen::Matrix3d& ms = ShownSigma(*result.uncertainty, k).Of(accel).misalignment_std;
      rows += "<tr><td class=\"name\">" + E(name) + "</td><td>" + sensor + "</td>";
      for (const auto& e : kEntries) {
        const double sd = ms(e[0], e[1]);
        const std::string why = std::isfinite(axis_std_limit) && sd > axis_std_limit
                                    ? "\xCF\x83 beyond max_axis_std"
                                    : std::string();
        rows += ValueCell(1e3 * m(e[0], e[1]), 3, 1e3 * sd, why);
      }
      rows += "</tr>";
    }
  }
  return "<details><summary>Misalignment entries (mrad), every triad</summary><div "
         "class=\"table-wrap\"><table class=\"table-array-full-misalignment\"><thead>" +
         head + "</thead><tbody>" + rows +
         "</tbody></table></div><p class=\"muted small\">Off-diagonal entries of the "
         "misalignment matrix (unit diagonal): T[i][j] tilts the sensor's axis j towards body "
         "axis i. \xCF\x83 0: fixed by the gauge (the reference accelerometer's lower "
         "triangle).</p></details>";
}

std::string TriadsSection(const results::ArrayResult& result) {
  const results::ArrayFullDiagnostics& diag = result.full_diagnostics;
  const Limits lim = ReadLimits(result);
  const bool deg = diag.gyro_unit == "deg/s";
  Kind accel{"accelerometer", true, "m/s\xC2\xB2", 1, lim.accel_bias, lim.accel_bias_std};
  Kind gyro{"gyroscope",         false,         deg ? "\xC2\xB0/s" : "rad/s",
            deg ? kPi / 180 : 1, lim.gyro_bias, lim.gyro_bias_std};
  const results::ArrayFullNoise& noise = diag.noise;
  std::string s = "<dl class=\"kv\">";
  // The description, or the gauge's name when the result has none (an earlier calibd's).
  s += "<dt>gauge</dt><dd>" +
       E(diag.gauge.description.empty() ? diag.gauge.scale : diag.gauge.description) + "</dd>";
  s += "<dt>statics</dt><dd>" + Count(diag.statics) + " (" + Count(diag.static_samples) +
       " samples), motion " + Count(diag.dynamic_samples) + " samples</dd>";
  s += "<dt>noise \xCF\x83 used</dt><dd>" + FormatSig(noise.accelerometer, 3) + " m/s\xC2\xB2, " +
       FormatSig(noise.gyroscope, 3) + " " + E(gyro.bias_unit) +
       (noise.source.empty() ? std::string() : " (" + E(noise.source) + ")") + "</dd>";
  s += "<dt>\xCF\x87\xC2\xB2 / degrees of freedom</dt><dd>" + FormatSig(diag.chi2_per_dof, 3) +
       "</dd>";
  s += "<dt>\xCF\x83 shown</dt><dd class=\"sigma-shown\">" +
       ArraySigmaBasisText(*result.uncertainty) + "; the limits are marked against it</dd></dl>";
  if (result.parameters->imus.empty())
    return Section("triads", "Triads (model full)",
                   s + "<p class=\"muted\">Not available: the result has no triads.</p>");
  s += SensorTable(result, accel, lim);
  s += SensorTable(result, gyro, lim);
  s += "<p class=\"muted small\">Per triad: gain \xE2\x88\x92 1 is the scale factor against the "
       "nominal unit; the axis misalignment is the angle between the sensor's axis and the body "
       "axis (frame of the reference accelerometer); biases in reading units. Beside each value "
       "its 1\xCF\x83 in small print.</p>";
  s += MisalignmentTable(result, lim.axis_std);
  return Section("triads", "Triads (model full)", s);
}

// The static intervals the fit used (SPEC §7 lists them for every method with statics), each
// with its means' residuals over all triads; empty for a result stored before they were listed.
std::string StaticsTable(const results::ArrayFullDiagnostics& diag, const std::string& gyro_unit) {
  if (diag.static_intervals.empty()) return "";
  std::string rows;
  for (size_t j = 0; j < diag.static_intervals.size(); ++j) {
    const results::ArrayFullStaticInterval& st = diag.static_intervals[j];
    rows += "<tr><td>" + std::to_string(j + 1) + "</td>" +
            web::internal::NumCell(FormatFixed(st.start, 2)) +
            web::internal::NumCell(FormatFixed(st.end, 2)) +
            web::internal::NumCell(std::to_string(st.samples)) +
            web::internal::NumCell(FormatSig(st.accel_residual_rms, 3)) +
            web::internal::NumCell(FormatSig(st.gyro_residual_rms, 3)) + "</tr>";
  }
  return "<details class=\"array-full-statics\"><summary>The " +
         std::to_string(diag.static_intervals.size()) +
         " static intervals</summary><div class=\"table-wrap\"><table "
         "class=\"table-array-full-statics\"><thead><tr><th>#</th><th>start (s)</th><th>end "
         "(s)</th><th>samples</th><th>accelerometer residual RMS (m/s\xC2\xB2)</th><th>gyroscope "
         "residual RMS (" +
         gyro_unit + ")</th></tr></thead><tbody>" + rows +
         "</tbody></table></div><p class=\"muted small\">The residual of a static is its means' "
         "misfit over every triad's three axes; a static far above the others was probably not "
         "still.</p></details>";
}

std::string ResidualsSection(const results::ArrayResult& result) {
  const results::ArrayFullDiagnostics& diag = result.full_diagnostics;
  const std::vector<results::ArrayImuResiduals>& per = diag.residual_rms_imus;
  if (per.empty()) return "";
  const bool deg = diag.gyro_unit == "deg/s";
  const std::string gu = deg ? "\xC2\xB0/s" : "rad/s";
  std::string figs, words;
  for (const char* kind : {"accelerometer", "gyroscope"}) {
    const bool a = std::string(kind) == "accelerometer";
    const std::string unit = a ? "m/s\xC2\xB2" : gu;
    std::vector<std::string> names;
    BarSeries st{"statics", {}, {}, 0}, dy{"motion", {}, {}, 1};
    for (size_t k = 0; k < per.size(); ++k) {
      const std::string& name = per[k].name;
      names.push_back(name.empty() ? std::to_string(k) : name);
      st.values.push_back(a ? per[k].static_rms.accelerometer : per[k].static_rms.gyroscope);
      dy.values.push_back(a ? per[k].dynamic_rms.accelerometer : per[k].dynamic_rms.gyroscope);
    }
    const double noise = a ? diag.static_noise.accelerometer : diag.static_noise.gyroscope;
    // Since the static intervals are listed, the statics' figures are the means' residuals (in
    // reading units, their noise σ/√samples); before, the means' residuals × √samples.
    const bool means = !diag.static_intervals.empty();
    std::vector<double> samples;
    for (const auto& st : diag.static_intervals) samples.push_back(static_cast<double>(st.samples));
    const double mean_noise = means ? noise / std::sqrt(Median(samples)) : kNaN;
    PlotOptions o;
    o.name = std::string("array-full-residuals-") + kind;
    o.title = std::string("Residual RMS per triad, ") + (a ? "accelerometers" : "gyroscopes");
    o.x.title = "triad";
    o.y.title = "RMS (" + unit + ")";
    o.y.type = ScaleType::kLog10;
    if (std::isfinite(noise) && noise > 0)
      o.ref_lines.push_back({false, noise, "sample noise " + FormatSig(noise, 2), true});
    if (std::isfinite(mean_noise) && mean_noise > 0)
      o.ref_lines.push_back(
          {false, mean_noise, "noise of a static mean " + FormatSig(mean_noise, 2), true});
    figs += Figure(
        RenderBarChart(o, names, {st, dy}),
        means ? "Statics: RMS of the static means' residuals (" + unit +
                    "), at the noise of a mean (the sample noise / \xE2\x88\x9Asamples, median "
                    "static) when the model fits; motion: RMS over the dynamic samples, at the "
                    "sample noise when the model fits."
              : std::string("Statics: RMS of the static means' residuals times "
                            "\xE2\x88\x9Asamples (a result stored by an earlier calibd); motion: "
                            "RMS over the dynamic samples. Both sit at the static noise when the "
                            "model fits."));
    // Triads that stand out: more than twice the median of all triads.
    for (const auto* series : {&st, &dy}) {
      const double med = Median(series->values);
      std::vector<std::string> out;
      for (size_t k = 0; k < names.size(); ++k) {
        const double v = series->values[k];
        if (std::isfinite(v) && std::isfinite(med) && med > 0 && v > 2 * med)
          out.push_back(E(names[k]) + " (" + FormatSig(v / med, 2) + "\xC3\x97)");
      }
      if (out.empty()) continue;
      std::string list;
      for (size_t i = 0; i < out.size(); ++i) list += (i ? ", " : "") + out[i];
      words += "<li>" + std::string(kind) + " residual in " +
               (series == &st ? "the statics" : "motion") +
               " more than twice the median of the triads: " + list + "</li>";
    }
    const double motion_med = Median(dy.values);
    if (std::isfinite(noise) && noise > 0 && std::isfinite(motion_med) && motion_med > 2 * noise)
      words += "<li>" + std::string(kind) + " residual in motion is " +
               FormatSig(motion_med / noise, 2) +
               "\xC3\x97 the static noise (median over the triads): the model does not explain "
               "the motion to the noise level (sampling-time errors between the IMUs?)</li>";
  }
  std::string body = "<div class=\"plots\">" + figs + "</div>";
  if (!words.empty()) body += "<ul class=\"warnings triad-outliers\">" + words + "</ul>";
  body += StaticsTable(diag, gu);
  return Section("triad-residuals", "Residuals per triad", body);
}

std::string ChangeSection(const results::ArrayResult& result) {
  const results::ArrayFullDiagnostics& diag = result.full_diagnostics;
  const std::vector<results::ArrayPositionChange>& ch = diag.changed_from_positions_only;
  if (ch.empty()) return "";
  const bool robust = result.uncertainty->basis == "sandwich";
  std::vector<std::string> names;
  BarSeries sx{"\xCE\x94x / \xCF\x83x", {}, {}, 0}, sy{"\xCE\x94y / \xCF\x83y", {}, {}, 1},
      sz{"\xCE\x94z / \xCF\x83z", {}, {}, 2};
  std::string rows;
  double worst = 0;
  std::string worst_name;
  for (size_t k = 0; k < ch.size(); ++k) {
    const results::ArrayPositionChange& c = ch[k];
    std::string name = c.name;
    if (name.empty()) name = std::to_string(k);
    names.push_back(name);
    const Eigen::Vector3d& d = c.position_change;
    const Eigen::Vector3d& po = c.positions_only;
    // The shift in the full model's primary σ (as the tables above).
    double ratio[3];
    std::string row = "<tr><td class=\"name\">" + E(name) + "</td>";
    for (int a = 0; a < 3; ++a) row += "<td class=\"num\">" + FormatFixed(1e3 * po(a), 4) + "</td>";
    double n2 = 0;
    for (int a = 0; a < 3; ++a) {
      ratio[a] = c.position_change_sigma(a);
      if (!std::isfinite(ratio[a])) ratio[a] = kNaN;
      n2 += d(a) * d(a);
      row += std::string("<td class=\"num") + (a == 0 ? " gs" : "") + "\">" +
             FormatFixed(1e6 * d(a), 2) + "</td>";
    }
    row += "<td class=\"num\">" + FormatFixed(1e6 * std::sqrt(n2), 2) + "</td>";
    for (int a = 0; a < 3; ++a) {
      const bool big = std::isfinite(ratio[a]) && std::abs(ratio[a]) > 3;
      row += std::string("<td class=\"num") + (a == 0 ? " gs" : "") + (big ? " beyond" : "") +
             "\"" + (big ? " title=\"more than 3\xCF\x83\"" : "") + ">" + FormatFixed(ratio[a], 2) +
             "</td>";
      if (std::isfinite(ratio[a]) && std::abs(ratio[a]) > worst) {
        worst = std::abs(ratio[a]);
        worst_name = name;
      }
    }
    sx.values.push_back(ratio[0]);
    sy.values.push_back(ratio[1]);
    sz.values.push_back(ratio[2]);
    rows += row + "</tr>";
  }
  const std::string sub =
      "<th class=\"num gs\">x</th><th class=\"num\">y</th><th class=\"num\">z</th>";
  std::string head =
      "<tr><th rowspan=\"2\">triad</th><th class=\"group\" colspan=\"3\">positions-only fit "
      "(mm)</th><th class=\"group gs\" colspan=\"4\">shift by the full model (\xC2\xB5m)</th><th "
      "class=\"group gs\" colspan=\"3\">shift / \xCF\x83</th></tr><tr><th class=\"num\">x</th><th "
      "class=\"num\">y</th><th class=\"num\">z</th><th class=\"num gs\">x</th><th "
      "class=\"num\">y</th><th class=\"num\">z</th><th class=\"num\">|\xCE\x94|</th>" +
      sub + "</tr>";
  // Absent (a result of an earlier calibd): the start is not known, so neither sentence.
  const std::optional<bool> fitted = diag.positions_only_start;
  std::string s =
      "<p>" +
      std::string(!fitted   ? "The full model's shift from the start of its fit. "
                  : *fitted ? "The full model starts from the positions-only fit of the same log "
                              "(its dynamic samples, the accelerometers corrected by the statics' "
                              "closed form, the gyroscope biases removed, ideal gyroscopes). "
                            : "The positions-only fit for the start failed: the full model started "
                              "from the nominal geometry, so the shift below is from it. ") +
      "\xCF\x83 is the full model's 1\xCF\x83 of the position" +
      std::string(robust ? " (residual-aware)" : "") + "; shifts beyond 3\xCF\x83 are marked." +
      (worst > 0 ? " Largest: triad " + E(worst_name) + ", " + FormatSig(worst, 2) + "\xCF\x83."
                 : "") +
      "</p>";
  s += "<div class=\"table-wrap\"><table class=\"table-array-full-change\"><thead>" + head +
       "</thead><tbody>" + rows + "</tbody></table></div>";
  PlotOptions o;
  o.name = "array-full-position-change";
  o.title = "Position shift by the full model, in units of its \xCF\x83";
  o.x.title = "triad";
  o.y.title = "shift / \xCF\x83";
  o.ref_lines.push_back({false, 3, "+3\xCF\x83", true});
  o.ref_lines.push_back({false, -3,
                         "\xE2\x88\x92"
                         "3\xCF\x83",
                         true});
  s += "<div class=\"plots\">" +
       Figure(RenderBarChart(o, names, {sx, sy, sz}),
              "Within \xC2\xB1"
              "3\xCF\x83: the triads' own errors did not bias the positions-only "
              "fit beyond its precision.") +
       "</div>";
  return Section("full-vs-positions", "What the full model changed", s);
}

}  // namespace

std::string ArraySigmaBasisText(const results::ArrayUncertainty& u) {
  const std::string chi2 = std::isfinite(u.chi2_per_dof)
                               ? ", \xCF\x87\xC2\xB2/dof " + FormatSig(u.chi2_per_dof, 3)
                               : std::string();
  if (u.basis == "sandwich")
    return "residual-aware sandwich (the residuals exceed the noise model" + chi2 +
           "; the Cram\xC3\xA9r\xE2\x80\x93Rao bound, too small here, is in "
           "uncertainty.*.crb of the JSON)";
  if (u.basis == "crb")
    return "Cram\xC3\xA9r\xE2\x80\x93Rao bound (the residuals match the noise model" + chi2 + ")";
  return "Cram\xC3\xA9r\xE2\x80\x93Rao \xCF\x83 only (stored by an earlier calibd)";
}

std::string ArrayFullSections(const results::ArrayResult& result) {
  if (!result.full || !result.parameters || !result.uncertainty)
    return "<p class=\"muted\">The triads: not available (not a usable result of model full).</p>";
  std::string out;
  struct Part {
    const char* what;
    std::string (*build)(const results::ArrayResult&);
  };
  for (const Part& part : {Part{"The triads' parameters", &TriadsSection},
                           Part{"The residuals per triad", &ResidualsSection},
                           Part{"The comparison with the positions-only fit", &ChangeSection}}) {
    try {
      out += part.build(result);
    } catch (const std::exception&) {
      out += "<p class=\"muted\">" + std::string(part.what) + ": not available.</p>";
    }
  }
  return out;
}

std::string ArrayFullSections(const json& result) {
  results::ArrayResult r;
  const Status s = results::FromJson(result, &r);
  if (!s.ok())
    return "<p class=\"muted not-available\">" + EscapeText("The triads (" + s.message() + ")") +
           ": not available.</p>";
  return ArrayFullSections(r);
}

}  // namespace calibd::web
