#include "server/failure_reasons.h"

#include <algorithm>
#include <cstddef>
#include <utility>

namespace calibd::server {
namespace {

std::vector<FailureReason> MakeCatalog() {
  using R = Reason;
  // Advice says what to record or set instead; the method's message (kept beside it) says what
  // it found. Keep the codes stable: they are stored with jobs and read by clients.
  std::vector<FailureReason> c = {
      {R::kInvalidConfig, "invalid_config", "Invalid config",
       "Correct the config key the message names (SPEC §3 lists the keys of each method) and "
       "upload again."},
      {R::kInvalidRecording, "invalid_recording", "The recording cannot be used as given",
       "Check the recording against the config: its columns, units, number of sensors and "
       "time column (SPEC §2), then upload it again."},
      {R::kRecordingUnreadable, "recording_unreadable", "The recording does not parse",
       "Upload the recording in one of the SPEC §2 layouts: a header line, then one number per "
       "column on every row."},
      {R::kOverMemoryBudget, "over_memory_budget", "Over the memory budget per job",
       "Upload a shorter recording (fewer rows or columns), or ask the operator to raise "
       "--job-memory-mb."},
      {R::kProblemTooLarge, "problem_too_large", "The problem is too large",
       "Calibrate fewer sensors or positions per job, or raise the method's size limits "
       "(pca: max_memory_bytes, max_flops) if the server can afford it."},
      {R::kNotDeterminable, "not_determinable", "The data do not determine the parameters",
       "Record again following the method's recording instructions (README), with more "
       "positions or motion than the minimum."},
      {R::kNoSignal, "no_signal", "No signal",
       "Check that the sensors were powered and the field (gravity, magnetic field) applied "
       "while recording; all readings are equal."},
      {R::kTooFewSensors, "too_few_sensors", "Too few sensors",
       "Record with at least as many sensors as the dimension d of the field."},
      {R::kTooFewPositions, "too_few_positions", "Too few positions",
       "Record more static positions: at least the minimum the message names, and better twice "
       "as many, spread over the sphere."},
      {R::kPoorOrientationCoverage, "poor_orientation_coverage",
       "Orientations do not cover the sphere",
       "Hold the device still in orientations spread over the whole sphere (the six faces and "
       "the diagonals between them), not only about one axis or in one plane."},
      {R::kNoRankGap, "no_rank_gap", "No clear rank gap",
       "Record positions whose field directions differ more (spread over the sphere), and "
       "average longer per position to lower the noise."},
      {R::kNotAnEllipsoid, "not_an_ellipsoid", "The readings lie on no ellipsoid",
       "Estimate the sensor biases (bias: estimate, or record the static/moving layout), keep "
       "the field constant between positions, and average longer per position."},
      {R::kDeadSensor, "dead_sensor", "A sensor does not respond",
       "Check the sensor the message names (power, wiring, channel mapping), or remove it from "
       "the recording."},
      {R::kIllConditioned, "ill_conditioned", "Numbers out of range",
       "Check the units and range of the readings (convert raw counts to a sensible unit) and "
       "that the field was applied."},
      {R::kTooFewStatics, "too_few_statics", "Too few static intervals",
       "Hold the device still for a few seconds in more orientations (12 or more, spread over "
       "the sphere), turning it between them."},
      {R::kTooFewRotations, "too_few_rotations", "Too few rotations",
       "Join the static orientations by rotations: turn the device between every two statics, "
       "about every axis, and hold it still again."},
      {R::kNoDynamicPhase, "no_dynamic_phase", "No dynamic phase",
       "After the statics, rotate the board for a while (about every axis) before stopping the "
       "log."},
      {R::kUnknownNoise, "unknown_noise", "Noise levels unknown",
       "Set accel_noise and gyro_noise in the config (the statics show no noise)."},
      {R::kSingularInformation, "singular_information", "Some parameters are not determined",
       "Record statics spread over the sphere and rotate about every axis, so every parameter "
       "shows in the data."},
      {R::kImplausibleEstimate, "implausible_estimate", "Implausible estimate",
       "Check the config's units (accel_unit, gyro_unit: deg/s or rad/s), the time column and "
       "saturation; raise max_scale_deviation only for gains known roughly."},
      {R::kLogTooShort, "log_too_short", "The log is too short",
       "Record longer: the longest cluster time is a quarter of the log, so record four times "
       "the longest averaging time of interest."},
      {R::kIrregularSampling, "irregular_sampling", "Irregular sample times",
       "Split the log at its gaps or resample it to a uniform rate before uploading."},
      {R::kNotStationary, "not_stationary", "The sensor moved",
       "Record the sensor at rest and untouched (on a stable surface, away from vibration) for "
       "the whole log."},
      {R::kNoGyroscope, "no_gyroscope", "No gyroscope",
       "Record with at least one gyroscope triad (columns g0_x, g0_y, g0_z)."},
      {R::kTooFewTriads, "too_few_triads", "Too few accelerometer triads",
       "Mount at least 3 accelerometer triads that are not on one line."},
      {R::kTriadsCollinear, "triads_collinear", "Triads on one line",
       "Mount at least 3 triads that span a plane and give their nominal positions."},
      {R::kTooFewSamples, "too_few_samples", "Too few usable samples",
       "Record longer while rotating, below the gyroscopes' range."},
      {R::kWeakExcitation, "weak_excitation", "Weak excitation",
       "Rotate the array about every axis, briskly and in changing directions, not about one "
       "fixed axis only."},
      {R::kNumericalFailure, "numerical_failure", "The solver failed",
       "Check the noise settings and the recording's units; record with more motion."},
      {R::kImplausibleTimeUnit, "implausible_time_unit", "The time column is not in seconds",
       "Give the time column's unit in the config (time_unit: s, ms, us or ns), or convert it "
       "to seconds before uploading."},
      {R::kDeadline, "deadline", "The job ran out of time",
       "The job took longer than its time limit (--job-seconds, config job_seconds). Check that "
       "the recording is what the method expects (time unit, layout); shorten it, or ask the "
       "operator for a longer limit."},
      {R::kCancelled, "cancelled", "The job was cancelled",
       "Someone cancelled the job (POST /api/v1/jobs/{id}/cancel); rerun it if that was a "
       "mistake."},
      {R::kLeaseExpired, "lease_expired", "The job's worker stopped",
       "Upload again; if it recurs, the job may be too large for the server (ask the "
       "operator)."},
      {R::kStorageError, "storage_error", "Storage error",
       "Upload again later; the server could not read or write its database."},
      {R::kDiskFull, "disk_full", "The server's disk is full",
       "Ask the operator to free space where the database and its staging folder are; then "
       "upload again. Nothing of the failed request was stored."},
      {R::kStorageDamaged, "storage_damaged", "Stored data is damaged",
       "The database holds damaged bytes (see /healthz). Upload the original recording again to "
       "repair a damaged recording; the operator should restore the database from a backup."},
      {R::kInternal, "internal", "Internal error",
       "Report it to the operator with the job id: this is calibd's fault, not the data's."},
  };
  return c;
}

}  // namespace

const std::vector<FailureReason>& AllFailureReasons() {
  // Never destroyed (like every static of the server): a worker thread still failing a job while
  // the process exits must not read a destroyed catalog (found by fuzz_multipart under ASan:
  // exit() destroyed it before the fuzzer's atexit handler stopped the workers).
  static const std::vector<FailureReason>& catalog = *new std::vector<FailureReason>(MakeCatalog());
  return catalog;
}

const FailureReason& DescribeReason(Reason reason) {
  const std::vector<FailureReason>& all = AllFailureReasons();
  for (const FailureReason& r : all) {
    if (r.reason == reason) return r;
  }
  return *FindFailureReason("internal");
}

const FailureReason* FindFailureReason(std::string_view code) {
  for (const FailureReason& r : AllFailureReasons()) {
    if (code == r.code) return &r;
  }
  return nullptr;
}

Reason ReasonOf(const Status& s) {
  if (s.reason() != Reason::kUnspecified) return s.reason();
  switch (s.code()) {
    case StatusCode::kInvalidInput:
      return Reason::kInvalidRecording;
    case StatusCode::kNotDeterminable:
      return Reason::kNotDeterminable;
    case StatusCode::kTooLarge:
      return Reason::kOverMemoryBudget;
    case StatusCode::kCorruption:
      return Reason::kStorageDamaged;
    case StatusCode::kBusy:
    case StatusCode::kIoError:
      return Reason::kStorageError;
    default:
      return Reason::kInternal;
  }
}

Reason ReasonForErrorCode(std::string_view error_code) {
  if (const FailureReason* r = FindFailureReason(error_code)) return r->reason;
  if (error_code == "invalid_input") return Reason::kInvalidRecording;
  if (error_code == "not_determinable") return Reason::kNotDeterminable;
  if (error_code == "too_large") return Reason::kOverMemoryBudget;
  if (error_code == "corruption") return Reason::kStorageDamaged;
  if (error_code == "busy" || error_code == "io_error") return Reason::kStorageError;
  return Reason::kInternal;
}

const FailureReason& StoredFailureReason(std::string_view reason_code,
                                         std::string_view error_code) {
  if (const FailureReason* r = FindFailureReason(reason_code)) return *r;
  return DescribeReason(ReasonForErrorCode(error_code));
}

std::string PartialDiagnosticsText(const nlohmann::json& result, size_t max_bytes) {
  if (!result.is_object() || result.empty()) return "";
  // Only a run's own partial document (usable: false) is kept: a complete result that failed
  // later (storing it was busy, the gate threw) must not be shown as "before the failure".
  const auto usable = result.find("usable");
  if (usable == result.end() || !usable->is_boolean() || usable->get<bool>()) return "";
  auto dump = [](const nlohmann::json& j) {
    return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  };
  std::string text = dump(result);
  if (text.size() <= max_bytes) return text;
  const size_t full = text.size();
  nlohmann::json trimmed = result;
  nlohmann::json dropped = nlohmann::json::array();
  auto note = [&] {
    trimmed["trimmed"] = {
        {"bytes", full},
        {"dropped", dropped},
        {"note", "the partial diagnostics were " + std::to_string(full) + " bytes, more than the " +
                     std::to_string(max_bytes) + " kept; the largest were left out"}};
  };
  nlohmann::json* diagnostics =
      trimmed.contains("diagnostics") && trimmed["diagnostics"].is_object()
          ? &trimmed["diagnostics"]
          : nullptr;
  if (diagnostics != nullptr) {
    std::vector<std::pair<size_t, std::string>> sizes;
    for (auto it = diagnostics->begin(); it != diagnostics->end(); ++it) {
      sizes.emplace_back(dump(it.value()).size(), it.key());
    }
    std::sort(sizes.rbegin(), sizes.rend());
    for (const auto& [size, key] : sizes) {
      diagnostics->erase(key);  // absent, as the typed readers take a partial member they lack
      dropped.push_back(key);
      note();
      text = dump(trimmed);
      if (text.size() <= max_bytes) return text;
    }
  }
  nlohmann::json bare = {{"method", result.value("method", std::string())}, {"usable", false}};
  trimmed = std::move(bare);
  dropped = nlohmann::json::array({"diagnostics"});
  note();
  return dump(trimmed);
}

}  // namespace calibd::server
