#include "server/failure_reasons.h"

#include <algorithm>
#include <cstddef>
#include <utility>

#include "methods/method.h"
#include "methods/registry.h"

namespace calibd::server {
namespace {

std::vector<FailureReason> MakeCatalog() {
  using R = Reason;
  const auto E = CatalogEntry;
  // Advice says what to record or set instead; the method's message (kept beside it) says what
  // it found. Keep the codes stable: they are stored with jobs and read by clients.
  std::vector<FailureReason> c = {
      E(R::kInvalidConfig, "Invalid config",
        "Correct the config key the message names (SPEC §3 lists the keys of each method) and "
        "upload again."),
      E(R::kInvalidRecording, "The recording cannot be used as given",
        "Check the recording against the config: its columns, units, number of sensors and "
        "time column (SPEC §2), then upload it again."),
      E(R::kRecordingUnreadable, "The recording does not parse",
        "Upload the recording in one of the SPEC §2 layouts: a header line, then one number per "
        "column on every row."),
      E(R::kOverMemoryBudget, "Over the memory budget per job",
        "Upload a shorter recording (fewer rows or columns), or ask the operator to raise "
        "--job-memory-mb."),
      E(R::kProblemTooLarge, "The problem is too large",
        "Calibrate fewer sensors or positions per job, or raise the size limits the message "
        "names if the server can afford it."),
      E(R::kNotDeterminable, "The data do not determine the parameters",
        "Record again following the method's recording instructions (README), with more "
        "positions or motion than the minimum."),
      E(R::kNoSignal, "No signal",
        "Check that the sensors were powered and the field (gravity, magnetic field) applied "
        "while recording; all readings are equal."),
      E(R::kTooFewPositions, "Too few positions",
        "Record more static positions: at least the minimum the message names, and better twice "
        "as many, spread over the sphere."),
      E(R::kPoorOrientationCoverage, "Orientations do not cover the sphere",
        "Hold the device still in orientations spread over the whole sphere (the six faces and "
        "the diagonals between them), not only about one axis or in one plane."),
      E(R::kNotAnEllipsoid, "The readings lie on no ellipsoid",
        "Keep the field constant while recording (away from iron, motors and cables), spread the "
        "orientations over the sphere, and let the fit estimate the biases where the method "
        "allows it (the message says how)."),
      E(R::kFieldDisturbed, "The field was disturbed",
        "Record again away from iron, motors, cables and vehicles, keeping the device in one "
        "place while turning it; the message names the disturbed spans."),
      E(R::kIllConditioned, "Numbers out of range",
        "Check the units and range of the readings (convert raw counts to a sensible unit) and "
        "that the field was applied."),
      E(R::kTooFewStatics, "Too few static intervals",
        "Hold the device still for a few seconds in more orientations (12 or more, spread over "
        "the sphere), turning it between them."),
      E(R::kUnknownNoise, "Noise levels unknown",
        "Set accel_noise and gyro_noise in the config (the statics show no noise)."),
      E(R::kSingularInformation, "Some parameters are not determined",
        "Record statics spread over the sphere and rotate about every axis, so every parameter "
        "shows in the data."),
      E(R::kImplausibleEstimate, "Implausible estimate",
        "Check the config's units (accel_unit, gyro_unit: deg/s or rad/s), the time column and "
        "saturation; raise max_scale_deviation only for gains known roughly."),
      E(R::kLogTooShort, "The log is too short",
        "Record longer: the longest cluster time is a quarter of the log, so record four times "
        "the longest averaging time of interest."),
      E(R::kNumericalFailure, "The solver failed",
        "Check the noise settings and the recording's units; record with more motion."),
      E(R::kImplausibleTimeUnit, "The time column is not in seconds",
        "Give the time column's unit in the config (time_unit: s, ms, us or ns), or convert it "
        "to seconds before uploading."),
      E(R::kDeadline, "The job ran out of time",
        "The job took longer than its time limit (--job-seconds, config job_seconds). Check that "
        "the recording is what the method expects (time unit, layout); shorten it, or ask the "
        "operator for a longer limit."),
      E(R::kCancelled, "The job was cancelled",
        "Someone cancelled the job (POST /api/v1/jobs/{id}/cancel); rerun it if that was a "
        "mistake."),
      E(R::kLeaseExpired, "The job's worker stopped",
        "Upload again; if it recurs, the job may be too large for the server (ask the "
        "operator)."),
      E(R::kStorageError, "Storage error",
        "Upload again later; the server could not read or write its database."),
      E(R::kDiskFull, "The server's disk is full",
        "Ask the operator to free space where the database and its staging folder are; then "
        "upload again. Nothing of the failed request was stored."),
      E(R::kStorageDamaged, "Stored data is damaged",
        "The database holds damaged bytes (see /healthz). Upload the original recording again to "
        "repair a damaged recording; the operator should restore the database from a backup."),
      E(R::kInternal, "Internal error",
        "Report it to the operator with the job id: this is calibd's fault, not the data's."),
  };
  for (const Method* m : AllMethods()) {
    for (const FailureReason& r : m->FailureReasons()) c.push_back(r);
  }
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
