#include "formats/inertial_log.h"

#include <charconv>
#include <cmath>
#include <cstdio>

#include "core/array_simulation.h"

namespace calibd::server {

using nlohmann::json;

namespace {

Status ReadUnit(const json& config, const char* key, double si_named, const char* si_name,
                double alt_value, const char* alt_name, double* value, std::string* text) {
  auto it = config.find(key);
  if (it == config.end() || it->is_null()) return Status::Ok();
  const std::string help = std::string("must be \"") + si_name + "\", \"" + alt_name +
                           "\" or a number > 0 (" + si_name + " per reading unit)";
  if (it->is_string()) {
    const std::string& s = it->get_ref<const std::string&>();
    if (s == si_name) {
      *value = si_named;
    } else if (s == alt_name) {
      *value = alt_value;
    } else {
      return Status::InvalidInput(std::string("'") + key + "' " + help + ", not \"" +
                                  s.substr(0, 40) + "\"")
          .WithField(key);
    }
    *text = s;
    return Status::Ok();
  }
  if (it->is_number() && std::isfinite(it->get<double>()) && it->get<double>() > 0) {
    *value = it->get<double>();
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.9g", *value);
    *text = buf;
    return Status::Ok();
  }
  return Status::InvalidInput(std::string("'") + key + "' " + help).WithField(key);
}

}  // namespace

Status ParseInertialUnits(const json& config, InertialUnits* units) {
  *units = InertialUnits();
  Status s =
      ReadUnit(config, "accel_unit", 1.0, "m/s^2", 9.80665, "g", &units->accel, &units->accel_text);
  if (!s.ok()) return s;
  return ReadUnit(config, "gyro_unit", 1.0, "rad/s", core::kDegree, "deg/s", &units->gyro,
                  &units->gyro_text);
}

Status ParseTimeUnit(const json& config, TimeUnit* unit, bool* given) {
  *unit = TimeUnit::kSeconds;
  *given = false;
  if (!config.is_object()) return Status::Ok();
  auto it = config.find("time_unit");
  if (it == config.end()) return Status::Ok();
  if (it->is_string() && TimeUnitFromName(it->get_ref<const std::string&>(), unit)) {
    *given = true;
    return Status::Ok();
  }
  return Status::InvalidInput(
             "'time_unit' (the unit of the time column t) must be \"s\", \"ms\", \"us\" or "
             "\"ns\", not " +
             it->dump(-1, ' ', false, json::error_handler_t::replace).substr(0, 40))
      .WithField("time_unit");
}

namespace {

const char* LongUnitName(TimeUnit unit) {
  switch (unit) {
    case TimeUnit::kSeconds:
      return "seconds";
    case TimeUnit::kMilliseconds:
      return "milliseconds";
    case TimeUnit::kMicroseconds:
      return "microseconds";
    case TimeUnit::kNanoseconds:
      return "nanoseconds";
  }
  return "seconds";
}

std::string G(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

}  // namespace

Status CheckTimeUnit(const RecordingSummary& summary, const std::string& file_name) {
  if (summary.t_column == 0 || summary.t_first_line == 0) return Status::Ok();
  const double step = summary.t_median_step;  // seconds, if the log is in seconds
  const double first = std::fabs(summary.t_first);
  // (A relative margin for the decimal rounding of the steps: a 10 kHz log in ms steps by 0.1.)
  const bool slow = step >= kMaxPlausibleStep * (1 - 1e-9);
  const bool large = first >= kMaxPlausibleSeconds;
  if (!slow && !large) return Status::Ok();
  // The likely unit: the sample rate nearest 100 Hz (log scale) among the units that bring the
  // first value below kMaxPlausibleSeconds; by the first value alone when the step says nothing.
  TimeUnit best = TimeUnit::kNanoseconds;
  double best_score = HUGE_VAL;
  for (TimeUnit u : {TimeUnit::kMilliseconds, TimeUnit::kMicroseconds, TimeUnit::kNanoseconds}) {
    const double scale = std::pow(10.0, TimeUnitDigits(u));
    if (first / scale >= kMaxPlausibleSeconds) continue;
    const double score = step > 0 ? std::fabs(std::log10(scale / step) - 2.0)
                                  : std::fabs(std::log10(std::max(first / scale, 1.0)) - 9.2);
    if (score < best_score) {
      best_score = score;
      best = u;
    }
  }
  const double scale = std::pow(10.0, TimeUnitDigits(best));
  std::string why;
  if (large) {
    why = "its first value " + G(summary.t_first) + " is too large for seconds (at least " +
          G(kMaxPlausibleSeconds) + ", past the year 5000)";
  }
  if (slow) {
    if (!why.empty()) why += ", and ";
    why += "its median step " + G(step) + " would mean one sample every " + G(step) + " s (" +
           G(1 / step) + " Hz)";
  }
  std::string likely = std::string("it is most likely in ") + LongUnitName(best);
  if (step > 0) {
    likely += " (" + G(scale / step) + " Hz)";
  } else if (large) {
    likely += " (starting at " + G(summary.t_first / scale) + " s)";
  }
  std::string message = "the time column 't' does not look like seconds: " + why + "; " + likely +
                        ": set the config key time_unit to \"" + TimeUnitName(best) + "\"";
  if (!large) message += " (or to \"s\" if the log really is sampled that slowly)";
  return Status::InvalidInput(Reason::kImplausibleTimeUnit, message)
      .WithFile(file_name)
      .WithLocation(summary.t_first_line, summary.t_column)
      .WithField("time_unit");
}

Status CheckTimesIncrease(const RecordingSummary& summary, const std::string& method) {
  return CheckTimesIncrease(summary, method, summary.time_unit);
}

Status CheckTimesIncrease(const RecordingSummary& summary, const std::string& method,
                          TimeUnit unit) {
  if (summary.t_disorder_line == 0) return Status::Ok();
  // Shortest round-trip form: "0.005", and every digit of an epoch stamp.
  auto shortest = [](double v) {
    char text[40];
    const auto r = std::to_chars(text, text + sizeof text, v);
    return std::string(text, r.ptr);
  };
  char buf[240];
  const char* u = TimeUnitName(unit);
  std::snprintf(buf, sizeof buf,
                "t must increase strictly for the %s method: t = %s %s %s t = %s %s of the row "
                "before",
                method.c_str(), shortest(summary.t_disorder).c_str(), u,
                summary.t_disorder == summary.t_disorder_previous ? "repeats" : "comes after",
                shortest(summary.t_disorder_previous).c_str(), u);
  return Status::InvalidInput(buf)
      .WithLocation(summary.t_disorder_line, summary.t_disorder_column)
      .WithField("t");
}

Status CheckLogTimes(const ArrayRecording& recording, const std::string& method,
                     const RecordingSummary* summary) {
  return CheckLogTimes(recording.t, method, summary);
}

Status CheckLogTimes(const Eigen::VectorXd& t, const std::string& method,
                     const RecordingSummary* summary) {
  if (t.size() == 0) {
    return Status::InvalidInput("the " + method +
                                " method needs the time column 't' (seconds) in the log")
        .WithField("t");
  }
  if (summary != nullptr && summary->t_disorder_line > 0) {
    return CheckTimesIncrease(*summary, method);
  }
  for (Eigen::Index i = 1; i < t.size(); ++i) {
    if (!(t[i] > t[i - 1])) {
      char buf[160];
      std::snprintf(buf, sizeof buf,
                    "t must increase strictly: sample %lld has t = %.9g s after t = %.9g s",
                    static_cast<long long>(i), t[i], t[i - 1]);
      // Data rows start on line 2 when the file has no comments; the parser's own errors carry
      // exact lines, this check names the sample.
      return Status::InvalidInput(buf).WithField("t");
    }
  }
  return Status::Ok();
}

}  // namespace calibd::server
