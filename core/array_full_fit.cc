// The stages of CalibrateArrayFull (core/array_full_fit.h).
#include "core/array_full_fit.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <string>
#include <vector>

#include "core/array.h"
#include "core/static_detection.h"
#include "core/stop_token.h"

namespace calibd::core::array_full_model {
namespace {

std::string Fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

}  // namespace

// The statics, their means and the noise levels the fit weights by.
Status FindStatics(FullFit* f) {
  const ArrayFullProblem& problem = f->problem;
  const ArrayFullOptions& options = f->options;
  ArrayFullResult& res = f->res;
  FullData& d = f->d;
  const int K = f->K;
  std::vector<Eigen::MatrixX3d> series(2 * K);
  std::vector<TriadSeries> triads(2 * K);
  for (int k = 0; k < 2 * K; ++k) {
    const Eigen::MatrixXd& src = k < K ? problem.accel : problem.gyro;
    const int kk = k % K;
    series[k] = src.middleCols(3 * kk, 3);
    triads[k].name = (k < K ? "a" : "g") + res.names[kk];
    triads[k].kind = k < K ? TriadKind::kAccelerometer : TriadKind::kGyroscope;
    triads[k].readings = &series[k];
    if (k >= K && options.gyro_saturation) {
      triads[k].saturation_low = -*options.gyro_saturation;
      triads[k].saturation_high = *options.gyro_saturation;
    }
    if (k < K && options.accel_saturation) {
      triads[k].saturation_low = -*options.accel_saturation;
      triads[k].saturation_high = *options.accel_saturation;
    }
  }
  StaticDetection det;
  if (Status s = DetectStatics(problem.t, triads, options.statics, &det); !s.ok()) return s;
  series.clear();
  if (StopRequested(options.stop)) return f->Stopped("statics");
  d.K = K;
  d.gravity = options.gravity;
  d.J = static_cast<int64_t>(det.intervals.size());
  res.statics = d.J;
  res.static_samples = det.static_samples;
  res.static_intervals.clear();
  for (const StaticInterval& iv : det.intervals)
    res.static_intervals.push_back({iv.start, iv.end, iv.samples, 0, 0});
  if (d.J < options.min_statics)
    return f->NotDeterminable(
        Reason::kTooFewStatics,
        "the full array model needs at least " + std::to_string(options.min_statics) +
            " static orientations (the accelerometers' closed form); the log has " +
            std::to_string(d.J) +
            ": record the board at rest in many different orientations before the dynamic phase; " +
            StaticShortfall(det));
  d.static_a.resize(3 * K, d.J);
  d.static_g.resize(3 * K, d.J);
  d.static_n.resize(d.J);
  double var_a = 0, var_g = 0, var_dof = 0;
  std::vector<char>& in_static = f->in_static;
  in_static.assign(f->N, 0);
  for (int64_t j = 0; j < d.J; ++j) {
    const StaticInterval& iv = det.intervals[j];
    d.static_n(j) = static_cast<double>(iv.samples);
    for (int64_t n = iv.first; n <= iv.last; ++n) in_static[n] = 1;
    for (int k = 0; k < K; ++k) {
      d.static_a.col(j).segment<3>(3 * k) = iv.mean[k];
      d.static_g.col(j).segment<3>(3 * k) = iv.mean[K + k];
      var_a += (iv.samples - 1) * iv.std[k].squaredNorm();
      var_g += (iv.samples - 1) * iv.std[K + k].squaredNorm();
    }
    var_dof += 3.0 * K * (iv.samples - 1);
  }
  res.static_noise_accel = var_dof > 0 ? std::sqrt(var_a / var_dof) : 0;
  res.static_noise_gyro = var_dof > 0 ? std::sqrt(var_g / var_dof) : 0;
  const double sigma_a = f->sigma_a =
      options.accel_noise > 0 ? options.accel_noise : res.static_noise_accel;
  const double sigma_g = f->sigma_g =
      options.gyro_noise > 0 ? options.gyro_noise : res.static_noise_gyro;
  res.noise_estimated = !(options.accel_noise > 0 && options.gyro_noise > 0);
  res.accel_noise = sigma_a;
  res.gyro_noise = sigma_g;
  if (!(sigma_a > 0) || !(sigma_g > 0))
    return f->NotDeterminable(
        Reason::kUnknownNoise,
        "the noise levels are zero in the statics (noise-free readings?): configure accel_noise "
        "and gyro_noise");
  d.wa = 1 / sigma_a;
  d.wg = 1 / sigma_g;
  d.wa_d = d.wa / options.dynamic_noise_scale;
  d.wg_d = d.wg / options.dynamic_noise_scale;
  res.dynamic_accel_noise = 1 / d.wa_d;
  res.dynamic_gyro_noise = 1 / d.wg_d;

  return Status::Ok();
}

// Every sample outside the statics, without saturated readings.
Status SelectDynamicSamples(FullFit* f) {
  const ArrayFullProblem& problem = f->problem;
  const ArrayFullOptions& options = f->options;
  ArrayFullResult& res = f->res;
  FullData& d = f->d;
  const int K = f->K;
  const std::vector<char>& in_static = f->in_static;
  for (int64_t n = 0; n < f->N; ++n) {
    if (in_static[n]) continue;
    if ((options.gyro_saturation &&
         problem.gyro.row(n).cwiseAbs().maxCoeff() >= *options.gyro_saturation) ||
        (options.accel_saturation &&
         problem.accel.row(n).cwiseAbs().maxCoeff() >= *options.accel_saturation)) {
      ++res.samples_dropped;
      continue;
    }
    d.dyn_index.push_back(n);
  }
  d.Nd = static_cast<int64_t>(d.dyn_index.size());
  res.dynamic_samples = d.Nd;
  if (d.Nd < 10)
    return f->NotDeterminable(array_reason::kNoDynamicPhase,
                              "the full array model needs a dynamic phase (rotation) after the "
                              "statics; the log has " +
                                  std::to_string(d.Nd) + " usable samples outside the statics");
  d.ya.resize(3 * K, d.Nd);
  d.yg.resize(3 * K, d.Nd);
  for (int64_t m = 0; m < d.Nd; ++m) {
    d.ya.col(m) = problem.accel.row(d.dyn_index[m]).transpose();
    d.yg.col(m) = problem.gyro.row(d.dyn_index[m]).transpose();
  }

  return Status::Ok();
}

// The start of the accelerometers: the ellipsoid fit of the reference triad's static means gives
// gravity in every static; the other triads follow by linear least squares.
Status StartAccelerometers(FullFit* f) {
  const ArrayFullProblem& problem = f->problem;
  const ArrayFullOptions& options = f->options;
  const FullData& d = f->d;
  const int K = f->K;
  const int ref = problem.reference;
  Mat3 M_ref;
  Vec3 b_ref;
  if (!EllipsoidFit(d.static_a.middleRows(3 * ref, 3), options.gravity, &M_ref, &b_ref))
    return f->NotDeterminable(
        Reason::kPoorOrientationCoverage,
        "the static orientations do not determine the accelerometers (no ellipsoid through the "
        "reference triad's static means): record statics in orientations spread over the whole "
        "sphere (e.g. the six faces and the diagonals)");
  Eigen::Matrix3Xd& s_dir = f->s_dir;
  s_dir.resize(3, d.J);
  for (int64_t j = 0; j < d.J; ++j)
    s_dir.col(j) =
        options.gravity * (M_ref * (d.static_a.col(j).segment<3>(3 * ref) - b_ref)).normalized();
  std::vector<ArrayFullTriad>& start = f->start;
  start.resize(K);
  Eigen::MatrixXd Aj(d.J, 4);
  Aj.leftCols(3) = s_dir.transpose();
  Aj.col(3).setOnes();
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Aj);
  if (qr.rank() < 4)
    return f->NotDeterminable(Reason::kPoorOrientationCoverage,
                              "the static orientations are coplanar: record statics in "
                              "orientations spread over the whole sphere");
  const double n_static = d.static_n.sum();
  for (int k = 0; k < K; ++k) {
    if (k == ref) {
      start[k].accel_T = M_ref.inverse();
      start[k].accel_T(1, 0) = start[k].accel_T(2, 0) = start[k].accel_T(2, 1) = 0;
      start[k].accel_bias = b_ref;
    } else {
      const Eigen::MatrixXd X =
          qr.solve(Eigen::MatrixXd(d.static_a.middleRows(3 * k, 3).transpose()));
      start[k].accel_T = X.topRows(3).transpose();
      start[k].accel_bias = X.row(3).transpose();
    }
    start[k].gyro_bias = d.static_g.middleRows(3 * k, 3) * d.static_n / n_static;
    start[k].gyro_T.setIdentity();
    start[k].position = problem.nominal_positions.col(k);
  }

  return Status::Ok();
}

// The start of the positions: the positions-only fit (core/array.h) on the readings corrected by
// the start of the sensors; the nominal positions when it fails.
Status StartPositions(FullFit* f) {
  const ArrayFullProblem& problem = f->problem;
  const ArrayFullOptions& options = f->options;
  ArrayFullResult& res = f->res;
  const FullData& d = f->d;
  const int K = f->K;
  const int ref = problem.reference;
  std::vector<ArrayFullTriad>& start = f->start;
  const double sigma_a = f->sigma_a, sigma_g = f->sigma_g;
  const int threads = f->threads;
  {
    ArrayProblem ap;
    ap.nominal_positions = problem.nominal_positions;
    ap.reference = ref;
    ap.accel.resize(d.Nd, 3 * K);
    ap.gyro.resize(d.Nd, 3 * K);
    for (int k = 0; k < K; ++k) {
      const Mat3 Ti = start[k].accel_T.inverse();
      for (int64_t m = 0; m < d.Nd; ++m) {
        ap.accel.row(m).segment<3>(3 * k) =
            (Ti * (d.ya.col(m).segment<3>(3 * k) - start[k].accel_bias)).transpose();
        ap.gyro.row(m).segment<3>(3 * k) =
            (d.yg.col(m).segment<3>(3 * k) - start[k].gyro_bias).transpose();
      }
    }
    ArrayOptions ao;
    ao.accel_noise = sigma_a;
    ao.gyro_noise = sigma_g;
    ao.threads = threads;
    ao.executor = options.executor;
    ao.max_iterations = 30;
    ao.tolerance = 1e-8;
    ao.stop = options.stop;
    ArrayResult ar;
    const Status s = CalibrateArray(ap, ao, &ar);
    if (StopRequested(options.stop)) return f->Stopped("positions-only start");
    if (s.ok() && ar.usable) {
      for (int k = 0; k < K; ++k) start[k].position = ar.positions.col(k);
      res.initial_positions_from_array = true;
      res.initial_position_std = ar.position_std_crb;
    } else {
      res.warnings.push_back("the positions-only fit for the start failed (" + s.message() +
                             "); the full model starts from the nominal positions");
    }
  }
  res.initial = start;

  return Status::Ok();
}

// The start of the motion per sample given the start (omega from the gyroscopes, omega_dot and s
// by linear least squares on the corrected accelerometers); the statics' gravity directions.
void StartMotion(FullFit* f) {
  const FullData& d = f->d;
  const int K = f->K;
  const Eigen::Matrix3Xd& s_dir = f->s_dir;
  const std::vector<ArrayFullTriad>& start = f->start;
  Eigen::Matrix<double, 10, Eigen::Dynamic>& x = f->x;
  x.resize(10, d.J + d.Nd);
  for (int64_t j = 0; j < d.J; ++j) {
    x.col(j).setZero();
    x.col(j).head<3>() = s_dir.col(j);
    x(9, j) = 1;
  }
  {
    Eigen::Matrix<double, 6, 6> N6 = Eigen::Matrix<double, 6, 6>::Zero();
    for (int k = 0; k < K; ++k) {
      Eigen::Matrix<double, 3, 6> G;
      G << Mat3::Identity(), -Skew(start[k].position);
      N6 += G.transpose() * G;
    }
    const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(N6);
    std::vector<Mat3> Ti(K);
    for (int k = 0; k < K; ++k) Ti[k] = start[k].accel_T.inverse();
    for (int64_t m = 0; m < d.Nd; ++m) {
      Vec3 w = Vec3::Zero();
      for (int k = 0; k < K; ++k) w += d.yg.col(m).segment<3>(3 * k) - start[k].gyro_bias;
      w /= K;
      Eigen::Matrix<double, 6, 1> rhs = Eigen::Matrix<double, 6, 1>::Zero();
      for (int k = 0; k < K; ++k) {
        const Vec3 r = start[k].position;
        const Vec3 f = Ti[k] * (d.ya.col(m).segment<3>(3 * k) - start[k].accel_bias);
        const Vec3 z = f - (w * w.dot(r) - r * w.squaredNorm());
        rhs.head<3>() += z;
        rhs.tail<3>() += r.cross(z);
      }
      const Eigen::Matrix<double, 6, 1> sol = ldlt.solve(rhs);
      x.col(d.J + m) << w, sol.tail<3>(), sol.head<3>(), 0;
    }
  }
}

// Rotation excitation, on the start's motion (omega: the mean of the bias-corrected gyroscopes),
// before the solver spends time on an undetermined problem.
Status CheckRotationExcitation(FullFit* f) {
  ArrayFullResult& res = f->res;
  const FullData& d = f->d;
  const int K = f->K;
  const double sigma_g = f->sigma_g;
  const Eigen::Matrix<double, 10, Eigen::Dynamic>& x = f->x;
  {
    Mat3 W = Mat3::Zero();
    for (int64_t m = 0; m < d.Nd; ++m)
      W += x.col(d.J + m).head<3>() * x.col(d.J + m).head<3>().transpose();
    const Eigen::SelfAdjointEigenSolver<Mat3> es(W);
    res.rotation_eigenvalues = es.eigenvalues();
    res.weakest_rotation_axis = es.eigenvectors().col(0);
    int i = 0;
    res.weakest_rotation_axis.cwiseAbs().maxCoeff(&i);
    if (res.weakest_rotation_axis(i) < 0) res.weakest_rotation_axis *= -1;
    res.rotation_noise_floor = static_cast<double>(d.Nd) * sigma_g * sigma_g / K;
    const double lam = res.rotation_eigenvalues(0);
    res.rotation_verdict = lam >= 100 * res.rotation_noise_floor ? "good"
                           : lam >= 3 * res.rotation_noise_floor ? "weak"
                                                                 : "insufficient";
  }
  const Vec3& ax = res.weakest_rotation_axis;
  auto c2 = [](double v) { return Fmt("%.2f", std::abs(v) < 0.005 ? 0.0 : v); };  // no "-0.00"
  const std::string axis_text = "(" + c2(ax.x()) + ", " + c2(ax.y()) + ", " + c2(ax.z()) + ")";
  if (res.rotation_verdict == "insufficient")
    return f->NotDeterminable(
        array_reason::kWeakExcitation,
        "too little rotation about the body axis " + axis_text + " (sum of squared rates " +
            Fmt("%.3g", res.rotation_eigenvalues(0)) +
            " (rad/s)^2 against the gyroscope noise floor " +
            Fmt("%.3g", res.rotation_noise_floor) +
            "): the gyroscope gains and misalignments along that axis (the T_g columns) are not "
            "determined; twist the board about that axis too in the dynamic phase");
  if (res.rotation_verdict == "weak")
    res.warnings.push_back("little rotation about the body axis " + axis_text +
                           ": the gyroscope gains along it are weakly determined (see their σ)");
  return Status::Ok();
}

// The joint maximum-likelihood fit by block LM from the start; with dynamic_weighting "residual",
// solved again twice with the dynamic samples weighted by their own residual level.
Status SolveJoint(FullFit* f, const FullProblem& fp, BlockLm<FullProblem>& lm) {
  const ArrayFullOptions& options = f->options;
  ArrayFullResult& res = f->res;
  FullData& d = f->d;
  const int K = f->K;
  const double sigma_a = f->sigma_a, sigma_g = f->sigma_g;
  Eigen::Matrix<double, 10, Eigen::Dynamic>& x = f->x;
  Eigen::VectorXd& theta = f->theta;
  BlockLm<FullProblem>::Callback callback;
  if (options.callback)
    callback = [&options](int it, const Eigen::VectorXd&) { return options.callback(it); };
  f->summary = lm.Solve(&x, &theta, callback);
  const BlockLmSummary& summary = f->summary;
  BlockLmSummary& final_summary = f->final_summary;
  final_summary = summary;
  std::vector<double> resolved_costs;  // of the re-solves (kResidual): their own weights
  if (options.dynamic_weighting == ArrayFullDynamicWeighting::kResidual &&
      summary.termination != BlockLmTermination::kNumericalFailure &&
      summary.termination != BlockLmTermination::kUserStopped) {
    // Weight the dynamic samples by their own residual level (per sensor kind, corrected for
    // the 9 motion unknowns per sample) and solve again from the estimate; twice, the levels
    // then move by far less than their own uncertainty.
    for (int round = 0; round < 2; ++round) {
      const std::vector<TriadParams> c = Unpack(theta, K);
      Eigen::MatrixX2d dy = Eigen::MatrixX2d::Zero(K, 2);
      if (StopRequested(options.stop)) return f->Stopped("joint solver (reweighting)");
      for (int64_t m = 0; m < d.Nd; ++m) fp.AddSquaredResiduals(d.J + m, x.col(d.J + m), c, &dy);
      const double correction = 6.0 * K / (6.0 * K - 9);
      const double sa = std::sqrt(dy.col(0).sum() / (3.0 * K * d.Nd) * correction);
      const double sg = std::sqrt(dy.col(1).sum() / (3.0 * K * d.Nd) * correction);
      d.wa_d = 1 / std::max(sa, sigma_a * options.dynamic_noise_scale);
      d.wg_d = 1 / std::max(sg, sigma_g * options.dynamic_noise_scale);
      final_summary = lm.Solve(&x, &theta, callback);
      res.iterations += final_summary.iterations;
      resolved_costs.insert(resolved_costs.end(), final_summary.cost.begin(),
                            final_summary.cost.end());
      if (StopRequested(options.stop)) return f->Stopped("joint solver (reweighting)");
      if (final_summary.termination == BlockLmTermination::kUserStopped) {
        res.reason = "stopped by the caller";
        return Status::Internal("the full array calibration was stopped by the caller");
      }
    }
    res.dynamic_accel_noise = 1 / d.wa_d;
    res.dynamic_gyro_noise = 1 / d.wg_d;
  }
  res.termination = final_summary.termination;
  res.iterations += summary.iterations;
  res.converged = final_summary.converged();
  res.cost = summary.cost;
  res.cost.insert(res.cost.end(), resolved_costs.begin(), resolved_costs.end());
  if (StopRequested(options.stop)) return f->Stopped("joint solver");
  if (summary.termination == BlockLmTermination::kUserStopped) {
    res.reason = "stopped by the caller";
    return Status::Internal("the full array calibration was stopped by the caller");
  }
  if (final_summary.termination == BlockLmTermination::kNumericalFailure)
    return f->NotDeterminable(Reason::kNumericalFailure,
                              "the joint solver found no step with a finite cost (numerical "
                              "failure): the recording or the noise settings are degenerate");
  res.theta = theta;
  f->ctx = Unpack(theta, K);
  res.triads.resize(K);
  res.report.resize(K);
  for (int k = 0; k < K; ++k) {
    res.triads[k] = UnpackArrayFullTriad(theta.segment<kP>(kP * k));
    res.report[k] = ReportArrayFullTriad(res.triads[k]);
    res.report[k].name = res.names[k];
  }

  return Status::Ok();
}

// Residuals per triad and kind, chi^2 per degree of freedom.
void ComputeResiduals(FullFit* f, const FullProblem& fp) {
  ArrayFullResult& res = f->res;
  const FullData& d = f->d;
  const int K = f->K;
  const Eigen::Matrix<double, 10, Eigen::Dynamic>& x = f->x;
  const std::vector<TriadParams>& ctx = f->ctx;
  const BlockLmSummary& final_summary = f->final_summary;
  const int P = static_cast<int>(f->E.cols());
  res.dof = 6LL * K * (d.J + d.Nd) - 9 * d.Nd - 2 * d.J - P;
  res.chi2_per_dof = res.dof > 0 ? final_summary.final_cost() / static_cast<double>(res.dof) : 0;
  {
    // The model weights a static mean's residual by √samples (its noise is σ/√samples); the
    // figures reported are the means' residuals themselves, in reading units.
    Eigen::MatrixX2d st = Eigen::MatrixX2d::Zero(K, 2), dy = Eigen::MatrixX2d::Zero(K, 2);
    Eigen::MatrixX2d one(K, 2);
    double static_chi2 = 0;
    for (int64_t n = 0; n < d.J; ++n) {
      one.setZero();
      fp.AddSquaredResiduals(n, x.col(n), ctx, &one);
      static_chi2 += one.col(0).sum() / (f->sigma_a * f->sigma_a) +
                     one.col(1).sum() / (f->sigma_g * f->sigma_g);
      one /= d.static_n(n);
      st += one;
      if (n < static_cast<int64_t>(res.static_intervals.size())) {
        res.static_intervals[n].accel_rms = std::sqrt(one.col(0).sum() / (3.0 * K));
        res.static_intervals[n].gyro_rms = std::sqrt(one.col(1).sum() / (3.0 * K));
      }
    }
    for (int64_t n = d.J; n < d.J + d.Nd; ++n) fp.AddSquaredResiduals(n, x.col(n), ctx, &dy);
    res.residuals.resize(K);
    for (int k = 0; k < K; ++k) {
      res.residuals[k].static_accel = std::sqrt(st(k, 0) / (3.0 * d.J));
      res.residuals[k].static_gyro = std::sqrt(st(k, 1) / (3.0 * d.J));
      res.residuals[k].dynamic_accel = std::sqrt(dy(k, 0) / (3.0 * d.Nd));
      res.residuals[k].dynamic_gyro = std::sqrt(dy(k, 1) / (3.0 * d.Nd));
    }
    const double static_dof = 6.0 * K * d.J - 2.0 * d.J - 15.0 * K;
    res.static_chi2_per_dof = static_dof > 0 ? static_chi2 / static_dof : 0;
    res.dynamic_rms_accel = std::sqrt(dy.col(0).sum() / (3.0 * K * d.Nd));
    res.dynamic_rms_gyro = std::sqrt(dy.col(1).sum() / (3.0 * K * d.Nd));
  }
}

// Sampling-time offsets (a diagnostic of the model's main misfit on real hardware): if
// IMU k samples at t + delta_k, its gyroscope residual is ~ delta_k T_g,k omega_dot. Least
// squares per IMU, made relative to their mean (a common offset is absorbed by omega).
void EstimateSamplingTimeOffsets(FullFit* f) {
  ArrayFullResult& res = f->res;
  const FullData& d = f->d;
  const int K = f->K;
  const Eigen::Matrix<double, 10, Eigen::Dynamic>& x = f->x;
  const std::vector<TriadParams>& ctx = f->ctx;
  {
    res.time_offsets = Eigen::VectorXd::Zero(K);
    Eigen::VectorXd num = Eigen::VectorXd::Zero(K), den = Eigen::VectorXd::Zero(K);
    double ss = 0, along = 0, vv = 0;
    for (int64_t m = 0; m < d.Nd; ++m) {
      const Vec3 w = x.col(d.J + m).head<3>(), wd = x.col(d.J + m).segment<3>(3);
      for (int k = 0; k < K; ++k) {
        const Vec3 e = d.yg.col(m).segment<3>(3 * k) - ctx[k].Tg * w - ctx[k].bg;
        const Vec3 v = ctx[k].Tg * wd;
        num(k) += e.dot(v);
        den(k) += v.squaredNorm();
        ss += e.squaredNorm();
        if (v.squaredNorm() > 0) along += e.dot(v) * e.dot(v) / v.squaredNorm();
        vv += v.squaredNorm();
      }
    }
    for (int k = 0; k < K; ++k) res.time_offsets(k) = den(k) > 0 ? num(k) / den(k) : 0;
    // Fraction of the gyroscope residual explained by the per-IMU offsets (before centring).
    double explained = 0;
    for (int k = 0; k < K; ++k) explained += den(k) > 0 ? num(k) * num(k) / den(k) : 0;
    res.time_offset_explained = ss > 0 ? explained / ss : 0;
    res.time_offsets.array() -= res.time_offsets.mean();
    res.jitter_explained = ss > 0 ? along / ss : 0;
    res.jitter_rms = vv > 0 ? std::sqrt(along / vv) : 0;
  }
}

// The Fisher information, its null directions (named), and the Cramér-Rao bound.
Status ComputeCramerRaoBound(FullFit* f, BlockLm<FullProblem>& lm) {
  const ArrayFullOptions& options = f->options;
  ArrayFullResult& res = f->res;
  const int K = f->K;
  const Eigen::MatrixXd& E = f->E;
  const int P = static_cast<int>(E.cols());
  const Eigen::Matrix<double, 10, Eigen::Dynamic>& x = f->x;
  const Eigen::VectorXd& theta = f->theta;
  BlockLmInformation info;
  lm.ComputeSharedInformation(x, theta, &info, nullptr);
  if (StopRequested(options.stop)) return f->Stopped("information");
  {
    Eigen::VectorXd dg = info.information.diagonal();
    Eigen::VectorXd scale(P);
    for (int i = 0; i < P; ++i) scale(i) = dg(i) > 0 ? 1 / std::sqrt(dg(i)) : 0;
    const Eigen::MatrixXd Sn = scale.asDiagonal() * info.information * scale.asDiagonal();
    // The eigenvalues first (about a fifth of the work with the vectors, which a regular
    // information, the usual case, does not need); the vectors only to name null directions.
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> values(Sn, Eigen::EigenvaluesOnly);
    const bool singular =
        values.eigenvalues().minCoeff() <= 1e-12 * values.eigenvalues().maxCoeff();
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es =
        singular ? Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Sn)
                 : Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>();
    const double lmax = values.eigenvalues().maxCoeff();
    for (int i = 0; singular && i < P; ++i) {
      if (es.eigenvalues()(i) > 1e-12 * lmax) break;
      const Eigen::VectorXd dir = E * (scale.asDiagonal() * es.eigenvectors().col(i));
      if (!(dir.norm() > 0)) continue;  // a parameter without information: named below
      std::vector<int> idx(dir.size());
      std::iota(idx.begin(), idx.end(), 0);
      std::partial_sort(idx.begin(), idx.begin() + 3, idx.end(),
                        [&](int a, int b) { return std::abs(dir(a)) > std::abs(dir(b)); });
      std::string text;
      for (int t = 0; t < 3; ++t)
        text += (t ? ", " : "") + ArrayFullParameterName(res.names, idx[t]);
      res.null_directions.push_back(text);
    }
    for (int i = 0; i < P; ++i)
      if (!(dg(i) > 0)) {
        int j = 0;
        E.col(i).cwiseAbs().maxCoeff(&j);
        res.null_directions.push_back(ArrayFullParameterName(res.names, j) + " (no information)");
      }
  }
  if (!res.null_directions.empty()) {
    std::string list;
    for (const auto& t : res.null_directions) list += (list.empty() ? "" : "; ") + t;
    return f->NotDeterminable(Reason::kSingularInformation,
                              "the recording does not determine every parameter (null directions "
                              "of the Fisher information, largest components: " +
                                  list +
                                  "): record statics spread over the sphere and rotate about "
                                  "every axis");
  }
  Eigen::MatrixXd covE;
  if (!InvertInformation(info.information, &covE))
    return f->NotDeterminable(Reason::kSingularInformation,
                              "the Fisher information is not positive definite: the recording "
                              "does not determine the parameters");
  res.theta_covariance = E * covE * E.transpose();
  res.theta_covariance_crb = res.theta_covariance;
  res.report_std.resize(K);
  for (int k = 0; k < K; ++k) {
    res.report_std[k] =
        ReportArrayFullTriadStd(res.triads[k], res.theta_covariance.block<kP, kP>(kP * k, kP * k));
    res.report_std[k].name = res.names[k];
  }
  res.report_std_crb = res.report_std;
  return Status::Ok();
}

// The residual-aware (sandwich) covariance; the primary σ when the residuals exceed the noise.
Status ComputeResidualAwareCovariance(FullFit* f, const FullProblem& fp) {
  const ArrayFullProblem& problem = f->problem;
  const ArrayFullOptions& options = f->options;
  ArrayFullResult& res = f->res;
  const FullData& d = f->d;
  const int K = f->K;
  const double sigma_a = f->sigma_a, sigma_g = f->sigma_g;
  const Eigen::Matrix<double, 10, Eigen::Dynamic>& x = f->x;
  const std::vector<TriadParams>& ctx = f->ctx;
  const bool reweighted =
      options.dynamic_weighting == ArrayFullDynamicWeighting::kResidual &&
      (d.wa_d * options.dynamic_noise_scale < d.wa || d.wg_d * options.dynamic_noise_scale < d.wg);
  {
    // Batches: every static alone, the dynamic samples in runs of robust_batch seconds.
    std::vector<std::vector<int64_t>> batches;
    for (int64_t j = 0; j < d.J; ++j) batches.push_back({j});
    const double t0 = problem.t(d.dyn_index[0]);
    int64_t current = -1;
    for (int64_t m = 0; m < d.Nd; ++m) {
      const auto id =
          static_cast<int64_t>(std::floor((problem.t(d.dyn_index[m]) - t0) / options.robust_batch));
      if (id != current) batches.emplace_back();
      current = id;
      batches.back().push_back(d.J + m);
    }
    res.robust_batches = static_cast<int64_t>(batches.size());
    // Jackknife-type (HC3) sandwich: each batch's score s_b is mapped by (S - I_b)^-1 instead of
    // S^-1 (I_b: the batch's own reduced information), which undoes the shrinking of the
    // residuals by the fit (the leverage of a batch); Neumann series in theta coordinates,
    // t = Cov s + Cov I_b t. Without it the sandwich is ~30 % too small on short logs.
    const int q = kP * K;
    const Eigen::MatrixXd& Cov = res.theta_covariance;
    Eigen::MatrixXd Bm = Eigen::MatrixXd::Zero(q, q);
    Eigen::MatrixXd Ib(q, q);
    FullProblem::Normal b;
    b.C.resize(9, q);
    Eigen::Matrix<double, 9, Eigen::Dynamic> Z(9, q);
    int not_converged = 0;
    for (const auto& batch : batches) {
      if (StopRequested(options.stop)) return f->Stopped("residual-aware covariance");
      FullProblem::Sums sums = fp.MakeSums();
      // Σ C_n^T H_n^-1 C_n into the lower triangle of Ib (a dynamic sample by its Kronecker
      // structure, as the solve's Schur term; a static densely), then Ib = H_pp − that.
      Ib.setZero();
      for (int64_t n : batch) {
        fp.Linearize(n, x.col(n), ctx, &b, &sums);
        const Eigen::Matrix<double, 9, 9> Linv = InverseCholeskyFactor<9>(b.H);
        if (!fp.AddCouplingGram(n, x.col(n), ctx, Linv, &Ib)) {
          Z.noalias() = Linv * b.C;
          Ib.selfadjointView<Eigen::Lower>().rankUpdate(Z.transpose());
        }
      }
      Ib = -Ib.selfadjointView<Eigen::Lower>().toDenseMatrix();
      for (int k = 0; k < K; ++k) Ib.block<kP, kP>(kP * k, kP * k) += sums.H[k];
      const Eigen::VectorXd t0v = Cov * sums.g;
      Eigen::VectorXd tv = t0v;
      bool done = false;
      for (int it = 0; it < 100 && !done; ++it) {
        const Eigen::VectorXd next = t0v + Cov * (Ib * tv);
        done = (next - tv).norm() <= 1e-10 * next.norm();
        tv = next;
      }
      if (!done || !tv.allFinite()) {
        ++not_converged;
        tv = t0v;
      }
      Bm.selfadjointView<Eigen::Lower>().rankUpdate(tv);
    }
    Bm = Bm.selfadjointView<Eigen::Lower>();
    if (not_converged > 0)
      res.warnings.push_back(std::to_string(not_converged) +
                             " batches of the residual-aware σ alone determine some parameter "
                             "(leverage ~ 1): their scores are not leverage-corrected");
    double ratio2 = 0;
    int counted = 0;
    for (int i = 0; i < q; ++i)
      if (Cov(i, i) > 1e-12 * Cov.diagonal().maxCoeff()) {
        ratio2 += Bm(i, i) / Cov(i, i);
        ++counted;
      }
    res.sigma_ratio = counted > 0 ? std::sqrt(ratio2 / counted) : 1;
    const bool chi2_high = res.chi2_per_dof > options.robust_ratio;
    // Noise correlated in time leaves chi2_per_dof near 1 (the many dynamic samples) but inflates
    // the static means' χ² (bench/sigma_consistency: AR(1) noise, z RMS 2.9 with the CRB).
    const bool static_high = res.static_chi2_per_dof > options.robust_ratio;
    // Not on the variance ratio alone (as the positions model does): on short simulated logs
    // (4 one-second batches) the sandwich exceeds the CRB by that much under white noise too.
    if (!chi2_high && !static_high && !reweighted) return Status::Ok();
    res.sigma_basis = "sandwich";
    res.theta_covariance = Bm;
    for (int k = 0; k < K; ++k) {
      res.report_std[k] = ReportArrayFullTriadStd(
          res.triads[k], res.theta_covariance.block<kP, kP>(kP * k, kP * k));
      res.report_std[k].name = res.names[k];
    }
    const GyroMessageUnit& gu = options.gyro_message_unit;
    const std::string noise = "dynamic residual rms " + Fmt("%.3g", res.dynamic_rms_accel) +
                              " m/s² and " + gu.Quote(res.dynamic_rms_gyro) + " against noise " +
                              Fmt("%.3g", sigma_a) + " m/s² and " + gu.Quote(sigma_g);
    res.warnings.push_back(
        "σ is the residual-aware sandwich, " + Fmt("%.2g", res.sigma_ratio) +
        "× the white-noise bound (uncertainty.imus[].crb): the residuals exceed the noise model "
        "(χ²/dof " +
        Fmt("%.3g", res.chi2_per_dof) + ", of the static means " +
        Fmt("%.3g", res.static_chi2_per_dof) + "; " + noise +
        "): the model does not explain the data to the noise level (e.g. sampling-time errors "
        "between the IMUs)");
    if (reweighted)
      res.warnings.push_back(
          "the dynamic residuals exceed the statics' noise: the dynamic samples were weighted by "
          "their own residual level (" +
          Fmt("%.3g", 1 / d.wa_d) + " m/s² and " + gu.Quote(1 / d.wg_d) + ")");
  }
  return Status::Ok();
}

}  // namespace calibd::core::array_full_model
