// Ticks, scales, axis domains and decimation of the plots (web/svg_plot.h, svg_plot_parts.h).
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "web/svg_plot.h"
#include "web/svg_plot_parts.h"

namespace calibd::web {

double NiceStep(double lo, double hi, int target) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) return 0;
  if (lo > hi) std::swap(lo, hi);
  const double span = hi - lo;
  if (!(span > 0) || !std::isfinite(span)) return 0;
  if (target < 1) target = 1;
  const double raw = span / target;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  const double norm = raw / mag;
  double nice;
  if (norm < 1.5) {
    nice = 1;
  } else if (norm < 3.5) {
    nice = 2;
  } else if (norm < 7.5) {
    nice = 5;
  } else {
    nice = 10;
  }
  return nice * mag;
}

std::vector<double> NiceLinearTicks(double lo, double hi, int target) {
  std::vector<double> out;
  const double step = NiceStep(lo, hi, target);
  if (!(step > 0) || !std::isfinite(step)) return out;
  if (lo > hi) std::swap(lo, hi);
  const double k0 = std::ceil(lo / step - 1e-9), k1 = std::floor(hi / step + 1e-9);
  if (!(k1 - k0 < 1000)) return out;
  for (double k = k0; k <= k1; k += 1) {
    double v = k * step;
    // Snap to the decimal grid of the step, so 0.1*3 prints and compares as 0.3.
    const double decimals = std::max(0.0, -std::floor(std::log10(step)) + 1);
    if (decimals < 15) {
      const double p = std::pow(10.0, decimals);
      v = std::round(v * p) / p;
    }
    if (std::fabs(v) < step * 1e-9) v = 0;
    out.push_back(v);
  }
  return out;
}

std::vector<double> LogTicks(double lo, double hi, int max_decades) {
  std::vector<double> out;
  if (!std::isfinite(lo) || !std::isfinite(hi) || lo <= 0 || hi <= 0) return out;
  if (lo > hi) std::swap(lo, hi);
  const int k0 = static_cast<int>(std::ceil(std::log10(lo) - 1e-9));
  const int k1 = static_cast<int>(std::floor(std::log10(hi) + 1e-9));
  const int decades = k1 - k0 + 1;
  if (max_decades < 1) max_decades = 1;
  const int every = decades > max_decades ? (decades + max_decades - 1) / max_decades : 1;
  for (int k = k0; k <= k1; ++k) {
    if ((k - k0) % every == 0) out.push_back(std::pow(10.0, k));
  }
  if (std::log10(hi / lo) < 2.05) {
    // Few decades: add 2× and 5× multiples.
    for (int k = k0 - 1; k <= k1; ++k) {
      for (int m : {2, 5}) {
        const double v = m * std::pow(10.0, k);
        if (v >= lo * (1 - 1e-9) && v <= hi * (1 + 1e-9)) out.push_back(v);
      }
    }
    std::sort(out.begin(), out.end());
  }
  return out;
}

std::string FormatTick(double value, double step) {
  if (!std::isfinite(value)) return "";
  char buf[64];
  if (step > 0) {
    if (std::fabs(value) < step * 1e-9) return "0";
    const int decimals = std::max(0, static_cast<int>(-std::floor(std::log10(step) + 1e-9)));
    const double a = std::fabs(value);
    if (a >= 1e6 || decimals > 4) {
      const int sig = std::max(1, static_cast<int>(std::floor(std::log10(a) + 1e-9)) -
                                      static_cast<int>(std::floor(std::log10(step) + 1e-9)) + 1);
      std::snprintf(buf, sizeof(buf), "%.*e", std::min(sig - 1, 15), value);
    } else {
      std::snprintf(buf, sizeof(buf), "%.*f", decimals, value);
    }
  } else {
    const double a = std::fabs(value);
    if (a == 0) return "0";
    if (a >= 1e-3 && a < 1e5) {
      const int decimals = std::max(0, static_cast<int>(-std::floor(std::log10(a) + 1e-9)));
      std::snprintf(buf, sizeof(buf), "%.*f", decimals, value);
    } else {
      std::snprintf(buf, sizeof(buf), "%.0e", value);
    }
  }
  std::string s(buf);
  // Strip trailing zeros of a mantissa in exponent form: "2.50e-07" -> "2.5e-7".
  const size_t e = s.find('e');
  if (e != std::string::npos) {
    std::string mant = s.substr(0, e), exp = s.substr(e + 1);
    if (mant.find('.') != std::string::npos) {
      while (!mant.empty() && mant.back() == '0') mant.pop_back();
      if (!mant.empty() && mant.back() == '.') mant.pop_back();
    }
    bool neg = false;
    if (!exp.empty() && (exp[0] == '+' || exp[0] == '-')) {
      neg = exp[0] == '-';
      exp.erase(0, 1);
    }
    while (exp.size() > 1 && exp[0] == '0') exp.erase(0, 1);
    s = mant + "e" + (neg ? "-" : "") + exp;
  }
  if (s.size() > 1 && s[0] == '-' && s.find_first_not_of("-0.") == std::string::npos) s.erase(0, 1);
  return s;
}

Scale::Scale(ScaleType type, double d0, double d1, double r0, double r1)
    : type_(type), d0_(d0), d1_(d1), r0_(r0), r1_(r1) {
  if (type_ == ScaleType::kLog10) {
    if (!(d0_ > 0)) d0_ = 1e-300;
    if (!(d1_ > 0)) d1_ = d0_ * 10;
  }
  if (d0_ == d1_) d1_ = d0_ + 1;
}

double Scale::operator()(double v) const {
  double t;
  if (type_ == ScaleType::kLog10) {
    if (!(v > 0)) return std::numeric_limits<double>::quiet_NaN();
    t = (std::log10(v) - std::log10(d0_)) / (std::log10(d1_) - std::log10(d0_));
  } else {
    t = (v - d0_) / (d1_ - d0_);
  }
  return r0_ + t * (r1_ - r0_);
}

std::vector<size_t> DecimateMinMax(const std::vector<double>& x, const std::vector<double>& y,
                                   size_t max_points) {
  const size_t n = std::min(x.size(), y.size());
  std::vector<size_t> finite;
  finite.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    if (std::isfinite(x[i]) && std::isfinite(y[i])) finite.push_back(i);
  }
  if (max_points < 4) max_points = 4;
  if (finite.size() <= max_points) return finite;
  const size_t buckets = max_points / 2 - 1;
  std::vector<size_t> out;
  out.reserve(max_points + 2);
  out.push_back(finite.front());
  const size_t m = finite.size();
  for (size_t b = 0; b < buckets; ++b) {
    const size_t begin = b * m / buckets, end = (b + 1) * m / buckets;
    if (begin >= end) continue;
    size_t imin = finite[begin], imax = finite[begin];
    for (size_t k = begin; k < end; ++k) {
      const size_t i = finite[k];
      if (y[i] < y[imin]) imin = i;
      if (y[i] > y[imax]) imax = i;
    }
    const size_t a = std::min(imin, imax), c = std::max(imin, imax);
    if (a != out.back()) out.push_back(a);
    if (c != out.back()) out.push_back(c);
  }
  if (finite.back() != out.back()) out.push_back(finite.back());
  return out;
}

namespace svg_parts {

// Final domain of an axis from the data extent.
std::pair<double, double> AxisDomain(const AxisOptions& axis, Extent e) {
  if (axis.min < axis.max && std::isfinite(axis.min) && std::isfinite(axis.max) &&
      (axis.type == ScaleType::kLinear || axis.min > 0)) {
    return {axis.min, axis.max};
  }
  if (axis.type == ScaleType::kLog10) {
    if (e.empty()) return {1, 10};
    double lo = std::pow(10.0, std::floor(std::log10(e.lo) + 1e-9));
    double hi = std::pow(10.0, std::ceil(std::log10(e.hi) - 1e-9));
    if (!(lo < hi)) {
      lo /= 10;
      hi *= 10;
    }
    if (!std::isfinite(lo) || !std::isfinite(hi) || lo <= 0) return {1, 10};
    return {lo, hi};
  }
  // Data of one value (a constant |ω|): drawn inside the frame, never on its edge.
  const bool flat =
      !e.empty() && !(e.hi - e.lo > std::max(std::fabs(e.lo), std::fabs(e.hi)) * 1e-12);
  const double value = e.lo;
  if (axis.include_zero) e.Add(0);
  if (e.empty()) return {0, 1};
  double lo = e.lo, hi = e.hi;
  if (!(hi - lo > std::max(std::fabs(lo), std::fabs(hi)) * 1e-12)) {
    const double pad = lo == 0 ? 1 : std::fabs(lo) * 0.1;
    lo -= pad;
    hi += pad;
  }
  double step = NiceStep(lo, hi, axis.target_ticks);
  if (step > 0 && std::isfinite(step)) {
    lo = std::floor(lo / step + 1e-9) * step;
    hi = std::ceil(hi / step - 1e-9) * step;
  }
  if (flat && std::isfinite(lo) && std::isfinite(hi) && lo < hi) {
    if (!(step > 0 && std::isfinite(step))) step = (hi - lo) / 4;
    const double room = 0.05 * (hi - lo);
    if (hi - value < room) hi += step;
    if (value - lo < room) lo -= step;
  }
  if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo < hi)) return {0, 1};
  return {lo, hi};
}

AxisTicks MakeTicks(const AxisOptions& axis, double d0, double d1) {
  AxisTicks t;
  if (axis.type == ScaleType::kLog10) {
    t.values = LogTicks(d0, d1);
    for (double v : t.values) t.labels.push_back(FormatTick(v, 0));
    const double decades = std::log10(d1 / d0);
    if (decades <= 6) {
      for (int k = static_cast<int>(std::floor(std::log10(d0))); k <= std::ceil(std::log10(d1));
           ++k) {
        for (int m = 2; m <= 9; ++m) {
          const double v = m * std::pow(10.0, k);
          if (v > d0 * (1 + 1e-9) && v < d1 * (1 - 1e-9)) t.minor.push_back(v);
        }
      }
    }
  } else {
    const double step = NiceStep(d0, d1, axis.target_ticks);
    t.values = NiceLinearTicks(d0, d1, axis.target_ticks);
    for (double v : t.values) t.labels.push_back(FormatTick(v, step));
  }
  return t;
}

}  // namespace svg_parts
}  // namespace calibd::web
