#include "core/array_full.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <thread>

#include "core/array_full_fit.h"
#include "core/array_full_model.h"

namespace calibd::core {

using array_full_model::FullFit;
using array_full_model::FullProblem;
using array_full_model::kBa;
using array_full_model::kBg;
using array_full_model::kP;
using array_full_model::kR;
using array_full_model::kTa;
using array_full_model::kTg;
using array_full_model::Mat27;
using array_full_model::Mat3;
using array_full_model::TriadParams;
using array_full_model::Unpack;
using array_full_model::Vec27;
using array_full_model::Vec3;

namespace {

Eigen::Matrix<double, 33, 1> ReportVector(const ArrayFullTriad& t) {
  Eigen::Matrix<double, 33, 1> v;
  auto sensor = [&](const Mat3& T, const Vec3& b, int o) {
    const Mat3 M = T.inverse();
    const Vec3 scale = M.diagonal();
    const Mat3 mis = M * scale.cwiseInverse().asDiagonal();
    v.segment<3>(o) = b;
    v.segment<3>(o + 3) = scale;
    for (int i = 0; i < 9; ++i) v(o + 6 + i) = mis(i / 3, i % 3);
  };
  sensor(t.accel_T, t.accel_bias, 0);
  sensor(t.gyro_T, t.gyro_bias, 15);
  v.segment<3>(30) = t.position;
  return v;
}

}  // namespace

Vec27 PackArrayFullTriad(const ArrayFullTriad& t) {
  Vec27 p;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      p(kTa + 3 * i + j) = t.accel_T(i, j);
      p(kTg + 3 * i + j) = t.gyro_T(i, j);
    }
  p.segment<3>(kBa) = t.accel_bias;
  p.segment<3>(kBg) = t.gyro_bias;
  p.segment<3>(kR) = t.position;
  return p;
}

ArrayFullTriad UnpackArrayFullTriad(const Vec27& p) {
  const TriadParams c = Unpack(Eigen::VectorXd(p), 1)[0];
  ArrayFullTriad t;
  t.accel_T = c.Ta;
  t.accel_bias = c.ba;
  t.gyro_T = c.Tg;
  t.gyro_bias = c.bg;
  t.position = c.r;
  return t;
}

ArrayFullTriadReport ReportArrayFullTriad(const ArrayFullTriad& t) {
  ArrayFullTriadReport r;
  auto sensor = [](const Mat3& T, const Vec3& b, ArrayFullSensorReport* s) {
    s->matrix = T.inverse();
    s->scale = s->matrix.diagonal();
    s->misalignment = s->matrix * s->scale.cwiseInverse().asDiagonal();
    s->bias = b;
  };
  sensor(t.accel_T, t.accel_bias, &r.accelerometer);
  sensor(t.gyro_T, t.gyro_bias, &r.gyroscope);
  r.position = t.position;
  return r;
}

ArrayFullTriadStd ReportArrayFullTriadStd(const ArrayFullTriad& t, const Mat27& covariance) {
  const Vec27 p0 = PackArrayFullTriad(t);
  Eigen::Matrix<double, 33, 27> D;
  for (int i = 0; i < 27; ++i) {
    const double h = 1e-6 * std::max(1.0, std::abs(p0(i)));
    Vec27 a = p0, b = p0;
    a(i) += h;
    b(i) -= h;
    D.col(i) =
        (ReportVector(UnpackArrayFullTriad(a)) - ReportVector(UnpackArrayFullTriad(b))) / (2 * h);
  }
  const Eigen::Matrix<double, 33, 1> var = (D * covariance * D.transpose()).diagonal();
  const Eigen::Matrix<double, 33, 1> sd = var.cwiseMax(0).cwiseSqrt();
  ArrayFullTriadStd out;
  auto sensor = [&](int o, ArrayFullSensorStd* s) {
    s->bias_std = sd.segment<3>(o);
    s->scale_std = sd.segment<3>(o + 3);
    for (int i = 0; i < 9; ++i) s->misalignment_std(i / 3, i % 3) = sd(o + 6 + i);
  };
  sensor(0, &out.accelerometer);
  sensor(15, &out.gyroscope);
  out.position_std = sd.segment<3>(30);
  return out;
}

std::string ArrayFullParameterName(const std::vector<std::string>& names, int i) {
  const int k = i / kP, l = i % kP;
  const std::string triad = k < static_cast<int>(names.size()) ? names[k] : std::to_string(k);
  static const char* const kAxis[] = {"x", "y", "z"};
  if (l < kBa)
    return triad + ".accelerometer.T[" + std::to_string(l / 3) + "][" + std::to_string(l % 3) + "]";
  if (l < kTg) return triad + ".accelerometer.bias." + kAxis[l - kBa];
  if (l < kBg)
    return triad + ".gyroscope.T[" + std::to_string((l - kTg) / 3) + "][" +
           std::to_string((l - kTg) % 3) + "]";
  if (l < kR) return triad + ".gyroscope.bias." + kAxis[l - kBg];
  return triad + ".position." + kAxis[l - kR];
}

bool ArrayFullOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(accel_noise >= 0) || !std::isfinite(accel_noise))
    return fail("accel_noise must be a finite number >= 0 (m/s^2; 0: from the statics)");
  if (!(gyro_noise >= 0) || !std::isfinite(gyro_noise))
    return fail("gyro_noise must be a finite number >= 0 (rad/s; 0: from the statics)");
  if (!(gravity > 0) || !std::isfinite(gravity)) return fail("gravity must be > 0 (m/s^2)");
  if (!gyro_message_unit.IsValid(error)) return false;
  if (gyro_saturation && (!(*gyro_saturation > 0) || !std::isfinite(*gyro_saturation)))
    return fail("gyro_saturation must be a finite number > 0 (rad/s)");
  if (accel_saturation && (!(*accel_saturation > 0) || !std::isfinite(*accel_saturation)))
    return fail("accel_saturation must be a finite number > 0 (m/s^2)");
  std::string e;
  if (!statics.IsValid(&e)) return fail("static detection: " + e);
  if (max_iterations < 1) return fail("max_iterations must be >= 1");
  if (!(tolerance >= 0 && tolerance < 1)) return fail("tolerance must be >= 0 and < 1");
  if (threads < 0) return fail("threads must be >= 0 (0: hardware concurrency)");
  if (!(robust_ratio >= 1) || !std::isfinite(robust_ratio))
    return fail("robust_ratio must be >= 1");
  if (!(robust_batch > 0) || !std::isfinite(robust_batch))
    return fail("robust_batch must be > 0 (seconds)");
  if (min_statics < 9) return fail("min_statics must be >= 9");
  if (!(dynamic_noise_scale > 0) || !std::isfinite(dynamic_noise_scale))
    return fail("dynamic_noise_scale must be > 0");
  return true;
}

std::string ArrayFullResult::BriefReport() const {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "array full: %s, termination %s, %d iterations, cost %.6g -> %.6g, chi2/dof %.4g, "
                "%lld statics, %lld dynamic samples (%lld dropped)",
                usable ? "usable" : "not usable", BlockLmTerminationName(termination), iterations,
                cost.empty() ? 0.0 : cost.front(), cost.empty() ? 0.0 : cost.back(), chi2_per_dof,
                static_cast<long long>(statics), static_cast<long long>(dynamic_samples),
                static_cast<long long>(samples_dropped));
  return buf;
}

Status CalibrateArrayFull(const ArrayFullProblem& problem, const ArrayFullOptions& options,
                          ArrayFullResult* result) {
  *result = ArrayFullResult();
  std::string error;
  if (!options.IsValid(&error)) return Status::InvalidInput(error);
  const int K = static_cast<int>(problem.nominal_positions.cols());
  const int64_t N = problem.t.size();
  if (K < 3 || problem.nominal_positions.rows() != 3)
    return Status::InvalidInput("the full array model needs nominal positions of >= 3 triads");
  if (problem.accel.rows() != N || problem.gyro.rows() != N || problem.accel.cols() != 3 * K ||
      problem.gyro.cols() != 3 * K)
    return Status::InvalidInput(
        "the full array model needs N x 3K accelerometer and gyroscope "
        "readings for the K = " +
        std::to_string(K) + " triads and N sample times");
  if (problem.reference < 0 || problem.reference >= K)
    return Status::InvalidInput("reference triad " + std::to_string(problem.reference) +
                                " out of range [0, " + std::to_string(K - 1) + "]");
  if (!problem.nominal_positions.allFinite() || !problem.accel.allFinite() ||
      !problem.gyro.allFinite() || !problem.t.allFinite())
    return Status::InvalidInput("positions, times and readings must be finite");
  if (!problem.names.empty() && static_cast<int>(problem.names.size()) != K)
    return Status::InvalidInput("names must be empty or hold one name per triad");
  FullFit f(problem, options, result);
  ArrayFullResult& res = f.res;
  res.reference = problem.reference;
  res.names = problem.names;
  if (res.names.empty())
    for (int k = 0; k < K; ++k) res.names.push_back(std::to_string(k));
  f.K = K;
  f.N = N;
  f.threads = options.threads > 0
                  ? options.threads
                  : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  if (StopRequested(options.stop)) return f.Stopped("statics");
  const auto stage = [&options](const char* name) {
    if (options.on_stage) options.on_stage(name);
  };
  namespace afm = array_full_model;
  stage("statics");
  if (Status s = afm::FindStatics(&f); !s.ok()) return s;
  if (Status s = afm::SelectDynamicSamples(&f); !s.ok()) return s;
  stage("start");
  if (Status s = afm::StartAccelerometers(&f); !s.ok()) return s;
  if (Status s = afm::StartPositions(&f); !s.ok()) return s;
  afm::StartMotion(&f);
  if (Status s = afm::CheckRotationExcitation(&f); !s.ok()) return s;

  // The joint fit, in the gauge of triad `reference`.
  stage("joint solver");
  const int ref = problem.reference;
  f.E = afm::GaugeBasis(K, ref);
  res.gauge_basis = f.E;
  res.gauge = "sum_trace_gyroscope";
  res.gauge_description =
      "triad " + res.names[ref] +
      " fixes the body frame (its position held at the nominal, its accelerometer T upper "
      "triangular) and the scale is fixed by sum_k trace T_g,k = 3K (mean gyroscope gain 1)";
  f.theta.resize(kP * K);
  for (int k = 0; k < K; ++k) f.theta.segment<kP>(kP * k) = PackArrayFullTriad(f.start[k]);
  const FullProblem fp(f.d, f.E);
  BlockLmOptions lo;
  lo.max_iterations = options.max_iterations;
  lo.cost_tolerance = options.tolerance;
  lo.step_tolerance = options.tolerance;
  lo.threads = f.threads;
  lo.executor = options.executor;
  lo.stop = options.stop;
  if (StopRequested(options.stop)) return f.Stopped("joint solver");
  BlockLm<FullProblem> lm(fp, lo);
  if (Status s = afm::SolveJoint(&f, fp, lm); !s.ok()) return s;
  afm::ComputeResiduals(&f, fp);
  afm::EstimateSamplingTimeOffsets(&f);
  stage("crb");
  if (Status s = afm::ComputeCramerRaoBound(&f, lm); !s.ok()) return s;
  if (options.residual_aware_sigma) {
    stage("residual-aware sigma");
    if (Status s = afm::ComputeResidualAwareCovariance(&f, fp); !s.ok()) return s;
  } else {
    res.sigma_ratio = std::numeric_limits<double>::quiet_NaN();
  }
  if (!res.converged)
    res.warnings.push_back(std::string("the solver did not converge (") +
                           BlockLmTerminationName(f.final_summary.termination) +
                           "): the estimate is usable but not at the optimum");
  res.usable = true;
  res.reason = res.converged ? std::string("converged (") +
                                   BlockLmTerminationName(f.summary.termination) + ")"
                             : "not converged: see warnings";
  stage("done");
  return Status::Ok();
}

}  // namespace calibd::core
