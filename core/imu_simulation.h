// Simulated hand-held IMU calibration logs with known truth (issue #16): a board placed in
// random static orientations joined by smooth rotations, read by an accelerometer and a
// gyroscope with the imu_tk error model of core/imu.h. For tests, benchmarks and
// `calibd simulate imu`. Deterministic for a seed (GaussianRng of core/array_simulation.h).
//
// Motion: orientation R_j (body → world, world z up) of static j is uniform on SO(3) (the first
// one after an optional initial motion). The rotation from static j to j+1 lasts
// rotation_duration T and turns about one body axis a by the angle θ of R_jᵀR_{j+1}:
//   R(τ) = R_j Exp(a θ s(τ/T)),  s(x) = x − sin(2πx)/(2π),
// so the body rate ω(τ) = a θ (1 − cos(2πτ/T)) / T starts and ends at zero with zero angular
// acceleration (smooth). The board turns about the sensor's origin: the specific force in the
// body frame is f = R(τ)ᵀ (0, 0, g) throughout (no linear acceleration).
//
// Readings (reading units): y_a = (T_a K_a)⁻¹ f + b_a + n_a,  y_g = (T_g K_g)⁻¹ ω + b_g + n_g.
#ifndef CALIBD_CORE_IMU_SIMULATION_H_
#define CALIBD_CORE_IMU_SIMULATION_H_

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/imu.h"

namespace calibd::core {

struct ImuSimulationOptions {
  int statics = 20;                // number of static orientations, >= 1
  double static_duration = 3.0;    // s per static, > 0
  double rotation_duration = 2.0;  // s per rotation, > 0
  double initial_motion = 0;       // s of rotation before the first static (0: starts static)
  double rate = 100;               // samples per second, > 0
  double gravity = 9.80665;        // |f| at rest, m/s², > 0
  double accel_noise = 0.01;       // σ per axis per sample, m/s² (SI), >= 0
  double gyro_noise = 0.002;       // σ per axis per sample, rad/s (SI), >= 0
  // Per axis, the σ of that axis over the one above (>= 0 each): unequal axes, as a real IMU's.
  Eigen::Vector3d accel_axis_ratio = Eigen::Vector3d::Ones();
  Eigen::Vector3d gyro_axis_ratio = Eigen::Vector3d::Ones();
  double accel_unit = 1;    // SI per reading unit (nominal), > 0 (e.g. 0.0024 for counts)
  double gyro_unit = 1;     // SI per reading unit (nominal), > 0
  double accel_offset = 0;  // added to every accelerometer reading, reading units
                            // (e.g. 32768 for offset-binary counts)
  double gyro_offset = 0;   // same for the gyroscope
  // Sensor errors, drawn per seed: K = unit · (1 + N(0, scale_error²)), off-diagonal T entries
  // N(0, misalignment²) (T_a upper triangular, T_g full), biases N(0, bias²) (SI, converted).
  double scale_error = 0.01;    // relative, >= 0
  double misalignment = 0.005;  // rad, >= 0
  double accel_bias = 0.1;      // m/s², >= 0
  double gyro_bias = 0.01;      // rad/s, >= 0
  double gyro_bias_drift = 0;   // rad/s per s, linear drift along a random direction, >= 0
  double accel_bias_drift = 0;  // m/s² per s, same
  // The statics' orientations R_j (body → world, world z up), in order; empty: uniform on SO(3)
  // per seed. When given, `statics` must equal their number and each rotation between statics
  // is the shortest one (angle-axis of R_jᵀR_{j+1}); consecutive equal orientations join into one
  // static. A plan's protocol (methods/plan.h) sets them.
  std::vector<Eigen::Matrix3d> orientations;
  // Per static its duration, s (> 0 each; `statics` of them), and per rotation between
  // consecutive statics its duration (`statics` − 1 of them); empty: static_duration and
  // rotation_duration for all. A recorded log's replay (the check's predicted σ) sets them.
  std::vector<double> static_durations;
  std::vector<double> rotation_durations;
  bool quantize = false;    // round readings to whole reading units (counts)
  uint64_t seed = 1;        // sensor errors and motion
  uint64_t noise_seed = 0;  // the noise stream; 0: derived from seed (set it to vary only the
                            // noise of one board and one motion, e.g. for Monte Carlo)

  bool IsValid(std::string* error) const;
};

// The truth of a simulation. Model as in core/imu.h: value = matrix (y − bias).
struct ImuTriadTruth {
  Eigen::Vector3d bias = Eigen::Vector3d::Zero();  // reading units, at t = 0 (offset included)
  Eigen::Vector3d bias_drift = Eigen::Vector3d::Zero();        // reading units per s
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();             // K diagonal, SI per reading unit
  Eigen::Matrix3d misalignment = Eigen::Matrix3d::Identity();  // T, unit diagonal
  Eigen::Matrix3d matrix = Eigen::Matrix3d::Identity();        // T K
};

struct ImuSimulation {
  Eigen::VectorXd t;       // N sample times, s (k / rate)
  Eigen::MatrixX3d accel;  // N×3 accelerometer readings, reading units
  Eigen::MatrixX3d gyro;   // N×3 gyroscope readings, reading units
  ImuTriadTruth accel_truth, gyro_truth;
  std::vector<Eigen::Matrix3d> orientations;         // R_j per static (body → world)
  std::vector<std::pair<int64_t, int64_t>> statics;  // true [first, last] sample of each static
};

// kInvalidInput: options not valid (message names the option).
Status SimulateImu(const ImuSimulationOptions& options, ImuSimulation* out);

// The protocol a recorded log followed, for a simulation that replays it (the recording check's
// predicted σ, issue #27 item 2): sets `statics`, `orientations`, `static_durations` and
// `rotation_durations` of *sim from the statics of `detection` (IMU `k`: triads 2k and 2k + 1 of
// the detection, readings `imu`) and leaves the other options as they are. Each static's duration
// is its extent's (the run the detection grew, which it trims again by half a window at each end
// in the replay) plus one sample period, each rotation's the time between two extents.
// Orientations: R_0 is the shortest rotation turning the first static's up direction (its mean
// specific force read with the nominal conversion: y − nominal bias) to world z (its heading is
// arbitrary; no σ depends on it); R_{j+1} = C R_j ΔR_j with ΔR_j the nominal gyroscope (gyro_unit
// (y − b_j), b_j the mean of the two statics' gyroscope means) integrated between the statics, and
// C the least rotation that makes static j + 1's up direction the measured one (the accelerometer's
// information is then the log's exactly; the gyroscope's up to the path, which the simulation
// replaces by the shortest rotation). kNotDeterminable with fewer than 2 statics.
Status ReplayImuProtocol(const Eigen::VectorXd& t, const ImuReadings& imu,
                         const StaticDetection& detection, int k, const ImuOptions& options,
                         ImuSimulationOptions* sim);

}  // namespace calibd::core

#endif  // CALIBD_CORE_IMU_SIMULATION_H_
