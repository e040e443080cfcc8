// The stages of one calibration by CalibratePca (core/pca.h), in the order CalibrateScaled
// (core/pca.cc) runs them on readings already divided by a power-of-two unit:
//   ValidateProblem -> CheckBudget -> FitModel -> Diagnose -> EstimateUncertainty ->
//   ExpressInFrame -> ReportSensors -> AssessCoverage -> CheckFinite
// Each reads the PcaSetup and the outputs of the stages before it and fills its part of the
// PcaResult (and appends its warnings, so their order is the order of the stages). A stage that
// returns a Status not ok() has already marked the result unusable (Fail). Internal to
// core/pca*.cc; thread-compatible (no shared state).
#ifndef CALIBD_CORE_PCA_STAGES_H_
#define CALIBD_CORE_PCA_STAGES_H_

#include <Eigen/Core>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/pca.h"
#include "core/pca_internal.h"

namespace calibd::core::pca_internal {

// The problem as every stage sees it. Borrows problem and options: both must outlive the setup.
struct PcaSetup {
  PcaSetup(const PcaProblem& problem, const PcaOptions& options, double unit);

  const PcaProblem& problem;  // readings (m×n) and biases in units of `unit`
  const PcaOptions& options;  // noise_std in units of `unit`
  double unit;                // the power of two the readings were divided by (messages quote
                              // readings multiplied back by it)
  int d;                      // dimension
  int m;                      // sensors
  int n;                      // positions
  bool affine;                // biases estimated (BiasModel::kEstimate)
  int p;                      // parameters per sensor: d, or d + 1 with biases
  double c;                   // field magnitude, 1 when unknown
};

// The stopped status of `stage` ("closed form", ...), through Fail.
Status Stopped(const PcaSetup& setup, const std::string& stage, PcaResult* result);

// Fills the result's description of the problem (dimension, bias_model, positions,
// min_positions, magnitude*, noise_std_given) and checks the readings, names, labels, removed
// biases and nominal against the sizes and the minimum numbers of sensors and positions.
Status ValidateProblem(const PcaSetup& setup, PcaResult* result);

// Fills cost_estimate and refuses a problem over max_memory_bytes or max_flops, before any work.
Status CheckBudget(const PcaSetup& setup, PcaResult* result);

// The closed form, then (options.refine) the maximum-likelihood refinement: *fit with positions
// on the sphere; fills cost_closed_form, cost, refine_iterations, refined and the rank
// diagnostics. Polls options.stop between the steps.
Status FitModel(const PcaSetup& setup, PcaResult* result, Fit* fit);

// Positions whose field magnitude disagrees far more than the others' (Diagnose finds them; the
// warning is pushed by AssessCoverage, once the coverage is known).
struct OutlierReport {
  std::string warning;  // the start of the warning; empty: no outlier
  int count = 0;        // outlying positions
};

// Residuals, magnitude errors, degrees of freedom and noise level at the fit; warns about the
// noise level and a small rank gap.
OutlierReport Diagnose(const PcaSetup& setup, const Fit& fit, PcaResult* result);

// The p×p covariance block of each sensor's [a_i; b_i] at the result's noise level, frame-free
// (*cov_blocks empty when the noise level or the information leaves them undefined, with a
// warning for the latter). Not ok() only when options.stop asked.
Status EstimateUncertainty(const PcaSetup& setup, const Fit& fit, PcaResult* result,
                           std::vector<Eigen::MatrixXd>* cov_blocks);

// Rotates the fit into the reported frame (nominal or canonical): fills frame, reflection, a, v,
// b (with the removed bias added back). Returns the frame's description for the advice.
std::string ExpressInFrame(const PcaSetup& setup, const Fit& fit, PcaResult* result);

// One PcaSensorEstimate per sensor (scale, axis, bias and their σ from cov_blocks, in the
// result's frame), with the warnings on the magnitude, the nominal axes and undefined σ.
void ReportSensors(const PcaSetup& setup, const Fit& fit,
                   const std::vector<Eigen::MatrixXd>& cov_blocks, PcaResult* result);

// The σ convention (SPEC §7) on the σ of ReportSensors: keeps the white-noise bound in each
// sensor's `crb` when noise_std is given, and scales the σ by √(χ²/dof) where the residuals exceed
// it (uncertainty_basis "chi2_scaled", with a warning naming the factor), else leaves them ("crb").
void ApplySigmaBasis(const PcaSetup& setup, PcaResult* result);

// The coverage of the sphere in the result's frame (frame_note from ExpressInFrame), with the
// coverage and outlier warnings.
void AssessCoverage(const PcaSetup& setup, const std::string& frame_note,
                    const OutlierReport& outliers, PcaResult* result);

// A usable result has finite parameters and every sensor a defined axis: sets usable, or fails.
Status CheckFinite(PcaResult* result);

}  // namespace calibd::core::pca_internal

#endif  // CALIBD_CORE_PCA_STAGES_H_
