// The stages of CalibrateArrayFull (core/array_full.h), in the order it runs them, and the state
// they share. Internal to core/array_full*.cc.
#ifndef CALIBD_CORE_ARRAY_FULL_FIT_H_
#define CALIBD_CORE_ARRAY_FULL_FIT_H_

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/array_full.h"
#include "core/array_full_model.h"
#include "core/block_lm.h"

namespace calibd::core::array_full_model {

// What the stages of CalibrateArrayFull share, in the order the stages fill it.
struct FullFit {
  FullFit(const ArrayFullProblem& p, const ArrayFullOptions& o, ArrayFullResult* r)
      : problem(p), options(o), res(*r) {}
  const ArrayFullProblem& problem;
  const ArrayFullOptions& options;
  ArrayFullResult& res;
  int K = 0;                    // triads
  int64_t N = 0;                // samples of the log
  int threads = 1;              // of the parallel numerics
  FullData d;                   // statics (FindStatics) and dynamic samples (SelectDynamicSamples)
  std::vector<char> in_static;  // N: the sample lies in a static (FindStatics)
  double sigma_a = 0, sigma_g = 0;    // the noise the statics are weighted by (FindStatics)
  Eigen::Matrix3Xd s_dir;             // 3 x J: gravity in the statics (StartAccelerometers)
  std::vector<ArrayFullTriad> start;  // K: the start (StartAccelerometers, StartPositions)
  Eigen::Matrix<double, 10, Eigen::Dynamic> x;  // per block: the start (StartMotion), then the LM's
  Eigen::MatrixXd E;                            // gauge basis of the parameters
  Eigen::VectorXd theta;                        // 27 K parameters: the start, then the LM's
  BlockLmSummary summary;                       // the first solve (SolveJoint)
  BlockLmSummary final_summary;                 // the last (re)solve (SolveJoint)
  std::vector<TriadParams> ctx;                 // theta unpacked after the LM (SolveJoint)

  Status NotDeterminable(Reason reason, const std::string& m) {
    res.usable = false;
    res.reason = m;
    return Status::NotDeterminable(reason, m);
  }
  Status Stopped(const std::string& stage) {
    res.usable = false;
    res.termination = BlockLmTermination::kUserStopped;
    const Status s = StoppedStatus(*options.stop, "array (full model): " + stage);
    res.reason = s.message();
    return s;
  }
};

// The statics, their means and the noise levels the fit weights by.
Status FindStatics(FullFit* f);

// Every sample outside the statics, without saturated readings.
Status SelectDynamicSamples(FullFit* f);

// The start of the accelerometers: the ellipsoid fit of the reference triad's static means gives
// gravity in every static; the other triads follow by linear least squares.
Status StartAccelerometers(FullFit* f);

// The start of the positions: the positions-only fit (core/array.h) on the readings corrected by
// the start of the sensors; the nominal positions when it fails.
Status StartPositions(FullFit* f);

// The start of the motion per sample given the start (omega from the gyroscopes, omega_dot and s
// by linear least squares on the corrected accelerometers); the statics' gravity directions.
void StartMotion(FullFit* f);

// Rotation excitation, on the start's motion (omega: the mean of the bias-corrected gyroscopes),
// before the solver spends time on an undetermined problem.
Status CheckRotationExcitation(FullFit* f);

// The joint maximum-likelihood fit by block LM from the start; with dynamic_weighting "residual",
// solved again twice with the dynamic samples weighted by their own residual level.
Status SolveJoint(FullFit* f, const FullProblem& fp, BlockLm<FullProblem>& lm);

// Residuals per triad and kind, chi^2 per degree of freedom.
void ComputeResiduals(FullFit* f, const FullProblem& fp);

// Sampling-time offsets (a diagnostic of the model's main misfit on real hardware): if
// IMU k samples at t + delta_k, its gyroscope residual is ~ delta_k T_g,k omega_dot. Least
// squares per IMU, made relative to their mean (a common offset is absorbed by omega).
void EstimateSamplingTimeOffsets(FullFit* f);

// The Fisher information, its null directions (named), and the Cramér-Rao bound.
Status ComputeCramerRaoBound(FullFit* f, BlockLm<FullProblem>& lm);

// The residual-aware (sandwich) covariance when the residuals exceed the noise.
Status ComputeResidualAwareCovariance(FullFit* f, const FullProblem& fp);

}  // namespace calibd::core::array_full_model

#endif  // CALIBD_CORE_ARRAY_FULL_FIT_H_
