#include "core/imu.h"

#include <Eigen/Core>
#include <cmath>
#include <sstream>

#include "core/imu_internal.h"
#include "core/imu_stages.h"

namespace calibd::core {
namespace {

using Eigen::Vector3d;
using Eigen::VectorXd;
using imu_internal::AccelFit;
using imu_internal::Coverage;
using imu_internal::Fail;
using imu_internal::FitAccelerometer;
using imu_internal::Integrate;
using imu_internal::KeepLongestStatics;
using imu_internal::kNaN;

// Marks every result failed with s; returns s.
Status FailAll(const Status& s, ImuTermination term, std::vector<ImuResult>* results) {
  for (ImuResult& r : *results) Fail(s, term, &r);
  return s;
}

// Checks the options and that every IMU has both triads; *triads the series the static detection
// reads, accelerometer 2k and gyroscope 2k+1 of IMU k (borrowing the IMUs' readings).
Status CheckInputs(const std::vector<ImuReadings>& imus, const ImuOptions& options,
                   std::vector<TriadSeries>* triads) {
  std::string error;
  if (!options.IsValid(&error)) {
    return Status::InvalidInput(Reason::kInvalidConfig, "imu options: " + error);
  }
  if (imus.empty()) return Status::InvalidInput(Reason::kInvalidRecording, "the log has no IMU");
  for (const ImuReadings& imu : imus) {
    if (imu.accel == nullptr || imu.gyro == nullptr) {
      return Status::InvalidInput(Reason::kInvalidRecording,
                                  "IMU " + imu.name + " lacks accelerometer or gyroscope");
    }
    TriadSeries a{"a" + imu.name,     TriadKind::kAccelerometer,    imu.accel,
                  options.accel_unit, options.accel_saturation_low, options.accel_saturation_high};
    TriadSeries g{"g" + imu.name,    TriadKind::kGyroscope,       imu.gyro,
                  options.gyro_unit, options.gyro_saturation_low, options.gyro_saturation_high};
    triads->push_back(a);
    triads->push_back(g);
  }
  return Status::Ok();
}

// One static-detection threshold tried: its detection and every IMU's accelerometer fit on it.
struct ThresholdCandidate {
  StaticDetection det;
  int64_t found = 0;           // statics the detection found (det keeps at most max_statics)
  std::vector<AccelFit> fits;  // one per IMU; empty when too few statics to fit
  double criterion = kNaN;     // Σχ² / Σdof of the fits; NaN when some fit failed
};

// Steps 1-2 for each candidate threshold multiplier, and the choice among them.
struct ThresholdChoice {
  std::vector<double> multipliers;             // the candidates (one when the threshold is given)
  bool overridden = false;                     // both static thresholds given in the options
  std::vector<ThresholdCandidate> candidates;  // one per multiplier
  int best = -1;    // the candidate with the smallest criterion; -1: no fit succeeded
  int chosen = -1;  // best, or else the candidate with the most statics
};

// Detects the statics at every candidate multiplier and fits every IMU's accelerometer on them.
// Not ok() only when options.stop asked.
Status ChooseThreshold(const std::vector<ImuReadings>& imus, const StaticDetector& detector,
                       const ImuOptions& options, ThresholdChoice* choice) {
  std::vector<double>& mults = choice->multipliers;
  std::vector<ThresholdCandidate>& cands = choice->candidates;
  int& best = choice->best;
  int most = -1;
  mults = options.threshold_multipliers;
  choice->overridden = options.detection.accel_threshold && options.detection.gyro_threshold;
  if (mults.empty() || choice->overridden) mults = {options.detection.threshold_multiplier};
  for (double m : mults) {
    if (StopRequested(options.stop)) return StoppedStatus(*options.stop, "imu: threshold choice");
    ThresholdCandidate c;
    c.det = detector.Detect(m);
    c.found = static_cast<int64_t>(c.det.intervals.size());
    KeepLongestStatics(options.max_statics, &c.det);
    if (StopRequested(options.stop)) return StoppedStatus(*options.stop, "imu: threshold choice");
    const int n = static_cast<int>(c.det.intervals.size());
    if (most < 0 || n > static_cast<int>(cands[static_cast<size_t>(most)].det.intervals.size())) {
      most = static_cast<int>(cands.size());
    }
    if (n >= options.min_statics) {
      double chi2 = 0;
      int dof = 0;
      bool ok = true;
      for (size_t k = 0; k < imus.size(); ++k) {
        c.fits.push_back(FitAccelerometer(c.det, static_cast<int>(k), options));
        if (c.fits.back().stopped) return StoppedStatus(*options.stop, "imu: accelerometer fit");
        ok = ok && c.fits.back().ok;
        chi2 += c.fits.back().chi2;
        dof += c.fits.back().dof;
      }
      if (ok) c.criterion = dof > 0 ? chi2 / dof : 0;
    }
    cands.push_back(std::move(c));
  }
  for (size_t i = 0; i < cands.size(); ++i) {
    if (std::isnan(cands[i].criterion)) continue;
    if (best < 0 || cands[i].criterion < cands[static_cast<size_t>(best)].criterion) {
      best = static_cast<int>(i);
    }
  }
  choice->chosen = best >= 0 ? best : most;
  return Status::Ok();
}

// Every result gets the chosen detection, the warning when it was capped at max_statics, and the
// trials of the threshold choice.
void ReportThresholdChoice(const ThresholdChoice& choice, const ImuOptions& options,
                           std::vector<ImuResult>* results) {
  const std::vector<double>& mults = choice.multipliers;
  const std::vector<ThresholdCandidate>& cands = choice.candidates;
  const bool overridden = choice.overridden;
  const int chosen = choice.chosen;
  const ThresholdCandidate& picked = cands[static_cast<size_t>(chosen)];
  int64_t capped_from = 0;  // statics found by the chosen detection when over max_statics
  if (picked.found > static_cast<int64_t>(picked.det.intervals.size())) capped_from = picked.found;
  for (size_t k = 0; k < results->size(); ++k) {
    ImuResult& r = (*results)[k];
    r.detection = picked.det;
    if (capped_from > 0) {
      r.warnings.push_back(
          "static detection found " + std::to_string(capped_from) +
          " static intervals, more than max_statics (" + std::to_string(options.max_statics) +
          "): the fits use the " + std::to_string(options.max_statics) +
          " longest (so many usually means a time column not in seconds, or a static_window "
          "far shorter than the holds)");
    }
    if (!overridden && mults.size() > 1) {
      for (size_t i = 0; i < cands.size(); ++i) {
        ImuThresholdTrial tr;
        tr.multiplier = mults[i];
        tr.statics = static_cast<int>(cands[i].det.intervals.size());
        if (!cands[i].fits.empty() && cands[i].fits[k].ok && cands[i].fits[k].dof > 0) {
          tr.accel_chi2_per_dof = cands[i].fits[k].chi2 / cands[i].fits[k].dof;
        }
        tr.chosen = static_cast<int>(i) == chosen;
        r.threshold_trials.push_back(tr);
      }
      std::ostringstream w;
      w << "threshold multiplier " << mults[static_cast<size_t>(chosen)]
        << " × noise floor, chosen among " << mults.size()
        << " candidates as the one whose accelerometer fit has the smallest chi²/dof";
      r.threshold_choice = w.str();
    } else {
      r.threshold_choice = overridden ? "static_threshold given" : "single multiplier given";
    }
  }
}

// The coverage of the gravity directions of IMU k's statics in `d`, read with the nominal
// conversion (no fit): what the too-few-statics failure and FindImuStatics report.
ImuCoverage NominalCoverage(const StaticDetection& d, int k, const ImuOptions& options) {
  std::vector<Vector3d> u;
  for (const StaticInterval& iv : d.intervals) {
    const Vector3d v =
        iv.mean[static_cast<size_t>(2 * k)] - Vector3d::Constant(options.nominal_accel_bias);
    if (v.norm() > 0) u.push_back(v.normalized());
  }
  ImuCoverage cov;
  Coverage(u, Vector3d::Ones(), &cov);
  return cov;
}

// No candidate's statics determine the accelerometer: fails every result, with the coverage of
// the orientations found (nominal conversion, first IMU) and what is missing.
Status FailTooFewStatics(const ThresholdChoice& choice, const ImuOptions& options,
                         std::vector<ImuResult>* results) {
  const int chosen = choice.chosen;
  const std::vector<ThresholdCandidate>& cands = choice.candidates;
  const StaticDetection& d = cands[static_cast<size_t>(chosen)].det;
  const int n = static_cast<int>(d.intervals.size());
  // Which orientations are there (nominal conversion, first IMU) and which are missing.
  const ImuCoverage cov = NominalCoverage(d, 0, options);
  std::ostringstream m;
  m << "found " << n << " static intervals, at least " << options.min_statics << " are needed ("
    << options.recommended_statics << " or more recommended)";
  if (n >= options.min_statics) m << ", but they do not determine the accelerometer";
  m << ": "
    << (cov.missing_up.empty()
            ? "hold the board still for a few seconds in more orientations spread over the "
              "sphere"
            : cov.verdict);
  if (n < options.min_statics) m << "; " << StaticShortfall(d);  // what was found, what to change
  const std::string msg = m.str();
  // Enough statics that do not determine the ellipsoid: their orientations are the problem.
  const Reason why =
      n >= options.min_statics ? Reason::kPoorOrientationCoverage : Reason::kTooFewStatics;
  for (ImuResult& r : *results) {
    Fail(Status::NotDeterminable(why, msg), ImuTermination::kTooFewStatics, &r);
    r.coverage = cov;
  }
  return Status::NotDeterminable(why, msg);
}

// Steps 1-2 for every IMU (CalibrateImus and FindImuStatics): the inputs checked, the static
// detection at every candidate multiplier with the accelerometer fits, and the choice reported
// in every result. Not ok(): every result has been failed (invalid input, stopped, or too few
// statics: kNotDeterminable).
Status DetectAndChooseStatics(const Eigen::VectorXd& t, const std::vector<ImuReadings>& imus,
                              const ImuOptions& options, std::vector<ImuResult>* results,
                              ThresholdChoice* choice) {
  results->assign(imus.size(), ImuResult());
  for (size_t k = 0; k < imus.size(); ++k) {
    (*results)[k].name = imus[k].name;
    (*results)[k].gravity = options.gravity;
    (*results)[k].gyro_bias_model = options.gyro_bias;
  }
  std::vector<TriadSeries> triads;
  Status s = CheckInputs(imus, options, &triads);
  if (!s.ok()) return FailAll(s, ImuTermination::kInvalidInput, results);
  auto stopped_all = [&](const std::string& stage) {
    return FailAll(StoppedStatus(*options.stop, "imu: " + stage), ImuTermination::kStopped,
                   results);
  };
  if (StopRequested(options.stop)) return stopped_all("static detection");
  StaticDetector detector;
  s = detector.Init(t, triads, options.detection);
  if (s.code() == StatusCode::kStopped) return FailAll(s, ImuTermination::kStopped, results);
  if (!s.ok()) return FailAll(s, ImuTermination::kInvalidInput, results);
  if (StopRequested(options.stop)) return stopped_all("static detection");

  s = ChooseThreshold(imus, detector, options, choice);
  if (!s.ok()) return FailAll(s, ImuTermination::kStopped, results);
  ReportThresholdChoice(*choice, options, results);
  if (choice->best < 0) return FailTooFewStatics(*choice, options, results);
  return Status::Ok();
}

// Steps 3-5 and the diagnostics for IMU k, given its accelerometer fit on the chosen detection:
// the stages of core/imu_stages.h in order.
Status Finish(const VectorXd& t, const ImuReadings& imu, int k, const ImuOptions& o, AccelFit fit,
              ImuResult* res) {
  namespace ii = imu_internal;
  const ii::ImuStageInput in{t, imu, k, o};
  const ii::NominalTriads nominal = ii::NominalOf(o);
  ii::ImuFit f = ii::StartGyroscope(in, std::move(fit), res);
  Status s = ii::CollectRotations(in, &f, res);
  if (s.ok()) s = ii::FitGyroscope(in, nominal, &f, res);
  if (s.ok()) s = ii::RefineJointly(in, &f, res);
  VectorXd sd;
  if (s.ok()) s = ii::EstimateCovariance(in, f, res, &sd);
  if (!s.ok()) return s;
  ii::ReportParameters(f.x, sd, res);
  ii::DiagnoseStatics(in, nominal, f.x, res);
  s = ii::DiagnoseRotations(in, nominal, f.x, res);
  if (!s.ok()) return s;
  return ii::CheckPlausibility(in, f.max_iter, res);
}

}  // namespace

double Wgs84NormalGravity(double latitude_deg, double height_m) {
  // Somigliana: γ = γ_e (1 + k sin²φ) / sqrt(1 − e² sin²φ); free air to second order (WGS-84).
  const double a = 6378137.0, f = 1 / 298.257223563, gm = 3.986004418e14, omega = 7292115e-11;
  const double ge = 9.7803253359, k = 0.00193185265241, e2 = 6.69437999013e-3;
  const double phi = latitude_deg * 3.14159265358979323846 / 180;
  const double s2 = std::sin(phi) * std::sin(phi);
  const double g0 = ge * (1 + k * s2) / std::sqrt(1 - e2 * s2);
  const double m = omega * omega * a * a * (a * (1 - f)) / gm;
  return g0 * (1 - 2 / a * (1 + f + m - 2 * f * s2) * height_m + 3 / (a * a) * height_m * height_m);
}

const char* GyroBiasModelName(GyroBiasModel model) {
  return model == GyroBiasModel::kStatics ? "statics" : "estimate";
}

const char* ImuTerminationName(ImuTermination t) {
  switch (t) {
    case ImuTermination::kNotRun:
      return "not_run";
    case ImuTermination::kConverged:
      return "converged";
    case ImuTermination::kMaxIterations:
      return "max_iterations";
    case ImuTermination::kInvalidInput:
      return "invalid_input";
    case ImuTermination::kTooFewStatics:
      return "too_few_statics";
    case ImuTermination::kTooFewRotations:
      return "too_few_rotations";
    case ImuTermination::kDegenerate:
      return "degenerate";
    case ImuTermination::kImplausible:
      return "implausible";
    case ImuTermination::kStopped:
      return "stopped";
  }
  return "unknown";
}

std::string ImuResult::BriefReport() const {
  int used = 0;
  for (const ImuRotationDiagnostics& r : rotations) used += r.used ? 1 : 0;
  char buf[640];
  std::snprintf(buf, sizeof buf,
                "imu %s: %s%s; termination %s, %zu statics, %d of %zu rotations used, iterations "
                "%d/%d/%d (accel/gyro/joint), chi2/dof %.4g, |a|-g rms %.3g -> %.3g m/s^2, gyro "
                "direction rms %.3g -> %.3g rad",
                name.c_str(), usable ? "usable" : "not usable: ", usable ? "" : reason.c_str(),
                ImuTerminationName(termination), statics.size(), used, rotations.size(),
                accel_iterations, gyro_iterations, joint_iterations, chi2_per_dof,
                accel_norm_rms_before, accel_norm_rms_after, gyro_direction_rms_before,
                gyro_direction_rms_after);
  return buf;
}

bool ImuOptions::IsValid(std::string* error) const {
  auto fail = [error](const std::string& what) {
    if (error != nullptr) *error = what;
    return false;
  };
  auto pos = [](double v) { return std::isfinite(v) && v > 0; };
  if (!pos(accel_unit)) return fail("accel_unit must be a finite number > 0");
  if (!pos(gyro_unit)) return fail("gyro_unit must be a finite number > 0");
  if (!pos(gravity)) return fail("gravity must be a finite number > 0 (m/s^2)");
  if (!std::isfinite(nominal_accel_bias) || !std::isfinite(nominal_gyro_bias)) {
    return fail("nominal biases must be finite");
  }
  std::string e;
  if (!detection.IsValid(&e)) return fail(e);
  for (double m : threshold_multipliers) {
    if (!pos(m)) return fail("threshold_multipliers must be finite numbers > 0");
  }
  if (min_statics < 9) return fail("min_statics must be >= 9 (the accelerometer has 9 unknowns)");
  if (recommended_statics < min_statics) return fail("recommended_statics must be >= min_statics");
  if (accel_noise && !pos(*accel_noise)) return fail("accel_noise must be a finite number > 0");
  if (gyro_noise && !pos(*gyro_noise)) return fail("gyro_noise must be a finite number > 0");
  if (max_iterations < 1) return fail("max_iterations must be >= 1");
  if (max_statics < min_statics) return fail("max_statics must be >= min_statics");
  if (!pos(max_scale_deviation)) return fail("max_scale_deviation must be > 0");
  if (!pos(max_direction_error)) return fail("max_direction_error must be > 0 (rad)");
  if (!(accel_saturation_low < accel_saturation_high) ||
      !(gyro_saturation_low < gyro_saturation_high)) {
    return fail("saturation_low must be below saturation_high");
  }
  return true;
}

Eigen::Matrix3d IntegrateRotation(const Eigen::VectorXd& t, const Eigen::MatrixX3d& gyro,
                                  const Eigen::Matrix3d& matrix, const Eigen::Vector3d& bias,
                                  int64_t first, int64_t last) {
  return Integrate(t, gyro, matrix, bias, first, last, nullptr);
}

Eigen::Vector3d PooledStd(const StaticDetection& d, int tri) {
  Eigen::Vector3d ss = Eigen::Vector3d::Zero();
  double dof = 0;
  for (const StaticInterval& iv : d.intervals) {
    if (iv.samples < 2) continue;
    ss += (iv.std[static_cast<size_t>(tri)].array().square() * (iv.samples - 1.0)).matrix();
    dof += static_cast<double>(iv.samples - 1);
  }
  return dof > 0 ? Eigen::Vector3d((ss / dof).cwiseSqrt()) : Eigen::Vector3d::Zero();
}

Status CalibrateImus(const Eigen::VectorXd& t, const std::vector<ImuReadings>& imus,
                     const ImuOptions& options, std::vector<ImuResult>* results) {
  ThresholdChoice choice;
  Status s = DetectAndChooseStatics(t, imus, options, results, &choice);
  if (!s.ok()) return s;
  const int best = choice.best;
  const std::vector<ThresholdCandidate>& cands = choice.candidates;
  Status first_failure;
  for (size_t k = 0; k < imus.size(); ++k) {
    Status st = Finish(t, imus[k], static_cast<int>(k), options,
                       cands[static_cast<size_t>(best)].fits[k], &(*results)[k]);
    if (st.code() == StatusCode::kStopped) {
      // Every IMU not finished is stopped too; the status says where the first one was.
      for (size_t i = k + 1; i < imus.size(); ++i) {
        Fail(st, ImuTermination::kStopped, &(*results)[i]);
      }
      return st;
    }
    if (!st.ok() && first_failure.ok()) {
      first_failure =
          Status(st.code(), "IMU " + imus[k].name + ": " + st.message()).WithReason(st.reason());
    }
  }
  return first_failure;
}

Status FindImuStatics(const Eigen::VectorXd& t, const std::vector<ImuReadings>& imus,
                      const ImuOptions& options, std::vector<ImuResult>* results) {
  ThresholdChoice choice;
  Status s = DetectAndChooseStatics(t, imus, options, results, &choice);
  if (!s.ok()) return s;
  for (size_t k = 0; k < results->size(); ++k) {
    (*results)[k].coverage = NominalCoverage((*results)[k].detection, static_cast<int>(k), options);
  }
  return Status::Ok();
}

Status CalibrateImu(const Eigen::VectorXd& t, const Eigen::MatrixX3d& accel,
                    const Eigen::MatrixX3d& gyro, const ImuOptions& options, ImuResult* result) {
  std::vector<ImuResult> results;
  Status s = CalibrateImus(t, {ImuReadings{"0", &accel, &gyro}}, options, &results);
  *result = std::move(results[0]);
  return s;
}

}  // namespace calibd::core
