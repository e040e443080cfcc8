// The stages of one IMU's calibration after its accelerometer fit (core/imu.h, steps 3-5 and the
// diagnostics), in the order Finish (core/imu.cc) runs them:
//   StartGyroscope -> CollectRotations -> FitGyroscope -> RefineJointly -> EstimateCovariance ->
//   ReportParameters -> DiagnoseStatics -> DiagnoseRotations -> CheckPlausibility
// Each reads the ImuStageInput and the ImuFit the stages before it left, and fills its part of
// the ImuResult (its warnings appended in stage order). A stage that returns a Status not ok() has
// already marked the result unusable (Fail). Internal to core/imu*.cc; thread-compatible.
#ifndef CALIBD_CORE_IMU_STAGES_H_
#define CALIBD_CORE_IMU_STAGES_H_

#include <Eigen/Core>

#include "base/status.h"
#include "core/imu.h"
#include "core/imu_internal.h"

namespace calibd::core::imu_internal {

// What every stage reads. Borrows t, imu and o: they must outlive the stages.
struct ImuStageInput {
  const VectorXd& t;       // sample times (s), one per row of imu's readings
  const ImuReadings& imu;  // the IMU's accelerometer and gyroscope readings (reading units)
  int k;                   // its index: triads 2k (accelerometer) and 2k+1 (gyroscope) of the
                           // detection in the result
  const ImuOptions& o;
};

// The nominal conversion (the options' units and nominal biases): the gyroscope's start and the
// "before" of the diagnostics.
struct NominalTriads {
  Matrix3d ma, mg;  // accel_unit · I, gyro_unit · I
  Vector3d ba, bg;  // nominal_accel_bias, nominal_gyro_bias on every axis
};
NominalTriads NominalOf(const ImuOptions& o);

// The problem and estimate as the stages refine them.
struct ImuFit {
  Problem pr;             // statics from the accelerometer fit; rotations, weights and the
                          // active unknowns set by the stages
  State x;                // the current estimate
  Vector3d sg;            // gyroscope noise σ per axis (reading units)
  bool max_iter = false;  // some Levenberg-Marquardt stage stopped at max_iterations
};

// From the accelerometer fit: the problem over t and the gyroscope, the gyroscope noise (given or
// pooled within statics) and the gyroscope start (nominal unit, bias the mean over statics).
// Fills accel_iterations, accel_noise and gyro_noise.
ImuFit StartGyroscope(const ImuStageInput& in, AccelFit accel, ImuResult* res);

// The rotations between consecutive statics (one diagnostic each; those without gaps or
// saturation join the problem); fails with too few for the gyroscope model.
Status CollectRotations(const ImuStageInput& in, ImuFit* fit, ImuResult* res);

// Step 3: M_g (and b_g for GyroBiasModel::kEstimate) from the rotations, the accelerometer and
// the directions held. Fills gyro_iterations and cost.
Status FitGyroscope(const ImuStageInput& in, const NominalTriads& nominal, ImuFit* fit,
                    ImuResult* res);

// Step 4: every unknown against every residual (the problem set up even when
// options.joint_refinement is off, for the uncertainty). Fills joint_iterations and cost.
Status RefineJointly(const ImuStageInput& in, ImuFit* fit, ImuResult* res);

// Step 5: the covariance of the 21 reported quantities: the CRB (inverse Fisher information,
// directions marginalised), *crb_sd its standard deviations; degrees_of_freedom, chi2_per_dof,
// uncertainty_basis, crb_scale and the primary covariance (the CRB × crb_scale²), with a warning
// when the primary is not the CRB.
Status EstimateCovariance(const ImuStageInput& in, const ImuFit& fit, ImuResult* res,
                          VectorXd* crb_sd);

// The accelerometer and gyroscope triads of x with their primary σ (crb_sd × crb_scale) and the
// CRB's in accelerometer_crb / gyroscope_crb.
void ReportParameters(const State& x, const VectorXd& crb_sd, ImuResult* res);

// One diagnostic per static (gravity norm before and after) and their RMS.
void DiagnoseStatics(const ImuStageInput& in, const NominalTriads& nominal, const State& x,
                     ImuResult* res);

// The rotations' direction errors before and after and their RMS, the coverage, and the warnings
// on coverage, number of statics and χ². Polls options.stop per rotation.
Status DiagnoseRotations(const ImuStageInput& in, const NominalTriads& nominal, const State& x,
                         ImuResult* res);

// Refuses scale factors and direction errors beyond the options' limits; else marks the result
// usable with its termination.
Status CheckPlausibility(const ImuStageInput& in, bool max_iter, ImuResult* res);

}  // namespace calibd::core::imu_internal

#endif  // CALIBD_CORE_IMU_STAGES_H_
