// Simulated thermal-calibration logs with a known truth (`calibd simulate thermal`, tests):
// one IMU at rest while it warms up along T(t) = t0 + Δ (1 − e^{−t/τ}) (or a linear ramp),
// optionally followed by a cool-down T(t) = T_end − Δ_c (1 − e^{−(t − t_w)/τ}); per channel the
// bias
//   b(T) = b0 + Σ_{k=1..p} c_k (T − t_ref)^k  (+ hysteresis offset on cooling),
// on each accelerometer axis the gravity part of the reading times 1 + Σ_k d_k (T − t_ref)^k (a
// scale drift; none by default), white noise per channel, a temperature reading with white noise,
// optionally a sensing element that follows the (noise-free) reading through a first-order lag of
// `lag` s (the bias is then evaluated at the element's temperature, which starts equal to the
// reading), and several orientations held for equal parts of the log, in sequence, `cycles` times
// (an instant change between them: the windows around it are not static). Deterministic per seed.
// Thread-compatible.
#ifndef CALIBD_CORE_THERMAL_SIMULATION_H_
#define CALIBD_CORE_THERMAL_SIMULATION_H_

#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace calibd::core {

struct ThermalSimulationOptions {
  double rate = 100;       // Hz
  double warmup = 1800;    // s, duration of the warm-up
  double cooldown = 0;     // s, duration of the cool-down after it (0: none)
  double t0 = 20;          // °C at the start
  double delta = 40;       // °C, asymptotic rise of the warm-up
  double cool_delta = 30;  // °C, asymptotic fall of the cool-down
  double tau = 600;        // s, time constant of both
  // °C/s, > 0: the warm-up is the linear ramp T(t) = t0 + ramp t instead (delta and tau unused
  // for it; a plan's protocol, methods/thermal/thermal_plan.cc). 0: the exponential.
  double ramp = 0;
  double lag = 0;             // s, > 0: the sensing element's lag behind the reading
  double t_ref = 35;          // °C, reference of the truth's polynomials
  double accel_noise = 0.02;  // m/s² per sample
  double gyro_noise = 0.002;  // rad/s per sample
  double temp_noise = 0.01;   // °C per sample
  double gravity = 9.80665;
  int orientations = 1;  // gravity along +z, then −z, +x, −x, +y, −y
  // The orientations' sequence is held this many times over the log (>= 1; each hold then lasts
  // the log / (orientations × cycles)): a tumble repeated through the warm-up and cool-down, so
  // that every face is seen across the range.
  int cycles = 1;
  // Truth: per channel (ax ay az gx gy gz) the coefficients c_1..c_p (SI per °C^k) and b0.
  std::vector<Eigen::VectorXd> coefficients;  // 6 entries; empty: DefaultThermalTruth(3)
  Eigen::Matrix<double, 6, 1> b0 = Eigen::Matrix<double, 6, 1>::Zero();
  // Scale drift per accelerometer axis: d_1..d_p (per °C^k, dimensionless gain change); empty
  // (default) or 3 entries.
  std::vector<Eigen::VectorXd> scale_coefficients;
  Eigen::Matrix<double, 6, 1> hysteresis = Eigen::Matrix<double, 6, 1>::Zero();  // on cooling
  uint64_t seed = 1;
};

struct ThermalSimulation {
  Eigen::VectorXd t;               // s
  Eigen::MatrixX3d accel;          // m/s²
  Eigen::MatrixX3d gyro;           // rad/s
  Eigen::VectorXd temp;            // °C, as read
  ThermalSimulationOptions truth;  // with the coefficients filled in
};

// A plausible truth of order `order` (1..5): MEMS-sized drifts (accelerometer ~1e-3 m/s²/°C,
// gyroscope ~1e-4 rad/s/°C at first order; each further order contributes ~3× less at ±15 °C).
std::vector<Eigen::VectorXd> DefaultThermalTruth(int order);

// A plausible scale drift of order `order` (1..5) per accelerometer axis: ~1e-4 per °C (100 ppm/°C)
// at first order, each further order ~3× less at ±15 °C.
std::vector<Eigen::VectorXd> DefaultThermalScaleTruth(int order);

ThermalSimulation SimulateThermal(const ThermalSimulationOptions& options);

}  // namespace calibd::core

#endif  // CALIBD_CORE_THERMAL_SIMULATION_H_
