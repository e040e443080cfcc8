#include "core/pca_simulation.h"

#include <cmath>

namespace calibd::core {

double PcaRandom::Uniform() {
  // 53 random bits -> (0, 1); never 0, so log() in Normal() is finite.
  for (;;) {
    const double u = static_cast<double>(engine_() >> 11) * 0x1.0p-53;
    if (u > 0) return u;
  }
}

double PcaRandom::Normal() {
  if (has_spare_) {
    has_spare_ = false;
    return spare_;
  }
  const double u1 = Uniform();
  const double u2 = Uniform();
  const double r = std::sqrt(-2.0 * std::log(u1));
  const double phi = 2.0 * M_PI * u2;
  spare_ = r * std::sin(phi);
  has_spare_ = true;
  return r * std::cos(phi);
}

Eigen::MatrixXd PcaRandom::NormalMatrix(int rows, int cols) {
  Eigen::MatrixXd x(rows, cols);
  for (int j = 0; j < cols; ++j) {
    for (int i = 0; i < rows; ++i) x(i, j) = Normal();
  }
  return x;
}

Eigen::VectorXd PcaRandom::UnitVector(int d) {
  for (;;) {
    Eigen::VectorXd x(d);
    for (int i = 0; i < d; ++i) x(i) = Normal();
    const double norm = x.norm();
    if (norm > 1e-12) return x / norm;
  }
}

Eigen::MatrixXd PcaRandom::SphereColumns(int d, int n, double radius) {
  Eigen::MatrixXd v(d, n);
  for (int j = 0; j < n; ++j) v.col(j) = radius * UnitVector(d);
  return v;
}

Eigen::MatrixXd PcaModelSensitivities() {
  Eigen::MatrixXd a(3, 12);
  a << 1, 0, 0, 0, 1, 0, 0, -1, 0, 1, 0, 0,  //
      0, 1, 0, -1, 0, 0, 1, 0, 0, 0, 0, -1,  //
      0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 1, 0;
  return a;
}

bool PcaSimulationOptions::IsValid(std::string* error) const {
  auto fail = [error](const char* what) {
    if (error != nullptr) *error = what;
    return false;
  };
  if (positions < 1) return fail("positions must be >= 1");
  if (!(noise_std >= 0) || !std::isfinite(noise_std)) return fail("noise_std must be >= 0");
  if (!(axis_perturbation >= 0) || !std::isfinite(axis_perturbation)) {
    return fail("axis_perturbation must be >= 0");
  }
  if (!(magnitude > 0) || !std::isfinite(magnitude)) return fail("magnitude must be > 0");
  if (!(bias_std >= 0) || !std::isfinite(bias_std)) return fail("bias_std must be >= 0");
  return true;
}

PcaSimulation SimulatePca(const PcaSimulationOptions& options) {
  PcaRandom rng(options.seed);
  PcaSimulation sim;
  sim.a_model = PcaModelSensitivities();
  const int m = static_cast<int>(sim.a_model.cols());
  const int n = options.positions;
  // Draw order is part of the reproducibility contract: axes, biases, orientations, noise.
  sim.a_true = sim.a_model + options.axis_perturbation * rng.NormalMatrix(3, m);
  sim.b = Eigen::VectorXd::Zero(m);
  if (options.bias_std > 0) sim.b = options.bias_std * rng.NormalMatrix(m, 1);
  sim.v = rng.SphereColumns(3, n, options.magnitude);
  sim.m = sim.a_true.transpose() * sim.v;
  sim.m.colwise() += sim.b;
  if (options.noise_std > 0) sim.m += options.noise_std * rng.NormalMatrix(m, n);
  for (int k = 0; k < 4; ++k) {
    for (const char* axis : {"x", "y", "z"}) {
      sim.sensor_names.push_back("g" + std::to_string(k) + "_" + axis);
    }
  }
  return sim;
}

}  // namespace calibd::core
