#include "core/array_full_simulation.h"

#include <cmath>
#include <string>

namespace calibd::core {

bool ArrayFullSimulationOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  const int K = static_cast<int>(nominal_positions.cols());
  if (nominal_positions.rows() != 3 || K < 3 || !nominal_positions.allFinite())
    return fail("nominal_positions must be 3 x K with K >= 3, finite");
  if (reference < 0 || reference >= K) return fail("reference out of range");
  if (!(rate > 0) || !std::isfinite(rate)) return fail("rate must be > 0");
  if (statics < 0 || !(static_duration > 0)) return fail("statics >= 0, static_duration > 0");
  if (dynamic_samples < 0) return fail("dynamic_samples must be >= 0");
  for (double v : {omega_norm, omega_dot_norm, specific_force_norm, accel_noise, gyro_noise,
                   gain_error, misalignment, accel_bias, gyro_bias, position_perturbation})
    if (!(v >= 0) || !std::isfinite(v)) return fail("magnitudes and sigmas must be finite, >= 0");
  if (!omega_axes.allFinite() || !(omega_axes.cwiseAbs().maxCoeff() > 0))
    return fail("omega_axes must be finite and not all zero");
  if (!(gravity > 0) || !std::isfinite(gravity)) return fail("gravity must be > 0");
  if (rotation_axis && (!rotation_axis->allFinite() || !(rotation_axis->norm() > 0)))
    return fail("rotation_axis must be finite and not zero");
  for (size_t j = 0; j < static_directions.size(); ++j)
    if (!static_directions[j].allFinite() || !(static_directions[j].norm() > 0))
      return fail("static_directions[" + std::to_string(j) + "] must be finite and not zero");
  return true;
}

Eigen::Matrix3Xd Mimu4444NominalPositions() {
  Eigen::Matrix3Xd r(3, 8);
  const double a = 0.00945, h = 0.001;
  r << -a, -a, -a, -a, a, a, a, a,  //
      a, a, -a, -a, a, a, -a, -a,   //
      h, -h, h, -h, h, -h, h, -h;
  return r;
}

Status SimulateArrayFull(const ArrayFullSimulationOptions& o, ArrayFullSimulation* out) {
  std::string error;
  if (!o.IsValid(&error)) return Status::InvalidInput(error);
  *out = ArrayFullSimulation();
  const int K = static_cast<int>(o.nominal_positions.cols());
  GaussianRng rng(o.seed);
  auto draw_T = [&](bool upper) {
    Eigen::Matrix3d T;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        T(i, j) = i == j ? 1 + o.gain_error * rng.Normal() : o.misalignment * rng.Normal();
    if (upper) T(1, 0) = T(2, 0) = T(2, 1) = 0;
    return T;
  };
  out->truth.resize(K);
  double trace = 0;
  for (int k = 0; k < K; ++k) {
    ArrayFullTriad& t = out->truth[k];
    t.accel_T = draw_T(k == o.reference);
    for (int i = 0; i < 3; ++i) t.accel_bias(i) = o.accel_bias * rng.Normal();
    t.gyro_T = draw_T(false);
    for (int i = 0; i < 3; ++i) t.gyro_bias(i) = o.gyro_bias * rng.Normal();
    t.position = o.nominal_positions.col(k);
    if (k != o.reference)
      for (int i = 0; i < 3; ++i) t.position(i) += o.position_perturbation * rng.Normal();
    trace += t.gyro_T.trace();
  }
  for (auto& t : out->truth) t.gyro_T *= 3.0 * K / trace;  // the scale gauge
  out->truth_theta.resize(27 * K);
  for (int k = 0; k < K; ++k)
    out->truth_theta.segment<27>(27 * k) = PackArrayFullTriad(out->truth[k]);

  const int64_t per_static = std::max<int64_t>(1, std::llround(o.static_duration * o.rate));
  out->static_samples_per_orientation = per_static;
  const int statics =
      o.static_directions.empty() ? o.statics : static_cast<int>(o.static_directions.size());
  const int64_t N = statics * per_static + o.dynamic_samples;
  ArrayFullProblem& p = out->problem;
  p.nominal_positions = o.nominal_positions;
  p.reference = o.reference;
  p.t.resize(N);
  p.accel.resize(N, 3 * K);
  p.gyro.resize(N, 3 * K);
  out->motion.resize(9, N);
  for (int64_t n = 0; n < N; ++n) p.t(n) = static_cast<double>(n) / o.rate;
  std::vector<Eigen::Vector3d> dirs(statics);
  for (int j = 0; j < statics; ++j) {
    dirs[j] = o.gravity * (o.static_directions.empty() ? rng.UnitVector()
                                                       : o.static_directions[j].normalized());
  }
  auto emit = [&](int64_t n, const Eigen::Vector3d& w, const Eigen::Vector3d& wd,
                  const Eigen::Vector3d& s) {
    out->motion.col(n) << w, wd, s;
    Eigen::Matrix3d A = w * w.transpose() - w.squaredNorm() * Eigen::Matrix3d::Identity();
    A(0, 1) -= wd.z();
    A(0, 2) += wd.y();
    A(1, 0) += wd.z();
    A(1, 2) -= wd.x();
    A(2, 0) -= wd.y();
    A(2, 1) += wd.x();
    for (int k = 0; k < K; ++k) {
      const ArrayFullTriad& t = out->truth[k];
      const Eigen::Vector3d u = A * t.position + s;
      Eigen::Vector3d ya = t.accel_T * u + t.accel_bias, yg = t.gyro_T * w + t.gyro_bias;
      for (int i = 0; i < 3; ++i) ya(i) += o.accel_noise * rng.Normal();
      for (int i = 0; i < 3; ++i) yg(i) += o.gyro_noise * rng.Normal();
      p.accel.row(n).segment<3>(3 * k) = ya.transpose();
      p.gyro.row(n).segment<3>(3 * k) = yg.transpose();
    }
  };
  int64_t n = 0;
  for (int j = 0; j < statics; ++j)
    for (int64_t i = 0; i < per_static; ++i, ++n)
      emit(n, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), dirs[j]);
  for (int64_t m = 0; m < o.dynamic_samples; ++m, ++n) {
    Eigen::Vector3d w, wd;
    if (o.rotation_axis) {
      const Eigen::Vector3d axis = o.rotation_axis->normalized();
      w = (rng.Uniform() < 0.5 ? 1 : -1) * o.omega_norm * axis;
      wd = (rng.Uniform() < 0.5 ? 1 : -1) * o.omega_dot_norm * axis;
    } else {
      w = rng.UnitVector().cwiseProduct(o.omega_axes);
      w = w.norm() > 0 ? Eigen::Vector3d(o.omega_norm * w.normalized()) : Eigen::Vector3d::Zero();
      wd = o.omega_dot_norm * rng.UnitVector();
    }
    const Eigen::Vector3d s = o.specific_force_norm * rng.UnitVector();
    emit(n, w, wd, s);
  }
  return Status::Ok();
}

}  // namespace calibd::core
