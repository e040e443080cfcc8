// Tests of pca's cost and numerics (issue #14): the low-rank (Woodbury) and dense solvers of the
// Fisher information give the same σ, equal to figures computed before the change; the budget
// refuses a too-large problem at once; the cost estimate is linear in the number of sensors; the
// relative σ do not depend on the scale of the problem; non-finite values are never usable.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "core/pca.h"
#include "core/pca_simulation.h"

namespace calibd::core {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

struct Case {
  int d, m, n;
  bool bias;
  double c;
  uint64_t seed;
  std::vector<std::vector<double>> sigma;  // per sensor: scale_std, axis_std_rad, bias_std
};

// Random sensors (unit axes, gains 1 ± 5 %), biases, positions and noise (1 % of c).
PcaProblem MakeProblem(const Case& k) {
  PcaRandom rng(k.seed);
  MatrixXd a = MatrixXd::Zero(k.d, k.m);
  for (int i = 0; i < k.m; ++i) {
    // Two statements: the order of the draws must not depend on the compiler (the operands of
    // one expression are evaluated in an unspecified order; GCC and Clang differ). This is the
    // order the stored figures below were computed with.
    const VectorXd axis = rng.UnitVector(k.d);
    a.col(i) = (1 + 0.05 * rng.Normal()) * axis;
  }
  const VectorXd b = k.bias ? VectorXd(0.1 * rng.NormalMatrix(k.m, 1)) : VectorXd::Zero(k.m);
  const MatrixXd v = rng.SphereColumns(k.d, k.n, k.c);
  PcaProblem p;
  p.m = a.transpose() * v;
  p.m.colwise() += b;
  p.m += 0.01 * k.c * rng.NormalMatrix(k.m, k.n);
  return p;
}

PcaOptions OptionsFor(const Case& k, PcaInformationSolver solver) {
  PcaOptions o;
  o.dimension = k.d;
  o.magnitude = k.c;
  o.bias = k.bias ? BiasModel::kEstimate : BiasModel::kNone;
  o.information_solver = solver;
  return o;
}

double RelativeDifference(double x, double y) {
  if (x == y) return 0;
  return std::abs(x - y) / std::max(std::abs(x), std::abs(y));
}

// Figures printed with %.17g by the dense Fisher code as it was before the low-rank solver and the
// equilibration (commit 6a23585), on the problems of MakeProblem.
const std::vector<Case>& ReferenceCases() {
  static const std::vector<Case> cases = {
      {3,
       12,
       20,
       false,
       1,
       11,
       {{0.004389228176018614, 0.0071329702768304481, 0},
        {0.0049080578924258619, 0.0063474722750788033, 0},
        {0.0052772580125363417, 0.005178018645826326, 0},
        {0.005276302201174192, 0.0050255386329865195, 0},
        {0.0046759167808195865, 0.0058885272312786431, 0},
        {0.0048954939499196723, 0.0058324340832954825, 0},
        {0.004303525057620927, 0.0064928610065440795, 0},
        {0.0039995484028904522, 0.0068896912416736905, 0},
        {0.0053066700164264707, 0.0049526020896719673, 0},
        {0.0041451120426514087, 0.0063016576943847619, 0},
        {0.0054778793056469181, 0.0054667073795854008, 0},
        {0.0052966026386081803, 0.0050421002494202881, 0}}},
      {3,
       7,
       15,
       true,
       9.81,
       12,
       {{0.0061068831493866875, 0.0082867553432437562, 0.041182818526433462},
        {0.0071874295390789815, 0.0083821282412636106, 0.051069455182083758},
        {0.0058112004726158604, 0.0079830704770723088, 0.038139337962876517},
        {0.0066786477255130249, 0.0079681436842776281, 0.042843655484474802},
        {0.0054360252815729504, 0.0086087147576338133, 0.037964262891678154},
        {0.0052930470801217907, 0.0090654497213877635, 0.038662788719513792},
        {0.0070062407688969682, 0.0079078943623061386, 0.0477213957074272}}},
      {2,
       5,
       9,
       true,
       2,
       13,
       {{0.017248448639311836, 0.0055701329954784733, 0.026276365555015585},
        {0.018480776964891414, 0.0052245123827946056, 0.028426725393747677},
        {0.0081245392114064844, 0.0080511661710552379, 0.0098357471531440605},
        {0.0091490761579708247, 0.012697754120012181, 0.016842975593843571},
        {0.01185074595651818, 0.013354405774510062, 0.029990346204467659}}},
      {4,
       9,
       25,
       false,
       1,
       14,
       {{0.010362873174262766, 0.0085452674902673983, 0},
        {0.0063478018229587672, 0.0087799636960317669, 0},
        {0.0053878879086640668, 0.010158265113016896, 0},
        {0.0127619488808857, 0.0080969253914857844, 0},
        {0.0088041913098461447, 0.0081824308867247744, 0},
        {0.0075150683334814254, 0.013859589585731639, 0},
        {0.0048432488370492646, 0.0090079646687957829, 0},
        {0.0054779741363027278, 0.0094000919605682041, 0},
        {0.0080779057569855799, 0.010410120959059778, 0}}},
      {3,
       3,
       12,
       true,
       1,
       15,
       {{0.20241827362780931, 0.072536623048463006, 0.13526201949104213},
        {0.06399877787908069, 0.10682602632917459, 0.07984895125673544},
        {0.13726757217137014, 0.16328485815684562, 0.12669585484282136}}},
  };
  return cases;
}

TEST(PcaInformation, BothSolversReproduceTheFiguresComputedBeforeTheChange) {
  for (PcaInformationSolver solver :
       {PcaInformationSolver::kDense, PcaInformationSolver::kLowRank}) {
    for (const Case& k : ReferenceCases()) {
      PcaResult r;
      ASSERT_TRUE(CalibratePca(MakeProblem(k), OptionsFor(k, solver), &r).ok()) << r.reason;
      ASSERT_EQ(r.cost_estimate.solver, solver);
      for (int i = 0; i < k.m; ++i) {
        const PcaSensorEstimate& se = r.sensors[i];
        EXPECT_LT(RelativeDifference(se.scale_std, k.sigma[i][0]), 1e-11)
            << PcaInformationSolverName(solver) << " d=" << k.d << " m=" << k.m << " i=" << i;
        EXPECT_LT(RelativeDifference(se.axis_std_rad, k.sigma[i][1]), 1e-11);
        EXPECT_LT(RelativeDifference(se.bias_std, k.sigma[i][2]), 1e-11);
      }
    }
  }
}

// Random problems of many shapes: the two solvers agree to rounding on every σ and on the refined
// estimate (each refinement step solves with the same S⁺).
TEST(PcaInformation, LowRankAndDenseSolversAgreeOnRandomProblems) {
  int compared = 0;
  for (int t = 0; t < 24; ++t) {
    PcaRandom rng(900 + t);
    Case k;
    k.d = 2 + t % 3;
    k.bias = t % 2 == 1;
    k.m = k.d + static_cast<int>(rng.Uniform() * 30);
    const int min_n = k.bias ? k.d * (k.d + 3) / 2 : k.d * (k.d + 1) / 2;
    k.n = min_n + 3 + static_cast<int>(rng.Uniform() * 20);
    k.c = std::pow(10.0, -3 + 6 * rng.Uniform());
    k.seed = 1000 + t;
    const PcaProblem problem = MakeProblem(k);
    PcaResult dense, low;
    PcaOptions od = OptionsFor(k, PcaInformationSolver::kDense);
    PcaOptions ol = OptionsFor(k, PcaInformationSolver::kLowRank);
    od.refine = ol.refine = t % 3 == 0;
    const Status sd = CalibratePca(problem, od, &dense);
    const Status sl = CalibratePca(problem, ol, &low);
    ASSERT_EQ(sd.ok(), sl.ok()) << sd.message() << " / " << sl.message();
    if (!sd.ok()) continue;
    ++compared;
    EXPECT_EQ(dense.refine_iterations, low.refine_iterations);
    EXPECT_LT((dense.a - low.a).norm(), 1e-9 * dense.a.norm());
    for (int i = 0; i < k.m; ++i) {
      const PcaSensorEstimate& x = dense.sensors[i];
      const PcaSensorEstimate& y = low.sensors[i];
      ASSERT_TRUE(std::isfinite(x.scale_std) && std::isfinite(y.scale_std));
      EXPECT_LT(RelativeDifference(x.scale_std, y.scale_std), 1e-9) << "t=" << t << " i=" << i;
      EXPECT_LT(RelativeDifference(x.axis_std_rad, y.axis_std_rad), 1e-9) << "t=" << t;
      EXPECT_LT(RelativeDifference(x.bias_std, y.bias_std), 1e-9) << "t=" << t;
    }
  }
  EXPECT_GE(compared, 20);
}

TEST(PcaInformation, AutoPicksLowRankForManySensorsAndDenseForManyPositions) {
  EXPECT_EQ(EstimatePcaCost(1000, 12, 3, BiasModel::kNone).solver, PcaInformationSolver::kLowRank);
  EXPECT_EQ(EstimatePcaCost(12, 1000, 3, BiasModel::kEstimate).solver,
            PcaInformationSolver::kDense);
  EXPECT_EQ(EstimatePcaCost(12, 12, 3, BiasModel::kNone, PcaInformationSolver::kDense).solver,
            PcaInformationSolver::kDense);
}

// The whole estimate is linear in m for fixed n: ten times the sensors, about ten times the cost;
// the old dense path grows as m² in memory and m³ in time.
TEST(PcaCost, LinearInTheNumberOfSensorsForFixedPositions) {
  for (BiasModel bias : {BiasModel::kNone, BiasModel::kEstimate}) {
    const PcaCost c1 = EstimatePcaCost(1000, 12, 3, bias);
    const PcaCost c10 = EstimatePcaCost(10000, 12, 3, bias);
    EXPECT_NEAR(c10.bytes / c1.bytes, 10, 1);
    EXPECT_NEAR(c10.flops / c1.flops, 10, 1);
    EXPECT_LT(c10.bytes, 50e6);  // 10 000 sensors in well under the default 1 GiB
    const PcaCost d1 = EstimatePcaCost(1000, 12, 3, bias, PcaInformationSolver::kDense);
    const PcaCost d2 = EstimatePcaCost(2000, 12, 3, bias, PcaInformationSolver::kDense);
    EXPECT_GT(d2.bytes / d1.bytes, 3.5);
    EXPECT_GT(d2.flops / d1.flops, 7);
    EXPECT_GT(d1.bytes, 50 * c1.bytes);
  }
}

// 1000 sensors × 12 positions (what took 23 s and 465 MB with the dense solver), Monte Carlo:
// fixed sensors and positions, fresh noise per trial. The observed variance of each sensor's
// scale factor and bias, pooled over all sensors, matches the reported one: the pooled ratio of
// variances has a standard error of about √(2/(trials−1)/m) (sensors nearly independent); the
// margin is 3 of those plus 2 % for the Cramér–Rao bound's first-order approximation.
TEST(PcaCost, ThousandSensorsGiveSigmaMatchingMonteCarlo) {
  const int m = 1000, n = 12, trials = 40;
  const double c = 9.81, sigma = 0.01 * c;
  PcaRandom rng(4242);
  MatrixXd a(3, m);
  for (int i = 0; i < m; ++i) {
    const VectorXd axis = rng.UnitVector(3);  // before the gain: a fixed order of draws
    a.col(i) = (1 + 0.05 * rng.Normal()) * axis;
  }
  const VectorXd b = 0.1 * rng.NormalMatrix(m, 1);
  const MatrixXd v = rng.SphereColumns(3, n, c);
  MatrixXd clean = a.transpose() * v;
  clean.colwise() += b;
  PcaOptions o;
  o.magnitude = c;
  o.bias = BiasModel::kEstimate;
  std::vector<double> sum(m, 0), sum_sq(m, 0), bsum(m, 0), bsum_sq(m, 0);
  VectorXd reported_scale_var = VectorXd::Zero(m), reported_bias_var = VectorXd::Zero(m);
  for (int t = 0; t < trials; ++t) {
    PcaProblem p;
    p.m = clean + sigma * rng.NormalMatrix(m, n);
    PcaResult r;
    ASSERT_TRUE(CalibratePca(p, o, &r).ok()) << r.reason;
    ASSERT_EQ(r.cost_estimate.solver, PcaInformationSolver::kLowRank);
    for (int i = 0; i < m; ++i) {
      const PcaSensorEstimate& se = r.sensors[i];
      sum[i] += se.scale;
      sum_sq[i] += se.scale * se.scale;
      bsum[i] += se.bias;
      bsum_sq[i] += se.bias * se.bias;
      reported_scale_var(i) += se.scale_std * se.scale_std / trials;
      reported_bias_var(i) += se.bias_std * se.bias_std / trials;
    }
  }
  double scale_ratio = 0, bias_ratio = 0;
  for (int i = 0; i < m; ++i) {
    const double var = (sum_sq[i] - sum[i] * sum[i] / trials) / (trials - 1);
    const double bvar = (bsum_sq[i] - bsum[i] * bsum[i] / trials) / (trials - 1);
    scale_ratio += var / reported_scale_var(i) / m;
    bias_ratio += bvar / reported_bias_var(i) / m;
  }
  const double margin = 3 * std::sqrt(2.0 / (trials - 1) / m) + 0.02;
  std::printf("observed/reported variance: scale %.4f, bias %.4f (margin %.4f)\n", scale_ratio,
              bias_ratio, margin);
  EXPECT_NEAR(scale_ratio, 1.0, margin);
  EXPECT_NEAR(bias_ratio, 1.0, margin);
}

TEST(PcaBudget, RefusesATooLargeProblemAtOnceNamingTheLimit) {
  Case k{3, 2000, 12, true, 1.0, 7, {}};
  PcaProblem problem;
  problem.m = MatrixXd::Zero(k.m, k.n);  // never looked at: the refusal comes first
  PcaOptions o = OptionsFor(k, PcaInformationSolver::kDense);
  PcaResult r;
  Status s = CalibratePca(problem, o, &r);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
  EXPECT_EQ(s.field(), "max_flops");
  EXPECT_NE(s.message().find("2000 sensors"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("max_flops"), std::string::npos);
  EXPECT_FALSE(r.usable);
  EXPECT_EQ(r.reason, s.message());
  o.max_flops = 0;  // no flop limit: now the memory limit
  o.max_memory_bytes = 100e6;
  s = CalibratePca(problem, o, &r);
  EXPECT_EQ(s.field(), "max_memory_bytes");
  EXPECT_NE(s.message().find("MiB"), std::string::npos) << s.message();
  EXPECT_GT(r.cost_estimate.bytes, 100e6);
  // The same size with the low-rank solver fits.
  o.information_solver = PcaInformationSolver::kAuto;
  EXPECT_LT(EstimatePcaCost(k.m, k.n, 3, o.bias).bytes, 100e6);
}

TEST(PcaBudget, OptionsMustBeNonNegative) {
  PcaOptions o;
  std::string error;
  o.max_memory_bytes = -1;
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_NE(error.find("max_memory_bytes"), std::string::npos);
  o = PcaOptions();
  o.max_flops = std::nan("");
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_NE(error.find("max_flops"), std::string::npos);
}

// Bias estimation with the field's magnitude from 1e-6 to 1e6 (and the readings scaled with it):
// every relative σ is that of c = 1, to rounding; before the equilibration c = 1e-6 gave NaN.
TEST(PcaScaling, RelativeSigmaDoesNotDependOnTheScaleOfTheProblem) {
  PcaSimulationOptions so;
  so.positions = 30;
  so.bias_std = 0.1;
  const PcaSimulation base = SimulatePca(so);
  auto run = [&](double c, double reading_scale, bool refine) {
    PcaProblem p;
    p.m = base.m * (c * reading_scale);
    PcaOptions o;
    o.magnitude = c;
    o.bias = BiasModel::kEstimate;
    o.refine = refine;
    PcaResult r;
    EXPECT_TRUE(CalibratePca(p, o, &r).ok()) << r.reason;
    EXPECT_TRUE(r.usable);
    return r;
  };
  for (bool refine : {false, true}) {
    const PcaResult ref = run(1.0, 1.0, refine);
    for (double c : {1e-6, 1e-3, 1e3, 1e6}) {
      for (double reading_scale : {1.0, 1e-4, 1e4}) {
        const PcaResult r = run(c, reading_scale, refine);
        const double k = c * reading_scale;  // the readings' scale
        for (size_t i = 0; i < r.sensors.size(); ++i) {
          const PcaSensorEstimate& x = r.sensors[i];
          const PcaSensorEstimate& y = ref.sensors[i];
          ASSERT_TRUE(std::isfinite(x.scale_std) && std::isfinite(x.bias_std)) << "c=" << c;
          EXPECT_LT(RelativeDifference(x.scale_std / x.scale, y.scale_std / y.scale), 1e-8)
              << "c=" << c << " scale " << reading_scale;
          EXPECT_LT(RelativeDifference(x.axis_std_rad, y.axis_std_rad), 1e-8);
          EXPECT_LT(RelativeDifference(x.bias_std / k, y.bias_std), 1e-8);
          EXPECT_LT(RelativeDifference(x.bias / k, y.bias), 1e-8);
          EXPECT_LT(RelativeDifference(x.scale * c / k, y.scale), 1e-8);
        }
        EXPECT_LT(RelativeDifference(r.noise_std / k, ref.noise_std), 1e-8);
      }
    }
  }
}

// Readings near the limits of double precision still give finite, correct results.
TEST(PcaScaling, ExtremeReadingMagnitudesStayFinite) {
  PcaSimulationOptions so;
  so.positions = 30;
  so.bias_std = 0.1;
  const PcaSimulation base = SimulatePca(so);
  PcaOptions o;
  o.magnitude = 1.0;
  o.bias = BiasModel::kEstimate;
  PcaResult ref;
  ASSERT_TRUE(CalibratePca(PcaProblem{base.m, {}, {}, {}, {}}, o, &ref).ok());
  for (double f : {1e-300, 1e-150, 1e150, 1e250}) {
    PcaResult r;
    ASSERT_TRUE(CalibratePca(PcaProblem{base.m * f, {}, {}, {}, {}}, o, &r).ok())
        << "f=" << f << ": " << r.reason;
    EXPECT_LT(RelativeDifference(r.sensors[3].scale / f, ref.sensors[3].scale), 1e-9);
    EXPECT_LT(RelativeDifference(r.sensors[3].scale_std / f, ref.sensors[3].scale_std), 1e-8);
    EXPECT_LT(RelativeDifference(r.sensors[3].bias_std / f, ref.sensors[3].bias_std), 1e-8);
  }
}

// An undefined σ is NaN with a warning, never 0.
TEST(PcaGuards, UndefinedSigmaIsNaNNeverZero) {
  // m = d = 3 with biases, n = 9: no redundancy, no noise level.
  Case k{3, 3, 9, true, 1.0, 31, {}};
  PcaResult r;
  ASSERT_TRUE(CalibratePca(MakeProblem(k), OptionsFor(k, PcaInformationSolver::kAuto), &r).ok())
      << r.reason;
  EXPECT_LE(r.degrees_of_freedom, 0);
  for (const PcaSensorEstimate& se : r.sensors) {
    EXPECT_TRUE(std::isnan(se.scale_std));
    EXPECT_TRUE(std::isnan(se.axis_std_rad));
    EXPECT_TRUE(std::isnan(se.bias_std));
  }
}

// A sensor whose readings never change has no axis: never a usable result with a NaN axis; the
// message names the sensor.
TEST(PcaGuards, DeadSensorIsNotUsableAndNamed) {
  PcaSimulationOptions so;
  so.positions = 30;
  so.noise_std = 0;
  const PcaSimulation sim = SimulatePca(so);
  for (BiasModel bias : {BiasModel::kNone, BiasModel::kEstimate}) {
    PcaProblem p;
    p.m = sim.m;
    p.m.row(4).setZero();
    p.sensor_names = sim.sensor_names;
    PcaOptions o;
    o.magnitude = 1.0;
    o.bias = bias;
    PcaResult r;
    const Status s = CalibratePca(p, o, &r);
    EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
    EXPECT_FALSE(r.usable);
    EXPECT_NE(s.message().find(sim.sensor_names[4] + "'s axis is undefined"), std::string::npos)
        << s.message();
  }
}

}  // namespace
}  // namespace calibd::core
