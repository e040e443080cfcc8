// Tests of the block Levenberg-Marquardt solver (core/block_lm.h) on a toy with the structure of
// the array problems: points y_n = c + R u_n + eps (eps ~ N(0, sigma^2 I3)) on a sphere, one unit
// direction u_n per point (a block on the sphere S^2: state 3, tangent 2) and the shared centre
// and radius p = (c, R). Known answer, a closed-form-free CRB checked against Monte-Carlo
// spread, and a dense LM on the full problem as the reference.
#include "core/block_lm.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <vector>

#include "core/array_simulation.h"  // GaussianRng

namespace calibd::core {
namespace {

using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;
using Mat32 = Eigen::Matrix<double, 3, 2>;

// Orthonormal tangent basis of S^2 at u (deterministic).
Mat32 TangentBasis(const Vec3& u) {
  Eigen::Index i;
  u.cwiseAbs().minCoeff(&i);
  const Vec3 a = Vec3::Unit(i);
  const Vec3 e1 = (a - a.dot(u) * u).normalized();
  Mat32 E;
  E << e1, u.cross(e1);
  return E;
}

struct SphereFit {
  static constexpr int kBlockDim = 2;
  static constexpr int kBlockStateDim = 3;
  static constexpr int kResidualDim = 3;

  Eigen::Matrix3Xd y;  // observed points
  double sigma = 1;

  int64_t NumBlocks() const { return y.cols(); }
  int SharedDim() const { return 4; }

  // r = (c + R u - y) / sigma; J_u = R E(u) / sigma (u [+] d = normalise(u + E(u) d));
  // J_p = [I3 u] / sigma.
  void Evaluate(int64_t n, const Vec3& u, const Eigen::VectorXd& p, Vec3* r,
                Eigen::Matrix<double, 3, 2>* J_u,
                Eigen::Matrix<double, 3, Eigen::Dynamic>* J_p) const {
    *r = (p.head<3>() + p(3) * u - y.col(n)) / sigma;
    if (J_u) *J_u = p(3) * TangentBasis(u) / sigma;
    if (J_p) {
      J_p->leftCols<3>() = Eigen::Matrix3d::Identity() / sigma;
      J_p->col(3) = u / sigma;
    }
  }
  Vec3 PlusBlock(const Vec3& u, const Vec2& d) const {
    return (u + TangentBasis(u) * d).normalized();
  }
  Eigen::VectorXd PlusShared(const Eigen::VectorXd& p, const Eigen::VectorXd& dp) const {
    return p + dp;
  }
};

using SphereProblem = JacobianBlockProblem<SphereFit>;
using SphereSolver = BlockLm<SphereProblem>;

struct Truth {
  Eigen::Matrix3Xd u;
  Eigen::VectorXd p;  // c, R
};

Truth MakeTruth(int n, uint64_t seed) {
  GaussianRng rng(seed);
  Truth t;
  t.u.resize(3, n);
  for (int i = 0; i < n; ++i) t.u.col(i) = rng.UnitVector();
  t.p.resize(4);
  t.p << 0.3, -0.2, 0.5, 2.0;
  return t;
}

SphereFit Observe(const Truth& t, double sigma, GaussianRng* rng) {
  SphereFit f;
  f.sigma = sigma > 0 ? sigma : 1e-3;
  f.y.resize(3, t.u.cols());
  for (int i = 0; i < t.u.cols(); ++i) {
    const Vec3 eps{rng->Normal(), rng->Normal(), rng->Normal()};  // left to right
    f.y.col(i) = t.p.head<3>() + t.p(3) * t.u.col(i) + sigma * eps;
  }
  return f;
}

// Start: centre and radius off by a few percent, directions from the starting centre.
void Start(const SphereFit& f, Eigen::Matrix3Xd* u, Eigen::VectorXd* p) {
  p->resize(4);
  *p << 0.4, -0.1, 0.35, 1.8;
  u->resize(3, f.y.cols());
  for (int i = 0; i < f.y.cols(); ++i) u->col(i) = (f.y.col(i) - p->head<3>()).normalized();
}

BlockLmOptions Options() {
  BlockLmOptions o;
  o.threads = 1;
  return o;
}

TEST(BlockLm, RecoversSharedAndBlockUnknownsExactlyWithoutNoise) {
  const Truth t = MakeTruth(300, 1);
  GaussianRng rng(2);
  const SphereFit f = Observe(t, 0.0, &rng);
  const SphereProblem problem(f);
  Eigen::Matrix3Xd u;
  Eigen::VectorXd p;
  Start(f, &u, &p);
  SphereSolver solver(problem, Options());
  const BlockLmSummary s = solver.Solve(&u, &p);
  EXPECT_TRUE(s.converged()) << s.BriefReport();
  EXPECT_LE(s.iterations, 15) << s.BriefReport();
  EXPECT_LT((p - t.p).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((u - t.u).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT(s.final_cost(), 1e-20);
  EXPECT_GT(s.initial_cost(), 1e3);
  for (size_t i = 1; i < s.cost.size(); ++i) EXPECT_LE(s.cost[i], s.cost[i - 1]);
}

// Over T trials with the same design, the whitened error (p^ - p)^T F (p^ - p) of an efficient
// estimator has mean P = 4 (chi^2_4: standard error sqrt(2 P / T)), each coordinate's mean square
// error equals the CRB (relative standard error sqrt(2 / T)) and the mean error is zero (standard
// error sqrt(CRB / T)). sigma << R keeps the ML bias (about sigma^2 / R) negligible.
TEST(BlockLm, CramerRaoBoundMatchesMonteCarloSpread) {
  constexpr int kTrials = 400;
  const Truth t = MakeTruth(40, 3);
  const double sigma = 1e-3;
  GaussianRng rng(4);
  Eigen::Matrix4d crb = Eigen::Matrix4d::Zero();
  Eigen::Matrix4d fisher = Eigen::Matrix4d::Zero();
  Eigen::Vector4d mean_error = Eigen::Vector4d::Zero(), mse = Eigen::Vector4d::Zero();
  double chi2 = 0;
  for (int trial = 0; trial < kTrials; ++trial) {
    const SphereFit f = Observe(t, sigma, &rng);
    const SphereProblem problem(f);
    Eigen::Matrix3Xd u;
    Eigen::VectorXd p;
    Start(f, &u, &p);
    SphereSolver solver(problem, Options());
    const BlockLmSummary s = solver.Solve(&u, &p);
    ASSERT_TRUE(s.converged()) << s.BriefReport();
    if (trial == 0) {
      // The design's information at the truth (the estimate's differs by O(sigma)).
      Eigen::Matrix3Xd u_true = t.u;
      BlockLmInformation info;
      solver.ComputeSharedInformation(u_true, t.p, &info, nullptr);
      fisher = info.information;
      Eigen::MatrixXd cov;
      ASSERT_TRUE(InvertInformation(info.information, &cov));
      crb = cov;
    }
    const Eigen::Vector4d e = p - t.p;
    mean_error += e / kTrials;
    mse += e.cwiseAbs2() / kTrials;
    chi2 += e.dot(fisher * e) / kTrials;
  }
  EXPECT_NEAR(chi2, 4.0, 3 * std::sqrt(2.0 * 4 / kTrials));
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(mse(i) / crb(i, i), 1.0, 3 * std::sqrt(2.0 / kTrials)) << "parameter " << i;
    EXPECT_NEAR(mean_error(i), 0.0, 3 * std::sqrt(crb(i, i) / kTrials)) << "parameter " << i;
  }
  // The radius is determined to sigma / sqrt(N) (it is the mean of the radial components).
  EXPECT_NEAR(std::sqrt(crb(3, 3)), sigma / std::sqrt(40.0), 0.2 * sigma / std::sqrt(40.0));
}

// Reference: plain dense LM over all 2N + 4 tangent coordinates with the full Jacobian.
struct DenseResult {
  Eigen::Matrix3Xd u;
  Eigen::VectorXd p;
  double cost = 0;
  Eigen::MatrixXd covariance;  // inverse of the full J^T J
};

DenseResult DenseLm(const SphereFit& f, Eigen::Matrix3Xd u, Eigen::VectorXd p) {
  const int N = static_cast<int>(f.y.cols()), D = 2 * N + 4;
  auto evaluate = [&](const Eigen::Matrix3Xd& uu, const Eigen::VectorXd& pp, Eigen::VectorXd* r,
                      Eigen::MatrixXd* J) {
    r->resize(3 * N);
    if (J) J->setZero(3 * N, D);
    for (int n = 0; n < N; ++n) {
      Vec3 rn;
      Eigen::Matrix<double, 3, 2> Ju;
      Eigen::Matrix<double, 3, Eigen::Dynamic> Jp(3, 4);
      f.Evaluate(n, uu.col(n), pp, &rn, &Ju, &Jp);
      r->segment<3>(3 * n) = rn;
      if (J) {
        J->block<3, 2>(3 * n, 2 * n) = Ju;
        J->block<3, 4>(3 * n, 2 * N) = Jp;
      }
    }
  };
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  double mu = 1e-8;
  evaluate(u, p, &r, &J);
  double cost = r.squaredNorm();
  for (int it = 0; it < 200 && mu < 1e10; ++it) {
    Eigen::MatrixXd H = J.transpose() * J;
    H.diagonal() *= 1 + mu;
    const Eigen::VectorXd d = H.llt().solve(-J.transpose() * r);
    Eigen::Matrix3Xd u2(3, N);
    for (int n = 0; n < N; ++n) u2.col(n) = f.PlusBlock(u.col(n), d.segment<2>(2 * n));
    const Eigen::VectorXd p2 = p + d.tail<4>();
    Eigen::VectorXd r2;
    evaluate(u2, p2, &r2, nullptr);
    if (r2.squaredNorm() < cost) {
      u = u2;
      p = p2;
      cost = r2.squaredNorm();
      evaluate(u, p, &r, &J);
      mu = std::max(mu / 10, 1e-15);
    } else {
      mu *= 10;
    }
  }
  DenseResult out{u, p, cost, {}};
  out.covariance = (J.transpose() * J).inverse();
  return out;
}

TEST(BlockLm, MatchesDenseLevenbergMarquardtOnTheFullProblem) {
  const Truth t = MakeTruth(12, 5);
  GaussianRng rng(6);
  const SphereFit f = Observe(t, 0.05, &rng);
  const SphereProblem problem(f);
  Eigen::Matrix3Xd u;
  Eigen::VectorXd p;
  Start(f, &u, &p);
  const DenseResult dense = DenseLm(f, u, p);
  BlockLmOptions o = Options();
  o.cost_tolerance = 0;
  o.step_tolerance = 1e-15;
  SphereSolver solver(problem, o);
  const BlockLmSummary s = solver.Solve(&u, &p);
  ASSERT_TRUE(s.converged()) << s.BriefReport();
  EXPECT_GT(s.final_cost(), 1.0);  // noisy: a real optimum, not an exact fit
  EXPECT_NEAR(s.final_cost(), dense.cost, 1e-12 * dense.cost);
  // The Schur complement's inverse is the shared block of the full inverse.
  BlockLmInformation info;
  solver.ComputeSharedInformation(u, p, &info, nullptr);
  Eigen::MatrixXd cov;
  ASSERT_TRUE(InvertInformation(info.information, &cov));
  // Both stop where rounding hides any further cost decrease (relative 1e-16 of the cost moves
  // the parameters by about 1e-8 of their standard deviation): the same optimum to rounding.
  for (int i = 0; i < 4; ++i)
    EXPECT_NEAR(p(i), dense.p(i), 1e-8 * std::sqrt(cov(i, i))) << "parameter " << i;
  EXPECT_LT((u - dense.u).cwiseAbs().maxCoeff(), 1e-8 * std::sqrt(cov(0, 0)));
  const Eigen::MatrixXd dense_shared = dense.covariance.bottomRightCorner(4, 4);
  EXPECT_LT((cov - dense_shared).cwiseAbs().maxCoeff(), 1e-9 * dense_shared.cwiseAbs().maxCoeff());
  EXPECT_LT(info.gradient.cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_NEAR(info.cost, s.final_cost(), 1e-12 * s.final_cost());
}

TEST(BlockLm, ResultIsBitIdenticalForAnyThreadCountOrExecutor) {
  const Truth t = MakeTruth(3000, 7);
  GaussianRng rng(8);
  const SphereFit f = Observe(t, 0.01, &rng);
  const SphereProblem problem(f);
  auto run = [&](int threads, TaskExecutor executor, Eigen::Matrix3Xd* u, Eigen::VectorXd* p) {
    Start(f, u, p);
    BlockLmOptions o = Options();
    o.threads = threads;
    o.executor = std::move(executor);
    SphereSolver solver(problem, o);
    return solver.Solve(u, p);
  };
  Eigen::Matrix3Xd u1, u2, u3, u4;
  Eigen::VectorXd p1, p2, p3, p4;
  const BlockLmSummary s1 = run(1, {}, &u1, &p1);
  const BlockLmSummary s2 = run(2, {}, &u2, &p2);
  const BlockLmSummary s3 = run(3, {}, &u3, &p3);
  int64_t tasks_seen = 0;
  // An external executor that runs the chunks backwards.
  const BlockLmSummary s4 = run(
      1,
      [&](int64_t tasks, const std::function<void(int64_t)>& task) {
        tasks_seen += tasks;
        for (int64_t c = tasks - 1; c >= 0; --c) task(c);
      },
      &u4, &p4);
  EXPECT_GT(tasks_seen, 0);
  EXPECT_EQ(p1, p2);
  EXPECT_EQ(p1, p3);
  EXPECT_EQ(p1, p4);
  EXPECT_EQ(u1, u3);
  EXPECT_EQ(u1, u4);
  EXPECT_EQ(s1.cost, s2.cost);
  EXPECT_EQ(s1.cost, s4.cost);
}

TEST(BlockLm, IterationLimitIsUsableButNotConverged) {
  const Truth t = MakeTruth(100, 9);
  GaussianRng rng(10);
  const SphereFit f = Observe(t, 0.01, &rng);
  const SphereProblem problem(f);
  Eigen::Matrix3Xd u;
  Eigen::VectorXd p;
  Start(f, &u, &p);
  BlockLmOptions o = Options();
  o.max_iterations = 1;
  SphereSolver solver(problem, o);
  const BlockLmSummary s = solver.Solve(&u, &p);
  EXPECT_EQ(s.termination, BlockLmTermination::kMaxIterations);
  EXPECT_EQ(s.iterations, 1);
  EXPECT_EQ(s.cost.size(), 2u);
  EXPECT_TRUE(s.usable());
  EXPECT_FALSE(s.converged());
  EXPECT_LT(s.final_cost(), s.initial_cost());
}

TEST(BlockLm, CallbackStopsTheSolver) {
  const Truth t = MakeTruth(100, 11);
  GaussianRng rng(12);
  const SphereFit f = Observe(t, 0.01, &rng);
  const SphereProblem problem(f);
  Eigen::Matrix3Xd u;
  Eigen::VectorXd p;
  Start(f, &u, &p);
  SphereSolver solver(problem, Options());
  int calls = 0;
  const BlockLmSummary s = solver.Solve(&u, &p, [&](int iteration, const Eigen::VectorXd& at) {
    ++calls;
    EXPECT_EQ(at.size(), 4);
    return iteration < 2;
  });
  EXPECT_EQ(s.termination, BlockLmTermination::kUserStopped);
  EXPECT_EQ(calls, 2);
  EXPECT_EQ(s.iterations, 2);
}

// With every tolerance off the solver runs until the damping exceeds its limit at the optimum:
// the rejected steps reuse the linearisation (only the blocks are refactored).
TEST(BlockLm, WithoutTolerancesItEndsWithNoProgressAtTheOptimum) {
  const Truth t = MakeTruth(200, 13);
  GaussianRng rng(14);
  const SphereFit f = Observe(t, 0.01, &rng);
  const SphereProblem problem(f);
  Eigen::Matrix3Xd u, u_ref;
  Eigen::VectorXd p, p_ref;
  Start(f, &u, &p);
  Start(f, &u_ref, &p_ref);
  SphereSolver(problem, Options()).Solve(&u_ref, &p_ref);
  BlockLmOptions o = Options();
  o.cost_tolerance = 0;
  o.step_tolerance = 0;
  o.max_iterations = 200;
  SphereSolver solver(problem, o);
  const BlockLmSummary s = solver.Solve(&u, &p);
  EXPECT_EQ(s.termination, BlockLmTermination::kNoProgress) << s.BriefReport();
  EXPECT_TRUE(s.converged());
  EXPECT_GT(s.damping, o.max_damping);
  EXPECT_LT(s.accepted_iterations, s.iterations);
  // The reference stopped at its cost tolerance; both are at the optimum to far below σ (1e-3).
  EXPECT_LT((p - p_ref).cwiseAbs().maxCoeff(), 1e-8);
}

TEST(BlockLm, GradientToleranceStopsAtASmallGradient) {
  const Truth t = MakeTruth(200, 15);
  GaussianRng rng(16);
  const SphereFit f = Observe(t, 0.01, &rng);
  const SphereProblem problem(f);
  Eigen::Matrix3Xd u;
  Eigen::VectorXd p;
  Start(f, &u, &p);
  BlockLmOptions o = Options();
  o.cost_tolerance = 0;
  o.step_tolerance = 0;
  o.gradient_tolerance = 1e-8;
  SphereSolver solver(problem, o);
  const BlockLmSummary s = solver.Solve(&u, &p);
  EXPECT_EQ(s.termination, BlockLmTermination::kGradientTolerance) << s.BriefReport();
  EXPECT_GT(s.initial_gradient_max_norm, 0);
  EXPECT_LE(s.gradient_max_norm, 1e-8 * s.initial_gradient_max_norm);
  EXPECT_GT(s.gradient_max_norm, 0);
}

TEST(BlockLm, NonFiniteDataIsANumericalFailure) {
  const Truth t = MakeTruth(50, 17);
  GaussianRng rng(18);
  SphereFit f = Observe(t, 0.01, &rng);
  f.y(1, 7) = std::numeric_limits<double>::quiet_NaN();
  const SphereProblem problem(f);
  Eigen::Matrix3Xd u;
  Eigen::VectorXd p;
  Start(f, &u, &p);
  u.col(7) = Vec3::UnitX();
  SphereSolver solver(problem, Options());
  const BlockLmSummary s = solver.Solve(&u, &p);
  EXPECT_EQ(s.termination, BlockLmTermination::kNumericalFailure);
  EXPECT_FALSE(s.usable());
  EXPECT_STREQ(BlockLmTerminationName(s.termination), "numerical_failure");
}

TEST(BlockLm, InformationThatIsNotPositiveDefiniteHasNoInverse) {
  Eigen::MatrixXd singular = Eigen::MatrixXd::Zero(2, 2);
  singular(0, 0) = 1;
  Eigen::MatrixXd cov = Eigen::MatrixXd::Ones(2, 2);
  EXPECT_FALSE(InvertInformation(singular, &cov));
  EXPECT_EQ(cov.size(), 0);
  EXPECT_TRUE(InvertInformation(2 * Eigen::MatrixXd::Identity(3, 3), &cov));
  EXPECT_DOUBLE_EQ(cov(1, 1), 0.5);
}

TEST(BlockLmOptions, ValidationNamesTheViolatedConstraint) {
  std::string error;
  EXPECT_TRUE(BlockLmOptions().IsValid(&error));
  auto invalid = [&](auto change, const char* name) {
    BlockLmOptions o;
    change(o);
    error.clear();
    EXPECT_FALSE(o.IsValid(&error)) << name;
    EXPECT_NE(error.find(name), std::string::npos) << error;
  };
  invalid([](BlockLmOptions& o) { o.max_iterations = 0; }, "max_iterations");
  invalid([](BlockLmOptions& o) { o.cost_tolerance = 1; }, "cost_tolerance");
  invalid([](BlockLmOptions& o) { o.step_tolerance = -1; }, "step_tolerance");
  invalid([](BlockLmOptions& o) { o.gradient_tolerance = NAN; }, "gradient_tolerance");
  invalid([](BlockLmOptions& o) { o.initial_damping = 0; }, "damping");
  invalid([](BlockLmOptions& o) { o.damping_increase = 1; }, "damping_increase");
  invalid([](BlockLmOptions& o) { o.chunk = 0; }, "chunk");
  invalid([](BlockLmOptions& o) { o.threads = -1; }, "threads");
}

// The fixed-size Cholesky helpers agree with Eigen's LLT.
TEST(BlockLm, SmallCholeskyHelpersAgreeWithEigen) {
  GaussianRng rng(19);
  Eigen::Matrix<double, 9, 9> A;
  for (int i = 0; i < 81; ++i) A.data()[i] = rng.Normal();
  const Eigen::Matrix<double, 9, 9> H = A * A.transpose() + Eigen::Matrix<double, 9, 9>::Identity();
  Eigen::Matrix<double, 9, 1> b;
  for (int i = 0; i < 9; ++i) b(i) = rng.Normal();
  const Eigen::Matrix<double, 9, 1> x = CholeskySolve<9>(CholeskyFactor<9>(H), b);
  EXPECT_LT((H * x - b).norm(), 1e-10 * b.norm());
  const Eigen::Matrix<double, 9, 9> Li = InverseCholeskyFactor<9>(H);
  EXPECT_LT((Li.transpose() * Li - H.inverse()).cwiseAbs().maxCoeff(), 1e-12);
  Eigen::Matrix<double, 9, 9> not_pd = -H;
  EXPECT_FALSE(CholeskyFactor<9>(not_pd).allFinite());
}

}  // namespace
}  // namespace calibd::core
