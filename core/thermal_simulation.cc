// Simulated thermal logs (core/thermal_simulation.h).
#include "core/thermal_simulation.h"

#include <cmath>

#include "core/pca_simulation.h"
#include "core/thermal.h"

namespace calibd::core {

std::vector<Eigen::VectorXd> DefaultThermalTruth(int order) {
  std::vector<Eigen::VectorXd> out;
  const double first[6] = {1.2e-3, -0.8e-3, 1.5e-3, 1.0e-4, -0.6e-4, 0.8e-4};
  for (int c = 0; c < 6; ++c) {
    Eigen::VectorXd v(order);
    double size = first[c];
    for (int k = 0; k < order; ++k) {
      v(k) = size * ((k + c) % 2 == 0 ? 1 : -1);
      size /= 45.0;  // each order contributes ~3× less than the one before at ±15 °C
    }
    out.push_back(v);
  }
  return out;
}

std::vector<Eigen::VectorXd> DefaultThermalScaleTruth(int order) {
  std::vector<Eigen::VectorXd> out;
  const double first[3] = {1.0e-4, -1.5e-4, 2.0e-4};
  for (int a = 0; a < 3; ++a) {
    Eigen::VectorXd v(order);
    double size = first[a];
    for (int k = 0; k < order; ++k) {
      v(k) = size * ((k + a) % 2 == 0 ? 1 : -1);
      size /= 45.0;
    }
    out.push_back(v);
  }
  return out;
}

namespace {

Eigen::Vector3d GravityDirection(int orientation) {
  const int axis = orientation < 2 ? 2 : (orientation < 4 ? 0 : 1);
  Eigen::Vector3d d = Eigen::Vector3d::Zero();
  d(axis) = orientation % 2 == 0 ? 1 : -1;
  return d;
}

}  // namespace

ThermalSimulation SimulateThermal(const ThermalSimulationOptions& options) {
  ThermalSimulation sim;
  sim.truth = options;
  if (sim.truth.coefficients.empty()) sim.truth.coefficients = DefaultThermalTruth(3);
  const ThermalSimulationOptions& o = sim.truth;
  const int64_t n = static_cast<int64_t>(std::llround((o.warmup + o.cooldown) * o.rate));
  sim.t.resize(n);
  sim.accel.resize(n, 3);
  sim.gyro.resize(n, 3);
  sim.temp.resize(n);
  PcaRandom rng(o.seed);
  const auto warm = [&o](double t) {
    return o.ramp > 0 ? o.t0 + o.ramp * t : o.t0 + o.delta * (1 - std::exp(-t / o.tau));
  };
  const double t_peak = warm(o.warmup);
  const int orientations = std::max(1, std::min(6, o.orientations));
  const int64_t cycles = std::max(1, o.cycles);
  double sensor = o.t0, previous = o.t0;  // the element's temperature and the last true reading
  for (int64_t i = 0; i < n; ++i) {
    const double t = i / o.rate;
    const bool cooling = t > o.warmup;
    const double temp =
        cooling ? t_peak - o.cool_delta * (1 - std::exp(-(t - o.warmup) / o.tau)) : warm(t);
    const int orientation = static_cast<int>(i * orientations * cycles / n) % orientations;
    const Eigen::Vector3d g = o.gravity * GravityDirection(orientation);
    sim.t(i) = t;
    sim.temp(i) = temp + o.temp_noise * rng.Normal();
    // The lag integrated as core/thermal_lag.cc does (the step's mean reading), without noise.
    sensor = o.lag > 0 && i > 0
                 ? sensor - std::expm1(-1.0 / (o.rate * o.lag)) * (0.5 * (temp + previous) - sensor)
                 : temp;
    previous = temp;
    for (int c = 0; c < 6; ++c) {
      double b = o.b0(c) + ThermalCurve(o.coefficients[static_cast<size_t>(c)], sensor - o.t_ref);
      if (cooling) b += o.hysteresis(c);
      if (c < 3) {
        const double gain = o.scale_coefficients.empty()
                                ? 1.0
                                : 1.0 + ThermalCurve(o.scale_coefficients[static_cast<size_t>(c)],
                                                     sensor - o.t_ref);
        sim.accel(i, c) = g(c) * gain + b + o.accel_noise * rng.Normal();
      } else {
        sim.gyro(i, c - 3) = b + o.gyro_noise * rng.Normal();
      }
    }
  }
  return sim;
}

}  // namespace calibd::core
