// Representations of a stored calibration for production tooling (GET .../calibration?format=):
// the result JSON as stored, CSV (one row per sensor / triad), and a C++ header with the
// parameters as constexpr arrays.
#ifndef CALIBD_SERVER_EXPORTS_H_
#define CALIBD_SERVER_EXPORTS_H_

#include <nlohmann/json.hpp>
#include <string>

#include "core/status.h"

namespace calibd::server {

// Who and when, for the header comment of the exports.
struct ExportContext {
  int64_t job_id = 0;
  std::string device;
  std::string method;
  std::string finished_at;  // ISO-8601
};

// pca: name,scale,scale_std,axis_*,axis_std_rad,bias,bias_std,sensitivity_*;
// array: name,x,y,z,offset_x,offset_y,offset_z,std_x,std_y,std_z. Full double precision.
// kInternal if the result lacks the SPEC keys (a stored result always has them).
Status ResultToCsv(const nlohmann::json& result, std::string* out);
// Kalibr's imu.yaml (accelerometer_/gyroscope_noise_density and _random_walk, the largest over
// the axes, update_rate) of a noise result; for an imu result, OpenVINS's kalibr_imu_chain.yaml
// (server/openvins_yaml.h). kInvalidInput for other methods; kNotDeterminable when a figure is
// null (the log could not show it).
Status ResultToKalibrYaml(const nlohmann::json& result, const ExportContext& context,
                          std::string* out);

// A self-contained C++17 header: `namespace calibd_calibration { constexpr ... }`, with the job
// id, date and device in a comment. Strings from users are sanitised for comments and escaped in
// string literals.
Status ResultToHeader(const nlohmann::json& result, const ExportContext& context, std::string* out);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_EXPORTS_H_
