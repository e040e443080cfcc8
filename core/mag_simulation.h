// Simulated hand-held magnetometer logs for the `mag` method (core/mag.h) with a known truth: the
// device is turned by hand from one random orientation to the next (a smooth 1 − cos profile per
// turn), holding still in some of them; an accelerometer gives the statics' gravity.
//
//   y_i = h + P⁻¹ Rᵀ (Q_iᵀ (B + δB_i)) + ε_i,   f_i = Q_iᵀ (0, 0, −g) + ν_i
//
// Q_i the body-to-earth rotation (NED), B = F (cos δ, 0, sin δ) the Earth's field with dip δ, δB_i
// a disturbance fixed in space during its span (iron near the bench), ε_i white (or AR(1), same
// marginal σ; plus a random walk of the hard iron when asked) and ν_i white. Deterministic per seed
// (core/array_simulation.h GaussianRng).
#ifndef CALIBD_CORE_MAG_SIMULATION_H_
#define CALIBD_CORE_MAG_SIMULATION_H_

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "base/status.h"
#include "core/mag.h"

namespace calibd::core {

struct MagDisturbance {
  double start = 0, end = 0;                        // s
  Eigen::Vector3d field = Eigen::Vector3d::Zero();  // µT, earth frame, added to B
};

struct MagSimulationOptions {
  uint64_t seed = 1;
  double rate = 100;          // Hz, > 0
  int turns = 80;             // orientations visited after the first, >= 1
  double turn_seconds = 1.5;  // s per turn, > 0
  int statics = 12;           // turns after which the device holds still, 0..turns
  double static_seconds = 2;  // s per hold, > 0
  double field = 50;          // F, µT, > 0
  double dip = 60;            // δ, degrees, in (−90, 90)
  Eigen::Vector3d hard_iron = Eigen::Vector3d(12, -7, 25);  // h, µT
  // P (symmetric positive definite, per reading unit; readings are in µT when P is I).
  Eigen::Matrix3d soft_iron = (Eigen::Matrix3d() << 1.08, 0.03, -0.02,  //
                               0.03, 0.95, 0.04,                        //
                               -0.02, 0.04, 1.02)
                                  .finished();
  Eigen::Vector3d alignment = Eigen::Vector3d(0.02, -0.03, 0.015);  // R = exp([φ]×), rad
  double noise = 0.3;         // σ of ε per axis, reading units, >= 0
  double ar1 = 0;             // AR(1) coefficient of ε, in [0, 1): 0 white
  double accel_noise = 0.02;  // σ of ν per axis, m/s², >= 0
  // A hard iron that wanders: a random walk added to h, this many reading units per √s per axis
  // (the offset drift of a warming or 1/f sensor), its mean over the log removed so that the
  // truth `hard_iron` is the log's average offset. >= 0; 0: a constant hard iron.
  double hard_iron_walk = 0;
  // Turn only about the vertical (yaw), the board flat: the field sweeps a cone (poor coverage).
  bool yaw_only = false;
  // Otherwise: orientations with the board's z axis within this angle of down (degrees; 180: any
  // orientation), yaw uniform: below 90° the device is never turned over.
  double max_tilt = 180;
  std::vector<MagDisturbance> disturbances;
  // A given protocol instead of random turns (the plan, methods/mag/mag_plan.cc): the body's
  // attitudes Q_j (body → NED), held static_seconds each in order, joined by turns of
  // turn_seconds (the same 1 − cos slerp); turns, statics, yaw_only and max_tilt are then
  // ignored. Each entry a rotation matrix. Empty: random orientations.
  std::vector<Eigen::Matrix3d> orientations;
};

struct MagSimulation {
  MagProblem problem;      // t, y and the statics (their true sample ranges, 0.2 s trimmed)
  Eigen::Matrix3Xd accel;  // f_i, m/s²
  // The truth in the result's terms (core/mag.h) for a fit told the field F: hard_iron h,
  // soft_iron_symmetric P, soft_iron R P (µT per reading unit), alignment R, dip δ (degrees).
  Eigen::Vector3d hard_iron;
  Eigen::Matrix3d soft_iron_symmetric;
  Eigen::Matrix3d soft_iron;
  Eigen::Matrix3d alignment;
  double dip = 0;
  double field = 0;
};

// kInvalidInput naming the option out of range.
Status SimulateMag(const MagSimulationOptions& options, MagSimulation* out);

}  // namespace calibd::core

#endif  // CALIBD_CORE_MAG_SIMULATION_H_
