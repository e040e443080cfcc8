// The full array model's structured Schur term (FullProblem::AddCouplingGram) against block_lm's
// dense rank-k update on random problems: per block, the reduced information at a point, and a
// whole Levenberg-Marquardt solve.
#include "core/array_full_model.h"

#include <gtest/gtest.h>

#include <random>

namespace calibd::core::array_full_model {
namespace {

struct RandomCase {
  FullData d;
  Eigen::MatrixXd E;
  Eigen::VectorXd theta;
  Eigen::Matrix<double, 10, Eigen::Dynamic> x;
};

// K triads at random positions with random T_a, T_g near I and random biases; J statics and Nd
// dynamic samples of random (omega, omega_dot, s); readings = the model + noise of sigma.
RandomCase MakeCase(int K, int J, int Nd, double sigma, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> N01;
  auto randn = [&](int rows, int cols) {
    Eigen::MatrixXd m(rows, cols);
    for (int j = 0; j < cols; ++j)
      for (int i = 0; i < rows; ++i) m(i, j) = N01(rng);
    return m;
  };
  RandomCase c;
  FullData& d = c.d;
  d.K = K;
  d.J = J;
  d.Nd = Nd;
  d.wa = 1 / 0.04, d.wg = 1 / 0.003, d.wa_d = 1 / 0.05, d.wg_d = 1 / 0.004;
  c.theta.resize(kP * K);
  for (int k = 0; k < K; ++k) {
    double* p = c.theta.data() + kP * k;
    const Eigen::MatrixXd ta = Eigen::MatrixXd::Identity(3, 3) + 0.05 * randn(3, 3);
    const Eigen::MatrixXd tg = Eigen::MatrixXd::Identity(3, 3) + 0.05 * randn(3, 3);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) p[kTa + 3 * i + j] = ta(i, j), p[kTg + 3 * i + j] = tg(i, j);
    for (int i = 0; i < 3; ++i) {
      p[kBa + i] = 0.1 * N01(rng);
      p[kBg + i] = 0.01 * N01(rng);
      p[kR + i] = 0.02 * N01(rng);
    }
  }
  c.E = GaugeBasis(K, 0);
  const std::vector<TriadParams> tp = Unpack(c.theta, K);
  c.x.setZero(10, J + Nd);
  d.static_a.resize(3 * K, J), d.static_g.resize(3 * K, J), d.static_n.resize(J);
  for (int j = 0; j < J; ++j) {
    const Vec3 s = d.gravity * Vec3(randn(3, 1)).normalized();
    c.x.col(j).head<3>() = s;
    c.x(9, j) = 1;
    d.static_n(j) = 100 + j;
    for (int k = 0; k < K; ++k) {
      d.static_a.col(j).segment<3>(3 * k) = tp[k].Ta * s + tp[k].ba + sigma * Vec3(randn(3, 1));
      d.static_g.col(j).segment<3>(3 * k) = tp[k].bg + sigma * Vec3(randn(3, 1));
    }
  }
  d.ya.resize(3 * K, Nd), d.yg.resize(3 * K, Nd);
  for (int m = 0; m < Nd; ++m) {
    const Vec3 w = 3 * Vec3(randn(3, 1)), wd = 10 * Vec3(randn(3, 1)), s = 5 * Vec3(randn(3, 1));
    c.x.col(J + m).head<3>() = w, c.x.col(J + m).segment<3>(3) = wd;
    c.x.col(J + m).segment<3>(6) = s;
    for (int k = 0; k < K; ++k) {
      const Vec3 u = MatrixA(w, wd) * tp[k].r + s;
      d.ya.col(m).segment<3>(3 * k) = tp[k].Ta * u + tp[k].ba + sigma * Vec3(randn(3, 1));
      d.yg.col(m).segment<3>(3 * k) = tp[k].Tg * w + tp[k].bg + sigma * Vec3(randn(3, 1));
    }
  }
  return c;
}

double RelativeDifference(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).norm() / b.norm();
}

TEST(ArrayFullModel, StructuredCouplingGramEqualsTheDenseOneBlockByBlock) {
  static_assert(HasStructuredCouplingGram<FullProblem>::value);
  const RandomCase c = MakeCase(5, 3, 40, 0.01, 7);
  const FullProblem fp(c.d, c.E);
  const FullProblem::Context ctx = fp.MakeContext(c.theta);
  const int q = fp.CouplingDim();
  for (int64_t n = 0; n < fp.NumBlocks(); ++n) {
    FullProblem::Normal b;
    fp.BlockMatrices(n, c.x.col(n), ctx, &b);
    b.H.diagonal() *= 1.3;  // damped, as in the LM iterations
    const Eigen::Matrix<double, 9, 9> Linv = InverseCholeskyFactor<9>(b.H);
    const Eigen::MatrixXd Z = Linv * b.C;
    const Eigen::MatrixXd dense = Z.transpose() * Z;
    Eigen::MatrixXd T = Eigen::MatrixXd::Zero(q, q);
    const bool structured = fp.AddCouplingGram(n, c.x.col(n), ctx, Linv, &T);
    EXPECT_EQ(structured, n >= c.d.J) << "block " << n;  // statics stay on the dense path
    if (!structured) continue;
    const Eigen::MatrixXd lower = T.triangularView<Eigen::Lower>();
    const Eigen::MatrixXd dense_lower = dense.triangularView<Eigen::Lower>();
    EXPECT_LT(RelativeDifference(lower, dense_lower), 1e-13) << "block " << n;
  }
}

TEST(ArrayFullModel, StructuredAndDenseSolvesAgree) {
  const RandomCase c = MakeCase(4, 6, 300, 0.01, 11);
  const FullProblem structured(c.d, c.E, true), dense(c.d, c.E, false);
  BlockLmOptions o;
  o.threads = 1;
  BlockLm<FullProblem> ls(structured, o), ld(dense, o);
  // Reduced information and gradient at the (perturbed) truth.
  Eigen::VectorXd theta0 = c.theta;
  for (int i = 0; i < theta0.size(); ++i) theta0(i) += 1e-3 * std::sin(1.7 * i);
  BlockLmInformation is, id;
  ls.ComputeSharedInformation(c.x, theta0, &is, nullptr);
  ld.ComputeSharedInformation(c.x, theta0, &id, nullptr);
  EXPECT_LT(RelativeDifference(is.information, id.information), 1e-12);
  EXPECT_LT(RelativeDifference(is.gradient, id.gradient), 1e-10);
  EXPECT_EQ(is.cost, id.cost);
  // The whole solve from that start: same iterations, cost and estimate.
  auto xs = c.x, xd = c.x;
  Eigen::VectorXd ps = theta0, pd = theta0;
  const BlockLmSummary ss = ls.Solve(&xs, &ps), sd = ld.Solve(&xd, &pd);
  ASSERT_TRUE(ss.usable()) << ss.BriefReport();
  ASSERT_TRUE(sd.usable()) << sd.BriefReport();
  EXPECT_EQ(ss.iterations, sd.iterations);
  EXPECT_LT(std::abs(ss.final_cost() - sd.final_cost()), 1e-10 * sd.final_cost());
  EXPECT_LT(RelativeDifference(ps, pd), 1e-10);
  EXPECT_LT(RelativeDifference(xs, xd), 1e-10);
  EXPECT_GT(ss.iterations, 1);  // the start was away from the minimum
}

}  // namespace
}  // namespace calibd::core::array_full_model
