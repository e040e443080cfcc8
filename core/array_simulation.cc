#include "core/array_simulation.h"

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <cmath>

namespace calibd::core {
namespace {

// The seed of an independent random stream derived from the user's seed (SplitMix64 finaliser).
uint64_t StreamSeed(uint64_t seed, uint64_t stream) {
  uint64_t z = seed + stream * 0x9E3779B97F4A7C15ULL;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}
constexpr uint64_t kAccelErrorStream = 1;
constexpr uint64_t kStaticStream = 2;

bool HasAccelErrors(const ArraySimulationOptions& o) {
  return o.accel_bias > 0 || o.accel_scale_error > 0 || o.accel_misalignment > 0;
}

}  // namespace

double GaussianRng::Uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }

double GaussianRng::Normal() {
  if (has_spare_) {
    has_spare_ = false;
    return spare_;
  }
  const double u1 = 1.0 - Uniform();  // (0, 1]
  const double u2 = Uniform();
  const double radius = std::sqrt(-2.0 * std::log(u1));
  const double angle = 2.0 * 3.14159265358979323846 * u2;
  spare_ = radius * std::sin(angle);
  has_spare_ = true;
  return radius * std::cos(angle);
}

Eigen::Vector3d GaussianRng::UnitVector() {
  for (;;) {
    Eigen::Vector3d v;
    v.x() = Normal();
    v.y() = Normal();
    v.z() = Normal();
    const double n = v.norm();
    if (n > 1e-12) return v / n;
  }
}

bool ArraySimulationOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  auto ok = [](double v) { return std::isfinite(v) && v >= 0; };
  if (samples < 1) return fail("samples (N) must be >= 1");
  if (!ok(omega_norm)) return fail("omega_norm must be a finite number >= 0");
  if (!ok(omega_dot_norm)) return fail("omega_dot_norm must be a finite number >= 0");
  if (!ok(specific_force_norm)) return fail("specific_force_norm must be a finite number >= 0");
  if (!ok(accel_noise)) return fail("accel_noise must be a finite number >= 0");
  if (!ok(gyro_noise)) return fail("gyro_noise must be a finite number >= 0");
  if (!ok(position_perturbation)) return fail("position_perturbation must be a finite number >= 0");
  if (reference < 0 || reference >= 32) return fail("reference must be a triad index in [0, 32)");
  if (!ok(accel_bias)) return fail("accel_bias must be a finite number >= 0");
  if (!ok(accel_scale_error) || accel_scale_error >= 0.5)
    return fail("accel_scale_error must be a finite number >= 0 and < 0.5");
  if (!ok(accel_misalignment) || accel_misalignment >= 0.5)
    return fail("accel_misalignment must be a finite number >= 0 and < 0.5 (rad)");
  return true;
}

Eigen::Matrix3Xd PaperArrayNominalPositions() {
  Eigen::Matrix3Xd r(3, 32);
  const double pitch = 6.3e-3, half_gap = 1e-3;
  for (int side = 0; side < 2; ++side)
    for (int row = 0; row < 4; ++row)
      for (int col = 0; col < 4; ++col)
        r.col(16 * side + 4 * row + col) << (col - 1.5) * pitch, (row - 1.5) * pitch,
            side == 0 ? half_gap : -half_gap;
  return r;
}

void SimulateArrayReadings(const Eigen::Matrix3Xd& positions, const Eigen::Matrix3Xd& omega,
                           const Eigen::Matrix3Xd& omega_dot, const Eigen::Matrix3Xd& s,
                           double accel_noise, double gyro_noise, int gyro_triads, GaussianRng* rng,
                           Eigen::MatrixXd* accel, Eigen::MatrixXd* gyro,
                           const std::vector<AccelerometerTriadModel>* accel_models) {
  const int K = positions.cols();
  const int64_t N = omega.cols();
  accel->resize(N, 3 * K);
  gyro->resize(N, 3 * gyro_triads);
  for (int64_t n = 0; n < N; ++n) {
    const Eigen::Vector3d w = omega.col(n), wd = omega_dot.col(n);
    for (int k = 0; k < K; ++k) {
      const Eigen::Vector3d r = positions.col(k);
      Eigen::Vector3d y = s.col(n) + w.cross(w.cross(r)) + wd.cross(r);
      if (accel_models != nullptr)
        y = (*accel_models)[k].sensitivity.transpose() * y + (*accel_models)[k].bias;
      for (int i = 0; i < 3; ++i) (*accel)(n, 3 * k + i) = y(i) + accel_noise * rng->Normal();
    }
    for (int j = 0; j < gyro_triads; ++j)
      for (int i = 0; i < 3; ++i) (*gyro)(n, 3 * j + i) = w(i) + gyro_noise * rng->Normal();
  }
}

Status SimulateArray(const ArraySimulationOptions& options, ArraySimulation* out) {
  std::string error;
  if (!options.IsValid(&error)) return Status::InvalidInput(error);
  GaussianRng rng(options.seed);
  const Eigen::Matrix3Xd nominal = PaperArrayNominalPositions();
  const int K = nominal.cols();
  out->true_positions = nominal;
  for (int k = 0; k < K; ++k) {
    if (k == options.reference) continue;
    for (int i = 0; i < 3; ++i)
      out->true_positions(i, k) += options.position_perturbation * rng.Normal();
  }
  const int64_t N = options.samples;
  out->omega.resize(3, N);
  out->omega_dot.resize(3, N);
  out->s.resize(3, N);
  out->problem = ArrayProblem();
  out->problem.nominal_positions = nominal;
  out->problem.reference = options.reference;
  out->problem.accel.resize(N, 3 * K);
  out->problem.gyro.resize(N, 3 * K);
  out->problem.accel_names.clear();
  out->gyro_names.clear();
  for (int k = 0; k < K; ++k) {
    out->problem.accel_names.push_back("a" + std::to_string(k));
    out->gyro_names.push_back("g" + std::to_string(k));
  }
  out->accel_models = SimulateAccelerometerModels(options);
  const std::vector<AccelerometerTriadModel>* models =
      HasAccelErrors(options) ? &out->accel_models : nullptr;
  Eigen::MatrixXd accel, gyro;
  for (int64_t n = 0; n < N; ++n) {
    out->omega.col(n) = options.omega_norm * rng.UnitVector();
    out->omega_dot.col(n) = options.omega_dot_norm * rng.UnitVector();
    out->s.col(n) = options.specific_force_norm * rng.UnitVector();
    SimulateArrayReadings(out->true_positions, out->omega.col(n), out->omega_dot.col(n),
                          out->s.col(n), options.accel_noise, options.gyro_noise, K, &rng, &accel,
                          &gyro, models);
    out->problem.accel.row(n) = accel.row(0);
    out->problem.gyro.row(n) = gyro.row(0);
  }
  return Status::Ok();
}

std::vector<AccelerometerTriadModel> SimulateAccelerometerModels(
    const ArraySimulationOptions& options) {
  const int K = static_cast<int>(PaperArrayNominalPositions().cols());
  std::vector<AccelerometerTriadModel> models(K);
  if (!HasAccelErrors(options)) return models;
  GaussianRng rng(StreamSeed(options.seed, kAccelErrorStream));
  // Draws per triad, always all of them (so each sigma changes only its own errors): 3 scale
  // errors, 6 misalignments (row-major off-diagonal), 3 biases.
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  for (AccelerometerTriadModel& m : models) {
    Eigen::Vector3d scale;
    for (int i = 0; i < 3; ++i) scale(i) = 1 + options.accel_scale_error * rng.Normal();
    Eigen::Matrix3d tilt = Eigen::Matrix3d::Identity();
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (i != j) tilt(i, j) = options.accel_misalignment * rng.Normal();
    for (int i = 0; i < 3; ++i) m.bias(i) = options.accel_bias * rng.Normal();
    m.sensitivity = (scale.asDiagonal() * tilt).transpose();  // A_k^T = diag(1 + s)(I + M)
    sum += m.sensitivity;
  }
  // Remove the common rotation: with sum = U S V^T, Q = V U^T makes sum_k Q A_k = V S V^T.
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d q = svd.matrixV() * svd.matrixU().transpose();
  for (AccelerometerTriadModel& m : models) m.sensitivity = q * m.sensitivity;
  return models;
}

Status SimulateArrayStatic(const ArraySimulationOptions& options, int positions, double noise_std,
                           double gravity, ArrayStaticSimulation* out) {
  std::string error;
  if (!options.IsValid(&error)) return Status::InvalidInput(error);
  if (positions < 1) return Status::InvalidInput("static positions must be >= 1");
  if (!(std::isfinite(noise_std) && noise_std >= 0))
    return Status::InvalidInput("static noise must be a finite number >= 0");
  if (!(std::isfinite(gravity) && gravity > 0))
    return Status::InvalidInput("gravity must be a finite number > 0");
  out->models = SimulateAccelerometerModels(options);
  const int K = static_cast<int>(out->models.size());
  out->sensor_names.clear();
  for (int k = 0; k < K; ++k)
    for (const char* axis : {"_x", "_y", "_z"})
      out->sensor_names.push_back("a" + std::to_string(k) + axis);
  GaussianRng rng(StreamSeed(options.seed, kStaticStream));
  out->field.resize(3, positions);
  out->readings.resize(3 * K, positions);
  for (int j = 0; j < positions; ++j) {
    const Eigen::Vector3d f = gravity * rng.UnitVector();
    out->field.col(j) = f;
    for (int k = 0; k < K; ++k) {
      const Eigen::Vector3d y = out->models[k].sensitivity.transpose() * f + out->models[k].bias;
      for (int i = 0; i < 3; ++i) out->readings(3 * k + i, j) = y(i) + noise_std * rng.Normal();
    }
  }
  return Status::Ok();
}

}  // namespace calibd::core
