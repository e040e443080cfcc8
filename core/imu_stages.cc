// The stages of one IMU's calibration (core/imu_stages.h).
#include "core/imu_stages.h"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <sstream>

namespace calibd::core::imu_internal {
namespace {

// Reported quantities from the internal unknowns: b_a, K_a, T_a(01,02,12), b_g, K_g, T_g offdiag.
VectorXd Reported(const State& x) {
  VectorXd out(21);
  const Matrix3d ma = x.p.inverse();
  out.segment<3>(0) = x.ba;
  for (int i = 0; i < 3; ++i) out(3 + i) = ma(i, i);
  out(6) = ma(0, 1) / ma(1, 1);
  out(7) = ma(0, 2) / ma(2, 2);
  out(8) = ma(1, 2) / ma(2, 2);
  out.segment<3>(9) = x.bg;
  for (int i = 0; i < 3; ++i) out(12 + i) = x.mg(i, i);
  out(15) = x.mg(0, 1) / x.mg(1, 1);
  out(16) = x.mg(0, 2) / x.mg(2, 2);
  out(17) = x.mg(1, 0) / x.mg(0, 0);
  out(18) = x.mg(1, 2) / x.mg(2, 2);
  out(19) = x.mg(2, 0) / x.mg(0, 0);
  out(20) = x.mg(2, 1) / x.mg(1, 1);
  return out;
}

VectorXd Internal(const State& x) {
  VectorXd v(21);
  for (int q = 0; q < 6; ++q) v(q) = x.p(kUpperRow[q], kUpperCol[q]);
  v.segment<3>(6) = x.ba;
  for (int i = 0; i < 9; ++i) v(9 + i) = x.mg(i % 3, i / 3);
  v.segment<3>(18) = x.bg;
  return v;
}

State FromInternal(const VectorXd& v, const State& like) {
  State x = like;
  x.p.setZero();
  for (int q = 0; q < 6; ++q) x.p(kUpperRow[q], kUpperCol[q]) = v(q);
  x.ba = v.segment<3>(6);
  for (int i = 0; i < 9; ++i) x.mg(i % 3, i / 3) = v(9 + i);
  x.bg = v.segment<3>(18);
  return x;
}

void FillTriad(const Matrix3d& m, const Vector3d& b, TriadCalibration* tc) {
  tc->bias = b;
  tc->matrix = m;
  tc->scale = m.diagonal();
  tc->misalignment = m * tc->scale.cwiseInverse().asDiagonal();
}

// Sets up the problem for one Levenberg-Marquardt stage: the rotations' weights 1/σ_θ for the
// gyroscope matrix mg and noise fit->sg, the residuals (rotations always; the accelerometer's and
// the gyroscope statics' as asked) and every unknown active (1) or held (0).
void SetUpStage(const Matrix3d& mg, bool use_accel, bool use_gyro_statics, char active,
                ImuFit* fit) {
  const Vector3d& sg = fit->sg;
  const Matrix3d cov = mg * sg.array().square().matrix().asDiagonal() * mg.transpose();
  const double var = cov.trace() / 3;
  Problem& pr = fit->pr;
  for (RotationData& r : pr.rotations) r.weight = 1 / std::sqrt(var * r.sum_c2);
  pr.use_accel = use_accel;
  pr.use_gyro_statics = use_gyro_statics;
  pr.use_rotations = true;
  pr.active.assign(static_cast<size_t>(pr.Size()), active);
}

}  // namespace

Status Fail(Status s, ImuTermination term, ImuResult* r) {
  r->usable = false;
  r->termination = term;
  r->reason = s.message();
  return s;
}

Status Stopped(const ImuOptions& o, const std::string& stage, ImuResult* r) {
  return Fail(StoppedStatus(*o.stop, "imu: " + stage), ImuTermination::kStopped, r);
}

NominalTriads NominalOf(const ImuOptions& o) {
  NominalTriads nominal;
  nominal.ma = o.accel_unit * Matrix3d::Identity();
  nominal.ba = Vector3d::Constant(o.nominal_accel_bias);
  nominal.mg = o.gyro_unit * Matrix3d::Identity();
  nominal.bg = Vector3d::Constant(o.nominal_gyro_bias);
  return nominal;
}

ImuFit StartGyroscope(const ImuStageInput& in, AccelFit accel, ImuResult* res) {
  const ImuOptions& o = in.o;
  const int k = in.k;
  const StaticDetection& det = res->detection;
  ImuFit fit;
  Problem& pr = fit.pr;
  State& x = fit.x;
  pr = std::move(accel.pr);
  x = std::move(accel.x);
  res->accel_iterations = accel.iterations;
  pr.t = &in.t;
  pr.gyro = in.imu.gyro;
  pr.stop = o.stop;

  // Gyroscope noise and bias.
  Vector3d& sg = fit.sg;
  sg = o.gyro_noise ? Vector3d::Constant(*o.gyro_noise / o.gyro_unit) : PooledStd(det, 2 * k + 1);
  sg = sg.cwiseMax(1e-9 / o.gyro_unit);
  pr.wg = sg.cwiseInverse();
  res->accel_noise = pr.wa.cwiseInverse() * o.accel_unit;
  res->gyro_noise = sg * o.gyro_unit;
  {
    Vector3d sum = Vector3d::Zero();
    double cnt = 0;
    for (const StaticData& s : pr.statics) {
      sum += s.yg * s.n;
      cnt += s.n;
    }
    x.bg = sum / cnt;
  }
  x.mg = o.gyro_unit * Matrix3d::Identity();
  return fit;
}

Status CollectRotations(const ImuStageInput& in, ImuFit* fit, ImuResult* res) {
  const VectorXd& t = in.t;
  const ImuOptions& o = in.o;
  const Eigen::MatrixX3d& yg = *in.imu.gyro;
  const StaticDetection& det = res->detection;
  Problem& pr = fit->pr;
  const int n = pr.Statics();
  for (int j = 0; j + 1 < n; ++j) {
    if (StopRequested(o.stop)) return Stopped(o, "rotations", res);
    const StaticInterval& a = det.intervals[static_cast<size_t>(j)];
    const StaticInterval& b = det.intervals[static_cast<size_t>(j + 1)];
    ImuRotationDiagnostics rd;
    rd.from = j;
    rd.to = j + 1;
    rd.start = a.end;
    rd.end = b.start;
    for (const TimeGap& g : det.gaps) {
      if (g.index > a.last && g.index <= b.first) rd.excluded = "gap in t";
    }
    for (int64_t i = a.last; i <= b.first && rd.excluded.empty(); ++i) {
      const auto row = yg.row(i);
      if (row.minCoeff() <= o.gyro_saturation_low || row.maxCoeff() >= o.gyro_saturation_high) {
        rd.excluded = "saturated gyroscope samples";
      }
    }
    rd.used = rd.excluded.empty();
    if (rd.used) {
      RotationData r;
      r.j = j;
      r.first = a.last;
      r.last = b.first;
      for (int64_t i = r.first; i <= r.last; ++i) {
        const double c =
            0.5 * ((i > r.first ? t(i) - t(i - 1) : 0) + (i < r.last ? t(i + 1) - t(i) : 0));
        r.sum_c2 += c * c;
      }
      r.steps = Steps(t, yg, r.first, r.last);
      pr.rotations.push_back(r);
    }
    res->rotations.push_back(rd);
  }
  const bool estimate_bias = o.gyro_bias == GyroBiasModel::kEstimate;
  const int needed_rotations = estimate_bias ? 6 : 5;
  if (static_cast<int>(pr.rotations.size()) < needed_rotations) {
    return Fail(
        Status::NotDeterminable(
            imu_reason::kTooFewRotations,
            "the gyroscope needs at least " + std::to_string(needed_rotations) +
                " rotations between consecutive statics, " + std::to_string(pr.rotations.size()) +
                " are usable: record more static orientations joined by rotations"),
        ImuTermination::kTooFewRotations, res);
  }
  return Status::Ok();
}

Status FitGyroscope(const ImuStageInput& in, const NominalTriads& nominal, ImuFit* fit,
                    ImuResult* res) {
  const ImuOptions& o = in.o;
  Problem& pr = fit->pr;
  State& x = fit->x;
  const bool estimate_bias = o.gyro_bias == GyroBiasModel::kEstimate;
  SetUpStage(nominal.mg, false, false, 0, fit);
  for (int i = 0; i < 9; ++i) pr.active[static_cast<size_t>(kMg + i)] = 1;
  if (estimate_bias) {
    for (int i = 0; i < 3; ++i) pr.active[static_cast<size_t>(kBg + i)] = 1;
  }
  LmSummary gs = Minimize(pr, o.max_iterations, &x);
  res->gyro_iterations = gs.iterations;
  if (gs.stopped) return Stopped(o, "gyroscope fit", res);
  fit->max_iter = !gs.converged;
  res->cost = gs.cost;
  return Status::Ok();
}

Status RefineJointly(const ImuStageInput& in, ImuFit* fit, ImuResult* res) {
  const ImuOptions& o = in.o;
  Problem& pr = fit->pr;
  State& x = fit->x;
  const bool estimate_bias = o.gyro_bias == GyroBiasModel::kEstimate;
  SetUpStage(x.mg, true, !estimate_bias, 1, fit);
  if (o.joint_refinement) {
    LmSummary js = Minimize(pr, o.max_iterations, &x);
    res->joint_iterations = js.iterations;
    if (js.stopped) return Stopped(o, "joint refinement", res);
    fit->max_iter = fit->max_iter || !js.converged;
    res->cost = js.cost;
  }
  return Status::Ok();
}

Status EstimateCovariance(const ImuStageInput& in, const ImuFit& fit, ImuResult* res,
                          VectorXd* crb_sd) {
  const ImuOptions& o = in.o;
  const Problem& pr = fit.pr;
  const State& x = fit.x;
  const int n = pr.Statics();
  // Uncertainty: inverse Fisher information, u_j marginalised, then to the reported quantities.
  if (StopRequested(o.stop)) return Stopped(o, "uncertainty", res);
  Normal h;
  const double cost = Evaluate(pr, x, &h);
  if (StopRequested(o.stop)) return Stopped(o, "uncertainty", res);
  const int dim = pr.Size();
  const int residuals =
      3 * n * (pr.use_gyro_statics ? 2 : 1) + 3 * static_cast<int>(pr.rotations.size());
  // Rotation residuals carry 2 independent components (the one along u is second order).
  const int informative = residuals - static_cast<int>(pr.rotations.size());
  res->degrees_of_freedom = informative - dim;
  res->chi2_per_dof = res->degrees_of_freedom > 0 ? 2 * cost / res->degrees_of_freedom : kNaN;
  // The covariance of the shared unknowns: the inverse of their Schur complement (the directions
  // eliminated block by block), no dense matrix over the directions.
  Mat21 cov_int = Mat21::Zero();
  VectorXd unused;
  const bool solved = SolveNormal(h, pr.active, 0.0, VectorXd::Zero(dim), &unused, &cov_int);
  cov_int = (0.5 * (cov_int + cov_int.transpose())).eval();
  if (!solved || !cov_int.allFinite() || (cov_int.diagonal().array() <= 0).any()) {
    return Fail(Status::NotDeterminable(
                    Reason::kSingularInformation,
                    "the information matrix is singular: the statics and rotations do not "
                    "determine every parameter (add orientations and turn about every axis)"),
                ImuTermination::kDegenerate, res);
  }
  const VectorXd th = Internal(x);
  MatrixXd jmap(21, 21);
  for (int i = 0; i < 21; ++i) {
    const double step = 1e-6 * std::max(std::abs(th(i)), std::sqrt(cov_int(i, i)) * 1e-3 + 1e-300);
    VectorXd tp = th, tm = th;
    tp(i) += step;
    tm(i) -= step;
    jmap.col(i) = (Reported(FromInternal(tp, x)) - Reported(FromInternal(tm, x))) / (2 * step);
  }
  const MatrixXd crb = jmap * cov_int * jmap.transpose();
  *crb_sd = crb.diagonal().cwiseMax(0).cwiseSqrt();
  // The primary σ: χ²-scaled, not a sandwich. The residuals are per-static means and per-rotation
  // ends, one batch each, so the χ² already measures what the white-noise model misses per batch
  // (bias wander, coloured noise, an understated noise); the parameters share one scale because
  // the misfit is common to every static, and a per-static sandwich (HC3) with ~20-50 statics
  // against 21 parameters is itself too noisy. Scaled only when χ²/dof exceeds 1 by more than 3
  // of its standard deviations √(2/dof) (else the residuals are consistent: the CRB).
  const double dof = res->degrees_of_freedom;
  const bool scaled = dof > 0 && res->chi2_per_dof > 1 + 3 * std::sqrt(2 / dof);
  res->uncertainty_basis = scaled ? "chi2_scaled" : "crb";
  res->crb_scale = scaled ? std::sqrt(res->chi2_per_dof) : 1.0;
  res->covariance = crb * (res->crb_scale * res->crb_scale);
  if (scaled) {
    std::ostringstream w;
    w.precision(3);
    w << "σ is the CRB scaled by √(χ²/dof), " << res->crb_scale
      << "× the white-noise bound: the residuals exceed the noise model (χ²/dof "
      << res->chi2_per_dof
      << "; bias instability, motion during statics, coloured or understated noise)";
    res->warnings.push_back(w.str());
  }
  return Status::Ok();
}

namespace {

// The *_std members of the two triads from the 21 σ in the order of ImuResult::covariance.
void FillStd(const VectorXd& sd, TriadCalibration* ac, TriadCalibration* gc) {
  ac->bias_std = sd.segment<3>(0);
  ac->scale_std = sd.segment<3>(3);
  ac->misalignment_std.setZero();
  ac->misalignment_std(0, 1) = sd(6);
  ac->misalignment_std(0, 2) = sd(7);
  ac->misalignment_std(1, 2) = sd(8);
  gc->bias_std = sd.segment<3>(9);
  gc->scale_std = sd.segment<3>(12);
  gc->misalignment_std.setZero();
  gc->misalignment_std(0, 1) = sd(15);
  gc->misalignment_std(0, 2) = sd(16);
  gc->misalignment_std(1, 0) = sd(17);
  gc->misalignment_std(1, 2) = sd(18);
  gc->misalignment_std(2, 0) = sd(19);
  gc->misalignment_std(2, 1) = sd(20);
}

}  // namespace

void ReportParameters(const State& x, const VectorXd& crb_sd, ImuResult* res) {
  const Matrix3d ma = x.p.inverse();
  FillTriad(ma, x.ba, &res->accelerometer);
  FillTriad(x.mg, x.bg, &res->gyroscope);
  FillStd(crb_sd * res->crb_scale, &res->accelerometer, &res->gyroscope);
  FillStd(crb_sd, &res->accelerometer_crb, &res->gyroscope_crb);
}

void DiagnoseStatics(const ImuStageInput& in, const NominalTriads& nominal, const State& x,
                     ImuResult* res) {
  const ImuOptions& o = in.o;
  const int k = in.k;
  const StaticDetection& det = res->detection;
  const int n = static_cast<int>(x.u.size());
  const Matrix3d ma = x.p.inverse();
  const Matrix3d& ma0 = nominal.ma;
  const Vector3d& ba0 = nominal.ba;
  double ss_before = 0, ss_after = 0;
  for (int j = 0; j < n; ++j) {
    const StaticInterval& iv = det.intervals[static_cast<size_t>(j)];
    ImuStaticDiagnostics sd_j;
    sd_j.start = iv.start;
    sd_j.end = iv.end;
    sd_j.first = iv.first;
    sd_j.last = iv.last;
    sd_j.samples = iv.samples;
    sd_j.accel_mean = iv.mean[static_cast<size_t>(2 * k)];
    sd_j.accel_std = iv.std[static_cast<size_t>(2 * k)];
    sd_j.gyro_mean = iv.mean[static_cast<size_t>(2 * k + 1)];
    sd_j.gyro_std = iv.std[static_cast<size_t>(2 * k + 1)];
    sd_j.gravity_direction = x.u[static_cast<size_t>(j)];
    sd_j.norm_residual_before = (ma0 * (sd_j.accel_mean - ba0)).norm() - o.gravity;
    sd_j.norm_residual_after = (ma * (sd_j.accel_mean - x.ba)).norm() - o.gravity;
    ss_before += sd_j.norm_residual_before * sd_j.norm_residual_before;
    ss_after += sd_j.norm_residual_after * sd_j.norm_residual_after;
    res->statics.push_back(sd_j);
  }
  res->accel_norm_rms_before = std::sqrt(ss_before / n);
  res->accel_norm_rms_after = std::sqrt(ss_after / n);
}

Status DiagnoseRotations(const ImuStageInput& in, const NominalTriads& nominal, const State& x,
                         ImuResult* res) {
  const VectorXd& t = in.t;
  const ImuOptions& o = in.o;
  const int k = in.k;
  const Eigen::MatrixX3d& yg = *in.imu.gyro;
  const StaticDetection& det = res->detection;
  const int n = static_cast<int>(x.u.size());
  const Matrix3d& ma0 = nominal.ma;
  const Vector3d& ba0 = nominal.ba;
  const Matrix3d& mg0 = nominal.mg;
  const Vector3d& bg0 = nominal.bg;
  Vector3d per_axis = Vector3d::Zero();
  double rb = 0, ra = 0;
  int used = 0;
  for (ImuRotationDiagnostics& rd : res->rotations) {
    if (StopRequested(o.stop)) return Stopped(o, "diagnostics", res);
    const StaticInterval& a = det.intervals[static_cast<size_t>(rd.from)];
    const StaticInterval& b = det.intervals[static_cast<size_t>(rd.to)];
    const Matrix3d r_after = Integrate(t, yg, x.mg, x.bg, a.last, b.first, nullptr);
    const Matrix3d r_before = Integrate(t, yg, mg0, bg0, a.last, b.first, nullptr);
    const Vector3d u0b = (ma0 * (a.mean[static_cast<size_t>(2 * k)] - ba0)).normalized();
    const Vector3d u1b = (ma0 * (b.mean[static_cast<size_t>(2 * k)] - ba0)).normalized();
    rd.angle = Eigen::AngleAxisd(r_after).angle();
    rd.direction_error_before = AngleBetween(r_before.transpose() * u0b, u1b);
    rd.direction_error_after = AngleBetween(r_after.transpose() * x.u[static_cast<size_t>(rd.from)],
                                            x.u[static_cast<size_t>(rd.to)]);
    if (!rd.used) continue;
    ++used;
    rb += rd.direction_error_before * rd.direction_error_before;
    ra += rd.direction_error_after * rd.direction_error_after;
    for (int64_t i = a.last; i < b.first; ++i) {
      const Vector3d w = x.mg * (0.5 * (yg.row(i) + yg.row(i + 1)).transpose() - x.bg);
      per_axis += w.cwiseAbs() * (t(i + 1) - t(i));
    }
  }
  res->gyro_direction_rms_before = used ? std::sqrt(rb / used) : 0;
  res->gyro_direction_rms_after = used ? std::sqrt(ra / used) : 0;
  Coverage(x.u, per_axis, &res->coverage);
  if (!res->coverage.sufficient) res->warnings.push_back("coverage: " + res->coverage.verdict);
  if (n < o.recommended_statics) {
    res->warnings.push_back(std::to_string(n) + " static intervals: at least " +
                            std::to_string(o.recommended_statics) + " are recommended");
  }
  return Status::Ok();
}

Status CheckPlausibility(const ImuStageInput& in, bool max_iter, ImuResult* res) {
  const ImuOptions& o = in.o;
  const TriadCalibration& ac = res->accelerometer;
  const TriadCalibration& gc = res->gyroscope;
  for (int i = 0; i < 3; ++i) {
    const double ra_i = ac.scale(i) / o.accel_unit, rg_i = gc.scale(i) / o.gyro_unit;
    std::ostringstream m;
    m.precision(4);
    if (!(std::abs(ra_i - 1) <= o.max_scale_deviation)) {
      m << "accelerometer scale "
        << "xyz"[i] << " is " << ra_i
        << " times the nominal accel_unit: wrong accel_unit or gravity? (a gain known only "
           "roughly: raise max_scale_deviation, now "
        << o.max_scale_deviation << " (relative: the largest |scale / nominal - 1|))";
    } else if (!(std::abs(rg_i - 1) <= o.max_scale_deviation)) {
      m << "gyroscope scale "
        << "xyz"[i] << " is " << rg_i
        << " times the nominal gyro_unit: wrong gyro_unit (deg/s vs rad/s?) (a gain known "
           "only roughly: raise max_scale_deviation, now "
        << o.max_scale_deviation << " (relative: the largest |scale / nominal - 1|))";
    }
    if (!m.str().empty()) {
      return Fail(Status::NotDeterminable(Reason::kImplausibleEstimate, m.str()),
                  ImuTermination::kImplausible, res);
    }
  }
  if (!(res->gyro_direction_rms_after <= o.max_direction_error)) {
    std::ostringstream m;
    m.precision(3);
    m << "after calibration the gravity direction still misses by " << res->gyro_direction_rms_after
      << " rad RMS per rotation (limit " << o.max_direction_error
      << " rad): the gyroscope does not explain the rotations: wrong gyro_unit (deg/s vs rad/s?), "
         "saturation or a wrong time column";
    return Fail(Status::NotDeterminable(Reason::kImplausibleEstimate, m.str()),
                ImuTermination::kImplausible, res);
  }
  res->usable = true;
  res->reason.clear();
  res->termination = max_iter ? ImuTermination::kMaxIterations : ImuTermination::kConverged;
  if (max_iter) res->warnings.push_back("a Levenberg-Marquardt stage reached max_iterations");
  return Status::Ok();
}

}  // namespace calibd::core::imu_internal
