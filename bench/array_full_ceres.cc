// The full array model (core/array_full.h, issue #18) side by side with the peer a C++ user
// would write: the same maximum-likelihood problem in Ceres Solver (per-sample blocks, sphere
// manifolds for the static directions, DENSE_SCHUR, 2 threads, analytic Jacobians), on the same
// simulated log (the 8-IMU MIMU4444-like board of bench/array_full_bench.cc: 62.5 Hz, 20 statics
// of 2 s, then the rotation, N samples in all) and from the same start.
//
// Built only when Ceres is found (bench/CMakeLists.txt); not needed by CI or the tests.
//
//   array_full_ceres_bench calibd N   calibd's joint LM (CalibrateArrayFull), per-stage CPU
//   array_full_ceres_bench ceres N    Ceres from calibd's start (its closed forms and
//                                     positions-only fit, computed first and not timed)
//   array_full_ceres_bench ceres N check   the same with Ceres checking the analytic Jacobians
//                                     against numeric differences (slow)
//   array_full_ceres_bench export N FILE   the problem and the start Ceres gets, for
//                                     bench/array_full_scipy.py (ExportProblem)
//   array_full_ceres_bench ceres N covariance   then ceres::Covariance of the triads' parameters
//                                     (what calibd's CRB stage computes), timed apart
// Both use 2 threads ($BENCH_THREADS to change). One solver per process, so the peak RSS is its
// own; prints wall and CPU seconds, iterations, the final cost (sum of squared whitened residuals)
// and the extra peak RSS of the solve.
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
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>
#include <iomanip>
#include <memory>
#include <string>
#include <utility>
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

// Threads of both solvers: 2, or $BENCH_THREADS (1 compares the algorithms without either's
// threading; on a loaded machine a spinning pool inflates the CPU time).
int BenchThreads() {
  const char* env = std::getenv("BENCH_THREADS");
  return env != nullptr && std::atoi(env) > 0 ? std::atoi(env) : 2;
}

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
  s->o.threads = BenchThreads();
}

int RunCalibd(int64_t n) {
  Setup s;
  MakeSetup(n, &s);
  const double rss0 = RssMb();
  ResetPeakRss();
  const double cpu0 = ProcessCpuSeconds();
  const auto t0 = std::chrono::steady_clock::now();
  // Process CPU at the start of each stage (ArrayFullOptions::on_stage).
  struct Stage {
    std::string name;
    double cpu, wall;
  };
  std::vector<Stage> stages;
  s.o.on_stage = [&stages](const char* name) {
    stages.push_back(
        {name, ProcessCpuSeconds(),
         std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
             .count()});
  };
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
  // Per stage, both threads; "joint solver" is what Ceres' run times (the same start, to the
  // same cost).
  const int other = s.sim.problem.reference == 1 ? 2 : 1;
  std::printf("calibd position_std_crb[%d].x=%.6g (another scale gauge than Ceres')\n", other,
              r.report_std_crb[other].position_std(0));
  std::printf("calibd stages cpu_s/wall_s:");
  for (size_t i = 0; i + 1 < stages.size(); ++i) {
    std::printf(" %s=%.3f/%.3f", stages[i].name.c_str(), stages[i + 1].cpu - stages[i].cpu,
                stages[i + 1].wall - stages[i].wall);
  }
  std::printf("\n");
  return 0;
}

// The problem as RunCeres sets it up (readings, statics, weights, its start) for
// bench/array_full_scipy.py: a header line "K Nd J ref wa wg g", then little-endian doubles:
// the dynamic samples' accelerometer and gyroscope readings (Nd × 3K each, sample-major), the
// statics' accelerometer and gyroscope means (J × 3K each) and sample counts (J), the start's
// T_a (9K, row-major per triad), b_a (3K), T_g (9K), b_g (3K), r (3K), static directions (3J) and
// per-sample motion (9 Nd: omega, omega_dot, s).
void ExportProblem(const std::string& path, const ArrayFullProblem& p, int K,
                   const std::vector<int64_t>& dyn, const StaticDetection& det, double wa,
                   double wg, double g, const std::vector<const std::vector<double>*>& start) {
  std::ofstream out(path, std::ios::binary);
  out << K << " " << dyn.size() << " " << det.intervals.size() << " " << p.reference << " "
      << std::setprecision(17) << wa << " " << wg << " " << g << "\n";
  const auto put = [&out](double v) { out.write(reinterpret_cast<const char*>(&v), sizeof v); };
  for (const Eigen::MatrixXd* m : {&p.accel, &p.gyro})
    for (int64_t i : dyn)
      for (int c = 0; c < 3 * K; ++c) put((*m)(i, c));
  for (int kind = 0; kind < 2; ++kind)
    for (const StaticInterval& iv : det.intervals)
      for (int k = 0; k < K; ++k)
        for (int a = 0; a < 3; ++a) put(iv.mean[kind * K + k](a));
  for (const StaticInterval& iv : det.intervals) put(static_cast<double>(iv.samples));
  for (const std::vector<double>* v : start)
    for (double e : *v) put(e);
}

int RunCeres(int64_t n, bool check_gradients, bool covariance, const std::string& export_path) {
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

  if (!export_path.empty()) {
    ExportProblem(export_path, p, K, dyn, det, wa, wg, g, {&Ta, &ba, &Tg, &bg, &rr, &sd, &x});
    std::printf("wrote %s\n", export_path.c_str());
    return 0;
  }
  // Timed from here: the problem's setup and the solve (the start above, the per-sample motion
  // included, is calibd's "start" stage, which calibd's solve time leaves out too).
  const double rss0 = RssMb();
  ResetPeakRss();
  const double cpu0 = ProcessCpuSeconds();
  const auto t0 = std::chrono::steady_clock::now();
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
  so.num_threads = BenchThreads();
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
  if (covariance && summary.IsSolutionUsable()) {
    // What calibd's "crb" stage gives: the covariance of every triad's parameters (the inverse
    // of the information with the per-sample and static unknowns eliminated), by ceres::Covariance
    // over all pairs of the triads' blocks (its default sparse QR, 2 threads).
    const double cpu1 = ProcessCpuSeconds();
    ceres::Covariance::Options co;
    co.num_threads = BenchThreads();
    ceres::Covariance cov(co);
    std::vector<const double*> blocks;
    for (int k = 0; k < K; ++k)
      for (const double* b : {&Ta[9 * k], &ba[3 * k], &Tg[9 * k], &bg[3 * k], &rr[3 * k]})
        if (k != ref || b != &rr[3 * ref]) blocks.push_back(b);
    std::vector<std::pair<const double*, const double*>> pairs;
    for (size_t i = 0; i < blocks.size(); ++i)
      for (size_t j = i; j < blocks.size(); ++j) pairs.emplace_back(blocks[i], blocks[j]);
    const bool ok = cov.Compute(pairs, &problem);
    const int other = ref == 1 ? 2 : 1;  // a triad whose position is estimated
    std::vector<double> rc(9);
    if (ok) cov.GetCovarianceBlock(&rr[3 * other], &rr[3 * other], rc.data());
    std::printf(
        "ceres  covariance cpu_s=%.3f ok=%d peak_rss_delta_MB=%.1f position_std[%d].x=%.6g\n",
        ProcessCpuSeconds() - cpu1, ok ? 1 : 0, PeakRssMb() - rss0, other,
        std::sqrt(std::max(0.0, rc[0])));
  }
  return summary.IsSolutionUsable() ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  const bool known =
      argc >= 3 && (std::strcmp(argv[1], "calibd") == 0 || std::strcmp(argv[1], "ceres") == 0 ||
                    std::strcmp(argv[1], "export") == 0);
  if (!known || argc > 4 || (std::strcmp(argv[1], "export") == 0 && argc != 4)) {
    std::fprintf(stderr, "usage: %s calibd|ceres N [check|covariance] | export N FILE\n", argv[0]);
    return 2;
  }
  const int64_t n = std::atoll(argv[2]);
  if (n < 3000) {
    std::fprintf(stderr, "N must be >= 3000 (2 500 samples of statics)\n");
    return 2;
  }
  if (std::strcmp(argv[1], "export") == 0) return RunCeres(n, false, false, argv[3]);
  return std::strcmp(argv[1], "calibd") == 0
             ? RunCalibd(n)
             : RunCeres(n, argc == 4 && std::strcmp(argv[3], "check") == 0,
                        argc == 4 && std::strcmp(argv[3], "covariance") == 0, "");
}
