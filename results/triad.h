// The per-IMU sensor blocks that `imu` and `array` with model full share (SPEC §7):
// parameters.imus[] = {"name", "accelerometer": SensorTriad, "gyroscope": SensorTriad, ...} and
// uncertainty.imus[] = {"name", "accelerometer": SensorTriadStd, "gyroscope": SensorTriadStd, ...}.
// Each method's result (methods/imu/imu_result.h, methods/array/array_result.h) holds these and
// adds its own members (array full: position, position_std); the judges (methods/acceptance.h
// JudgeImuTriads) and the drift tables read them typed.
#ifndef CALIBD_RESULTS_TRIAD_H_
#define CALIBD_RESULTS_TRIAD_H_

#include <Eigen/Core>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>

#include "results/json_reader.h"

namespace calibd::results {

// One triad's calibration: y = bias + (matrix)^-1 u, i.e. u = matrix (y − bias).
struct SensorTriad {
  Eigen::Vector3d bias = Eigen::Vector3d::Zero();              // reading units
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();             // K's diagonal, SI per reading unit
  Eigen::Matrix3d misalignment = Eigen::Matrix3d::Identity();  // T
  Eigen::Matrix3d matrix = Eigen::Matrix3d::Identity();        // T·K: bias-free reading -> SI
};

// One standard deviation of each entry (NaN: undefined, written as null).
struct SensorTriadStd {
  Eigen::Vector3d bias_std = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  Eigen::Vector3d scale_std = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  // radians, for the entries of T
  Eigen::Matrix3d misalignment_std =
      Eigen::Matrix3d::Constant(std::numeric_limits<double>::quiet_NaN());
};

// {"bias", "scale", "misalignment", "matrix"} / {"bias_std", "scale_std", "misalignment_std"}.
nlohmann::json ToJson(const SensorTriad& t);
nlohmann::json ToJson(const SensorTriadStd& t);
// Reads member `key` of `r` (an object of the shape above).
void ReadTriad(const JsonReader& r, const char* key, SensorTriad* out);
void ReadTriad(const JsonReader& r, const char* key, SensorTriadStd* out);

// One IMU's two triads: the members of parameters.imus[] / uncertainty.imus[] the two methods
// share. A method's per-IMU struct holds one and adds its own members.
struct ImuTriads {
  std::string name;
  SensorTriad accelerometer;
  SensorTriad gyroscope;
};
struct ImuTriadsStd {
  std::string name;
  SensorTriadStd accelerometer;
  SensorTriadStd gyroscope;
};
// Reads "name", "accelerometer" and "gyroscope" of the object `r` (its other members are the
// method's to read).
void ReadImuTriads(const JsonReader& r, ImuTriads* out);
void ReadImuTriads(const JsonReader& r, ImuTriadsStd* out);
// Writes "name", "accelerometer" and "gyroscope" into the object *out.
void WriteImuTriads(const ImuTriads& t, nlohmann::json* out);
void WriteImuTriads(const ImuTriadsStd& t, nlohmann::json* out);

}  // namespace calibd::results

#endif  // CALIBD_RESULTS_TRIAD_H_
