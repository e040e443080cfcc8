#include "web/html.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace calibd::web {
namespace {

constexpr char kReplacement[] = "\xEF\xBF\xBD";  // U+FFFD

std::string Escape(std::string_view s, bool attribute) {
  std::string out;
  out.reserve(s.size() + s.size() / 8 + 8);
  for (size_t i = 0; i < s.size();) {
    const size_t n = Utf8SequenceLength(s, i);
    if (n == 0) {
      out += kReplacement;
      ++i;
      continue;
    }
    if (n > 1) {
      out.append(s.data() + i, n);
      i += n;
      continue;
    }
    const char c = s[i++];
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      case '\t':
        out += attribute ? "&#9;" : "\t";
        break;
      case '\n':
        out += attribute ? "&#10;" : "\n";
        break;
      default:
        if (static_cast<unsigned char>(c) < 0x20 || c == 0x7F) break;  // drop controls
        out += c;
    }
  }
  return out;
}

std::string Printf(const char* fmt, int a, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), fmt, a, v);
  return buf;
}

// "1.23e-07" -> "1.23e-7", "4.5e+08" -> "4.5e8".
std::string TidyExponent(std::string s) {
  const size_t e = s.find('e');
  if (e == std::string::npos) return s;
  std::string mant = s.substr(0, e);
  std::string exp = s.substr(e + 1);
  bool neg = false;
  if (!exp.empty() && (exp[0] == '+' || exp[0] == '-')) {
    neg = exp[0] == '-';
    exp.erase(0, 1);
  }
  while (exp.size() > 1 && exp[0] == '0') exp.erase(0, 1);
  return mant + "e" + (neg ? "-" : "") + exp;
}

std::string NonFinite(double v) {
  if (std::isnan(v)) return "\xE2\x80\x93";  // en dash
  return v > 0 ? "\xE2\x88\x9E" : "\xE2\x88\x92\xE2\x88\x9E";
}

std::string FixNegativeZero(std::string s) {
  // "-0", "-0.00", "-0.0e0" -> without the sign.
  if (s.size() > 1 && s[0] == '-') {
    bool all_zero = true;
    for (size_t i = 1; i < s.size(); ++i) {
      const char c = s[i];
      if (c == 'e') break;
      if (c != '0' && c != '.') {
        all_zero = false;
        break;
      }
    }
    if (all_zero) s.erase(0, 1);
  }
  return s;
}

int64_t DaysFromCivil(int64_t y, unsigned m, unsigned d) {
  y -= m <= 2;
  const int64_t era = (y >= 0 ? y : y - 399) / 400;
  const unsigned yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + static_cast<int64_t>(doe) - 719468;
}

bool ReadInt(std::string_view s, size_t* pos, size_t digits, int* out) {
  int v = 0;
  for (size_t k = 0; k < digits; ++k) {
    if (*pos >= s.size() || s[*pos] < '0' || s[*pos] > '9') return false;
    v = v * 10 + (s[(*pos)++] - '0');
  }
  *out = v;
  return true;
}

}  // namespace

std::string EscapeText(std::string_view s) { return Escape(s, false); }
std::string EscapeAttr(std::string_view s) { return Escape(s, true); }

std::string FormatSig(double v, int sig) {
  if (!std::isfinite(v)) return NonFinite(v);
  if (sig < 1) sig = 1;
  if (sig > 17) sig = 17;
  if (v == 0) return "0";
  const double a = std::fabs(v);
  if (a >= 1e-3 && a < 1e6) {
    const int mag = static_cast<int>(std::floor(std::log10(a)));
    const int decimals = std::max(0, sig - 1 - mag);
    return FixNegativeZero(Printf("%.*f", decimals, v));
  }
  return FixNegativeZero(TidyExponent(Printf("%.*e", sig - 1, v)));
}

std::string FormatFixed(double v, int decimals) {
  if (!std::isfinite(v)) return NonFinite(v);
  if (decimals < 0) decimals = 0;
  if (decimals > 17) decimals = 17;
  return FixNegativeZero(Printf("%.*f", decimals, v));
}

std::string FormatMicrometres(double metres, int sig) {
  if (!std::isfinite(metres)) return NonFinite(metres);
  return FormatSig(metres * 1e6, sig) + " \xC2\xB5m";
}

std::string FormatSI(double v, std::string_view unit, int sig) {
  std::string u(unit);
  if (!std::isfinite(v)) return NonFinite(v) + (u.empty() ? "" : " " + u);
  if (v == 0) return "0" + (u.empty() ? "" : " " + u);
  static const char* kPrefix[] = {"p", "n", "\xC2\xB5", "m", "", "k", "M", "G"};
  int e3 = static_cast<int>(std::floor(std::log10(std::fabs(v)) / 3.0));
  e3 = std::max(-4, std::min(3, e3));
  double mant = v / std::pow(10.0, 3 * e3);
  // Rounding can push the mantissa to 1000 ("999.96" -> "1000"): move to the next prefix.
  const int mag = static_cast<int>(std::floor(std::log10(std::fabs(mant))));
  const double rounded =
      std::round(mant * std::pow(10.0, sig - 1 - mag)) / std::pow(10.0, sig - 1 - mag);
  if (std::fabs(rounded) >= 1000 && e3 < 3) {
    ++e3;
    mant = v / std::pow(10.0, 3 * e3);
  }
  const int m2 = static_cast<int>(std::floor(std::log10(std::max(std::fabs(mant), 1e-300))));
  const int decimals = std::max(0, sig - 1 - m2);
  std::string s = FixNegativeZero(Printf("%.*f", decimals, mant));
  const std::string prefix = kPrefix[e3 + 4];
  if (u.empty()) return prefix.empty() ? s : s + " " + prefix;
  return s + " " + prefix + u;
}

std::string FormatDuration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "\xE2\x80\x93";
  if (seconds > 1e12) return FormatSig(seconds / 86400, 3) + " d";
  char buf[64];
  if (seconds < 60) {
    return FormatSig(seconds, seconds < 10 ? 2 : 3) + " s";
  }
  const auto total = static_cast<int64_t>(std::llround(seconds));
  if (total < 3600) {
    std::snprintf(buf, sizeof(buf), "%lld min %02lld s", static_cast<long long>(total / 60),
                  static_cast<long long>(total % 60));
  } else if (total < 86400) {
    std::snprintf(buf, sizeof(buf), "%lld h %02lld min", static_cast<long long>(total / 3600),
                  static_cast<long long>((total % 3600) / 60));
  } else {
    std::snprintf(buf, sizeof(buf), "%lld d %lld h", static_cast<long long>(total / 86400),
                  static_cast<long long>((total % 86400) / 3600));
  }
  return buf;
}

bool ParseTimestamp(std::string_view s, double* unix_seconds) {
  while (!s.empty() && s.front() == ' ') s.remove_prefix(1);
  while (!s.empty() && s.back() == ' ') s.remove_suffix(1);
  if (s.empty()) return false;
  // Plain number: Unix seconds.
  {
    std::string tmp(s);
    char* end = nullptr;
    const double v = std::strtod(tmp.c_str(), &end);
    if (end && *end == '\0' && std::isfinite(v) && tmp.find('-', 1) == std::string::npos) {
      *unix_seconds = v;
      return true;
    }
  }
  size_t p = 0;
  int y, mo, d, h = 0, mi = 0, sec = 0;
  if (!ReadInt(s, &p, 4, &y) || p >= s.size() || s[p++] != '-') return false;
  if (!ReadInt(s, &p, 2, &mo) || p >= s.size() || s[p++] != '-') return false;
  if (!ReadInt(s, &p, 2, &d)) return false;
  double frac = 0;
  if (p < s.size() && (s[p] == 'T' || s[p] == 't' || s[p] == ' ')) {
    ++p;
    if (!ReadInt(s, &p, 2, &h) || p >= s.size() || s[p++] != ':') return false;
    if (!ReadInt(s, &p, 2, &mi)) return false;
    if (p < s.size() && s[p] == ':') {
      ++p;
      if (!ReadInt(s, &p, 2, &sec)) return false;
      if (p < s.size() && (s[p] == '.' || s[p] == ',')) {
        ++p;
        double scale = 0.1;
        while (p < s.size() && s[p] >= '0' && s[p] <= '9') {
          frac += (s[p++] - '0') * scale;
          scale /= 10;
        }
      }
    }
  }
  double offset = 0;
  if (p < s.size()) {
    if (s[p] == 'Z' || s[p] == 'z') {
      ++p;
    } else if (s[p] == '+' || s[p] == '-') {
      const int sign = s[p++] == '-' ? -1 : 1;
      int oh = 0, om = 0;
      if (!ReadInt(s, &p, 2, &oh)) return false;
      if (p < s.size() && s[p] == ':') ++p;
      if (p < s.size() && !ReadInt(s, &p, 2, &om)) return false;
      offset = sign * (oh * 3600.0 + om * 60.0);
    }
  }
  if (p != s.size()) return false;
  if (mo < 1 || mo > 12 || d < 1 || d > 31 || h > 23 || mi > 59 || sec > 60) return false;
  *unix_seconds = static_cast<double>(DaysFromCivil(y, mo, d)) * 86400.0 + h * 3600.0 + mi * 60.0 +
                  sec + frac - offset;
  return true;
}

const char* Stylesheet() {
  return R"css(
:root{--fg:#1c232b;--muted:#5d6874;--line:#d9dee4;--panel:#f5f7f9;--accent:#0b5cad;
--ok:#0a6b3d;--bad:#a3260f;--warn:#8a5200}
*{box-sizing:border-box}
html{-webkit-text-size-adjust:100%}
body{margin:0;color:var(--fg);background:#fff;
font:15px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,"Helvetica Neue",Arial,sans-serif}
header.top{display:flex;flex-wrap:wrap;align-items:baseline;gap:.4rem 1.2rem;
padding:.55rem 1.2rem;border-bottom:1px solid var(--line);background:var(--panel)}
header.top .brand{font-weight:700;color:var(--fg);text-decoration:none;letter-spacing:.02em}
header.top nav a{margin-right:.9rem}
main{max-width:1120px;margin:0 auto;padding:.8rem 1.2rem 3rem}
h1{font-size:1.45rem;margin:.5rem 0 .6rem;line-height:1.25;overflow-wrap:anywhere}
h2{font-size:1.12rem;margin:1.9rem 0 .6rem;padding-bottom:.2rem;border-bottom:1px solid var(--line)}
h3{font-size:.98rem;margin:1.2rem 0 .4rem}
a{color:var(--accent)}
p{margin:.4rem 0 .8rem}
.muted{color:var(--muted)}
.small{font-size:.85rem}
.table-wrap{overflow-x:auto;margin:.3rem 0 1rem}
table{border-collapse:collapse;width:100%;font-size:.9rem}
th,td{padding:.32rem .55rem;border-bottom:1px solid var(--line);text-align:left;vertical-align:top}
thead th{background:var(--panel);font-weight:600;white-space:nowrap;border-bottom:2px solid var(--line)}
tbody tr:hover{background:#fafbfc}
.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
td.name{overflow-wrap:anywhere}
td.time{white-space:nowrap}
table.table-devices td.time,table.table-devices th{white-space:normal}
table.table-diagnostics td{overflow-wrap:anywhere}
table.table-diagnostics th{white-space:normal}
code,pre,.mono{font-family:ui-monospace,SFMono-Regular,Menlo,Consolas,"DejaVu Sans Mono",monospace;
font-size:.86em}
pre{background:var(--panel);border:1px solid var(--line);padding:.6rem .8rem;overflow:auto;
max-height:24rem;white-space:pre-wrap;overflow-wrap:anywhere}
.badge{display:inline-block;padding:.02rem .55rem;border-radius:999px;font-size:.78rem;
font-weight:600;border:1px solid;line-height:1.5;white-space:nowrap}
.badge-succeeded{color:var(--ok);background:#e7f4ec;border-color:#9fd0b3}
.badge-failed{color:var(--bad);background:#fbebe7;border-color:#e9b1a4}
.badge-running{color:var(--accent);background:#e8f0fa;border-color:#a8c6ea}
.badge-queued{color:var(--muted);background:#f0f2f4;border-color:#c8d0d8}
.badge-unknown{color:var(--muted);background:#fff;border-color:#c8d0d8}
.badge-rejected{color:#fff;background:var(--bad);border-color:var(--bad)}
.badge-revoked{color:#fff;background:#6b4f00;border-color:#6b4f00}
.badge-accepted{color:var(--ok);background:#fff;border-color:#9fd0b3}
.verdict-reason{font-size:.8rem;color:var(--bad);display:block;max-width:28rem}
.verdict-reason-accepted{color:var(--ok)}
.device-hint a{white-space:nowrap}
.flag-warn{color:var(--warn);font-weight:600;white-space:nowrap}
.sd{font-size:.7rem;color:var(--muted);margin-left:.2rem}
table.table-array-full td,table.table-array-full th{padding:.28rem .3rem}
table.table-drift-imu,table.table-drift-noise,table.table-drift-thermal{font-size:.78rem}
table.table-drift-imu td,table.table-drift-imu th,table.table-drift-noise td,
table.table-drift-noise th,table.table-drift-thermal td,table.table-drift-thermal th{
padding:.28rem .3rem}
table.table-drift-imu thead th,table.table-drift-noise thead th,table.table-drift-pca thead th,
table.table-drift-thermal thead th{white-space:normal}
td details{margin:0}
th.group{text-align:center}
.gs{border-left:2px solid var(--line)}
td.beyond{background:#fcf0ed;color:var(--bad);font-weight:600}
.callout{border-left:4px solid var(--line);background:var(--panel);padding:.6rem .9rem;margin:.8rem 0}
.callout p{margin:.2rem 0}
.callout-error{border-color:var(--bad);background:#fcf0ed}
.callout-warn{border-color:#d08a00;background:#fdf5e6}
.callout-ok{border-color:var(--ok);background:#eef7f1}
dl.kv{display:grid;grid-template-columns:max-content minmax(0,1fr);gap:.2rem 1.2rem;margin:.4rem 0 1rem}
dl.kv dt{color:var(--muted)}
dl.kv dd{margin:0;overflow-wrap:anywhere}
ul.warnings li{margin:.2rem 0}
.plots{display:grid;grid-template-columns:repeat(auto-fill,minmax(min(440px,100%),1fr));gap:1.2rem 1.6rem}
figure{margin:0;min-width:0}
figcaption{font-size:.84rem;color:var(--muted);margin-top:.2rem}
svg.plot{display:block;width:100%;height:auto;max-width:100%}
form.filters{display:flex;flex-wrap:wrap;gap:.6rem 1rem;align-items:flex-end;margin:.4rem 0 1rem;
padding:.6rem .8rem;background:var(--panel);border:1px solid var(--line)}
form.filters label{display:flex;flex-direction:column;font-size:.8rem;color:var(--muted);gap:.15rem}
input,select,button{font:inherit;font-size:.92rem;padding:.25rem .45rem;border:1px solid #b9c2cc;
border-radius:4px;background:#fff;color:var(--fg)}
button{background:var(--accent);color:#fff;border-color:var(--accent);cursor:pointer}
nav.pager{margin:1rem 0;display:flex;gap:1rem}
ul.downloads{padding-left:1.1rem}
details{margin:.3rem 0 .8rem}
summary{cursor:pointer;color:var(--accent)}
footer.foot{margin-top:2.5rem;color:var(--muted);font-size:.8rem}
@media (max-width:640px){
body{font-size:14px}main{padding:.6rem .7rem 2rem}header.top{padding:.5rem .7rem}
th,td{padding:.25rem .35rem}dl.kv{grid-template-columns:1fr}dl.kv dd{margin-bottom:.3rem}
table.table-history thead,table.table-calibrations thead,table.table-devices thead{position:absolute;
width:1px;height:1px;overflow:hidden;clip:rect(0 0 0 0)}
table.table-history,table.table-history tbody,table.table-history tr,table.table-history td,
table.table-calibrations,table.table-calibrations tbody,table.table-calibrations tr,
table.table-calibrations td,table.table-devices,table.table-devices tbody,table.table-devices tr,
table.table-devices td{display:block;width:100%}
table.table-history tr,table.table-calibrations tr,table.table-devices tr{padding:.35rem 0;
border-bottom:1px solid var(--line)}
table.table-history td,table.table-calibrations td,table.table-devices td{border:0;
padding:.08rem .2rem;text-align:left;white-space:normal;overflow-wrap:anywhere}
table.table-history td[data-label]::before,table.table-calibrations td[data-label]::before,
table.table-devices td[data-label]::before{content:attr(data-label) ": ";color:var(--muted);
font-size:.8rem}}
@media print{
header.top,form.filters,nav.pager,ul.downloads{display:none}
body{font-size:10pt;color:#000}main{max-width:none;padding:0}
a{color:inherit;text-decoration:none}
.plots{display:block}figure,table,.callout,dl.kv{break-inside:avoid}
figure{margin-bottom:1rem}pre{max-height:none}
thead th{background:none}tbody tr:hover{background:none}}
)css";
}

std::string StatusBadge(std::string_view status) {
  const bool known =
      status == "succeeded" || status == "failed" || status == "running" || status == "queued";
  std::string cls = known ? std::string(status) : "unknown";
  return "<span class=\"badge badge-" + cls + "\">" +
         EscapeText(status.empty() ? std::string_view("unknown") : status) + "</span>";
}

std::string RenderPage(std::string_view title, std::string_view page_class,
                       std::string_view body_html) {
  std::string out;
  out.reserve(body_html.size() + 8192);
  out += "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n";
  out += "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n";
  out += "<title>" + EscapeText(title) + " \xC2\xB7 calibd</title>\n<style>";
  out += Stylesheet();
  out += "</style>\n</head>\n<body class=\"" + EscapeAttr(page_class) + "\">\n";
  out += "<header class=\"top\"><a class=\"brand\" href=\"/\">calibd</a>";
  out +=
      "<nav><a href=\"/\">Calibration history</a> <a "
      "href=\"/devices\">Devices</a></nav></header>\n<main>\n";
  out += body_html;
  out +=
      "\n<footer class=\"foot\">calibd \xC2\xB7 calibration server for inertial sensors</footer>";
  out += "\n</main>\n</body>\n</html>\n";
  return out;
}

}  // namespace calibd::web
