// Inertial logs (SPEC §2 "inertial logs"): the array layout with `t` required, read by the raw-log
// methods (`noise`, and `imu` and `array` with `model: full` as they come). Reading units: config
// `accel_unit` ("m/s^2" default, "g", or a number = m/s² per reading unit, e.g. 0.00479 for
// ±16 g counts) and `gyro_unit` ("rad/s" default, "deg/s", or rad/s per reading unit).
#ifndef CALIBD_SERVER_INERTIAL_LOG_H_
#define CALIBD_SERVER_INERTIAL_LOG_H_

#include <nlohmann/json.hpp>
#include <string>

#include "base/status.h"
#include "server/recording.h"

namespace calibd::server {

struct InertialUnits {
  double accel = 1;                  // m/s² per reading unit
  double gyro = 1;                   // rad/s per reading unit
  std::string accel_text = "m/s^2";  // as configured, for reports ("g", "0.00479", ...)
  std::string gyro_text = "rad/s";
};

// Reads accel_unit and gyro_unit (absent: SI). kInvalidInput naming the key.
Status ParseInertialUnits(const nlohmann::json& config, InertialUnits* units);

// The recording's times must be present and strictly increasing. With the parser's summary,
// the first non-increasing (or repeated) t is named by its line and column in the file; without
// it, by its sample index. `method` names the method in the message.
Status CheckLogTimes(const ArrayRecording& recording, const std::string& method,
                     const RecordingSummary* summary = nullptr);
// The same for the times alone (e.g. of an ArrayRecordingFloat).
Status CheckLogTimes(const Eigen::VectorXd& t, const std::string& method,
                     const RecordingSummary* summary = nullptr);
// From the parser's summary alone (at upload, before the log is stored): kInvalidInput with the
// line and column of the first t that does not increase, else Ok.
Status CheckTimesIncrease(const RecordingSummary& summary, const std::string& method);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_INERTIAL_LOG_H_
