// What the `mag` tests compare a calibration with: an ArduPilot-style least-squares ellipsoid fit,
// and the calibrated magnitude's spread split into the sensor's noise and the field's own.
#ifndef CALIBD_TESTS_LIB_MAG_PEER_H_
#define CALIBD_TESTS_LIB_MAG_PEER_H_

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "core/mag_internal.h"

namespace calibd::testing {

// ArduPilot's CompassCalibrator's fit: the least squares of F − |S(y − h)| over every sample
// alike, S symmetric, from the sphere through the readings' mean. Gauss-Newton with a numeric
// Jacobian (steps relative to each parameter, so reading units of any size work).
inline void PeerEllipsoidFit(const Eigen::Matrix3Xd& y, double field, Eigen::Vector3d* h,
                             Eigen::Matrix3d* s) {
  const Eigen::Vector3d mean = y.rowwise().mean();
  const double r = (y.colwise() - mean).colwise().norm().mean();
  Eigen::Matrix<double, 9, 1> p;
  p << mean, field / r, 0, 0, field / r, 0, field / r;
  auto residuals = [&](const Eigen::Matrix<double, 9, 1>& q) {
    const Eigen::Matrix3d m = core::mag_internal::Sym(q.tail<6>());
    Eigen::VectorXd e(y.cols());
    for (Eigen::Index i = 0; i < y.cols(); ++i)
      e(i) = field - (m * (y.col(i) - q.head<3>())).norm();
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
    if (d.norm() < 1e-12 * std::max(1.0, p.norm())) break;
  }
  *h = p.head<3>();
  *s = core::mag_internal::Sym(p.tail<6>());
}

// The calibrated magnitude's relative spread and its parts.
//  - total: the RMS of |m_i| − mean |m|, over mean |m|.
//  - noise: the part the sensor's white noise makes, √(½ var Δ|m|) over successive samples (the
//    field turns little in one sample).
//  - field: √(total² − noise²), the spread of the calibrated field itself: what the calibration
//    decides.
// The least-squares fit above minimises `total`, noise included. Where the noise is a sizeable
// part of the field and the ellipsoid far from a sphere, it buys a smaller `total` with a soft
// iron that amplifies the noise less than the true one does (tests/core/mag_test.cc).
struct MagnitudeSpread {
  double total = 0;
  double noise = 0;
  double field = 0;
};

inline MagnitudeSpread Spread(const Eigen::Matrix3Xd& y, const Eigen::Vector3d& h,
                              const Eigen::Matrix3d& s) {
  Eigen::ArrayXd norm(y.cols());
  for (Eigen::Index i = 0; i < y.cols(); ++i) norm(i) = (s * (y.col(i) - h)).norm();
  norm /= norm.mean();
  const Eigen::Index n = norm.size();
  const Eigen::ArrayXd diff = norm.tail(n - 1) - norm.head(n - 1);
  MagnitudeSpread out;
  out.total = std::sqrt((norm - 1).square().mean());
  out.noise = std::sqrt(0.5 * (diff - diff.mean()).square().mean());
  out.field = std::sqrt(std::max(0.0, out.total * out.total - out.noise * out.noise));
  return out;
}

}  // namespace calibd::testing

#endif  // CALIBD_TESTS_LIB_MAG_PEER_H_
