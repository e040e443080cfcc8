// The catalog of failure reasons: for every calibd::Reason (base/status.h: the generic ones; a
// method's own through its Method::FailureReasons()) its stable snake_case code (stored with a
// failed job and answered in GET /api/v1/jobs/{id} "error.reason", a SPEC §5 extension: README
// "Failure reasons"), a short title and the generic advice (what to record or set instead). The one
// place advice comes from: the API, the CLI and the job page look it up here by code, and show the
// method's own message (what it found) beside it.
#ifndef CALIBD_SERVER_FAILURE_REASONS_H_
#define CALIBD_SERVER_FAILURE_REASONS_H_

#include <cstddef>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "methods/failure_reason.h"

namespace calibd::server {

// Every entry: the generic reasons in base/status.h's order, then each method's own in the
// registry's order (kUnspecified excluded). Codes are unique. Never empty.
const std::vector<FailureReason>& AllFailureReasons();

// The entry of `reason`; for kUnspecified (or an out-of-range value) the entry of `internal`.
const FailureReason& DescribeReason(Reason reason);

// The entry whose code is `code`, or null (a code written by a newer calibd, or none).
const FailureReason* FindFailureReason(std::string_view code);

// The reason of a failed calibration: s.reason() when set, else one derived from the code
// (kInvalidInput: invalid_recording, kNotDeterminable: not_determinable, kTooLarge:
// over_memory_budget, kBusy/kIoError: storage_error, kCorruption: storage_damaged, the rest:
// internal).
Reason ReasonOf(const Status& s);

// The reason stored with a job failed before reasons were stored (schema v3 and older) or by
// the store itself: from its error code ("lease_expired", "invalid_input", ...).
Reason ReasonForErrorCode(std::string_view error_code);

// The entry of a stored failure: its reason code when it is in the catalog, else the one its
// error code gives (ReasonForErrorCode).
const FailureReason& StoredFailureReason(std::string_view reason_code, std::string_view error_code);

// The partial diagnostics a failed Method::Run left in `result`, as stored with the job: the
// JSON text of the object ("" unless `result` is an object with "usable": false: a complete result
// whose storing or judging failed is not partial diagnostics). Over `max_bytes`, the
// largest members of result.diagnostics are left out, largest first, until it fits,
// and result.trimmed says so: {"bytes": the full size, "dropped": [their names], "note"}; when
// even that does not fit, only {"method", "usable", "trimmed"} is kept.
std::string PartialDiagnosticsText(const nlohmann::json& result, size_t max_bytes);

// The cap the worker applies (1 MiB).
inline constexpr size_t kMaxPartialDiagnosticsBytes = size_t{1} << 20;

}  // namespace calibd::server

#endif  // CALIBD_SERVER_FAILURE_REASONS_H_
