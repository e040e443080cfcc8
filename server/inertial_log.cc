#include "server/inertial_log.h"

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

Status CheckTimesIncrease(const RecordingSummary& summary, const std::string& method) {
  if (summary.t_disorder_line == 0) return Status::Ok();
  char buf[200];
  std::snprintf(
      buf, sizeof buf,
      "t must increase strictly for the %s method: t = %.9g s %s t = %.9g s of the row before",
      method.c_str(), summary.t_disorder,
      summary.t_disorder == summary.t_disorder_previous ? "repeats" : "comes after",
      summary.t_disorder_previous);
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
