// Simulated recordings for the full array model (core/array_full.h, SPEC §7 `model: full`):
// per-triad accelerometer and gyroscope errors of realistic size, a static phase (the board at
// rest in random orientations, one after the other) and a dynamic phase, for tests, benchmarks
// and `calibd simulate array --model full`.
//
// The truth is drawn inside the model's gauges, so an estimate compares to it directly: the
// reference triad sits at its nominal position, its accelerometer T is upper triangular, and the
// gyroscope T are scaled so that sum_k trace T_g,k = 3K.
// Deterministic for a seed on every platform (GaussianRng of core/array_simulation.h).
#ifndef CALIBD_CORE_ARRAY_FULL_SIMULATION_H_
#define CALIBD_CORE_ARRAY_FULL_SIMULATION_H_

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/array_full.h"
#include "core/array_simulation.h"

namespace calibd::core {

struct ArrayFullSimulationOptions {
  Eigen::Matrix3Xd nominal_positions;  // 3 x K (K >= 3), metres; e.g. Mimu4444NominalPositions()
  int reference = 0;
  double rate = 100;                       // Hz, > 0
  int statics = 20;                        // static orientations, >= 0
  double static_duration = 1.0;            // s each, > 0
  int64_t dynamic_samples = 400;           // >= 0
  double omega_norm = 600 * kDegree;       // |omega| of every dynamic sample, rad/s
  double omega_dot_norm = 3000 * kDegree;  // |omega_dot|, rad/s^2
  double specific_force_norm = 9.81;       // |s| of the dynamic samples, m/s^2
  // The direction of omega is uniform on the sphere, then scaled per body axis by these weights
  // and renormalised to omega_norm (e.g. (1, 1, 0): no rotation about z). Not all zero.
  Eigen::Vector3d omega_axes = Eigen::Vector3d::Ones();
  // Rotation about this one body axis only (finite, not zero; normalised): omega = ±omega_norm
  // axis and omega_dot = ±omega_dot_norm axis, signs random (omega_axes ignored). Unset: as above.
  std::optional<Eigen::Vector3d> rotation_axis;
  // The statics' "up" directions in the body frame (each finite, not zero; normalised): static j
  // reads s_j = gravity u_j, in this order; `statics` is then ignored. Empty: `statics` random
  // directions.
  std::vector<Eigen::Vector3d> static_directions;
  double accel_noise = 0.04;            // sigma_a, m/s^2, >= 0
  double gyro_noise = 0.2 * kDegree;    // sigma_g, rad/s, >= 0
  double gain_error = 0.01;             // sigma of every relative gain error
  double misalignment = 0.01;           // sigma of every off-diagonal T entry, rad
  double accel_bias = 0.1;              // sigma of every accelerometer bias, m/s^2
  double gyro_bias = 1 * kDegree;       // sigma of every gyroscope bias, rad/s
  double position_perturbation = 1e-4;  // sigma of true - nominal (not the reference), m
  double gravity = 9.80665;             // |s| of the statics
  uint64_t seed = 1;

  bool IsValid(std::string* error) const;
};

struct ArrayFullSimulation {
  ArrayFullProblem problem;           // t, accel, gyro, nominal positions, reference
  std::vector<ArrayFullTriad> truth;  // K, in the gauges
  Eigen::VectorXd truth_theta;        // 27K, PackArrayFullTriad per triad
  // Per sample, the true motion (omega, omega_dot, s): rad/s, rad/s², m/s² (a static's s is its
  // gravity reaction, omega and omega_dot zero). 9 x N.
  Eigen::Matrix<double, 9, Eigen::Dynamic> motion;
  int64_t static_samples_per_orientation = 0;
};

// The 8 nominal positions of a MIMU4444-like board (the public recordings' IMU_positions.csv):
// x, y = +-9.45 mm, z = +1 mm (top) / -1 mm (underside), IMUs 1..8 in the file's order.
Eigen::Matrix3Xd Mimu4444NominalPositions();

// Draws, in order: the triads' errors (per triad: T_a gains and off-diagonals, b_a, T_g gains
// and off-diagonals, b_g, position perturbation), then the static orientations (unless given),
// then per static sample the noise, then per dynamic sample the directions (or with
// rotation_axis the signs) of omega, omega_dot, then s and the noise.
// kInvalidInput when the options are not valid.
Status SimulateArrayFull(const ArrayFullSimulationOptions& options, ArrayFullSimulation* out);

}  // namespace calibd::core

#endif  // CALIBD_CORE_ARRAY_FULL_SIMULATION_H_
