// The suggested protocol of an imu plan (SPEC §10, issue #27 item 1): the D-optimal design over
// the candidate orientations and its stopping point (methods/imu/imu_plan.cc explains both).
#ifndef CALIBD_METHODS_IMU_IMU_PLAN_H_
#define CALIBD_METHODS_IMU_IMU_PLAN_H_

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "methods/acceptance.h"
#include "methods/plan.h"

namespace calibd::server {

// The bounds of the suggestion's work: at most 1 + ⌈log2(max_positions − 8)⌉ runs of the method,
// each on a simulated log of at most max_samples samples.
struct ImuSuggestOptions {
  int max_positions = 24;    // in [9, PlanProtocol::kMaxPositions]: the longest suggestion
  double margin = 0.1;       // in [0, 1): the σ limits are met by this fraction (the plan's σ is
                             // within Monte-Carlo resolution of a recording's, not exact)
  double max_samples = 5e5;  // > 0: fewer positions when a log of max_positions has more
  bool IsValid(std::string* error) const;
};

// The linearised information of an imu protocol at nominal values, up to the noise scale of each
// block (a constant per block for equal statics and rotations): accelerometer, from |a| = g at
// each static u_j: features [u; u_x², u_y², u_z²; u_x u_y, u_x u_z, u_y u_z] for b_a, K_a and T_a's
// three angles; gyroscope, from the gravity direction after each shortest rotation φ_j between
// consecutive statics (methods/plan.h ProtocolRotations): [u_j]× J_r(φ_j) ∂φ/∂vec(M_g), M_g =
// T_g K_g row-major.
struct ImuDesignInformation {
  Eigen::Matrix<double, 9, 9> accel;
  Eigen::Matrix<double, 9, 9> gyro;
};
ImuDesignInformation ImuDesign(const std::vector<Eigen::Vector3d>& up);
// log det(accel + 1e-6 I) + log det(gyro + 1e-6 I): the D-optimal criterion of the suggestion.
double ImuDesignCriterion(const ImuDesignInformation& info);
// The first `positions` orientations of the greedy D-optimal sequence (starts at +z).
std::vector<const PlanCandidate*> ImuGreedySequence(int positions);
// The "suggested" object of the plan (keys: design, rotations, margin, orientations,
// meets_limits, unmet, uncertainty, fewer {positions, unmet}, predictions). `options` valid.
nlohmann::json SuggestImu(const nlohmann::json& config, const PlanProtocol& protocol,
                          const AcceptanceLimits& limits, const ImuSuggestOptions& options);

}  // namespace calibd::server

#endif  // CALIBD_METHODS_IMU_IMU_PLAN_H_
