// The `mag` numerics (core/mag.h) on a public real recording: CK-Explorer's acc_mag_log.csv
// (github.com/CK-Explorer/Magnetometer-and-Accelerometer-Calibration, "Data Examples": 12 000 rows
// of ax,ay,az (g) and mx,my,mz (gauss), a device turned by hand with still holds; no time column,
// so a nominal 100 Hz is assumed — only the sandwich's batch length and the static detection's
// windows depend on it). Fetch it into $CALIBD_MAG_DATA (default /work/data/mag/); skips when
// absent. Never committed.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "core/mag.h"
#include "core/mag_internal.h"
#include "core/static_detection.h"

namespace calibd::core {
namespace {

constexpr double kRate = 100;  // Hz, assumed (the file has no time column)
constexpr double kMicroteslaPerGauss = 100;

struct Log {
  Eigen::MatrixX3d accel, mag;
};

bool ReadLog(Log* log) {
  const char* dir = std::getenv("CALIBD_MAG_DATA");
  std::ifstream in(std::string(dir ? dir : "/work/data/mag") + "/acc_mag_log.csv");
  if (!in) return false;
  std::string line;
  std::getline(in, line);  // header
  std::vector<double> v;
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) v.push_back(std::stod(cell));
  }
  const Eigen::Index n = static_cast<Eigen::Index>(v.size() / 6);
  log->accel.resize(n, 3);
  log->mag.resize(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) {
      log->accel(i, k) = v[6 * i + k];
      log->mag(i, k) = v[6 * i + 3 + k];
    }
  }
  return n > 0;
}

// The problem of rows [first, first + n): statics found on the accelerometer by the detector the
// raw-log methods use.
MagProblem Problem(const Log& log, Eigen::Index first, Eigen::Index n) {
  MagProblem p;
  p.t = Eigen::VectorXd::LinSpaced(n, 0, (n - 1) / kRate);
  p.y = log.mag.middleRows(first, n).transpose();
  const Eigen::MatrixX3d accel = log.accel.middleRows(first, n);
  TriadSeries a;
  a.name = "a0";
  a.readings = &accel;
  StaticDetectionOptions so;
  so.static_window = 0.5;
  so.min_static = 0.5;
  StaticDetector detector;
  EXPECT_TRUE(detector.Init(p.t, {a}, so).ok());
  for (const StaticInterval& s : detector.Detect().intervals) {
    p.statics.push_back({s.first, s.last, s.mean[0]});
  }
  return p;
}

// |m| spread (RMS of |m_i| − mean |m|, relative) of calibrated readings.
double RelativeSpread(const Eigen::Matrix3Xd& y, const Eigen::Vector3d& h,
                      const Eigen::Matrix3d& s) {
  Eigen::VectorXd norm(y.cols());
  for (Eigen::Index i = 0; i < y.cols(); ++i) norm(i) = (s * (y.col(i) - h)).norm();
  const double mean = norm.mean();
  return std::sqrt((norm.array() - mean).square().mean()) / mean;
}

// The least-squares fit of |S(y − h)| = 1 (ArduPilot's CompassCalibrator's residual), by
// Gauss-Newton with a numeric Jacobian from the sphere through the mean.
void PeerFit(const Eigen::Matrix3Xd& y, Eigen::Vector3d* h, Eigen::Matrix3d* s) {
  const Eigen::Vector3d mean = y.rowwise().mean();
  const double r = (y.colwise() - mean).colwise().norm().mean();
  Eigen::Matrix<double, 9, 1> p;
  p << mean, 1 / r, 0, 0, 1 / r, 0, 1 / r;
  auto residuals = [&](const Eigen::Matrix<double, 9, 1>& q) {
    const Eigen::Matrix3d m = mag_internal::Sym(q.tail<6>());
    Eigen::VectorXd e(y.cols());
    for (Eigen::Index i = 0; i < y.cols(); ++i) e(i) = 1 - (m * (y.col(i) - q.head<3>())).norm();
    return e;
  };
  for (int it = 0; it < 50; ++it) {
    const Eigen::VectorXd e0 = residuals(p);
    Eigen::MatrixXd j(y.cols(), 9);
    for (int k = 0; k < 9; ++k) {
      Eigen::Matrix<double, 9, 1> q = p;
      const double step = 1e-7 * std::max(1.0, std::abs(p(k)));
      q(k) += step;
      j.col(k) = (residuals(q) - e0) / step;
    }
    const Eigen::Matrix<double, 9, 1> d = -(j.transpose() * j).ldlt().solve(j.transpose() * e0);
    p += d;
    if (d.norm() < 1e-12) break;
  }
  *h = p.head<3>();
  *s = mag_internal::Sym(p.tail<6>());
}

TEST(MagData, TheRealLogCalibratesAsWellAsALeastSquaresFitAndItsHalvesAgreeWithinSigma) {
  Log log;
  if (!ReadLog(&log)) GTEST_SKIP() << "acc_mag_log.csv absent (see the file comment)";
  MagOptions o;
  o.microtesla_per_unit = kMicroteslaPerGauss;
  const Eigen::Index n = log.mag.rows();
  const MagProblem whole = Problem(log, 0, n);
  MagResult r;
  const Status s = CalibrateMag(whole, o, &r);
  ASSERT_TRUE(s.ok()) << s.ToString();
  std::printf(
      "whole log: field %.2f µT, |m| residual RMS %.3f -> %.3f µT, σ basis %s (sandwich/bound "
      "%.2f), %lld disturbed samples, %zu statics, alignment %s, dip %.2f ± %.2f°, coverage %s\n",
      r.field_estimate, r.residual_rms_before, r.residual_rms_after, r.basis.c_str(),
      r.sandwich_ratio, static_cast<long long>(r.disturbed_samples), whole.statics.size(),
      r.alignment_note.c_str(), r.dip.value_or(NAN), r.std.dip, r.coverage.verdict.c_str());
  EXPECT_GT(r.field_estimate, 20);  // the Earth's field: 22-67 µT
  EXPECT_LT(r.field_estimate, 70);
  EXPECT_LT(r.residual_rms_after, r.residual_rms_before / 3);
  Eigen::Vector3d peer_h;
  Eigen::Matrix3d peer_s;
  PeerFit(whole.y, &peer_h, &peer_s);
  const double ours = RelativeSpread(whole.y, r.hard_iron, r.soft_iron_symmetric);
  const double peer = RelativeSpread(whole.y, peer_h, peer_s);
  std::printf("|m| relative spread: ours %.4f, least squares %.4f\n", ours, peer);
  EXPECT_LT(ours, 1.05 * peer);
  // Two halves, each with its own σ: the hard iron and the soft iron's entries agree.
  MagResult a, b;
  ASSERT_TRUE(CalibrateMag(Problem(log, 0, n / 2), o, &a).ok());
  ASSERT_TRUE(CalibrateMag(Problem(log, n / 2, n - n / 2), o, &b).ok());
  auto halves_z_rms = [&](const MagStd& sa, const MagStd& sb) {
    double sum = 0;
    int count = 0;
    for (int k = 0; k < 3; ++k) {
      const double z =
          (a.hard_iron(k) - b.hard_iron(k)) / std::hypot(sa.hard_iron(k), sb.hard_iron(k));
      sum += z * z;
      ++count;
    }
    for (int i = 0; i < 3; ++i) {
      for (int j = i; j < 3; ++j) {
        const double z = (a.soft_iron(i, j) - b.soft_iron(i, j)) /
                         std::hypot(sa.soft_iron(i, j), sb.soft_iron(i, j));
        sum += z * z;
        ++count;
      }
    }
    return std::sqrt(sum / count);
  };
  const double z_rms = halves_z_rms(a.std, b.std);
  std::printf(
      "halves: z RMS %.2f over hard and soft iron with the primary σ (bases %s, %s), %.2f "
      "with the white-noise bound\n",
      z_rms, a.basis.c_str(), b.basis.c_str(), halves_z_rms(a.crb, b.crb));
  EXPECT_LT(z_rms, 2.5);
}

}  // namespace
}  // namespace calibd::core
