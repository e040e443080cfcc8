// Inertial logs (SPEC §2 "inertial logs"): the array layout with `t` required, read by the raw-log
// methods (`noise`, and `imu` and `array` with `model: full` as they come). Time unit: config
// `time_unit` (s default, ms, us, ns), applied by the parser (server/config.h PrepareParser) so
// the methods see seconds. Reading units: config
// `accel_unit` ("m/s^2" default, "g", or a number = m/s² per reading unit, e.g. 0.00479 for
// ±16 g counts) and `gyro_unit` ("rad/s" default, "deg/s", or rad/s per reading unit).
#ifndef CALIBD_SERVER_INERTIAL_LOG_H_
#define CALIBD_SERVER_INERTIAL_LOG_H_

#include <nlohmann/json.hpp>
#include <string>

#include "base/status.h"
#include "formats/recording.h"

namespace calibd::server {

struct InertialUnits {
  double accel = 1;                  // m/s² per reading unit
  double gyro = 1;                   // rad/s per reading unit
  std::string accel_text = "m/s^2";  // as configured, for reports ("g", "0.00479", ...)
  std::string gyro_text = "rad/s";
};

// Reads accel_unit and gyro_unit (absent: SI). kInvalidInput naming the key.
Status ParseInertialUnits(const nlohmann::json& config, InertialUnits* units);

// Reads config `time_unit` ("s", "ms", "us" or "ns"; SPEC §9): *unit (seconds when absent) and
// whether it was given. kInvalidInput naming the key for anything else.
Status ParseTimeUnit(const nlohmann::json& config, TimeUnit* unit, bool* given);

// The time-unit plausibility rule, for a log read without `time_unit` (so in seconds). The time
// column does not look like seconds when
//   - its median step over the first kTimeProbeRows rows (RecordingSummary::t_median_step) is at
//     least kMaxPlausibleStep seconds (10 Hz or slower: a 1 kHz log in ms has a step of 1, a
//     100 Hz log 10; no IMU calibration or noise log is sampled that slowly), or
//   - its first value is at least kMaxPlausibleSeconds (epoch ms, us or ns: 1.7e12, 1.7e15,
//     1.7e18; epoch seconds, 1.7e9, are plausible).
// Then kInvalidInput with Reason::kImplausibleTimeUnit, located at the first row's t, naming the
// unit it most likely is (of ms, us and ns, the one that puts the sample rate nearest 100 Hz on a
// log scale, among those that do not leave the first value too large for seconds), the rate
// that unit gives, and the key that fixes it (field "time_unit"). Bounded work: the summary's
// figures only. A log without `t` passes (the methods that need it say so).
inline constexpr double kMaxPlausibleStep = 0.1;      // seconds
inline constexpr double kMaxPlausibleSeconds = 1e11;  // seconds (the year 5138)
Status CheckTimeUnit(const RecordingSummary& summary, const std::string& file_name);

// The recording's times must be present and strictly increasing. With the parser's summary,
// the first non-increasing (or repeated) t is named by its line and column in the file; without
// it, by its sample index. `method` names the method in the message.
Status CheckLogTimes(const ArrayRecording& recording, const std::string& method,
                     const RecordingSummary* summary = nullptr);
// The same for the times alone (e.g. of an ArrayRecordingFloat).
Status CheckLogTimes(const Eigen::VectorXd& t, const std::string& method,
                     const RecordingSummary* summary = nullptr);
// From the parser's summary alone (at upload, before the log is stored): kInvalidInput with the
// line and column of the first t that does not increase, else Ok. The values are named in
// `unit` (the summary's own time unit in the first form).
Status CheckTimesIncrease(const RecordingSummary& summary, const std::string& method);
Status CheckTimesIncrease(const RecordingSummary& summary, const std::string& method,
                          TimeUnit unit);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_INERTIAL_LOG_H_
