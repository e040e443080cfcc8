#include "web/array_full_report.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "web/html.h"
#include "web/svg_plot.h"

namespace calibd::web {
namespace {

using json = nlohmann::json;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kPi = 3.14159265358979323846;
constexpr const char* kDash = "\xE2\x80\x93";  // –
constexpr const char* kPm = "\xC2\xB1";        // ±
constexpr const char* kAxes[] = {"x", "y", "z"};

const json* Get(const json* j, const char* key) {
  if (j == nullptr || !j->is_object()) return nullptr;
  auto it = j->find(key);
  return it == j->end() ? nullptr : &*it;
}
const json* At(const json* j, size_t i) {
  return j != nullptr && j->is_array() && i < j->size() ? &(*j)[i] : nullptr;
}
double Num(const json* j) { return j != nullptr && j->is_number() ? j->get<double>() : kNaN; }
std::string Str(const json* j) {
  return j != nullptr && j->is_string() ? j->get<std::string>() : std::string();
}
size_t Size(const json* j) { return j != nullptr && j->is_array() ? j->size() : 0; }
// Component c of a 3-vector, or entry (r, c) of a 3x3 matrix given as rows.
double V(const json* v, size_t c) { return Num(At(v, c)); }
double M(const json* m, size_t r, size_t c) { return Num(At(At(m, r), c)); }

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

double Median(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return !std::isfinite(x); }), v.end());
  if (v.empty()) return kNaN;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// The σ the tables show of one entry of uncertainty.imus: the residual-aware one (`robust`) when
// the result has it (the residuals exceed the noise: the Cramér–Rao bound is then too small),
// else the Cramér–Rao bound.
const json* ShownSigma(const json* uimu) {
  const json* robust = Get(uimu, "robust");
  return robust != nullptr && robust->is_object() ? robust : uimu;
}
bool HasRobustSigma(const json& result) {
  const json* stds = Get(Get(&result, "uncertainty"), "imus");
  for (size_t k = 0; k < Size(stds); ++k)
    if (ShownSigma(At(stds, k)) != At(stds, k)) return true;
  return false;
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
Limits ReadLimits(const json& result) {
  const json* l = Get(Get(&result, "verdict"), "limits");
  Limits o;
  o.scale_range = Num(Get(l, "scale_range"));
  o.scale_std = Num(Get(l, "max_scale_std"));
  o.implausible = Num(Get(l, "implausible_factor"));
  o.axis_std = Num(Get(l, "max_axis_std"));
  o.accel_bias = Num(Get(l, "max_accel_bias"));
  o.accel_bias_std = Num(Get(l, "max_accel_bias_std"));
  o.gyro_bias = Num(Get(l, "max_gyro_bias"));
  o.gyro_bias_std = Num(Get(l, "max_gyro_bias_std"));
  return o;
}

struct Kind {
  const char* key;        // "accelerometer" | "gyroscope"
  std::string bias_unit;  // reading units, for headers
  double unit = 1;        // SI per reading unit (the nominal: 1 for m/s^2, pi/180 for deg/s)
  double bias_limit = kNaN, bias_std_limit = kNaN;  // SI
};

// The per-axis misalignment angle of axis j: the angle between the sensor's axis j (column j of
// the unit-diagonal misalignment matrix) and the body axis j, and its σ to first order from the
// entries' σ (entries taken as uncorrelated; for an angle near 0 the entries' rms σ).
void AxisAngle(const json* m, const json* m_std, size_t j, double* angle, double* sd) {
  double off2 = 0, var = 0, s2 = 0;
  int n = 0;
  for (size_t i = 0; i < 3; ++i) {
    if (i == j) continue;
    off2 += M(m, i, j) * M(m, i, j);
    s2 += M(m_std, i, j) * M(m_std, i, j);
    ++n;
  }
  const double r = std::sqrt(off2);
  *angle = std::atan2(r, M(m, j, j));
  for (size_t i = 0; i < 3; ++i) {
    if (i == j) continue;
    const double w = r > 0 ? M(m, i, j) / r : 1 / std::sqrt(static_cast<double>(n));
    var += w * w * M(m_std, i, j) * M(m_std, i, j);
  }
  *sd = std::sqrt(r > 0 ? var : s2 / n);
}

std::string SensorTable(const json& result, const Kind& kind, const Limits& lim) {
  const json* imus = Get(Get(&result, "parameters"), "imus");
  const json* stds = Get(Get(&result, "uncertainty"), "imus");
  const double ref = Num(Get(Get(&result, "parameters"), "reference"));
  const size_t K = Size(imus);
  // Precision per column group from the median σ.
  std::vector<double> g_sd, a_sd, b_sd;
  for (size_t k = 0; k < K; ++k) {
    const json* p = Get(At(imus, k), kind.key);
    const json* s = Get(ShownSigma(At(stds, k)), kind.key);
    for (size_t c = 0; c < 3; ++c) {
      g_sd.push_back(100 * V(Get(s, "scale_std"), c) / std::abs(V(Get(p, "scale"), c)));
      double ang, sd;
      AxisAngle(Get(p, "misalignment"), Get(s, "misalignment_std"), c, &ang, &sd);
      a_sd.push_back(1e3 * sd);
      b_sd.push_back(V(Get(s, "bias_std"), c));
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
    const json* imu = At(imus, k);
    const json* p = Get(imu, kind.key);
    const json* s = Get(ShownSigma(At(stds, k)), kind.key);
    std::string name = Str(Get(imu, "name"));
    if (name.empty()) name = std::to_string(k);
    const bool is_ref = std::isfinite(ref) && static_cast<double>(k) == ref;
    std::string row = "<tr><td class=\"name\">" + E(name) +
                      (is_ref ? " <span class=\"muted small\">(ref.)</span>" : "") + "</td>";
    for (size_t c = 0; c < 3; ++c) {
      const double scale = V(Get(p, "scale"), c);
      const double ratio = scale / kind.unit;
      const double rel_sd = V(Get(s, "scale_std"), c) / std::abs(scale);
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
    for (size_t c = 0; c < 3; ++c) {
      double ang, sd;
      AxisAngle(Get(p, "misalignment"), Get(s, "misalignment_std"), c, &ang, &sd);
      double worst = 0;
      for (size_t i = 0; i < 3; ++i)
        if (i != c) worst = std::max(worst, M(Get(s, "misalignment_std"), i, c));
      std::string why;
      if (std::isfinite(lim.axis_std) && worst > lim.axis_std)
        why =
            "an entry's \xCF\x83 beyond max_axis_std " + FormatSig(1e3 * lim.axis_std, 3) + " mrad";
      marked += !why.empty();
      row += ValueCell(1e3 * ang, ad, 1e3 * sd, why, c == 0, false);
    }
    for (size_t c = 0; c < 3; ++c) {
      const double b = V(Get(p, "bias"), c), sd = V(Get(s, "bias_std"), c);
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
std::string MisalignmentTable(const json& result, double axis_std_limit) {
  const json* imus = Get(Get(&result, "parameters"), "imus");
  const json* stds = Get(Get(&result, "uncertainty"), "imus");
  static const size_t kEntries[6][2] = {{0, 1}, {0, 2}, {1, 0}, {1, 2}, {2, 0}, {2, 1}};
  std::string head = "<tr><th>triad</th><th>sensor</th>";
  for (const auto& e : kEntries)
    head += "<th class=\"num\">T[" + std::to_string(e[0]) + "][" + std::to_string(e[1]) + "]</th>";
  head += "</tr>";
  std::string rows;
  for (size_t k = 0; k < Size(imus); ++k) {
    std::string name = Str(Get(At(imus, k), "name"));
    if (name.empty()) name = std::to_string(k);
    for (const char* sensor : {"accelerometer", "gyroscope"}) {
      const json* m = Get(Get(At(imus, k), sensor), "misalignment");
      const json* ms = Get(Get(ShownSigma(At(stds, k)), sensor), "misalignment_std");
      rows += "<tr><td class=\"name\">" + E(name) + "</td><td>" + sensor + "</td>";
      for (const auto& e : kEntries) {
        const double sd = M(ms, e[0], e[1]);
        const std::string why = std::isfinite(axis_std_limit) && sd > axis_std_limit
                                    ? "\xCF\x83 beyond max_axis_std"
                                    : std::string();
        rows += ValueCell(1e3 * M(m, e[0], e[1]), 3, 1e3 * sd, why);
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

std::string TriadsSection(const json& result) {
  const json* diag = Get(&result, "diagnostics");
  const Limits lim = ReadLimits(result);
  const bool deg = Str(Get(diag, "gyro_unit")) == "deg/s";
  Kind accel{"accelerometer", "m/s\xC2\xB2", 1, lim.accel_bias, lim.accel_bias_std};
  Kind gyro{"gyroscope", deg ? "\xC2\xB0/s" : "rad/s", deg ? kPi / 180 : 1, lim.gyro_bias,
            lim.gyro_bias_std};
  const json* noise = Get(diag, "noise");
  std::string s = "<dl class=\"kv\">";
  s += "<dt>gauge</dt><dd>" + E(Str(Get(Get(diag, "gauge"), "description"))) + "</dd>";
  s += "<dt>statics</dt><dd>" + FormatFixed(Num(Get(diag, "statics")), 0) + " (" +
       FormatFixed(Num(Get(diag, "static_samples")), 0) + " samples), motion " +
       FormatFixed(Num(Get(diag, "dynamic_samples")), 0) + " samples</dd>";
  s += "<dt>noise \xCF\x83 used</dt><dd>" + FormatSig(Num(Get(noise, "accelerometer")), 3) +
       " m/s\xC2\xB2, " + FormatSig(Num(Get(noise, "gyroscope")), 3) + " " + E(gyro.bias_unit) +
       " (" + E(Str(Get(noise, "source"))) + ")</dd>";
  s += "<dt>\xCF\x87\xC2\xB2 / degrees of freedom</dt><dd>" +
       FormatSig(Num(Get(diag, "chi2_per_dof")), 3) + "</dd>";
  s += "<dt>\xCF\x83 shown</dt><dd class=\"sigma-shown\">" +
       std::string(HasRobustSigma(result)
                       ? "residual-aware (the residuals exceed the noise, so the "
                         "Cram\xC3\xA9r\xE2\x80\x93Rao bound, in uncertainty.imus[] of the JSON, "
                         "is too small); the limits are marked against it"
                       : "Cram\xC3\xA9r\xE2\x80\x93Rao bound at the estimate") +
       "</dd></dl>";
  if (Size(Get(Get(&result, "parameters"), "imus")) == 0)
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

std::string ResidualsSection(const json& result) {
  const json* diag = Get(&result, "diagnostics");
  const json* per = Get(Get(diag, "residual_rms"), "imus");
  if (Size(per) == 0) return "";
  const bool deg = Str(Get(diag, "gyro_unit")) == "deg/s";
  const std::string gu = deg ? "\xC2\xB0/s" : "rad/s";
  std::string figs, words;
  for (const char* kind : {"accelerometer", "gyroscope"}) {
    const bool a = std::string(kind) == "accelerometer";
    const std::string unit = a ? "m/s\xC2\xB2" : gu;
    std::vector<std::string> names;
    BarSeries st{"statics", {}, {}, 0}, dy{"motion", {}, {}, 1};
    for (size_t k = 0; k < Size(per); ++k) {
      const json* r = At(per, k);
      std::string name = Str(Get(r, "name"));
      names.push_back(name.empty() ? std::to_string(k) : name);
      st.values.push_back(Num(Get(Get(r, "static"), kind)));
      dy.values.push_back(Num(Get(Get(r, "dynamic"), kind)));
    }
    const double noise = Num(Get(Get(diag, "static_noise"), kind));
    PlotOptions o;
    o.name = std::string("array-full-residuals-") + kind;
    o.title = std::string("Residual RMS per triad, ") + (a ? "accelerometers" : "gyroscopes");
    o.x.title = "triad";
    o.y.title = "RMS (" + unit + ")";
    o.y.type = ScaleType::kLog10;
    if (std::isfinite(noise) && noise > 0)
      o.ref_lines.push_back({false, noise, "static noise " + FormatSig(noise, 2), true});
    figs += Figure(RenderBarChart(o, names, {st, dy}),
                   "Statics: RMS of the static means' residuals times \xE2\x88\x9Asamples; "
                   "motion: RMS over the dynamic samples. Both sit at the static noise when the "
                   "model fits.");
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
  return Section("triad-residuals", "Residuals per triad", body);
}

std::string ChangeSection(const json& result) {
  const json* diag = Get(&result, "diagnostics");
  const json* ch = Get(diag, "changed_from_positions_only");
  if (Size(ch) == 0) return "";
  const json* pstd = Get(Get(&result, "uncertainty"), "positions");
  const bool robust = HasRobustSigma(result);
  std::vector<std::string> names;
  BarSeries sx{"\xCE\x94x / \xCF\x83x", {}, {}, 0}, sy{"\xCE\x94y / \xCF\x83y", {}, {}, 1},
      sz{"\xCE\x94z / \xCF\x83z", {}, {}, 2};
  std::string rows;
  double worst = 0;
  std::string worst_name;
  for (size_t k = 0; k < Size(ch); ++k) {
    const json* c = At(ch, k);
    std::string name = Str(Get(c, "name"));
    if (name.empty()) name = std::to_string(k);
    names.push_back(name);
    const json* d = Get(c, "position_change");
    const json* po = Get(c, "positions_only");
    const json* in_sigma = Get(c, "position_change_sigma");
    // Older results carry only the change: σ from uncertainty.positions. With a residual-aware
    // σ, the shift is measured against it (as the tables above).
    const json* sd = nullptr;
    for (size_t i = 0; i < Size(pstd); ++i)
      if (Str(Get(At(pstd, i), "name")) == Str(Get(c, "name"))) sd = Get(At(pstd, i), "std");
    const json* uimu = At(Get(Get(&result, "uncertainty"), "imus"), k);
    if (robust && ShownSigma(uimu) != uimu) {
      sd = Get(ShownSigma(uimu), "position_std");
      in_sigma = nullptr;
    }
    double ratio[3];
    std::string row = "<tr><td class=\"name\">" + E(name) + "</td>";
    for (size_t a = 0; a < 3; ++a)
      row += "<td class=\"num\">" + FormatFixed(1e3 * V(po, a), 4) + "</td>";
    double n2 = 0;
    for (size_t a = 0; a < 3; ++a) {
      ratio[a] = in_sigma != nullptr ? V(in_sigma, a) : V(d, a) / V(sd, a);
      if (!std::isfinite(ratio[a])) ratio[a] = kNaN;
      n2 += V(d, a) * V(d, a);
      row += std::string("<td class=\"num") + (a == 0 ? " gs" : "") + "\">" +
             FormatFixed(1e6 * V(d, a), 2) + "</td>";
    }
    row += "<td class=\"num\">" + FormatFixed(1e6 * std::sqrt(n2), 2) + "</td>";
    for (size_t a = 0; a < 3; ++a) {
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
  const json* from_fit = Get(diag, "positions_only_start");
  const bool fitted = from_fit == nullptr || !from_fit->is_boolean() || from_fit->get<bool>();
  std::string s =
      "<p>" +
      std::string(fitted ? "The full model starts from the positions-only fit of the same log "
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

bool IsArrayFullResult(const json& result) {
  const json* p = Get(&result, "parameters");
  return Str(Get(p, "model")) == "full" ||
         Str(Get(Get(&result, "diagnostics"), "model")) == "full" || Size(Get(p, "imus")) > 0;
}

std::string ArrayFullSections(const json& result) {
  std::string out;
  struct Part {
    const char* what;
    std::string (*build)(const json&);
  };
  for (const Part& part : {Part{"The triads' parameters", &TriadsSection},
                           Part{"The residuals per triad", &ResidualsSection},
                           Part{"The comparison with the positions-only fit", &ChangeSection}}) {
    try {
      out += part.build(result);
    } catch (const std::exception&) {
      out += "<p class=\"muted\">" + std::string(part.what) +
             ": not available (unexpected result shape).</p>";
    }
  }
  return out;
}

}  // namespace calibd::web
