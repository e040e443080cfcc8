// The full array model (core/array_full.h, issue #18) side by side with the peer a C++ user
// would write: the same maximum-likelihood problem in Ceres Solver (per-sample blocks, sphere
// manifolds for the static directions, DENSE_SCHUR, 2 threads, analytic Jacobians), on the same
// simulated log (the 8-IMU MIMU4444-like board of bench/array_full_bench.cc: 62.5 Hz, 20 statics
// of 2 s, then the rotation, N samples in all) and from the same start.
//
// Built only when Ceres is found (bench/CMakeLists.txt); not needed by CI or the tests.
//
//   array_full_ceres_bench calibd N   calibd's joint LM (CalibrateArrayFull, 2 threads)
//   array_full_ceres_bench ceres N    Ceres from calibd's start (its closed forms and
//                                     positions-only fit, computed first and not timed)
//   array_full_ceres_bench ceres N check   the same with Ceres checking the analytic Jacobians
//                                     against numeric differences (slow)
// One solver per process, so the peak RSS is its own; prints wall and CPU seconds, iterations,
// the final cost (sum of squared whitened residuals) and the extra peak RSS of the solve.
//
// Same problem: the statics are found by core/static_detection with calibd's options and enter
// as their means weighted by sqrt(samples); every other sample is a block (omega, omega_dot, s).
// Gauges: the reference triad's position and the lower triangle of its accelerometer T are held
// (as calibd does); the scale gauge is held by T_g,ref[0][0] instead of calibd's sum of traces
// (a cross-block linear constraint Ceres cannot express) - a different choice of the same
// one-dimensional gauge, so the minimum cost is the same.
#include <ceres/ceres.h>
#include <sys/resource.h>

#include <Eigen/Dense>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "core/array_full.h"
#include "core/array_full_simulation.h"
#include "core/static_detection.h"

namespace {

using namespace calibd::core;
using Mat3 = Eigen::Matrix3d;
using Vec3 = Eigen::Vector3d;
using RowMat3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;

double ProcessCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}
double PeakRssMb() {  // VmHWM (resettable, unlike getrusage's ru_maxrss)
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  return 0;
}
double RssMb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  return 0;
}
void ResetPeakRss() { std::ofstream("/proc/self/clear_refs") << "5"; }

Mat3 Skew(const Vec3& v) {
  Mat3 m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// Dynamic sample n, accelerometer of triad k: r = w (y - T_a u - b_a),
// u = omega x (omega x r) + omega_dot x r + s. Blocks: x = (omega, omega_dot, s), T_a (row-major),
// b_a, r.
class DynamicAccel final : public ceres::SizedCostFunction<3, 9, 9, 3, 3> {
 public:
  DynamicAccel(const Vec3& y, double w) : y_(y), w_(w) {}
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    const Eigen::Map<const Vec3> om(p[0]), omd(p[0] + 3), s(p[0] + 6), b(p[2]), r(p[3]);
    const Eigen::Map<const RowMat3> T(p[1]);
    const Mat3 A = Skew(om) * Skew(om) + Skew(omd);
    const Vec3 u = A * r + s;
    Eigen::Map<Vec3>{residuals} = w_ * (y_ - T * u - b);
    if (jac == nullptr) return true;
    if (jac[0] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 3, 9, Eigen::RowMajor>> J(jac[0]);
      const Mat3 du_dom =
          om.dot(r) * Mat3::Identity() + om * r.transpose() - 2 * r * om.transpose();
      J.leftCols<3>() = -w_ * T * du_dom;
      J.middleCols<3>(3) = w_ * T * Skew(r);
      J.rightCols<3>() = -w_ * T;
    }
    if (jac[1] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 3, 9, Eigen::RowMajor>> J(jac[1]);
      J.setZero();
      for (int i = 0; i < 3; ++i) J.block<1, 3>(i, 3 * i) = -w_ * u.transpose();
    }
    if (jac[2] != nullptr)
      Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>{jac[2]} = -w_ * Mat3::Identity();
    if (jac[3] != nullptr)
      Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>{jac[3]} = -w_ * T * A;
    return true;
  }

 private:
  Vec3 y_;
  double w_;
};

// Dynamic sample, gyroscope of triad k: r = w (y - T_g omega - b_g). Blocks: x, T_g, b_g.
class DynamicGyro final : public ceres::SizedCostFunction<3, 9, 9, 3> {
 public:
  DynamicGyro(const Vec3& y, double w) : y_(y), w_(w) {}
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    const Eigen::Map<const Vec3> om(p[0]), b(p[2]);
    const Eigen::Map<const RowMat3> T(p[1]);
    Eigen::Map<Vec3>{residuals} = w_ * (y_ - T * om - b);
    if (jac == nullptr) return true;
    if (jac[0] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 3, 9, Eigen::RowMajor>> J(jac[0]);
      J.setZero();
      J.leftCols<3>() = -w_ * T;
    }
    if (jac[1] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 3, 9, Eigen::RowMajor>> J(jac[1]);
      J.setZero();
      for (int i = 0; i < 3; ++i) J.block<1, 3>(i, 3 * i) = -w_ * om.transpose();
    }
    if (jac[2] != nullptr)
      Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>{jac[2]} = -w_ * Mat3::Identity();
    return true;
  }

 private:
  Vec3 y_;
  double w_;
};

// Static j, accelerometer of triad k: r = w sqrt(n) (ybar - T_a g s_j - b_a), |s_j| = 1 (sphere).
class StaticAccel final : public ceres::SizedCostFunction<3, 3, 9, 3> {
 public:
  StaticAccel(const Vec3& y, double w, double g) : y_(y), w_(w), g_(g) {}
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    const Eigen::Map<const Vec3> s(p[0]), b(p[2]);
    const Eigen::Map<const RowMat3> T(p[1]);
    Eigen::Map<Vec3>{residuals} = w_ * (y_ - g_ * T * s - b);
    if (jac == nullptr) return true;
    if (jac[0] != nullptr)
      Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>{jac[0]} = -w_ * g_ * T;
    if (jac[1] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 3, 9, Eigen::RowMajor>> J(jac[1]);
      J.setZero();
      for (int i = 0; i < 3; ++i) J.block<1, 3>(i, 3 * i) = -w_ * g_ * s.transpose();
    }
    if (jac[2] != nullptr)
      Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>{jac[2]} = -w_ * Mat3::Identity();
    return true;
  }

 private:
  Vec3 y_;
  double w_, g_;
};

// Static j, gyroscope of triad k: r = w sqrt(n) (ybar - b_g).
class StaticGyro final : public ceres::SizedCostFunction<3, 3> {
 public:
  StaticGyro(const Vec3& y, double w) : y_(y), w_(w) {}
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    Eigen::Map<Vec3>{residuals} = w_ * (y_ - Eigen::Map<const Vec3>(p[0]));
    if (jac != nullptr && jac[0] != nullptr)
      Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>{jac[0]} = -w_ * Mat3::Identity();
    return true;
  }

 private:
  Vec3 y_;
  double w_;
};

struct Setup {
  ArrayFullSimulationOptions so;
  ArrayFullSimulation sim;
  ArrayFullOptions o;
};

void MakeSetup(int64_t n, Setup* s) {
  s->so.nominal_positions = Mimu4444NominalPositions();
  s->so.rate = 62.5;
  s->so.static_duration = 2;
  s->so.dynamic_samples = n - 2500;
  s->so.seed = 2026;
  if (!SimulateArrayFull(s->so, &s->sim).ok()) std::abort();
  s->o.accel_noise = s->so.accel_noise;
  s->o.gyro_noise = s->so.gyro_noise;
  s->o.statics.static_window = 0.5;
  s->o.statics.min_static = 0.5;
  s->o.threads = 2;
}

int RunCalibd(int64_t n) {
  Setup s;
  MakeSetup(n, &s);
  const double rss0 = RssMb();
  ResetPeakRss();
  const double cpu0 = ProcessCpuSeconds();
  const auto t0 = std::chrono::steady_clock::now();
  ArrayFullResult r;
  const calibd::Status st = CalibrateArrayFull(s.sim.problem, s.o, &r);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double cpu = ProcessCpuSeconds() - cpu0;
  if (!st.ok()) {
    std::fprintf(stderr, "calibd: %s\n", st.message().c_str());
    return 1;
  }
  std::printf(
      "calibd N=%lld statics=%lld dynamic=%lld iterations=%d cost=%.10g wall_s=%.3f cpu_s=%.3f "
      "peak_rss_delta_MB=%.1f start_cost=%.10g sigma_ratio=%.12g (start, solve, CRB, "
      "residual-aware σ, null-space check, diagnostics)\n",
      static_cast<long long>(n), static_cast<long long>(r.statics),
      static_cast<long long>(r.dynamic_samples), r.iterations, r.cost.back(), wall, cpu,
      PeakRssMb() - rss0, r.cost.front(), r.sigma_ratio);
  return 0;
}

int RunCeres(int64_t n, bool check_gradients) {
  Setup s;
  MakeSetup(n, &s);
  const ArrayFullProblem& p = s.sim.problem;
  const int K = static_cast<int>(p.nominal_positions.cols());
  const int64_t N = p.t.size();
  // calibd's start (closed forms + positions-only fit), not timed.
  ArrayFullResult start;
  {
    ArrayFullOptions o1 = s.o;
    o1.max_iterations = 1;
    CalibrateArrayFull(p, o1, &start);
    if (start.initial.size() != static_cast<size_t>(K)) {
      std::fprintf(stderr, "no start\n");
      return 1;
    }
  }
  // The same segmentation as calibd.
  std::vector<Eigen::MatrixX3d> series(2 * K);
  std::vector<TriadSeries> triads(2 * K);
  for (int k = 0; k < 2 * K; ++k) {
    series[k] = (k < K ? p.accel : p.gyro).middleCols(3 * (k % K), 3);
    triads[k].kind = k < K ? TriadKind::kAccelerometer : TriadKind::kGyroscope;
    triads[k].readings = &series[k];
  }
  StaticDetection det;
  if (!DetectStatics(p.t, triads, s.o.statics, &det).ok()) return 1;
  std::vector<char> in_static(N, 0);
  for (const auto& iv : det.intervals)
    for (int64_t i = iv.first; i <= iv.last; ++i) in_static[i] = 1;
  std::vector<int64_t> dyn;
  for (int64_t i = 0; i < N; ++i)
    if (!in_static[i]) dyn.push_back(i);
  const int64_t J = static_cast<int64_t>(det.intervals.size()),
                Nd = static_cast<int64_t>(dyn.size());
  const double wa = 1 / s.o.accel_noise, wg = 1 / s.o.gyro_noise, g = s.o.gravity;

  const double rss0 = RssMb();
  ResetPeakRss();
  const double cpu0 = ProcessCpuSeconds();
  const auto t0 = std::chrono::steady_clock::now();
  // Parameters: per triad T_a, b_a, T_g, b_g, r; per static a direction; per sample x.
  std::vector<double> Ta(9 * K), ba(3 * K), Tg(9 * K), bg(3 * K), rr(3 * K), sd(3 * J), x(9 * Nd);
  for (int k = 0; k < K; ++k) {
    const ArrayFullTriad& t = start.initial[k];
    Eigen::Map<RowMat3>{&Ta[9 * k]} = t.accel_T;
    Eigen::Map<Vec3>{&ba[3 * k]} = t.accel_bias;
    Eigen::Map<RowMat3>{&Tg[9 * k]} = t.gyro_T;
    Eigen::Map<Vec3>{&bg[3 * k]} = t.gyro_bias;
    Eigen::Map<Vec3>{&rr[3 * k]} = t.position;
  }
  const int ref = p.reference;
  const ArrayFullTriad& tr = start.initial[ref];
  for (int64_t j = 0; j < J; ++j) {
    const Vec3 y = det.intervals[j].mean[ref];
    Eigen::Map<Vec3>{&sd[3 * j]} = (tr.accel_T.inverse() * (y - tr.accel_bias)).normalized();
  }
  // Per-sample motion in closed form given the start (as calibd's start does): omega from the
  // gyroscopes, then omega_dot and s by linear least squares on the accelerometers.
  for (int64_t m = 0; m < Nd; ++m) {
    Vec3 om = Vec3::Zero();
    for (int k = 0; k < K; ++k) {
      const ArrayFullTriad& t = start.initial[k];
      om += t.gyro_T.inverse() * (p.gyro.row(dyn[m]).segment<3>(3 * k).transpose() - t.gyro_bias);
    }
    om /= K;
    Eigen::MatrixXd A(3 * K, 6);
    Eigen::VectorXd rhs(3 * K);
    for (int k = 0; k < K; ++k) {
      const ArrayFullTriad& t = start.initial[k];
      const Vec3 u =
          t.accel_T.inverse() * (p.accel.row(dyn[m]).segment<3>(3 * k).transpose() - t.accel_bias);
      A.block<3, 3>(3 * k, 0) = -Skew(t.position);
      A.block<3, 3>(3 * k, 3).setIdentity();
      rhs.segment<3>(3 * k) = u - Skew(om) * Skew(om) * t.position;
    }
    const Eigen::VectorXd sol = A.colPivHouseholderQr().solve(rhs);
    Eigen::Map<Vec3>{&x[9 * m]} = om;
    Eigen::Map<Eigen::Matrix<double, 6, 1>>{&x[9 * m + 3]} = sol;
  }

  ceres::Problem::Options po;
  ceres::Problem problem(po);
  auto order = std::make_shared<ceres::ParameterBlockOrdering>();
  for (int64_t m = 0; m < Nd; ++m) {
    double* xm = &x[9 * m];
    for (int k = 0; k < K; ++k) {
      problem.AddResidualBlock(
          new DynamicAccel(p.accel.row(dyn[m]).segment<3>(3 * k).transpose(), wa), nullptr, xm,
          &Ta[9 * k], &ba[3 * k], &rr[3 * k]);
      problem.AddResidualBlock(
          new DynamicGyro(p.gyro.row(dyn[m]).segment<3>(3 * k).transpose(), wg), nullptr, xm,
          &Tg[9 * k], &bg[3 * k]);
    }
    order->AddElementToGroup(xm, 0);
  }
  for (int64_t j = 0; j < J; ++j) {
    const double w = std::sqrt(static_cast<double>(det.intervals[j].samples));
    for (int k = 0; k < K; ++k) {
      problem.AddResidualBlock(new StaticAccel(det.intervals[j].mean[k], w * wa, g), nullptr,
                               &sd[3 * j], &Ta[9 * k], &ba[3 * k]);
      problem.AddResidualBlock(new StaticGyro(det.intervals[j].mean[K + k], w * wg), nullptr,
                               &bg[3 * k]);
    }
    problem.SetManifold(&sd[3 * j], new ceres::SphereManifold<3>());
    order->AddElementToGroup(&sd[3 * j], 0);
  }
  for (int k = 0; k < K; ++k)
    for (double* b : {&Ta[9 * k], &ba[3 * k], &Tg[9 * k], &bg[3 * k], &rr[3 * k]})
      order->AddElementToGroup(b, 1);
  // Gauges: the reference's position, the lower triangle of its T_a, one gyroscope gain.
  problem.SetParameterBlockConstant(&rr[3 * ref]);
  problem.SetManifold(&Ta[9 * ref], new ceres::SubsetManifold(9, {3, 6, 7}));
  problem.SetManifold(&Tg[9 * ref], new ceres::SubsetManifold(9, {0}));

  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_SCHUR;
  so.linear_solver_ordering = order;
  so.num_threads = 2;
  so.max_num_iterations = 100;
  so.function_tolerance = 1e-10;  // calibd's tolerance (relative cost decrease)
  so.parameter_tolerance = 1e-10;
  so.gradient_tolerance = 1e-14;
  so.check_gradients = check_gradients;         // analytic vs numeric Jacobians (slow)
  so.gradient_check_relative_precision = 1e-4;  // entries ~1e-8 differ by ~1e-13 (rounding)
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double cpu = ProcessCpuSeconds() - cpu0;
  std::printf(
      "ceres  N=%lld statics=%lld dynamic=%lld iterations=%d cost=%.10g wall_s=%.3f cpu_s=%.3f "
      "peak_rss_delta_MB=%.1f start_cost=%.10g termination=%s (setup + solve, no covariance)\n",
      static_cast<long long>(n), static_cast<long long>(J), static_cast<long long>(Nd),
      static_cast<int>(summary.iterations.size()) - 1, 2 * summary.final_cost, wall, cpu,
      PeakRssMb() - rss0, 2 * summary.initial_cost,
      ceres::TerminationTypeToString(summary.termination_type));
  if (check_gradients) std::printf("%s\n", summary.message.c_str());
  return summary.IsSolutionUsable() ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3 || argc > 4 ||
      (std::strcmp(argv[1], "calibd") != 0 && std::strcmp(argv[1], "ceres") != 0)) {
    std::fprintf(stderr, "usage: %s calibd|ceres N [check]\n", argv[0]);
    return 2;
  }
  const int64_t n = std::atoll(argv[2]);
  if (n < 3000) {
    std::fprintf(stderr, "N must be >= 3000 (2 500 samples of statics)\n");
    return 2;
  }
  return std::strcmp(argv[1], "calibd") == 0 ? RunCalibd(n) : RunCeres(n, argc == 4);
}
