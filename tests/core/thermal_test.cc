// Tests of the thermal calibration (core/thermal.h) on simulated warm-up logs with a known
// polynomial truth: exact recovery without noise, Monte-Carlo honesty of the curve's band (also
// with a too-high max_order offered), the BIC weight of the true order, the min_range refusal, the
// hysteresis test's false-alarm rate and power; the error against a fixed-order least-squares fit
// of all samples (the flight stacks' approach); the lag's estimate, its σ and its refusal.
#include "core/thermal.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "core/thermal_simulation.h"

namespace calibd::core {
namespace {

ThermalSimulationOptions Warmup(uint64_t seed) {
  ThermalSimulationOptions o;
  o.rate = 50;
  o.warmup = 1800;
  o.seed = seed;
  return o;
}

Status Calibrate(const ThermalSimulation& sim, const ThermalOptions& options, ThermalResult* out) {
  const std::vector<ThermalImuInput> imus = {{"0", &sim.accel, &sim.gyro, &sim.temp}};
  return CalibrateThermal(sim.t, imus, options, out);
}

// The true deviation of channel c at T, relative to its value at the result's t_ref.
double TrueDeviation(const ThermalSimulation& sim, int c, double temp, double t_ref) {
  const Eigen::VectorXd& coef = sim.truth.coefficients[static_cast<size_t>(c)];
  return ThermalCurve(coef, temp - sim.truth.t_ref) - ThermalCurve(coef, t_ref - sim.truth.t_ref);
}

TEST(ThermalTest, RecoversTheCurveWithoutNoise) {
  ThermalSimulationOptions o = Warmup(1);
  o.accel_noise = o.gyro_noise = 0;
  o.temp_noise = 0;
  const ThermalSimulation sim = SimulateThermal(o);
  // Without noise the drift itself sets the spread: a fixed static threshold says the log is at
  // rest throughout.
  ThermalOptions options;
  options.window = 1;  // the window mean of a curved bias departs from the curve by ~c2 var(T)
  options.statics.accel_threshold = options.statics.gyro_threshold = 1.0;
  options.min_order = 0;  // every order offered: the data alone rule out those below the truth
  ThermalResult r;
  const Status st = Calibrate(sim, options, &r);
  ASSERT_TRUE(st.ok()) << st.message();
  const ThermalImuResult& imu = r.imus.at(0);
  EXPECT_GT(imu.t_max - imu.t_min, 30);
  for (int c = 0; c < 6; ++c) {
    const ThermalChannel& ch = imu.channels[static_cast<size_t>(c)];
    double below_truth = 0;  // BIC weight of the orders below the true 3
    for (const ThermalOrderRow& row : ch.fit.table) below_truth += row.order < 3 ? row.weight : 0;
    EXPECT_LT(below_truth, 1e-9) << ch.name;
    for (Eigen::Index i = 0; i < imu.grid.size(); ++i) {
      // The window mean of a curved bias differs from the bias at the window's mean temperature
      // by ~c2 × var(T within a window): ~1e-8 with 1 s windows.
      EXPECT_NEAR(ch.grid_value(i), TrueDeviation(sim, c, imu.grid(i), imu.t_ref), 1e-7)
          << ch.name << " at " << imu.grid(i) << " °C";
    }
  }
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR((*imu.gyro_at_t_ref)(a),
                ThermalCurve(sim.truth.coefficients[static_cast<size_t>(3 + a)],
                             imu.t_ref - sim.truth.t_ref),
                1e-8);
  }
}

// z of the curve against the truth over the grid (t_ref excluded: there σ = 0), per channel, over
// A truth of order 5 whose 4th and 5th orders are not small (ArduPilot's "very poor fit" of a
// cubic on the ICM-42688): each changes the bias as much as the first order does at 20 °C from
// t_ref.
std::vector<Eigen::VectorXd> StrongOrder5Truth() {
  std::vector<Eigen::VectorXd> truth = DefaultThermalTruth(5);
  for (Eigen::VectorXd& c : truth) {
    c(3) = -c(0) / std::pow(20.0, 3);
    c(4) = c(0) / std::pow(20.0, 4);
  }
  return truth;
}

// `trials` seeds; also the mean BIC weight of `true_order` per channel. `truth`: the simulated
// coefficients (empty: DefaultThermalTruth(true_order)).
struct Honesty {
  double z_rms[6] = {0};
  double true_order_weight[6] = {0};
};

Honesty MonteCarlo(int trials, int min_order, int max_order, int true_order,
                   const std::vector<Eigen::VectorXd>& truth = {}) {
  Honesty h;
  double sum[6] = {0};
  int count[6] = {0};
  for (int trial = 0; trial < trials; ++trial) {
    ThermalSimulationOptions o = Warmup(100 + static_cast<uint64_t>(trial));
    o.coefficients = truth.empty() ? DefaultThermalTruth(true_order) : truth;
    const ThermalSimulation sim = SimulateThermal(o);
    ThermalOptions options;
    options.min_order = min_order;
    options.max_order = max_order;
    options.grid_points = 11;
    ThermalResult r;
    const Status st = Calibrate(sim, options, &r);
    EXPECT_TRUE(st.ok()) << st.message();
    if (!st.ok()) continue;
    const ThermalImuResult& imu = r.imus[0];
    for (int c = 0; c < 6; ++c) {
      const ThermalChannel& ch = imu.channels[static_cast<size_t>(c)];
      for (const ThermalOrderRow& row : ch.fit.table) {
        if (row.order == true_order) h.true_order_weight[c] += row.weight / trials;
      }
      for (Eigen::Index i = 0; i < imu.grid.size(); ++i) {
        if (std::abs(imu.grid(i) - imu.t_ref) < 1e-6) continue;  // σ = 0 there (up to rounding)
        const double z =
            (ch.grid_value(i) - TrueDeviation(sim, c, imu.grid(i), imu.t_ref)) / ch.grid_std(i);
        sum[c] += z * z;
        ++count[c];
      }
    }
  }
  for (int c = 0; c < 6; ++c) h.z_rms[c] = std::sqrt(sum[c] / std::max(1, count[c]));
  return h;
}

// 100 trials × 10 grid points: a z RMS estimated from 100 independent trials has a relative σ of
// ~1/√200 = 7 % (the grid points of one trial are correlated, so not less); 0.7–1.4 is > 4σ
// either side, while a σ off by 1.5× (e.g. a missing χ² scaling) falls outside.
TEST(ThermalTest, BandIsHonestInMonteCarlo) {
  const Honesty h = MonteCarlo(100, 3, 5, 3);
  for (int c = 0; c < 6; ++c) {
    std::printf("channel %d: z RMS %.3f, mean weight of order 3 %.2f\n", c, h.z_rms[c],
                h.true_order_weight[c]);
    EXPECT_GT(h.z_rms[c], 0.7);
    EXPECT_LT(h.z_rms[c], 1.4);
    // The true order carries nearly all the weight on average: the penalty k ln N of the samples
    // (0.98–0.99 measured; with the windows' k ln n it was 0.83–0.86, the rest on orders 4–5).
    EXPECT_GE(h.true_order_weight[c], 0.95);
  }
}

// The flight stacks' cubic is the wrong order: a truth of order 5 whose 4th and 5th orders
// matter (ComparedWithTheFlightStacksCubic's case (b)). Gyroscope y's are weak against its noise,
// so the curve's weights (penalty k ln N) often drop them; the band's weights (k ln n) keep them
// in the spread. Measured z RMS 0.97–1.10 (gyroscope y's weight of order 5 0.81); with the
// curve's weights for the band too, gyroscope y's was 1.39 and 1.30 on two other seed sets (100
// and 400 logs). Same margins as BandIsHonestInMonteCarlo.
TEST(ThermalTest, BandIsHonestWhenTheCubicIsTheWrongOrder) {
  const Honesty h = MonteCarlo(100, 3, 5, 5, StrongOrder5Truth());
  for (int c = 0; c < 6; ++c) {
    std::printf("channel %d (strong orders 4, 5): z RMS %.3f, mean weight of order 5 %.2f\n", c,
                h.z_rms[c], h.true_order_weight[c]);
    EXPECT_GT(h.z_rms[c], 0.7);
    EXPECT_LT(h.z_rms[c], 1.4);
  }
}

// A truth of order 2 with orders up to 8 offered: from order 0 (the weights alone decide, and
// order 2 carries most of them) and from the default floor 3 (the unneeded cubic widens the band
// and leaves it unbiased).
TEST(ThermalTest, BandStaysHonestWithTooHighMaxOrder) {
  for (const int min_order : {0, 3}) {
    const Honesty h = MonteCarlo(100, min_order, 8, 2);
    for (int c = 0; c < 6; ++c) {
      std::printf("channel %d (orders %d..8, truth 2): z RMS %.3f, mean weight of order 2 %.2f\n",
                  c, min_order, h.z_rms[c], h.true_order_weight[c]);
      EXPECT_GT(h.z_rms[c], 0.7);
      EXPECT_LT(h.z_rms[c], 1.4);
      if (min_order == 0) {
        EXPECT_GE(h.true_order_weight[c], 0.5);
      }
    }
  }
}

TEST(ThermalTest, MinOrderIsValidatedAndCapped) {
  const ThermalSimulation sim = SimulateThermal(Warmup(4));
  ThermalOptions options;
  options.min_order = 9;
  ThermalResult r;
  Status st = Calibrate(sim, options, &r);
  ASSERT_EQ(st.code(), StatusCode::kInvalidInput);
  EXPECT_NE(st.message().find("min_order must be in [0, 8]"), std::string::npos) << st.message();
  // A floor above max_order is capped at it: one order, weight 1.
  options.min_order = 3;
  options.max_order = 2;
  st = Calibrate(sim, options, &r);
  ASSERT_TRUE(st.ok()) << st.message();
  for (const ThermalChannel& ch : r.imus[0].channels) {
    ASSERT_EQ(ch.fit.table.size(), 1u) << ch.name;
    EXPECT_EQ(ch.fit.table[0].order, 2);
    EXPECT_EQ(ch.fit.table[0].weight, 1.0);
  }
}

// The windows' σ come from a variance function of temperature (core/thermal.h stage 1): a gyroscope
// x whose noise grows from 0.002 to 0.0045 rad/s over the warm-up (extra white noise of σ 0 at
// 20 °C to 0.004 at 58 °C) gets window σ that follow it, and its band stays honest. 40 trials: a
// z RMS from 40 logs has a relative σ of ~11 %, 0.7–1.4 is > 2.7σ either side; a window σ from
// one log's fit is within a few % of the truth, 12 % is > 3σ (a constant σ would miss the hot end
// by 55 %).
TEST(ThermalTest, WindowSigmaFollowsANoiseThatGrowsWithTemperature) {
  double z2 = 0;
  int count = 0;
  for (int trial = 0; trial < 40; ++trial) {
    ThermalSimulation sim = SimulateThermal(Warmup(300 + static_cast<uint64_t>(trial)));
    std::mt19937_64 rng(900 + static_cast<uint64_t>(trial));
    std::normal_distribution<double> normal;
    const auto extra = [](double temp) { return 0.004 * std::max(0.0, (temp - 20) / 38); };
    for (Eigen::Index i = 0; i < sim.t.size(); ++i)
      sim.gyro(i, 0) += extra(sim.temp(i)) * normal(rng);
    ThermalOptions options;
    options.grid_points = 11;
    ThermalResult r;
    const Status st = Calibrate(sim, options, &r);
    ASSERT_TRUE(st.ok()) << st.message();
    const ThermalImuResult& imu = r.imus[0];
    for (const ThermalWindow* w : {&imu.windows.front(), &imu.windows.back()}) {
      const double truth = std::hypot(0.002, extra(w->temperature));
      EXPECT_NEAR(w->mean_std(3) * std::sqrt(static_cast<double>(w->samples)), truth, 0.12 * truth)
          << "trial " << trial << " at " << w->temperature << " °C";
    }
    const ThermalChannel& ch = imu.channels[3];
    for (Eigen::Index i = 0; i < imu.grid.size(); ++i) {
      if (std::abs(imu.grid(i) - imu.t_ref) < 1e-6) continue;
      z2 += std::pow(
          (ch.grid_value(i) - TrueDeviation(sim, 3, imu.grid(i), imu.t_ref)) / ch.grid_std(i), 2);
      ++count;
    }
  }
  const double z = std::sqrt(z2 / count);
  std::printf("noise growing with temperature: gyroscope x z RMS %.3f\n", z);
  EXPECT_GT(z, 0.7);
  EXPECT_LT(z, 1.4);
}

TEST(ThermalTest, RefusesARangeBelowMinRange) {
  ThermalSimulationOptions o = Warmup(3);
  o.delta = 4;
  const ThermalSimulation sim = SimulateThermal(o);
  // Without noise the drift itself sets the spread: a fixed static threshold says the log is at
  // rest throughout.
  ThermalOptions options;
  options.window = 1;  // the window mean of a curved bias departs from the curve by ~c2 var(T)
  options.statics.accel_threshold = options.statics.gyro_threshold = 1.0;
  ThermalResult r;
  const Status st = Calibrate(sim, options, &r);
  ASSERT_EQ(st.code(), StatusCode::kNotDeterminable);
  EXPECT_NE(st.message().find("min_range 10"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("span 3."), std::string::npos) << st.message();
}

// Heating then cooling without hysteresis: the Bonferroni test at α = 1 % over 6 channels × 11
// points flags at most ~1 % of logs. 200 trials: under a true rate of 1 % more than 7 flags has
// probability < 0.5 %; a test without the multiplicity correction (α per point) flags far more.
// With a hysteresis of 10σ of a window mean on one gyroscope axis it is flagged every time.
TEST(ThermalTest, HysteresisFalseAlarmRateAndPower) {
  int false_alarms = 0, detections = 0;
  const int trials = 200;
  for (int trial = 0; trial < trials; ++trial) {
    for (int with = 0; with < 2; ++with) {
      if (with && trial >= 20) continue;
      ThermalSimulationOptions o = Warmup(1000 + static_cast<uint64_t>(trial));
      o.warmup = 1200;
      o.cooldown = 1200;
      o.rate = 20;
      if (with) o.hysteresis(4) = 1e-3;  // rad/s, ~20× σ of one window mean (0.002/√200)
      const ThermalSimulation sim = SimulateThermal(o);
      ThermalOptions options;
      options.grid_points = 11;
      ThermalResult r;
      ASSERT_TRUE(Calibrate(sim, options, &r).ok());
      bool flagged = false;
      for (const ThermalChannel& ch : r.imus[0].channels) {
        EXPECT_TRUE(ch.hysteresis_tested) << ch.name;
        flagged = flagged || ch.hysteresis_flagged;
      }
      (with ? detections : false_alarms) += flagged;
    }
  }
  std::printf("hysteresis: %d false alarms in %d logs, %d/20 detected\n", false_alarms, trials,
              detections);
  EXPECT_LE(false_alarms, 7);
  EXPECT_EQ(detections, 20);
}

// The flight stacks' fit: ArduPilot (AP_InertialSensor_tempcal.cpp) and PX4
// (TemperatureCalibration*, process_sensor_caldata.py) both fit a cubic in the temperature
// reading to all samples by unweighted least squares. Returns the curve's coefficients c1..c3 of
// (T − t_ref)^k for channel c (the constant is each firmware's room-temperature business).
Eigen::VectorXd FlightStackFit(const ThermalSimulation& sim, int c, double t_ref) {
  // Normal equations in u = (T − t_ref)/h (well conditioned for a cubic), then unscaled.
  const double h = 0.5 * (sim.temp.maxCoeff() - sim.temp.minCoeff());
  Eigen::Matrix4d ata = Eigen::Matrix4d::Zero();
  Eigen::Vector4d aty = Eigen::Vector4d::Zero();
  for (Eigen::Index i = 0; i < sim.t.size(); ++i) {
    const double u = (sim.temp(i) - t_ref) / h;
    const Eigen::Vector4d row(1, u, u * u, u * u * u);
    ata.noalias() += row * row.transpose();
    aty += row * (c < 3 ? sim.accel(i, c) : sim.gyro(i, c - 3));
  }
  const Eigen::Vector4d a = ata.ldlt().solve(aty);
  return Eigen::Vector3d(a(1) / h, a(2) / (h * h), a(3) / (h * h * h));
}

// Mean squared error of the curve (relative to t_ref) over calibd's grid [t_min, t_max], per
// channel, summed over trials: calibd's and the flight stacks' cubic.
struct CurveErrors {
  double calibd[6] = {0}, cubic[6] = {0};
  std::vector<double> calibd_trials[6], cubic_trials[6];  // per trial, for the ratio's σ
  int trials = 0;
  double Ratio(int c) const { return calibd[c] / cubic[c]; }
  // Monte-Carlo σ of Ratio(c) (the delta method on the paired per-trial errors):
  // √(Σ (a_i − R b_i)²) / Σ b_i.
  double RatioStd(int c) const {
    double s = 0;
    for (size_t i = 0; i < calibd_trials[c].size(); ++i)
      s += std::pow(calibd_trials[c][i] - Ratio(c) * cubic_trials[c][i], 2);
    return std::sqrt(s) / cubic[c];
  }
};

void AddCurveErrors(const ThermalSimulation& sim, const ThermalImuResult& imu, CurveErrors* e) {
  for (int c = 0; c < 6; ++c) {
    const ThermalChannel& ch = imu.channels[static_cast<size_t>(c)];
    const Eigen::VectorXd cubic = FlightStackFit(sim, c, imu.t_ref);
    double sc = 0, sf = 0;
    for (Eigen::Index i = 0; i < imu.grid.size(); ++i) {
      const double truth = TrueDeviation(sim, c, imu.grid(i), imu.t_ref);
      sc += std::pow(ch.grid_value(i) - truth, 2);
      sf += std::pow(ThermalCurve(cubic, imu.grid(i) - imu.t_ref) - truth, 2);
    }
    e->calibd[c] += sc / imu.grid.size();
    e->cubic[c] += sf / imu.grid.size();
    e->calibd_trials[c].push_back(sc / imu.grid.size());
    e->cubic_trials[c].push_back(sf / imu.grid.size());
  }
  ++e->trials;
}

// Scenario (a) true order 3, (b) strong order 5, (c) a lag of 30–120 s on a warm-up and
// cool-down (calibd with lag "estimate", the cubic in the reading).
CurveErrors CompareWithFlightStacks(char scenario, int trials) {
  CurveErrors e;
  for (int trial = 0; trial < trials; ++trial) {
    ThermalSimulationOptions o = Warmup(5000 + static_cast<uint64_t>(trial));
    ThermalOptions options;
    options.grid_points = 11;
    if (scenario == 'b') o.coefficients = StrongOrder5Truth();
    if (scenario == 'c') {
      o.rate = 20;
      o.warmup = o.cooldown = 1200;
      o.lag = 30.0 * (1 << (trial % 3));
      options.lag = ThermalLagMode::kEstimate;
    }
    const ThermalSimulation sim = SimulateThermal(o);
    ThermalResult r;
    const Status st = Calibrate(sim, options, &r);
    EXPECT_TRUE(st.ok()) << st.message();
    if (st.ok()) AddCurveErrors(sim, r.imus[0], &e);
  }
  for (int c = 0; c < 6; ++c) {
    std::printf(
        "scenario %c channel %d: RMS error calibd %.3g, cubic of all samples %.3g (ratio "
        "of MSE %.3f ± %.3f)\n",
        scenario, c, std::sqrt(e.calibd[c] / e.trials), std::sqrt(e.cubic[c] / e.trials),
        e.Ratio(c), e.RatioStd(c));
  }
  return e;
}

// Ratios of the mean squared errors calibd / cubic over 100 trials (60 with the lag), each with its
// Monte-Carlo σ from the paired per-trial errors (CurveErrors::RatioStd: 0.01–0.03 in (a), 0.003–
// 0.034 in (b), 0.002–0.010 in (c)). The issue asks for no more than the cubic's error where the
// cubic is the true order (a): the ratio less 3σ below 1. "Clearly smaller" in (b), (c): below 0.6
// by 3σ. Measured ratios (a) / (b) / (c) per channel by the way the orders are combined (same
// seeds; "from 3": min_order 3):
//   AICc, one order:                  1.37–1.59 / 0.05–0.30 / 0.01–0.09 (order 4–5 in ~25 %)
//   AICc within 2 of its minimum:     1.17–1.40 / 0.05–0.30 / 0.01–0.10, lag z RMS up to 1.63
//   likelihood-ratio tests, α 5 %:    1.19–1.42 / 0.05–0.30 / 0.01–0.09, lag z RMS up to 1.59
//   BIC, one order:                   1.05–1.32 / 0.05–0.31 / 0.01–0.10, z RMS up to 2.05 (lag)
//   BIC, one order, from 3:           1.05–1.22 / 0.05–0.31 / 0.01–0.07
//   Akaike-weight average:            1.26–1.40 / 0.05–0.31 / 0.01–0.08
//   Akaike-weight average, from 3:    1.27–1.37 / 0.05–0.31 / 0.01–0.08
//   Mallows model averaging:          1.25–1.43 / 0.05–0.30 / 0.01–0.08, z RMS 0.68–0.83
//   Mallows model averaging, from 3:  1.23–1.30 / 0.05–0.30 / 0.01–0.07
//   jackknife averaging, from 3:      1.22–1.33 / 0.05–0.31 / 0.01–0.08
//   BIC-weight average:               1.06–1.31 / 0.05–0.32 / 0.01–0.09, z RMS 0.83–1.27
//   BIC-weight average, from 3, penalty k ln n (n windows), each window's own σ:
//                                     1.06–1.16 / 0.05–0.32 / 0.01–0.07, z RMS 0.89–1.04
//   the same, σ from the variance function: 1.05–1.13 / 0.05–0.31
//   BIC-weight average, from 3, penalty k ln N (N samples), variance function (now):
//                                     1.00–1.04 / 0.05–0.40 / 0.01–0.06
//   order fixed at 3 (the oracle in (a)), variance function: 0.98–1.04 (each window's σ:
//                                     0.99–1.06)
// Against a cubic of the samples calibd's statics keep (the detector leaves the first 0.5 s, the
// coldest), (a) is 0.999–1.026 ± 0.005–0.020. The price of the strict penalty is (b)'s gyroscope
// y (0.31 → 0.40): its weak 4th and 5th orders lose weight in the curve; the band keeps them
// (BandIsHonestWhenTheCubicIsTheWrongOrder). Mallows and jackknife averaging (Hansen 2007,
// Hansen & Racine 2012) and Akaike weights are efficient, not consistent: an absent 4th or 5th
// order keeps an O(1) weight and costs its variance (largest at the cold end, where a warm-up has
// few windows). Selecting one order strictly drops weak terms and leaves a bias the band does not
// cover. From order 0, gyroscope y's barely detectable cubic (0.6e-4/45² rad/s/°C³) cost 1.31; the
// floor at 3 keeps it.
TEST(ThermalTest, ComparedWithTheFlightStacksCubic) {
  const CurveErrors a = CompareWithFlightStacks('a', 100);
  const CurveErrors b = CompareWithFlightStacks('b', 100);
  const CurveErrors c = CompareWithFlightStacks('c', 60);
  for (int ch = 0; ch < 6; ++ch) {
    EXPECT_LT(a.Ratio(ch) - 3 * a.RatioStd(ch), 1.0) << ch;
    EXPECT_LT(b.Ratio(ch) + 3 * b.RatioStd(ch), 0.6) << ch;
    EXPECT_LT(c.Ratio(ch) + 3 * c.RatioStd(ch), 0.6) << ch;
  }
}

// Warm-up then cool-down with the element lagging the reading by 30, 60 or 120 s: τ estimated,
// its σ and the curves' bands honest (z RMS 0.7–1.4 over 90 trials: relative σ of a z RMS ~7 %).
TEST(ThermalTest, LagEstimateIsHonestInMonteCarlo) {
  const int trials = 90;
  double tau_z2 = 0, curve_z2[6] = {0};
  int curve_n = 0;
  for (int trial = 0; trial < trials; ++trial) {
    ThermalSimulationOptions o = Warmup(7000 + static_cast<uint64_t>(trial));
    o.rate = 20;
    o.warmup = o.cooldown = 1200;
    o.lag = 30.0 * (1 << (trial % 3));
    const ThermalSimulation sim = SimulateThermal(o);
    ThermalOptions options;
    options.grid_points = 11;
    options.lag = ThermalLagMode::kEstimate;
    ThermalResult r;
    const Status st = Calibrate(sim, options, &r);
    ASSERT_TRUE(st.ok()) << st.message();
    const ThermalImuResult& imu = r.imus[0];
    ASSERT_TRUE(imu.lag && imu.lag_std);
    tau_z2 += std::pow((*imu.lag - o.lag) / *imu.lag_std, 2);
    for (Eigen::Index i = 0; i < imu.grid.size(); ++i) {
      if (std::abs(imu.grid(i) - imu.t_ref) < 1e-6) continue;
      for (int c = 0; c < 6; ++c) {
        const ThermalChannel& ch = imu.channels[static_cast<size_t>(c)];
        curve_z2[c] += std::pow(
            (ch.grid_value(i) - TrueDeviation(sim, c, imu.grid(i), imu.t_ref)) / ch.grid_std(i), 2);
      }
      ++curve_n;
    }
  }
  const double tau_z = std::sqrt(tau_z2 / trials);
  std::printf("lag: z RMS of tau %.3f\n", tau_z);
  EXPECT_GT(tau_z, 0.7);
  EXPECT_LT(tau_z, 1.4);
  for (int c = 0; c < 6; ++c) {
    const double z = std::sqrt(curve_z2[c] / curve_n);
    std::printf("lag: channel %d z RMS %.3f\n", c, z);
    EXPECT_GT(z, 0.7);
    EXPECT_LT(z, 1.4);
  }
}

TEST(ThermalTest, LagEstimateRefusesASingleWarmup) {
  ThermalSimulationOptions o = Warmup(11);
  o.rate = 20;
  o.lag = 60;
  const ThermalSimulation sim = SimulateThermal(o);
  ThermalOptions options;
  options.lag = ThermalLagMode::kEstimate;
  ThermalResult r;
  const Status st = Calibrate(sim, options, &r);
  ASSERT_EQ(st.code(), StatusCode::kNotDeterminable);
  EXPECT_NE(st.message().find("heating and cooling"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("single warm-up"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("cooling: none"), std::string::npos) << st.message();
  // A known lag needs no cool-down: the curve then follows the element's temperature.
  options.lag = ThermalLagMode::kFixed;
  options.lag_seconds = 60;
  ASSERT_TRUE(Calibrate(sim, options, &r).ok());
  EXPECT_EQ(*r.imus[0].lag, 60);
  EXPECT_FALSE(r.imus[0].lag_std);
}

}  // namespace
}  // namespace calibd::core
