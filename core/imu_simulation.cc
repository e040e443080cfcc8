#include "core/imu_simulation.h"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "core/array_simulation.h"

namespace calibd::core {
namespace {

constexpr double kPi = 3.14159265358979323846;

Eigen::Matrix3d RandomRotation(GaussianRng* rng) {
  // Braces: the draws are made left to right with every compiler (parenthesised arguments are
  // evaluated in an unspecified order, and GCC and Clang differ).
  Eigen::Quaterniond q{rng->Normal(), rng->Normal(), rng->Normal(), rng->Normal()};
  q.normalize();
  return q.toRotationMatrix();
}

// One segment of motion: from orientation r0, turn by axis*angle (body frame) over duration.
struct Segment {
  double t0 = 0, duration = 0;
  Eigen::Matrix3d r0;
  Eigen::Vector3d axis = Eigen::Vector3d::UnitX();
  double angle = 0;  // 0: static
};

}  // namespace

bool ImuSimulationOptions::IsValid(std::string* error) const {
  auto fail = [error](const std::string& what) {
    if (error != nullptr) *error = what;
    return false;
  };
  auto pos = [](double v) { return std::isfinite(v) && v > 0; };
  auto nonneg = [](double v) { return std::isfinite(v) && v >= 0; };
  if (statics < 1) return fail("statics must be >= 1");
  if (!orientations.empty() && orientations.size() != static_cast<size_t>(statics)) {
    return fail("statics must equal the number of orientations given");
  }
  if (!pos(static_duration)) return fail("static_duration must be > 0 s");
  if (!pos(rotation_duration)) return fail("rotation_duration must be > 0 s");
  if (!static_durations.empty() && static_durations.size() != static_cast<size_t>(statics)) {
    return fail("static_durations must have one entry per static");
  }
  if (!rotation_durations.empty() &&
      rotation_durations.size() != static_cast<size_t>(statics - 1)) {
    return fail("rotation_durations must have one entry per rotation (statics - 1)");
  }
  for (double d : static_durations) {
    if (!pos(d)) return fail("static_durations must be > 0 s each");
  }
  for (double d : rotation_durations) {
    if (!pos(d)) return fail("rotation_durations must be > 0 s each");
  }
  if (!nonneg(initial_motion)) return fail("initial_motion must be >= 0 s");
  if (!pos(rate)) return fail("rate must be > 0 Hz");
  if (!pos(gravity)) return fail("gravity must be > 0");
  if (!nonneg(accel_noise) || !nonneg(gyro_noise)) return fail("noise must be >= 0");
  for (int i = 0; i < 3; ++i) {
    if (!nonneg(accel_axis_ratio(i)) || !nonneg(gyro_axis_ratio(i))) {
      return fail("the noise's axis ratios must be >= 0");
    }
  }
  if (!pos(accel_unit) || !pos(gyro_unit)) return fail("units must be > 0");
  if (!std::isfinite(accel_offset) || !std::isfinite(gyro_offset)) {
    return fail("offsets must be finite");
  }
  if (!nonneg(scale_error) || !nonneg(misalignment) || !nonneg(accel_bias) || !nonneg(gyro_bias) ||
      !nonneg(gyro_bias_drift) || !nonneg(accel_bias_drift)) {
    return fail("sensor error sigmas must be >= 0");
  }
  double total = initial_motion;
  for (int j = 0; j < statics; ++j) {
    total += static_durations.empty() ? static_duration : static_durations[j];
    if (j > 0) total += rotation_durations.empty() ? rotation_duration : rotation_durations[j - 1];
  }
  const double samples = rate * total;
  if (samples > 5e8) return fail("the log would have more than 5e8 samples");
  return true;
}

Status SimulateImu(const ImuSimulationOptions& o, ImuSimulation* out) {
  std::string error;
  if (!o.IsValid(&error)) return Status::InvalidInput("imu simulation: " + error);
  GaussianRng rng(o.seed);
  GaussianRng noise(o.noise_seed != 0 ? o.noise_seed : o.seed * 0x9E3779B97F4A7C15ULL + 1);
  ImuSimulation& s = *out;
  s = ImuSimulation();

  // Sensor errors.
  auto make_triad = [&](double unit, bool upper, double bias_si, double drift_si, double offset,
                        ImuTriadTruth* tr) {
    for (int i = 0; i < 3; ++i) tr->scale(i) = unit * (1 + o.scale_error * rng.Normal());
    tr->misalignment.setIdentity();
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        if (i == j || (upper && i > j)) continue;
        tr->misalignment(i, j) = o.misalignment * rng.Normal();
      }
    }
    tr->matrix = tr->misalignment * tr->scale.asDiagonal();
    for (int i = 0; i < 3; ++i) tr->bias(i) = offset + bias_si * rng.Normal() / unit;
    tr->bias_drift = rng.UnitVector() * drift_si / unit;
  };
  make_triad(o.accel_unit, true, o.accel_bias, o.accel_bias_drift, o.accel_offset, &s.accel_truth);
  make_triad(o.gyro_unit, false, o.gyro_bias, o.gyro_bias_drift, o.gyro_offset, &s.gyro_truth);

  // Motion plan.
  std::vector<Segment> segments;
  double t = 0;
  Eigen::Matrix3d r = o.orientations.empty() ? RandomRotation(&rng) : o.orientations.front();
  auto add_rotation = [&](const Eigen::Matrix3d& to, double duration) {
    const Eigen::AngleAxisd aa(r.transpose() * to);
    Segment seg;
    seg.t0 = t;
    seg.duration = duration;
    seg.r0 = r;
    seg.axis = aa.axis();
    seg.angle = aa.angle();
    segments.push_back(seg);
    t += duration;
    r = to;
  };
  auto add_static = [&](double duration) {
    Segment seg;
    seg.t0 = t;
    seg.duration = duration;
    seg.r0 = r;
    segments.push_back(seg);
    t += duration;
  };
  if (o.initial_motion > 0) add_rotation(RandomRotation(&rng), o.initial_motion);
  for (int j = 0; j < o.statics; ++j) {
    if (j > 0) {
      add_rotation(
          o.orientations.empty() ? RandomRotation(&rng) : o.orientations[j],
          o.rotation_durations.empty() ? o.rotation_duration : o.rotation_durations[j - 1]);
    }
    s.orientations.push_back(r);
    add_static(o.static_durations.empty() ? o.static_duration : o.static_durations[j]);
  }
  const double total = t;
  const int64_t n = static_cast<int64_t>(std::floor(total * o.rate));
  s.t.resize(n);
  s.accel.resize(n, 3);
  s.gyro.resize(n, 3);
  const Eigen::Matrix3d ma_inv = s.accel_truth.matrix.inverse();
  const Eigen::Matrix3d mg_inv = s.gyro_truth.matrix.inverse();
  const Eigen::Vector3d up(0, 0, o.gravity);
  // Per axis: the given ratios (default 1) times the σ.
  const Eigen::Vector3d an = o.accel_axis_ratio * (o.accel_noise / o.accel_unit);
  const Eigen::Vector3d gn = o.gyro_axis_ratio * (o.gyro_noise / o.gyro_unit);
  size_t seg_i = 0;
  std::vector<int64_t> first(segments.size(), -1), last(segments.size(), -1);
  for (int64_t k = 0; k < n; ++k) {
    const double tk = static_cast<double>(k) / o.rate;
    while (seg_i + 1 < segments.size() && tk >= segments[seg_i + 1].t0) ++seg_i;
    const Segment& seg = segments[seg_i];
    Eigen::Matrix3d rk = seg.r0;
    Eigen::Vector3d omega = Eigen::Vector3d::Zero();
    if (seg.angle != 0) {
      const double x = (tk - seg.t0) / seg.duration;
      const double sx = x - std::sin(2 * kPi * x) / (2 * kPi);
      rk = seg.r0 * Eigen::AngleAxisd(seg.angle * sx, seg.axis).toRotationMatrix();
      omega = seg.axis * seg.angle * (1 - std::cos(2 * kPi * x)) / seg.duration;
    } else {
      if (first[seg_i] < 0) first[seg_i] = k;
      last[seg_i] = k;
    }
    const Eigen::Vector3d f = rk.transpose() * up;
    Eigen::Vector3d ya = ma_inv * f + s.accel_truth.bias + s.accel_truth.bias_drift * tk;
    Eigen::Vector3d yg = mg_inv * omega + s.gyro_truth.bias + s.gyro_truth.bias_drift * tk;
    for (int i = 0; i < 3; ++i) ya(i) += an(i) * noise.Normal();
    for (int i = 0; i < 3; ++i) yg(i) += gn(i) * noise.Normal();
    if (o.quantize) {
      ya = ya.array().round();
      yg = yg.array().round();
    }
    s.t(k) = tk;
    s.accel.row(k) = ya.transpose();
    s.gyro.row(k) = yg.transpose();
  }
  for (size_t i = 0; i < segments.size(); ++i) {
    if (segments[i].angle == 0 && first[i] >= 0) s.statics.emplace_back(first[i], last[i]);
  }
  return Status::Ok();
}

Status ReplayImuProtocol(const Eigen::VectorXd& t, const ImuReadings& imu,
                         const StaticDetection& detection, int k, const ImuOptions& options,
                         ImuSimulationOptions* sim) {
  const std::vector<StaticInterval>& ivs = detection.intervals;
  if (ivs.size() < 2) {
    return Status::NotDeterminable("a replay needs 2 statics or more; the log has " +
                                   std::to_string(ivs.size()));
  }
  const size_t ta = static_cast<size_t>(2 * k), tg = ta + 1;
  const double period = detection.sample_period;
  auto up = [&](const StaticInterval& iv) -> Eigen::Vector3d {
    const Eigen::Vector3d v = iv.mean[ta] - Eigen::Vector3d::Constant(options.nominal_accel_bias);
    return v.norm() > 0 ? Eigen::Vector3d(v.normalized()) : Eigen::Vector3d::UnitZ();
  };
  const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
  const Eigen::Matrix3d nominal = Eigen::Matrix3d::Identity() * options.gyro_unit;
  sim->statics = static_cast<int>(ivs.size());
  sim->orientations.clear();
  sim->static_durations.clear();
  sim->rotation_durations.clear();
  Eigen::Matrix3d r = Eigen::Quaterniond::FromTwoVectors(up(ivs[0]), z).toRotationMatrix();
  for (size_t j = 0; j < ivs.size(); ++j) {
    if (j > 0) {
      const StaticInterval& a = ivs[j - 1];
      const StaticInterval& b = ivs[j];
      const Eigen::Vector3d bias = 0.5 * (a.mean[tg] + b.mean[tg]);
      r = r * IntegrateRotation(t, *imu.gyro, nominal, bias, a.last, b.first);
      // The least world-frame rotation putting the measured up direction on z.
      r = Eigen::Quaterniond::FromTwoVectors(r * up(b), z).toRotationMatrix() * r;
      sim->rotation_durations.push_back(std::max(b.extent_start - a.extent_end - period, period));
    }
    sim->orientations.push_back(r);
    sim->static_durations.push_back(ivs[j].extent_end - ivs[j].extent_start + period);
  }
  return Status::Ok();
}

}  // namespace calibd::core
