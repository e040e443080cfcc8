#include "core/array_full.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <thread>

#include "core/array.h"

namespace calibd::core {
namespace {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Vec27 = Eigen::Matrix<double, 27, 1>;
using Mat27 = Eigen::Matrix<double, 27, 27>;
using Vec9 = Eigen::Matrix<double, 9, 1>;
using Vec10 = Eigen::Matrix<double, 10, 1>;
using Mat9 = Eigen::Matrix<double, 9, 9>;

constexpr int kP = kArrayFullTriadParameters;
// Offsets in a triad's 27 parameters.
constexpr int kTa = 0, kBa = 9, kTg = 12, kBg = 21, kR = 24;

Mat3 Skew(const Vec3& v) {
  Mat3 m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// A = Omega_omega^2 + Omega_omega_dot: u = A r + s.
Mat3 MatrixA(const Vec3& w, const Vec3& wd) {
  return w * w.transpose() - w.squaredNorm() * Mat3::Identity() + Skew(wd);
}

// d/d omega [omega x (omega x r)] = (omega . r) I + omega r^T - 2 r omega^T.
Mat3 CentripetalJacobian(const Vec3& w, const Vec3& r) {
  return w.dot(r) * Mat3::Identity() + w * r.transpose() - 2 * r * w.transpose();
}

// Orthonormal basis of the tangent plane of the sphere at s (a deterministic function of s).
Eigen::Matrix<double, 3, 2> SphereBasis(const Vec3& s) {
  int i = 0;
  s.cwiseAbs().minCoeff(&i);
  const Vec3 e = Vec3::Unit(i);
  const Vec3 b1 = e.cross(s).normalized();
  const Vec3 b2 = s.normalized().cross(b1);
  Eigen::Matrix<double, 3, 2> B;
  B << b1, b2;
  return B;
}

struct TriadParams {
  Mat3 Ta, Tg;
  Vec3 ba, bg, r;
};

std::vector<TriadParams> Unpack(const Eigen::VectorXd& theta, int K) {
  std::vector<TriadParams> c(K);
  for (int k = 0; k < K; ++k) {
    const double* p = theta.data() + kP * k;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        c[k].Ta(i, j) = p[kTa + 3 * i + j];
        c[k].Tg(i, j) = p[kTg + 3 * i + j];
      }
    c[k].ba = Vec3(p[kBa], p[kBa + 1], p[kBa + 2]);
    c[k].bg = Vec3(p[kBg], p[kBg + 1], p[kBg + 2]);
    c[k].r = Vec3(p[kR], p[kR + 1], p[kR + 2]);
  }
  return c;
}

// The data of the fit: static means and dynamic samples, column-wise.
struct FullData {
  int K = 0;
  int64_t J = 0;                       // statics
  int64_t Nd = 0;                      // dynamic samples
  Eigen::MatrixXd static_a, static_g;  // 3K x J means
  Eigen::VectorXd static_n;            // J sample counts
  Eigen::MatrixXd ya, yg;              // 3K x Nd
  std::vector<int64_t> dyn_index;      // Nd: sample index in the log
  double wa = 0, wg = 0;               // 1 / sigma (statics)
  double wa_d = 0, wg_d = 0;           // 1 / sigma (dynamic samples)
  double gravity = 9.80665;
};

// The ML problem for core/block_lm.h: blocks 0..J-1 are the statics, J.. the dynamic samples.
class FullProblem {
 public:
  static constexpr int kBlockDim = 9;
  static constexpr int kBlockStateDim = 10;  // (omega, omega_dot, s, 0) or (s, 0..., 1)
  static constexpr int kCouplingDim = Eigen::Dynamic;
  using SharedState = Eigen::VectorXd;
  using Context = std::vector<TriadParams>;
  using Normal = BlockNormal<9, Eigen::Dynamic>;
  struct Sums {
    std::vector<Mat27> H;
    Eigen::VectorXd g;
  };

  FullProblem(const FullData& d, const Eigen::MatrixXd& E) : d_(d), E_(E) {}

  int64_t NumBlocks() const { return d_.J + d_.Nd; }
  int SharedDim() const { return static_cast<int>(E_.cols()); }
  int CouplingDim() const { return kP * d_.K; }
  Context MakeContext(const SharedState& p) const { return Unpack(p, d_.K); }
  Sums MakeSums() const {
    return Sums{std::vector<Mat27>(d_.K, Mat27::Zero()), Eigen::VectorXd::Zero(kP * d_.K)};
  }
  void Merge(const Sums& from, Sums* into) const {
    for (int k = 0; k < d_.K; ++k) into->H[k] += from.H[k];
    into->g += from.g;
  }

  template <class X>
  void Linearize(int64_t n, const X& x, const Context& c, Normal* out, Sums* sums) const {
    Evaluate(n, Vec10(x), c, out, true, &sums->H, &sums->g);
  }
  template <class X>
  void BlockMatrices(int64_t n, const X& x, const Context& c, Normal* out) const {
    Evaluate(n, Vec10(x), c, out, true, nullptr, nullptr);
  }
  template <class X>
  double Cost(int64_t n, const X& x, const Context& c) const {
    Normal b;
    Evaluate(n, Vec10(x), c, &b, false, nullptr, nullptr);
    return b.cost;
  }
  template <class M>
  void Factored(int64_t, const M&, Sums*) const {}
  void AssembleShared(const Sums& sums, const Context&, SharedNormal* out) const {
    const int q = CouplingDim();
    Eigen::MatrixXd HE(q, E_.cols());
    for (int k = 0; k < d_.K; ++k)
      HE.middleRows(kP * k, kP).noalias() = sums.H[k] * E_.middleRows(kP * k, kP);
    out->H.noalias() = E_.transpose() * HE;
    out->g.noalias() = E_.transpose() * sums.g;
    out->lift = E_;
    out->coupling_weight = 1;
  }
  template <class X, class D>
  Vec10 PlusBlock(const X& x_in, const D& dx) const {
    Vec10 x = x_in;
    if (x(9) > 0.5) {
      const Vec3 s = x.head<3>();
      const Vec3 moved = s + SphereBasis(s) * dx.template head<2>();
      x.head<3>() = d_.gravity * moved.normalized();
    } else {
      x.head<9>() += dx;
    }
    return x;
  }
  SharedState PlusShared(const SharedState& p, const Eigen::VectorXd& dp) const {
    return p + E_ * dp;
  }
  double SharedMaxNorm(const SharedState& p) const { return p.cwiseAbs().maxCoeff(); }

  // Raw (unwhitened) residuals of block n: accel and gyro, 3K each, added squared per triad
  // into acc (K x 2).
  void AddSquaredResiduals(int64_t n, const Vec10& x, const Context& c,
                           Eigen::MatrixX2d* acc) const {
    for (int k = 0; k < d_.K; ++k) {
      Vec3 ea, eg;
      if (n < d_.J) {
        const double sq = std::sqrt(d_.static_n(n));
        ea = sq * (d_.static_a.col(n).segment<3>(3 * k) - c[k].Ta * x.head<3>() - c[k].ba);
        eg = sq * (d_.static_g.col(n).segment<3>(3 * k) - c[k].bg);
      } else {
        const int64_t m = n - d_.J;
        const Vec3 w = x.head<3>();
        const Vec3 u = MatrixA(w, x.segment<3>(3)) * c[k].r + x.segment<3>(6);
        ea = d_.ya.col(m).segment<3>(3 * k) - c[k].Ta * u - c[k].ba;
        eg = d_.yg.col(m).segment<3>(3 * k) - c[k].Tg * w - c[k].bg;
      }
      (*acc)(k, 0) += ea.squaredNorm();
      (*acc)(k, 1) += eg.squaredNorm();
    }
  }

 private:
  // Residuals r = whitened (y - prediction); J = d r / d(unknowns) = -w d prediction.
  // full: also H, g and C of the block. H_pp/g_p sums when H/g are given.
  void Evaluate(int64_t n, const Vec10& x, const Context& c, Normal* out, bool full,
                std::vector<Mat27>* H, Eigen::VectorXd* g) const {
    const int K = d_.K;
    out->cost = 0;
    if (full) {
      out->H.setZero();
      out->g.setZero();
      out->C.setZero(9, CouplingDim());
    }
    if (n < d_.J) {
      EvaluateStatic(n, x, c, out, full, H, g);
      return;
    }
    const int64_t m = n - d_.J;
    const double wa = d_.wa_d, wg = d_.wg_d;
    const Vec3 w = x.head<3>(), wd = x.segment<3>(3), s = x.segment<3>(6);
    const Mat3 A = MatrixA(w, wd);
    for (int k = 0; k < K; ++k) {
      const TriadParams& p = c[k];
      const int o = kP * k;
      const Vec3 u = A * p.r + s;
      const Vec3 ea = wa * (d_.ya.col(m).segment<3>(3 * k) - p.Ta * u - p.ba);
      const Vec3 eg = wg * (d_.yg.col(m).segment<3>(3 * k) - p.Tg * w - p.bg);
      out->cost += ea.squaredNorm() + eg.squaredNorm();
      if (!full && !g) continue;
      // Accelerometer: J_p over (T_a row-major, b_a, r).
      Eigen::Matrix<double, 3, 15> Jp = Eigen::Matrix<double, 3, 15>::Zero();
      for (int i = 0; i < 3; ++i) Jp.block<1, 3>(i, 3 * i) = -wa * u.transpose();
      Jp.block<3, 3>(0, 9) = -wa * Mat3::Identity();
      Jp.block<3, 3>(0, 12) = -wa * p.Ta * A;
      // Gyroscope: J_p over (T_g row-major, b_g).
      Eigen::Matrix<double, 3, 12> Jg = Eigen::Matrix<double, 3, 12>::Zero();
      for (int i = 0; i < 3; ++i) Jg.block<1, 3>(i, 3 * i) = -wg * w.transpose();
      Jg.block<3, 3>(0, 9) = -wg * Mat3::Identity();
      if (g) {
        const Eigen::Matrix<double, 15, 1> ga = -Jp.transpose() * ea;
        g->segment<12>(o) += ga.head<12>();
        g->segment<3>(o + kR) += ga.tail<3>();
        g->segment<12>(o + kTg) -= Jg.transpose() * eg;
      }
      if (!full) continue;
      Eigen::Matrix<double, 3, 9> dU;
      dU << CentripetalJacobian(w, p.r), -Skew(p.r), Mat3::Identity();
      const Eigen::Matrix<double, 3, 9> Jx = -wa * p.Ta * dU;
      const Mat3 Jxg = -wg * p.Tg;
      out->H.noalias() += Jx.transpose() * Jx;
      out->H.topLeftCorner<3, 3>().noalias() += Jxg.transpose() * Jxg;
      out->g.noalias() -= Jx.transpose() * ea;
      out->g.head<3>().noalias() -= Jxg.transpose() * eg;
      const Eigen::Matrix<double, 9, 15> CJ = Jx.transpose() * Jp;
      out->C.block(0, o, 9, 12) += CJ.leftCols<12>();
      out->C.block(0, o + kR, 9, 3) += CJ.rightCols<3>();
      out->C.block(0, o + kTg, 3, 12).noalias() += Jxg.transpose() * Jg;
      if (H) {
        Mat27& h = (*H)[k];
        const Eigen::Matrix<double, 15, 15> hp = Jp.transpose() * Jp;
        h.topLeftCorner<12, 12>() += hp.topLeftCorner<12, 12>();
        h.block<12, 3>(0, kR) += hp.topRightCorner<12, 3>();
        h.block<3, 12>(kR, 0) += hp.bottomLeftCorner<3, 12>();
        h.block<3, 3>(kR, kR) += hp.bottomRightCorner<3, 3>();
        h.block<12, 12>(kTg, kTg).noalias() += Jg.transpose() * Jg;
      }
    }
  }

  void EvaluateStatic(int64_t j, const Vec10& x, const Context& c, Normal* out, bool full,
                      std::vector<Mat27>* H, Eigen::VectorXd* g) const {
    const double sq = std::sqrt(d_.static_n(j));
    const double wa = d_.wa * sq, wg = d_.wg * sq;
    const Vec3 s = x.head<3>();
    const Eigen::Matrix<double, 3, 2> Bs = SphereBasis(s);
    Eigen::Matrix2d H2 = Eigen::Matrix2d::Zero();
    Eigen::Vector2d g2 = Eigen::Vector2d::Zero();
    for (int k = 0; k < d_.K; ++k) {
      const TriadParams& p = c[k];
      const int o = kP * k;
      const Vec3 ea = wa * (d_.static_a.col(j).segment<3>(3 * k) - p.Ta * s - p.ba);
      const Vec3 eg = wg * (d_.static_g.col(j).segment<3>(3 * k) - p.bg);
      out->cost += ea.squaredNorm() + eg.squaredNorm();
      if (!full && !g) continue;
      Eigen::Matrix<double, 3, 12> Jp = Eigen::Matrix<double, 3, 12>::Zero();
      for (int i = 0; i < 3; ++i) Jp.block<1, 3>(i, 3 * i) = -wa * s.transpose();
      Jp.block<3, 3>(0, 9) = -wa * Mat3::Identity();
      if (g) {
        g->segment<12>(o) -= Jp.transpose() * ea;
        g->segment<3>(o + kBg) += wg * eg;
      }
      if (!full) continue;
      const Eigen::Matrix<double, 3, 2> Jx = -wa * p.Ta * Bs;
      H2.noalias() += Jx.transpose() * Jx;
      g2.noalias() -= Jx.transpose() * ea;
      out->C.block(0, o, 2, 12).noalias() += Jx.transpose() * Jp;
      if (H) {
        Mat27& h = (*H)[k];
        h.topLeftCorner<12, 12>().noalias() += Jp.transpose() * Jp;
        h.block<3, 3>(kBg, kBg).diagonal().array() += wg * wg;
      }
    }
    if (full) {
      // The unused tangent coordinates 2..8: identity Hessian, zero gradient and coupling.
      out->H.setIdentity();
      out->H.topLeftCorner<2, 2>() = H2;
      out->g.head<2>() = g2;
    }
  }

  const FullData& d_;
  const Eigen::MatrixXd& E_;
};

// Orthonormal basis of the gauge-fixed subspace of theta (27K): all coordinates but the
// reference's T_a lower entries and position; the 3K T_g diagonals restricted to sum zero
// (Helmert contrasts).
Eigen::MatrixXd GaugeBasis(int K, int reference) {
  const int q = kP * K;
  std::vector<int> free;
  std::vector<int> diag;
  for (int k = 0; k < K; ++k)
    for (int l = 0; l < kP; ++l) {
      const int i = kP * k + l;
      if (k == reference && (l == kTa + 3 || l == kTa + 6 || l == kTa + 7 || l >= kR)) continue;
      if (l == kTg || l == kTg + 4 || l == kTg + 8) {
        diag.push_back(i);
        continue;
      }
      free.push_back(i);
    }
  const int m = static_cast<int>(diag.size());
  Eigen::MatrixXd E = Eigen::MatrixXd::Zero(q, static_cast<int>(free.size()) + m - 1);
  int col = 0;
  for (int i : free) E(i, col++) = 1;
  for (int a = 1; a < m; ++a, ++col) {
    const double norm = std::sqrt(static_cast<double>(a) * (a + 1));
    for (int b = 0; b < a; ++b) E(diag[b], col) = 1 / norm;
    E(diag[a], col) = -a / norm;
  }
  return E;
}

// Ellipsoid through the static means: M upper triangular, b with |M (y_j - b)| = g (the
// closed form of core/imu.cc, worked in scaled coordinates for conditioning).
bool EllipsoidFit(const Eigen::Matrix3Xd& y, double g, Mat3* m_out, Vec3* b_out) {
  const int n = static_cast<int>(y.cols());
  const Vec3 c = y.rowwise().mean();
  const double sc = 1 / g;
  Eigen::MatrixXd d(n, 10);
  for (int j = 0; j < n; ++j) {
    const Vec3 z = (y.col(j) - c) * sc;
    d.row(j) << z.x() * z.x(), z.y() * z.y(), z.z() * z.z(), 2 * z.x() * z.y(), 2 * z.x() * z.z(),
        2 * z.y() * z.z(), z.x(), z.y(), z.z(), 1;
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(d, Eigen::ComputeFullV);
  const Eigen::VectorXd sv = svd.singularValues();
  if (!(sv(8) > 1e-9 * sv(0))) return false;  // the statics do not determine a quadric
  const Eigen::VectorXd th = svd.matrixV().col(9);
  Mat3 q;
  q << th(0), th(3), th(4), th(3), th(1), th(5), th(4), th(5), th(2);
  const Vec3 l = th.segment<3>(6);
  Eigen::FullPivLU<Mat3> lu(q);
  if (!lu.isInvertible()) return false;
  const Vec3 z0 = -0.5 * lu.solve(l);
  const double k = z0.dot(q * z0) - th(9);
  if (!(std::abs(k) > 0)) return false;
  Eigen::LLT<Mat3> llt(q / k);
  if (llt.info() != Eigen::Success) return false;
  const Mat3 mz = llt.matrixL().transpose();
  *m_out = g * sc * mz;
  *b_out = c + z0 / sc;
  return m_out->allFinite() && b_out->allFinite();
}

std::string Fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

Eigen::Matrix<double, 33, 1> ReportVector(const ArrayFullTriad& t) {
  Eigen::Matrix<double, 33, 1> v;
  auto sensor = [&](const Mat3& T, const Vec3& b, int o) {
    const Mat3 M = T.inverse();
    const Vec3 scale = M.diagonal();
    const Mat3 mis = M * scale.cwiseInverse().asDiagonal();
    v.segment<3>(o) = b;
    v.segment<3>(o + 3) = scale;
    for (int i = 0; i < 9; ++i) v(o + 6 + i) = mis(i / 3, i % 3);
  };
  sensor(t.accel_T, t.accel_bias, 0);
  sensor(t.gyro_T, t.gyro_bias, 15);
  v.segment<3>(30) = t.position;
  return v;
}

}  // namespace

Vec27 PackArrayFullTriad(const ArrayFullTriad& t) {
  Vec27 p;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      p(kTa + 3 * i + j) = t.accel_T(i, j);
      p(kTg + 3 * i + j) = t.gyro_T(i, j);
    }
  p.segment<3>(kBa) = t.accel_bias;
  p.segment<3>(kBg) = t.gyro_bias;
  p.segment<3>(kR) = t.position;
  return p;
}

ArrayFullTriad UnpackArrayFullTriad(const Vec27& p) {
  const TriadParams c = Unpack(Eigen::VectorXd(p), 1)[0];
  ArrayFullTriad t;
  t.accel_T = c.Ta;
  t.accel_bias = c.ba;
  t.gyro_T = c.Tg;
  t.gyro_bias = c.bg;
  t.position = c.r;
  return t;
}

ArrayFullTriadReport ReportArrayFullTriad(const ArrayFullTriad& t) {
  ArrayFullTriadReport r;
  auto sensor = [](const Mat3& T, const Vec3& b, ArrayFullSensorReport* s) {
    s->matrix = T.inverse();
    s->scale = s->matrix.diagonal();
    s->misalignment = s->matrix * s->scale.cwiseInverse().asDiagonal();
    s->bias = b;
  };
  sensor(t.accel_T, t.accel_bias, &r.accelerometer);
  sensor(t.gyro_T, t.gyro_bias, &r.gyroscope);
  r.position = t.position;
  return r;
}

ArrayFullTriadStd ReportArrayFullTriadStd(const ArrayFullTriad& t, const Mat27& covariance) {
  const Vec27 p0 = PackArrayFullTriad(t);
  Eigen::Matrix<double, 33, 27> D;
  for (int i = 0; i < 27; ++i) {
    const double h = 1e-6 * std::max(1.0, std::abs(p0(i)));
    Vec27 a = p0, b = p0;
    a(i) += h;
    b(i) -= h;
    D.col(i) =
        (ReportVector(UnpackArrayFullTriad(a)) - ReportVector(UnpackArrayFullTriad(b))) / (2 * h);
  }
  const Eigen::Matrix<double, 33, 1> var = (D * covariance * D.transpose()).diagonal();
  const Eigen::Matrix<double, 33, 1> sd = var.cwiseMax(0).cwiseSqrt();
  ArrayFullTriadStd out;
  auto sensor = [&](int o, ArrayFullSensorStd* s) {
    s->bias_std = sd.segment<3>(o);
    s->scale_std = sd.segment<3>(o + 3);
    for (int i = 0; i < 9; ++i) s->misalignment_std(i / 3, i % 3) = sd(o + 6 + i);
  };
  sensor(0, &out.accelerometer);
  sensor(15, &out.gyroscope);
  out.position_std = sd.segment<3>(30);
  return out;
}

std::string ArrayFullParameterName(const std::vector<std::string>& names, int i) {
  const int k = i / kP, l = i % kP;
  const std::string triad = k < static_cast<int>(names.size()) ? names[k] : std::to_string(k);
  static const char* const kAxis[] = {"x", "y", "z"};
  if (l < kBa)
    return triad + ".accelerometer.T[" + std::to_string(l / 3) + "][" + std::to_string(l % 3) + "]";
  if (l < kTg) return triad + ".accelerometer.bias." + kAxis[l - kBa];
  if (l < kBg)
    return triad + ".gyroscope.T[" + std::to_string((l - kTg) / 3) + "][" +
           std::to_string((l - kTg) % 3) + "]";
  if (l < kR) return triad + ".gyroscope.bias." + kAxis[l - kBg];
  return triad + ".position." + kAxis[l - kR];
}

bool ArrayFullOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(accel_noise >= 0) || !std::isfinite(accel_noise))
    return fail("accel_noise must be a finite number >= 0 (m/s^2; 0: from the statics)");
  if (!(gyro_noise >= 0) || !std::isfinite(gyro_noise))
    return fail("gyro_noise must be a finite number >= 0 (rad/s; 0: from the statics)");
  if (!(gravity > 0) || !std::isfinite(gravity)) return fail("gravity must be > 0 (m/s^2)");
  if (gyro_saturation && (!(*gyro_saturation > 0) || !std::isfinite(*gyro_saturation)))
    return fail("gyro_saturation must be a finite number > 0 (rad/s)");
  if (accel_saturation && (!(*accel_saturation > 0) || !std::isfinite(*accel_saturation)))
    return fail("accel_saturation must be a finite number > 0 (m/s^2)");
  std::string e;
  if (!statics.IsValid(&e)) return fail("static detection: " + e);
  if (max_iterations < 1) return fail("max_iterations must be >= 1");
  if (!(tolerance >= 0 && tolerance < 1)) return fail("tolerance must be >= 0 and < 1");
  if (threads < 0) return fail("threads must be >= 0 (0: hardware concurrency)");
  if (!(robust_ratio >= 1) || !std::isfinite(robust_ratio))
    return fail("robust_ratio must be >= 1");
  if (!(robust_batch > 0) || !std::isfinite(robust_batch))
    return fail("robust_batch must be > 0 (seconds)");
  if (min_statics < 9) return fail("min_statics must be >= 9");
  return true;
}

std::string ArrayFullResult::BriefReport() const {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "array full: %s, termination %s, %d iterations, cost %.6g -> %.6g, chi2/dof %.4g, "
                "%lld statics, %lld dynamic samples (%lld dropped)",
                usable ? "usable" : "not usable", BlockLmTerminationName(termination), iterations,
                cost.empty() ? 0.0 : cost.front(), cost.empty() ? 0.0 : cost.back(), chi2_per_dof,
                static_cast<long long>(statics), static_cast<long long>(dynamic_samples),
                static_cast<long long>(samples_dropped));
  return buf;
}

Status CalibrateArrayFull(const ArrayFullProblem& problem, const ArrayFullOptions& options,
                          ArrayFullResult* result) {
  *result = ArrayFullResult();
  std::string error;
  if (!options.IsValid(&error)) return Status::InvalidInput(error);
  const int K = static_cast<int>(problem.nominal_positions.cols());
  const int64_t N = problem.t.size();
  if (K < 3 || problem.nominal_positions.rows() != 3)
    return Status::InvalidInput("the full array model needs nominal positions of >= 3 triads");
  if (problem.accel.rows() != N || problem.gyro.rows() != N || problem.accel.cols() != 3 * K ||
      problem.gyro.cols() != 3 * K)
    return Status::InvalidInput(
        "the full array model needs N x 3K accelerometer and gyroscope "
        "readings for the K = " +
        std::to_string(K) + " triads and N sample times");
  if (problem.reference < 0 || problem.reference >= K)
    return Status::InvalidInput("reference triad " + std::to_string(problem.reference) +
                                " out of range [0, " + std::to_string(K - 1) + "]");
  if (!problem.nominal_positions.allFinite() || !problem.accel.allFinite() ||
      !problem.gyro.allFinite() || !problem.t.allFinite())
    return Status::InvalidInput("positions, times and readings must be finite");
  if (!problem.names.empty() && static_cast<int>(problem.names.size()) != K)
    return Status::InvalidInput("names must be empty or hold one name per triad");
  ArrayFullResult& res = *result;
  res.reference = problem.reference;
  res.names = problem.names;
  if (res.names.empty())
    for (int k = 0; k < K; ++k) res.names.push_back(std::to_string(k));
  auto not_determinable = [&](Reason reason, const std::string& m) {
    res.usable = false;
    res.reason = m;
    return Status::NotDeterminable(reason, m);
  };
  auto stopped = [&](const std::string& stage) {
    res.usable = false;
    res.termination = BlockLmTermination::kUserStopped;
    const Status s = StoppedStatus(*options.stop, "array (full model): " + stage);
    res.reason = s.message();
    return s;
  };
  if (StopRequested(options.stop)) return stopped("statics");

  // ----- Statics.
  std::vector<Eigen::MatrixX3d> series(2 * K);
  std::vector<TriadSeries> triads(2 * K);
  for (int k = 0; k < 2 * K; ++k) {
    const Eigen::MatrixXd& src = k < K ? problem.accel : problem.gyro;
    const int kk = k % K;
    series[k] = src.middleCols(3 * kk, 3);
    triads[k].name = (k < K ? "a" : "g") + res.names[kk];
    triads[k].kind = k < K ? TriadKind::kAccelerometer : TriadKind::kGyroscope;
    triads[k].readings = &series[k];
    if (k >= K && options.gyro_saturation) {
      triads[k].saturation_low = -*options.gyro_saturation;
      triads[k].saturation_high = *options.gyro_saturation;
    }
    if (k < K && options.accel_saturation) {
      triads[k].saturation_low = -*options.accel_saturation;
      triads[k].saturation_high = *options.accel_saturation;
    }
  }
  StaticDetection det;
  if (Status s = DetectStatics(problem.t, triads, options.statics, &det); !s.ok()) return s;
  series.clear();
  if (StopRequested(options.stop)) return stopped("statics");
  FullData d;
  d.K = K;
  d.gravity = options.gravity;
  d.J = static_cast<int64_t>(det.intervals.size());
  res.statics = d.J;
  res.static_samples = det.static_samples;
  if (d.J < options.min_statics)
    return not_determinable(
        Reason::kTooFewStatics,
        "the full array model needs at least " + std::to_string(options.min_statics) +
            " static orientations (the accelerometers' closed form); the log has " +
            std::to_string(d.J) +
            ": record the board at rest in many different orientations before the dynamic phase; " +
            StaticShortfall(det));
  d.static_a.resize(3 * K, d.J);
  d.static_g.resize(3 * K, d.J);
  d.static_n.resize(d.J);
  double var_a = 0, var_g = 0, var_dof = 0;
  std::vector<char> in_static(N, 0);
  for (int64_t j = 0; j < d.J; ++j) {
    const StaticInterval& iv = det.intervals[j];
    d.static_n(j) = static_cast<double>(iv.samples);
    for (int64_t n = iv.first; n <= iv.last; ++n) in_static[n] = 1;
    for (int k = 0; k < K; ++k) {
      d.static_a.col(j).segment<3>(3 * k) = iv.mean[k];
      d.static_g.col(j).segment<3>(3 * k) = iv.mean[K + k];
      var_a += (iv.samples - 1) * iv.std[k].squaredNorm();
      var_g += (iv.samples - 1) * iv.std[K + k].squaredNorm();
    }
    var_dof += 3.0 * K * (iv.samples - 1);
  }
  res.static_noise_accel = var_dof > 0 ? std::sqrt(var_a / var_dof) : 0;
  res.static_noise_gyro = var_dof > 0 ? std::sqrt(var_g / var_dof) : 0;
  const double sigma_a = options.accel_noise > 0 ? options.accel_noise : res.static_noise_accel;
  const double sigma_g = options.gyro_noise > 0 ? options.gyro_noise : res.static_noise_gyro;
  res.noise_estimated = !(options.accel_noise > 0 && options.gyro_noise > 0);
  res.accel_noise = res.dynamic_accel_noise = sigma_a;
  res.gyro_noise = res.dynamic_gyro_noise = sigma_g;
  if (!(sigma_a > 0) || !(sigma_g > 0))
    return not_determinable(
        Reason::kUnknownNoise,
        "the noise levels are zero in the statics (noise-free readings?): configure accel_noise "
        "and gyro_noise");
  d.wa = d.wa_d = 1 / sigma_a;
  d.wg = d.wg_d = 1 / sigma_g;

  // ----- Dynamic samples: everything outside the statics, without saturated gyroscopes.
  for (int64_t n = 0; n < N; ++n) {
    if (in_static[n]) continue;
    if ((options.gyro_saturation &&
         problem.gyro.row(n).cwiseAbs().maxCoeff() >= *options.gyro_saturation) ||
        (options.accel_saturation &&
         problem.accel.row(n).cwiseAbs().maxCoeff() >= *options.accel_saturation)) {
      ++res.samples_dropped;
      continue;
    }
    d.dyn_index.push_back(n);
  }
  d.Nd = static_cast<int64_t>(d.dyn_index.size());
  res.dynamic_samples = d.Nd;
  if (d.Nd < 10)
    return not_determinable(Reason::kNoDynamicPhase,
                            "the full array model needs a dynamic phase (rotation) after the "
                            "statics; the log has " +
                                std::to_string(d.Nd) + " usable samples outside the statics");
  d.ya.resize(3 * K, d.Nd);
  d.yg.resize(3 * K, d.Nd);
  for (int64_t m = 0; m < d.Nd; ++m) {
    d.ya.col(m) = problem.accel.row(d.dyn_index[m]).transpose();
    d.yg.col(m) = problem.gyro.row(d.dyn_index[m]).transpose();
  }

  // ----- Start: accelerometers from the static means.
  const int ref = problem.reference;
  Mat3 M_ref;
  Vec3 b_ref;
  if (!EllipsoidFit(d.static_a.middleRows(3 * ref, 3), options.gravity, &M_ref, &b_ref))
    return not_determinable(
        Reason::kPoorOrientationCoverage,
        "the static orientations do not determine the accelerometers (no ellipsoid through the "
        "reference triad's static means): record statics in orientations spread over the whole "
        "sphere (e.g. the six faces and the diagonals)");
  Eigen::Matrix3Xd s_dir(3, d.J);
  for (int64_t j = 0; j < d.J; ++j)
    s_dir.col(j) =
        options.gravity * (M_ref * (d.static_a.col(j).segment<3>(3 * ref) - b_ref)).normalized();
  std::vector<ArrayFullTriad> start(K);
  Eigen::MatrixXd Aj(d.J, 4);
  Aj.leftCols(3) = s_dir.transpose();
  Aj.col(3).setOnes();
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Aj);
  if (qr.rank() < 4)
    return not_determinable(Reason::kPoorOrientationCoverage,
                            "the static orientations are coplanar: record statics in "
                            "orientations spread over the whole sphere");
  const double n_static = d.static_n.sum();
  for (int k = 0; k < K; ++k) {
    if (k == ref) {
      start[k].accel_T = M_ref.inverse();
      start[k].accel_T(1, 0) = start[k].accel_T(2, 0) = start[k].accel_T(2, 1) = 0;
      start[k].accel_bias = b_ref;
    } else {
      const Eigen::MatrixXd X =
          qr.solve(Eigen::MatrixXd(d.static_a.middleRows(3 * k, 3).transpose()));
      start[k].accel_T = X.topRows(3).transpose();
      start[k].accel_bias = X.row(3).transpose();
    }
    start[k].gyro_bias = d.static_g.middleRows(3 * k, 3) * d.static_n / n_static;
    start[k].gyro_T.setIdentity();
    start[k].position = problem.nominal_positions.col(k);
  }

  // ----- Start: positions from the positions-only fit on the corrected readings.
  const int threads = options.threads > 0
                          ? options.threads
                          : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  {
    ArrayProblem ap;
    ap.nominal_positions = problem.nominal_positions;
    ap.reference = ref;
    ap.accel.resize(d.Nd, 3 * K);
    ap.gyro.resize(d.Nd, 3 * K);
    for (int k = 0; k < K; ++k) {
      const Mat3 Ti = start[k].accel_T.inverse();
      for (int64_t m = 0; m < d.Nd; ++m) {
        ap.accel.row(m).segment<3>(3 * k) =
            (Ti * (d.ya.col(m).segment<3>(3 * k) - start[k].accel_bias)).transpose();
        ap.gyro.row(m).segment<3>(3 * k) =
            (d.yg.col(m).segment<3>(3 * k) - start[k].gyro_bias).transpose();
      }
    }
    ArrayOptions ao;
    ao.accel_noise = sigma_a;
    ao.gyro_noise = sigma_g;
    ao.threads = threads;
    ao.executor = options.executor;
    ao.max_iterations = 30;
    ao.tolerance = 1e-8;
    ao.stop = options.stop;
    ArrayResult ar;
    const Status s = CalibrateArray(ap, ao, &ar);
    if (StopRequested(options.stop)) return stopped("positions-only start");
    if (s.ok() && ar.usable) {
      for (int k = 0; k < K; ++k) start[k].position = ar.positions.col(k);
      res.initial_positions_from_array = true;
      res.initial_position_std = ar.position_std;
    } else {
      res.warnings.push_back("the positions-only fit for the start failed (" + s.message() +
                             "); the full model starts from the nominal positions");
    }
  }
  res.initial = start;

  // ----- Start: motion per sample given the start (omega from the gyroscopes, omega_dot and s
  // by linear least squares on the corrected accelerometers).
  Eigen::Matrix<double, 10, Eigen::Dynamic> x(10, d.J + d.Nd);
  for (int64_t j = 0; j < d.J; ++j) {
    x.col(j).setZero();
    x.col(j).head<3>() = s_dir.col(j);
    x(9, j) = 1;
  }
  {
    Eigen::Matrix<double, 6, 6> N6 = Eigen::Matrix<double, 6, 6>::Zero();
    for (int k = 0; k < K; ++k) {
      Eigen::Matrix<double, 3, 6> G;
      G << Mat3::Identity(), -Skew(start[k].position);
      N6 += G.transpose() * G;
    }
    const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(N6);
    std::vector<Mat3> Ti(K);
    for (int k = 0; k < K; ++k) Ti[k] = start[k].accel_T.inverse();
    for (int64_t m = 0; m < d.Nd; ++m) {
      Vec3 w = Vec3::Zero();
      for (int k = 0; k < K; ++k) w += d.yg.col(m).segment<3>(3 * k) - start[k].gyro_bias;
      w /= K;
      Eigen::Matrix<double, 6, 1> rhs = Eigen::Matrix<double, 6, 1>::Zero();
      for (int k = 0; k < K; ++k) {
        const Vec3 r = start[k].position;
        const Vec3 f = Ti[k] * (d.ya.col(m).segment<3>(3 * k) - start[k].accel_bias);
        const Vec3 z = f - (w * w.dot(r) - r * w.squaredNorm());
        rhs.head<3>() += z;
        rhs.tail<3>() += r.cross(z);
      }
      const Eigen::Matrix<double, 6, 1> sol = ldlt.solve(rhs);
      x.col(d.J + m) << w, sol.tail<3>(), sol.head<3>(), 0;
    }
  }

  // ----- Rotation excitation, on the start's motion (omega: the mean of the bias-corrected
  // gyroscopes), before the solver spends time on an undetermined problem.
  {
    Mat3 W = Mat3::Zero();
    for (int64_t m = 0; m < d.Nd; ++m)
      W += x.col(d.J + m).head<3>() * x.col(d.J + m).head<3>().transpose();
    const Eigen::SelfAdjointEigenSolver<Mat3> es(W);
    res.rotation_eigenvalues = es.eigenvalues();
    res.weakest_rotation_axis = es.eigenvectors().col(0);
    int i = 0;
    res.weakest_rotation_axis.cwiseAbs().maxCoeff(&i);
    if (res.weakest_rotation_axis(i) < 0) res.weakest_rotation_axis *= -1;
    res.rotation_noise_floor = static_cast<double>(d.Nd) * sigma_g * sigma_g / K;
    const double lam = res.rotation_eigenvalues(0);
    res.rotation_verdict = lam >= 100 * res.rotation_noise_floor ? "good"
                           : lam >= 3 * res.rotation_noise_floor ? "weak"
                                                                 : "insufficient";
  }
  const Vec3& ax = res.weakest_rotation_axis;
  auto c2 = [](double v) { return Fmt("%.2f", std::abs(v) < 0.005 ? 0.0 : v); };  // no "-0.00"
  const std::string axis_text = "(" + c2(ax.x()) + ", " + c2(ax.y()) + ", " + c2(ax.z()) + ")";
  if (res.rotation_verdict == "insufficient")
    return not_determinable(
        Reason::kWeakExcitation,
        "too little rotation about the body axis " + axis_text + " (sum of squared rates " +
            Fmt("%.3g", res.rotation_eigenvalues(0)) +
            " (rad/s)^2 against the gyroscope noise floor " +
            Fmt("%.3g", res.rotation_noise_floor) +
            "): the gyroscope gains and misalignments along that axis (the T_g columns) are not "
            "determined; twist the board about that axis too in the dynamic phase");
  if (res.rotation_verdict == "weak")
    res.warnings.push_back("little rotation about the body axis " + axis_text +
                           ": the gyroscope gains along it are weakly determined (see their σ)");

  // ----- Joint LM.
  const Eigen::MatrixXd E = GaugeBasis(K, ref);
  res.gauge_basis = E;
  res.gauge = "sum_trace_gyroscope";
  res.gauge_description =
      "triad " + res.names[ref] +
      " fixes the body frame (its position held at the nominal, its accelerometer T upper "
      "triangular) and the scale is fixed by sum_k trace T_g,k = 3K (mean gyroscope gain 1)";
  Eigen::VectorXd theta(kP * K);
  for (int k = 0; k < K; ++k) theta.segment<kP>(kP * k) = PackArrayFullTriad(start[k]);
  const FullProblem fp(d, E);
  BlockLmOptions lo;
  lo.max_iterations = options.max_iterations;
  lo.cost_tolerance = options.tolerance;
  lo.step_tolerance = options.tolerance;
  lo.threads = threads;
  lo.executor = options.executor;
  lo.stop = options.stop;
  if (StopRequested(options.stop)) return stopped("joint solver");
  BlockLm<FullProblem> lm(fp, lo);
  BlockLm<FullProblem>::Callback callback;
  if (options.callback)
    callback = [&options](int it, const Eigen::VectorXd&) { return options.callback(it); };
  const BlockLmSummary summary = lm.Solve(&x, &theta, callback);
  BlockLmSummary final_summary = summary;
  std::vector<double> resolved_costs;  // of the re-solves (kResidual): their own weights
  if (options.dynamic_weighting == ArrayFullDynamicWeighting::kResidual &&
      summary.termination != BlockLmTermination::kNumericalFailure &&
      summary.termination != BlockLmTermination::kUserStopped) {
    // Weight the dynamic samples by their own residual level (per sensor kind, corrected for
    // the 9 motion unknowns per sample) and solve again from the estimate; twice, the levels
    // then move by far less than their own uncertainty.
    for (int round = 0; round < 2; ++round) {
      const std::vector<TriadParams> c = Unpack(theta, K);
      Eigen::MatrixX2d dy = Eigen::MatrixX2d::Zero(K, 2);
      if (StopRequested(options.stop)) return stopped("joint solver (reweighting)");
      for (int64_t m = 0; m < d.Nd; ++m) fp.AddSquaredResiduals(d.J + m, x.col(d.J + m), c, &dy);
      const double correction = 6.0 * K / (6.0 * K - 9);
      const double sa = std::sqrt(dy.col(0).sum() / (3.0 * K * d.Nd) * correction);
      const double sg = std::sqrt(dy.col(1).sum() / (3.0 * K * d.Nd) * correction);
      d.wa_d = 1 / std::max(sa, sigma_a);
      d.wg_d = 1 / std::max(sg, sigma_g);
      final_summary = lm.Solve(&x, &theta, callback);
      res.iterations += final_summary.iterations;
      resolved_costs.insert(resolved_costs.end(), final_summary.cost.begin(),
                            final_summary.cost.end());
      if (StopRequested(options.stop)) return stopped("joint solver (reweighting)");
      if (final_summary.termination == BlockLmTermination::kUserStopped) {
        res.reason = "stopped by the caller";
        return Status::Internal("the full array calibration was stopped by the caller");
      }
    }
    res.dynamic_accel_noise = 1 / d.wa_d;
    res.dynamic_gyro_noise = 1 / d.wg_d;
  }
  res.termination = final_summary.termination;
  res.iterations += summary.iterations;
  res.converged = final_summary.converged();
  res.cost = summary.cost;
  res.cost.insert(res.cost.end(), resolved_costs.begin(), resolved_costs.end());
  if (StopRequested(options.stop)) return stopped("joint solver");
  if (summary.termination == BlockLmTermination::kUserStopped) {
    res.reason = "stopped by the caller";
    return Status::Internal("the full array calibration was stopped by the caller");
  }
  if (final_summary.termination == BlockLmTermination::kNumericalFailure)
    return not_determinable(Reason::kNumericalFailure,
                            "the joint solver found no step with a finite cost (numerical "
                            "failure): the recording or the noise settings are degenerate");
  res.theta = theta;
  const std::vector<TriadParams> ctx = Unpack(theta, K);
  res.triads.resize(K);
  res.report.resize(K);
  for (int k = 0; k < K; ++k) {
    res.triads[k] = UnpackArrayFullTriad(theta.segment<kP>(kP * k));
    res.report[k] = ReportArrayFullTriad(res.triads[k]);
    res.report[k].name = res.names[k];
  }

  // ----- Residuals and chi^2.
  const int P = static_cast<int>(E.cols());
  res.dof = 6LL * K * (d.J + d.Nd) - 9 * d.Nd - 2 * d.J - P;
  res.chi2_per_dof = res.dof > 0 ? final_summary.final_cost() / static_cast<double>(res.dof) : 0;
  {
    Eigen::MatrixX2d st = Eigen::MatrixX2d::Zero(K, 2), dy = Eigen::MatrixX2d::Zero(K, 2);
    for (int64_t n = 0; n < d.J + d.Nd; ++n)
      fp.AddSquaredResiduals(n, x.col(n), ctx, n < d.J ? &st : &dy);
    res.residuals.resize(K);
    for (int k = 0; k < K; ++k) {
      res.residuals[k].static_accel = std::sqrt(st(k, 0) / (3.0 * d.J));
      res.residuals[k].static_gyro = std::sqrt(st(k, 1) / (3.0 * d.J));
      res.residuals[k].dynamic_accel = std::sqrt(dy(k, 0) / (3.0 * d.Nd));
      res.residuals[k].dynamic_gyro = std::sqrt(dy(k, 1) / (3.0 * d.Nd));
    }
    res.dynamic_rms_accel = std::sqrt(dy.col(0).sum() / (3.0 * K * d.Nd));
    res.dynamic_rms_gyro = std::sqrt(dy.col(1).sum() / (3.0 * K * d.Nd));
  }

  // ----- Sampling-time offsets (a diagnostic of the model's main misfit on real hardware): if
  // IMU k samples at t + delta_k, its gyroscope residual is ~ delta_k T_g,k omega_dot. Least
  // squares per IMU, made relative to their mean (a common offset is absorbed by omega).
  {
    res.time_offsets = Eigen::VectorXd::Zero(K);
    Eigen::VectorXd num = Eigen::VectorXd::Zero(K), den = Eigen::VectorXd::Zero(K);
    double ss = 0, along = 0, vv = 0;
    for (int64_t m = 0; m < d.Nd; ++m) {
      const Vec3 w = x.col(d.J + m).head<3>(), wd = x.col(d.J + m).segment<3>(3);
      for (int k = 0; k < K; ++k) {
        const Vec3 e = d.yg.col(m).segment<3>(3 * k) - ctx[k].Tg * w - ctx[k].bg;
        const Vec3 v = ctx[k].Tg * wd;
        num(k) += e.dot(v);
        den(k) += v.squaredNorm();
        ss += e.squaredNorm();
        if (v.squaredNorm() > 0) along += e.dot(v) * e.dot(v) / v.squaredNorm();
        vv += v.squaredNorm();
      }
    }
    for (int k = 0; k < K; ++k) res.time_offsets(k) = den(k) > 0 ? num(k) / den(k) : 0;
    // Fraction of the gyroscope residual explained by the per-IMU offsets (before centring).
    double explained = 0;
    for (int k = 0; k < K; ++k) explained += den(k) > 0 ? num(k) * num(k) / den(k) : 0;
    res.time_offset_explained = ss > 0 ? explained / ss : 0;
    res.time_offsets.array() -= res.time_offsets.mean();
    res.jitter_explained = ss > 0 ? along / ss : 0;
    res.jitter_rms = vv > 0 ? std::sqrt(along / vv) : 0;
  }

  // ----- Information, null directions, Cramér-Rao bound.
  BlockLmInformation info;
  lm.ComputeSharedInformation(x, theta, &info, nullptr);
  if (StopRequested(options.stop)) return stopped("information");
  {
    Eigen::VectorXd dg = info.information.diagonal();
    Eigen::VectorXd scale(P);
    for (int i = 0; i < P; ++i) scale(i) = dg(i) > 0 ? 1 / std::sqrt(dg(i)) : 0;
    const Eigen::MatrixXd Sn = scale.asDiagonal() * info.information * scale.asDiagonal();
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Sn);
    const double lmax = es.eigenvalues().maxCoeff();
    for (int i = 0; i < P; ++i) {
      if (es.eigenvalues()(i) > 1e-12 * lmax) break;
      const Eigen::VectorXd dir = E * (scale.asDiagonal() * es.eigenvectors().col(i));
      if (!(dir.norm() > 0)) continue;  // a parameter without information: named below
      std::vector<int> idx(dir.size());
      std::iota(idx.begin(), idx.end(), 0);
      std::partial_sort(idx.begin(), idx.begin() + 3, idx.end(),
                        [&](int a, int b) { return std::abs(dir(a)) > std::abs(dir(b)); });
      std::string text;
      for (int t = 0; t < 3; ++t)
        text += (t ? ", " : "") + ArrayFullParameterName(res.names, idx[t]);
      res.null_directions.push_back(text);
    }
    for (int i = 0; i < P; ++i)
      if (!(dg(i) > 0)) {
        int j = 0;
        E.col(i).cwiseAbs().maxCoeff(&j);
        res.null_directions.push_back(ArrayFullParameterName(res.names, j) + " (no information)");
      }
  }
  if (!res.null_directions.empty()) {
    std::string list;
    for (const auto& t : res.null_directions) list += (list.empty() ? "" : "; ") + t;
    return not_determinable(Reason::kSingularInformation,
                            "the recording does not determine every parameter (null directions "
                            "of the Fisher information, largest components: " +
                                list +
                                "): record statics spread over the sphere and rotate about "
                                "every axis");
  }
  Eigen::MatrixXd covE;
  if (!InvertInformation(info.information, &covE))
    return not_determinable(Reason::kSingularInformation,
                            "the Fisher information is not positive definite: the recording "
                            "does not determine the parameters");
  res.theta_covariance = E * covE * E.transpose();
  res.report_std.resize(K);
  for (int k = 0; k < K; ++k) {
    res.report_std[k] =
        ReportArrayFullTriadStd(res.triads[k], res.theta_covariance.block<kP, kP>(kP * k, kP * k));
    res.report_std[k].name = res.names[k];
  }

  // ----- Residual-aware (sandwich) covariance when the residuals exceed the noise.
  const bool reweighted = options.dynamic_weighting == ArrayFullDynamicWeighting::kResidual &&
                          (d.wa_d < d.wa || d.wg_d < d.wg);
  if (res.chi2_per_dof > options.robust_ratio || reweighted) {
    res.robust = true;
    // Batches: every static alone, the dynamic samples in runs of robust_batch seconds.
    std::vector<std::vector<int64_t>> batches;
    for (int64_t j = 0; j < d.J; ++j) batches.push_back({j});
    const double t0 = problem.t(d.dyn_index[0]);
    int64_t current = -1;
    for (int64_t m = 0; m < d.Nd; ++m) {
      const auto id =
          static_cast<int64_t>(std::floor((problem.t(d.dyn_index[m]) - t0) / options.robust_batch));
      if (id != current) batches.emplace_back();
      current = id;
      batches.back().push_back(d.J + m);
    }
    res.robust_batches = static_cast<int64_t>(batches.size());
    // Jackknife-type (HC3) sandwich: each batch's score s_b is mapped by (S - I_b)^-1 instead of
    // S^-1 (I_b: the batch's own reduced information), which undoes the shrinking of the
    // residuals by the fit (the leverage of a batch); Neumann series in theta coordinates,
    // t = Cov s + Cov I_b t. Without it the sandwich is ~30 % too small on short logs.
    const int q = kP * K;
    const Eigen::MatrixXd& Cov = res.theta_covariance;
    Eigen::MatrixXd Bm = Eigen::MatrixXd::Zero(q, q);
    Eigen::MatrixXd Ib(q, q);
    FullProblem::Normal b;
    b.C.resize(9, q);
    int not_converged = 0;
    for (const auto& batch : batches) {
      if (StopRequested(options.stop)) return stopped("residual-aware covariance");
      FullProblem::Sums sums = fp.MakeSums();
      Ib.setZero();
      for (int64_t n : batch) {
        fp.Linearize(n, x.col(n), ctx, &b, &sums);
        const Eigen::Matrix<double, 9, 9> Linv = InverseCholeskyFactor<9>(b.H);
        const Eigen::MatrixXd Z = Linv * b.C;
        Ib.noalias() -= Z.transpose() * Z;
      }
      for (int k = 0; k < K; ++k) Ib.block<kP, kP>(kP * k, kP * k) += sums.H[k];
      const Eigen::VectorXd t0v = Cov * sums.g;
      Eigen::VectorXd tv = t0v;
      bool done = false;
      for (int it = 0; it < 100 && !done; ++it) {
        const Eigen::VectorXd next = t0v + Cov * (Ib * tv);
        done = (next - tv).norm() <= 1e-10 * next.norm();
        tv = next;
      }
      if (!done || !tv.allFinite()) {
        ++not_converged;
        tv = t0v;
      }
      Bm.selfadjointView<Eigen::Lower>().rankUpdate(tv);
    }
    Bm = Bm.selfadjointView<Eigen::Lower>();
    if (not_converged > 0)
      res.warnings.push_back(std::to_string(not_converged) +
                             " batches of the residual-aware σ alone determine some parameter "
                             "(leverage ~ 1): their scores are not leverage-corrected");
    res.theta_covariance_robust = Bm;
    res.report_std_robust.resize(K);
    for (int k = 0; k < K; ++k) {
      res.report_std_robust[k] = ReportArrayFullTriadStd(
          res.triads[k], res.theta_covariance_robust.block<kP, kP>(kP * k, kP * k));
      res.report_std_robust[k].name = res.names[k];
    }
    if (reweighted)
      res.warnings.push_back(
          "the dynamic residuals exceed the statics' noise (dynamic samples weighted by their own "
          "residual level, " +
          Fmt("%.3g", 1 / d.wa_d) + " m/s^2 and " + Fmt("%.3g", 1 / d.wg_d) +
          " rad/s): the model does not explain the motion to the noise level (e.g. sampling-time "
          "errors between the IMUs) and the residuals are correlated in time, so use the "
          "residual-aware σ (uncertainty.imus[].robust)");
    else
      res.warnings.push_back(
          "the residuals exceed the noise (chi^2/dof = " + Fmt("%.3g", res.chi2_per_dof) +
          "; dynamic residual rms " + Fmt("%.3g", res.dynamic_rms_accel) + " m/s^2 and " +
          Fmt("%.3g", res.dynamic_rms_gyro) + " rad/s against noise " + Fmt("%.3g", sigma_a) +
          " and " + Fmt("%.3g", sigma_g) +
          "): the model does not explain the data to the noise level (e.g. sampling-time errors "
          "between the IMUs), so the Cramér-Rao σ is too optimistic; use the residual-aware σ "
          "(uncertainty.imus[].robust)");
  }
  if (!res.converged)
    res.warnings.push_back(std::string("the solver did not converge (") +
                           BlockLmTerminationName(final_summary.termination) +
                           "): the estimate is usable but not at the optimum");
  res.usable = true;
  res.reason = res.converged
                   ? std::string("converged (") + BlockLmTerminationName(summary.termination) + ")"
                   : "not converged: see warnings";
  return Status::Ok();
}

}  // namespace calibd::core
