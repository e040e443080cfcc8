// Simulated inertial sensor arrays: the set-up of Section IV of the array paper (seed 004) and
// readings of any given motion, for tests, benchmarks and `calibd simulate array`.
//
// Deterministic for a seed on every platform: std::mt19937_64 and our own Box-Muller transform
// (std::normal_distribution is implementation-defined).
#ifndef CALIBD_CORE_ARRAY_SIMULATION_H_
#define CALIBD_CORE_ARRAY_SIMULATION_H_

#include <Eigen/Core>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/array.h"

namespace calibd::core {

inline constexpr double kDegree = 3.14159265358979323846 / 180;  // rad per degree

// Standard normal samples from mt19937_64 with the polar-free Box-Muller transform.
class GaussianRng {
 public:
  explicit GaussianRng(uint64_t seed) : engine_(seed) {}
  double Uniform();              // in [0, 1), 53 random bits
  double Normal();               // N(0, 1)
  Eigen::Vector3d UnitVector();  // uniform on the sphere
  std::mt19937_64& engine() { return engine_; }

 private:
  std::mt19937_64 engine_;
  bool has_spare_ = false;
  double spare_ = 0;
};

struct ArraySimulationOptions {
  int64_t samples = 1000;                  // N, >= 1
  double omega_norm = 2000 * kDegree;      // |omega| of every sample, rad/s, >= 0
  double omega_dot_norm = 2000 * kDegree;  // |omega_dot| of every sample, rad/s^2, >= 0
  double specific_force_norm = 9.81;       // |s| of every sample, m/s^2, >= 0
  double accel_noise = 0.04;               // sigma_a, m/s^2, >= 0 (0: noise-free)
  double gyro_noise = 0.06 * kDegree;      // sigma_g, rad/s, >= 0
  double position_perturbation = 0.001;    // sigma_r, m: true = nominal + N(0, sigma_r^2 I), >= 0
  int reference = 0;                       // this triad is not perturbed
  uint64_t seed = 1;
  // Accelerometer sensor errors of each triad k (issue #8), readings y = A_k^T f + b_k + noise
  // (AccelerometerTriadModel). Drawn from their own seed-derived stream, so the same seed gives
  // the same board whatever N or the motion, and SimulateArrayStatic sees the same errors.
  // All 0 (default): ideal triads, A_k = I, b_k = 0, and the readings are exactly as before.
  double accel_bias = 0;          // sigma of each bias component b_k,i, m/s^2, >= 0
  double accel_scale_error = 0;   // sigma of each relative scale-factor error s_k,i, >= 0
  double accel_misalignment = 0;  // sigma of each axis' small tilt toward each other axis, rad,
                                  // >= 0

  bool IsValid(std::string* error) const;
};

struct ArraySimulation {
  ArrayProblem problem;  // nominal positions, reference, accel (N x 96), gyro (N x 96)
  std::vector<std::string> gyro_names;   // "g0".."g31"
  Eigen::Matrix3Xd true_positions;       // 3 x 32
  Eigen::Matrix3Xd omega, omega_dot, s;  // 3 x N true motion
  // The true accelerometer models (K), identity and zero bias unless the options add errors.
  std::vector<AccelerometerTriadModel> accel_models;
};

// The accelerometer errors of options (K = 32 triads), deterministic for options.seed and
// independent of every other option but the three sigmas. Each triad k:
//   A_k^T = diag(1 + s_k) (I + M_k),  s_k,i ~ N(0, accel_scale_error^2),
//   M_k off-diagonal ~ N(0, accel_misalignment^2), zero diagonal,   b_k,i ~ N(0, accel_bias^2),
// then all A_k are rotated by one common rotation Q (A_k <- Q A_k) so that sum_k A_k is
// symmetric positive definite: the best orthogonal fit (Procrustes) of the accelerometer axes onto
// the nominal identity blocks is then the identity, i.e. the gyroscopes' frame. A common rotation
// between accelerometers and gyroscopes cannot be seen by a static calibration (a `pca` result in
// the nominal frame is defined by that fit) and would bias the array fit; it is outside this model.
std::vector<AccelerometerTriadModel> SimulateAccelerometerModels(
    const ArraySimulationOptions& options);

// A static multi-orientation recording of the same board (the same accelerometer errors as
// SimulateArray with these options): the field f_j = gravity * u_j, u_j uniform on the sphere,
// readings y_k,j = A_k^T f_j + b_k + N(0, noise_std^2 I). Drawn from a third seed-derived stream.
struct ArrayStaticSimulation {
  Eigen::MatrixXd readings;                     // 3K x n: rows a0_x, a0_y, a0_z, a1_x, ...
  std::vector<std::string> sensor_names;        // 3K: "a0_x", ...
  Eigen::Matrix3Xd field;                       // 3 x n, |f_j| = gravity
  std::vector<AccelerometerTriadModel> models;  // K true models
};
inline constexpr double kStandardGravity = 9.80665;  // m/s^2
// kInvalidInput: options not valid, positions < 1, noise_std < 0 or gravity <= 0 (not finite).
Status SimulateArrayStatic(const ArraySimulationOptions& options, int positions, double noise_std,
                           double gravity, ArrayStaticSimulation* out);

// The 32 nominal positions of the paper's Fig. 2 array, metres: a 4x4 grid of 6.3 mm pitch
// centred on the origin, triads 0-15 on the top (z = +1 mm) and 16-31 on the underside
// (z = -1 mm); row-major in (y, x).
Eigen::Matrix3Xd PaperArrayNominalPositions();

// The paper's Section IV simulation: directions of omega, omega_dot and s uniform on the sphere,
// norms fixed; one accelerometer and one gyroscope triad per IMU.
// Random draws, in this order: perturbations (3 per non-reference triad), then per sample the
// directions of omega, omega_dot, s, the accelerometer noise (3K) and gyro noise (3G).
Status SimulateArray(const ArraySimulationOptions& options, ArraySimulation* out);

// Readings of a given motion (3 x N each) at the given positions, with white Gaussian noise,
// G gyroscope triads: accel N x 3K, gyro N x 3G. Draws, per sample: 3K accel then 3G gyro noise.
// accel_models: optional K triad models applied before the noise (y = A^T f + b + noise).
void SimulateArrayReadings(const Eigen::Matrix3Xd& positions, const Eigen::Matrix3Xd& omega,
                           const Eigen::Matrix3Xd& omega_dot, const Eigen::Matrix3Xd& s,
                           double accel_noise, double gyro_noise, int gyro_triads, GaussianRng* rng,
                           Eigen::MatrixXd* accel, Eigen::MatrixXd* gyro,
                           const std::vector<AccelerometerTriadModel>* accel_models = nullptr);

}  // namespace calibd::core

#endif  // CALIBD_CORE_ARRAY_SIMULATION_H_
