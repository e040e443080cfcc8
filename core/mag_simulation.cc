#include "core/mag_simulation.h"

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <cmath>
#include <string>

#include "core/array_simulation.h"
#include "core/mag_internal.h"

namespace calibd::core {
namespace {

constexpr double kRadPerDeg = 3.14159265358979323846 / 180;

Status Invalid(const std::string& what) {
  return Status::InvalidInput("mag simulation: " + what).WithField(what.substr(0, what.find(' ')));
}

Status Check(const MagSimulationOptions& o) {
  if (!(o.rate > 0)) return Invalid("rate must be > 0");
  if (o.turns < 1) return Invalid("turns must be >= 1");
  if (!(o.turn_seconds > 0)) return Invalid("turn_seconds must be > 0");
  if (o.statics < 0 || o.statics > o.turns) return Invalid("statics must lie in 0..turns");
  if (!(o.static_seconds > 0)) return Invalid("static_seconds must be > 0");
  if (!(o.field > 0)) return Invalid("field must be > 0");
  if (!(std::abs(o.dip) < 90)) return Invalid("dip must lie in (-90, 90)");
  if (!(o.noise >= 0) || !(o.accel_noise >= 0)) return Invalid("noise must be >= 0");
  if (!(o.ar1 >= 0 && o.ar1 < 1)) return Invalid("ar1 must lie in [0, 1)");
  if (!(o.hard_iron_walk >= 0)) return Invalid("hard_iron_walk must be >= 0");
  if (!(o.max_tilt > 0 && o.max_tilt <= 180)) return Invalid("max_tilt must lie in (0, 180]");
  for (const Eigen::Matrix3d& q : o.orientations) {
    if (!(q.transpose() * q).isApprox(Eigen::Matrix3d::Identity(), 1e-9) ||
        !(q.determinant() > 0)) {
      return Invalid("orientations must be rotation matrices");
    }
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(o.soft_iron);
  if (!o.soft_iron.isApprox(o.soft_iron.transpose()) || !(es.eigenvalues()(0) > 0)) {
    return Invalid("soft_iron must be symmetric positive definite");
  }
  return Status::Ok();
}

Eigen::Quaterniond RandomOrientation(const MagSimulationOptions& o, GaussianRng* rng) {
  constexpr double kPi = 3.14159265358979323846;
  const Eigen::AngleAxisd yaw(2 * kPi * rng->Uniform(), Eigen::Vector3d::UnitZ());
  if (o.yaw_only) return Eigen::Quaterniond(yaw);
  if (o.max_tilt < 180) {
    const double azimuth = 2 * kPi * rng->Uniform();
    const Eigen::AngleAxisd tilt(o.max_tilt * kRadPerDeg * rng->Uniform(),
                                 Eigen::Vector3d(std::cos(azimuth), std::sin(azimuth), 0));
    return Eigen::Quaterniond(tilt * yaw);
  }
  Eigen::Vector4d v;
  for (int k = 0; k < 4; ++k) v(k) = rng->Normal();
  v.normalize();
  return Eigen::Quaterniond(v(0), v(1), v(2), v(3));
}

}  // namespace

Status SimulateMag(const MagSimulationOptions& o, MagSimulation* out) {
  if (Status s = Check(o); !s.ok()) return s;
  GaussianRng rng(o.seed);
  const Eigen::Matrix3d r = mag_internal::ExpRotation(o.alignment);
  const Eigen::Matrix3d map = o.soft_iron.inverse() * r.transpose();
  const double dip = o.dip * kRadPerDeg;
  const Eigen::Vector3d b_earth = o.field * Eigen::Vector3d(std::cos(dip), 0, std::sin(dip));
  const Eigen::Vector3d g_earth(0, 0, -9.81);
  const int64_t per_turn = std::max<int64_t>(2, std::llround(o.turn_seconds * o.rate));
  const int64_t per_static = std::max<int64_t>(2, std::llround(o.static_seconds * o.rate));
  const bool given = !o.orientations.empty();
  const int64_t turns = given ? static_cast<int64_t>(o.orientations.size()) - 1 : o.turns;
  const int64_t holds_planned = given ? turns + 1 : o.statics;
  const int64_t n = turns * per_turn + holds_planned * per_static;
  out->problem.t.resize(n);
  out->problem.y.resize(3, n);
  out->problem.statics.clear();
  out->accel.resize(3, n);
  Eigen::Quaterniond from =
      given ? Eigen::Quaterniond(o.orientations.front()) : RandomOrientation(o, &rng);
  Eigen::Vector3d coloured = Eigen::Vector3d::Zero();
  const double innovation = std::sqrt(1 - o.ar1 * o.ar1);
  // The hard iron's random walk and its sum (its mean is removed at the end). Drawn only when
  // asked, so that logs without it keep their random sequence.
  Eigen::Vector3d walk = Eigen::Vector3d::Zero(), walk_sum = Eigen::Vector3d::Zero();
  const double walk_step = o.hard_iron_walk / std::sqrt(o.rate);
  int64_t i = 0;
  auto sample = [&](const Eigen::Quaterniond& q) {
    const double t = static_cast<double>(i) / o.rate;
    Eigen::Vector3d b = b_earth;
    for (const MagDisturbance& d : o.disturbances) {
      if (t >= d.start && t <= d.end) b += d.field;
    }
    const Eigen::Matrix3d qt = q.toRotationMatrix().transpose();
    for (int k = 0; k < 3; ++k) coloured(k) = o.ar1 * coloured(k) + innovation * rng.Normal();
    out->problem.t(i) = t;
    if (o.hard_iron_walk > 0) {
      for (int k = 0; k < 3; ++k) walk(k) += walk_step * rng.Normal();
      walk_sum += walk;
    }
    out->problem.y.col(i) = o.hard_iron + walk + map * (qt * b) + o.noise * coloured;
    Eigen::Vector3d nu;
    for (int k = 0; k < 3; ++k) nu(k) = o.accel_noise * rng.Normal();
    out->accel.col(i) = qt * g_earth + nu;
    ++i;
  };
  auto hold = [&]() {
    const int64_t first = i;
    for (int64_t k = 0; k < per_static; ++k) sample(from);
    const int64_t trim = std::min<int64_t>(per_static / 4, std::llround(0.2 * o.rate));
    MagStatic s;
    s.first = first + trim;
    s.last = i - 1 - trim;
    s.specific_force = out->accel.middleCols(s.first, s.last - s.first + 1).rowwise().mean();
    out->problem.statics.push_back(s);
  };
  if (given) hold();
  const int every = o.statics > 0 ? o.turns / o.statics : 0;
  int holds = 0;
  for (int64_t turn = 0; turn < turns; ++turn) {
    const Eigen::Quaterniond to =
        given ? Eigen::Quaterniond(o.orientations[turn + 1]) : RandomOrientation(o, &rng);
    for (int64_t k = 0; k < per_turn; ++k) {
      const double x = static_cast<double>(k + 1) / per_turn;
      sample(from.slerp(0.5 * (1 - std::cos(3.14159265358979323846 * x)), to));
    }
    from = to;
    if (given || (holds < o.statics && (turn + 1) % every == 0)) {
      hold();
      ++holds;
    }
  }
  out->problem.t.conservativeResize(i);
  out->problem.y.conservativeResize(3, i);
  out->accel.conservativeResize(3, i);
  out->problem.y.colwise() -= walk_sum / static_cast<double>(i);
  out->hard_iron = o.hard_iron;
  out->soft_iron_symmetric = o.soft_iron;
  out->soft_iron = r * o.soft_iron;
  out->alignment = r;
  out->dip = o.dip;
  out->field = o.field;
  return Status::Ok();
}

}  // namespace calibd::core
