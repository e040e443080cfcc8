// The `imu` result as OpenVINS reads IMU intrinsics: its kalibr_imu_chain.yaml (imu0, imu1, ...:
// `model: calibrated`, `Tw`, `R_IMUtoGYRO`, `Ta`, `R_IMUtoACC`, `Tg`, the noise densities,
// `update_rate`), written for `GET /devices/{serial}/calibration?method=imu&format=yaml`.
//
// Convention mapping. calibd: a = T_a K_a (y_a - b_a), w = T_g K_g (y_g - b_g), y in reading
// units, body frame = the accelerometer's (M_a = T_a K_a upper triangular). OpenVINS (Yang et al.,
// "Online IMU intrinsic calibration: is it necessary?", RSS 2020; ov_core's propagator):
//   a_I = R_ACCtoI D_a (a_m - b_a),   w_I = R_GYROtoI D_w (w_m - T_g a_I - b_g),
// with a_m, w_m in SI (a ROS sensor_msgs/Imu), D = T^-1 read from the file as `Ta`, `Tw`, and the
// model `calibrated` (= `kalibr`) taking D_a and D_w lower triangular, R_ACCtoI = I and
// R_GYROtoI = R_IMUtoGYRO^T free. With u the nominal SI per reading unit (accel_unit, gyro_unit),
// the SI matrices are M_a = T_a K_a / u_a and M_g = T_g K_g / u_g. A QL decomposition
// M_a = R L_a (R a rotation, L_a lower triangular with a positive diagonal) gives D_a = L_a in
// the frame I = R^T body, so Ta = L_a^-1, R_IMUtoACC = I; then R^T M_g = Q L_g gives D_w = L_g,
// Tw = L_g^-1, R_IMUtoGYRO = Q^T. Tg = 0 (calibd estimates no g-sensitivity). The frame I differs
// from calibd's body frame by the small rotation R (written in a comment; VIO extrinsics are
// calibrated against I anyway). Biases are not keys of the file (OpenVINS estimates them online);
// their SI values, u (b - n) with n the job's nominal_*_bias (offset-binary counts; 0 when not
// given), are given in comments. Noise figures: when the calibration named noise jobs
// (accel_noise/gyro_noise {"job": ID}, diagnostics.noise_model), their densities and random walks
// (the largest axis, Kalibr's units); else the densities from the static intervals' per-sample
// spread, sigma / sqrt(rate), and the random walks only as a comment saying to run a noise job
// (a hand-held log cannot show them).
#ifndef CALIBD_SERVER_OPENVINS_YAML_H_
#define CALIBD_SERVER_OPENVINS_YAML_H_

#include <nlohmann/json.hpp>
#include <string>

#include "base/status.h"
#include "methods/exports.h"

namespace calibd::server {

// kInternal when the result lacks the keys of an imu result; kNotDeterminable when a matrix is
// singular or mirrors (det <= 0) or the result predates the units being stored (rerun the job).
Status ImuResultToOpenVinsYaml(const nlohmann::json& result, const ExportContext& context,
                               std::string* out);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_OPENVINS_YAML_H_
