// The HTML pages of SPEC §5, rendered from plain view structs that the server fills from storage.
//
// Each Render* function is pure (data in, a complete HTML5 document out), thread-safe, and never
// throws: a result JSON with missing keys or keys of the wrong type (old results, failed jobs)
// renders the parts it can and says "not available" for the rest. Every user-controlled string
// (device serials, sensor names, labels, error messages, config values) is escaped. Pages need no
// JavaScript, no external resources, and carry one small embedded stylesheet.
//
// DOM hooks for tests and browser checks (stable):
//   <body class="page-history | page-job | page-device | page-devices | page-error">
//   tables:  table.table-history, table.table-pca-parameters, table.table-array-parameters,
//            table.table-diagnostics, table.table-calibrations, table.table-drift-pca,
//            table.table-drift-array, table.table-timings, table.table-devices
//   plots:   svg.plot (every plot) plus svg.plot-NAME, NAME one of
//            pca:   singular-values, magnitude-error, residual-rms, axes-xy, axes-xz
//            array: cost, positions-xy, positions-xz, position-sigma, residual-rms,
//                   residual-histogram-accelerometer, residual-histogram-gyroscope (only when
//                   the result carries histograms), excitation-omega, excitation-omega-dot
//                   (only when it carries diagnostics.motion.omega_norm / omega_dot_norm)
//            device: drift-scale, drift-axis, drift-position (noise and imu drift: see
//            methods/noise/noise_drift.h and methods/imu/imu_drift.h)
//            (pca axes-xz only for d >= 3; array positions-* and position-sigma only when the
//            result has positions; the others are always present on a job with a result of
//            that method, saying "no data" when their keys are missing)
//   other:   form.filters, nav.pager a.older, form.cancel-job (queued or running job: posts
//            reason [and token] to /api/v1/jobs/{id}/cancel), span.elapsed (running job),
//            .callout-error .failure-reason (failed job: the method's message, the one source of
//            what was wrong and what to do instead; or pca diagnostics.usable == false), p.model
//            (the result's `model` equation), ul.warnings, ul.downloads, pre.config,
//            span.badge.badge-STATUS, table.table-drift-detail (inside <details>, per sensor /
//            triad), span.badge.badge-accepted-by-person (history, device page),
//            div.device-hint (history: the device filter read as a prefix, or nothing matched),
//            td[data-label] (history, device and devices tables: the column's name, shown on
//            narrow screens where a row's cells stack)
//
// Result keys read beyond SPEC §4 (all optional): pca diagnostics.usable, .reason, .noise_std
// (drawn as a line on the residual plot); array diagnostics.termination, .gyro_unit,
// .noise_configured{accelerometer,gyroscope}, .excitation.noise_floor,
// .motion{stride, omega_norm[], omega_dot_norm[]} (older results: omega_norm / omega_dot_norm
// directly in diagnostics; optional diagnostics.t or .time per sample for a time axis),
// .residual_histogram.{accelerometer,gyroscope} = {"edges": [...], "counts": [...]} or raw
// .residuals.{accelerometer,gyroscope} arrays. config.nominal (pca, m×d rows) gives the angle to
// nominal; config.geometry.positions (array) the nominal positions (else position − offset).
#ifndef CALIBD_WEB_PAGES_H_
#define CALIBD_WEB_PAGES_H_

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/job_state.h"

namespace calibd::web {

// A person's decision on a result (the acceptance gate's revoke/accept history).
struct JobEventSummary {
  std::string action;  // "revoke" | "accept" | "cancel"
  std::string reason;
  std::string actor;  // "token" | "anonymous"
  std::string at;     // ISO 8601 UTC
};

// One calibration job as stored (the fields of GET /api/v1/jobs/{id}).
struct JobSummary {
  int64_t id = 0;
  JobStatus status = JobStatus::kQueued;
  std::string device;       // serial number; may be empty (no device given)
  std::string method;       // the method's registered name
  std::string created_at;   // timestamps as stored: ISO 8601 UTC ("2026-11-22T04:04:04Z" or
  std::string started_at;   //   "2026-11-22 04:04:04", fractions allowed) or Unix seconds;
  std::string finished_at;  //   empty when not reached yet
  int attempts = 0;         // times a worker claimed it
  std::string error;        // failure message in plain words (failed jobs), else empty
  // A failed job's reason (server/failure_reasons.h): its code ("too_few_positions"), title and
  // the generic advice (what to record or set instead), looked up by code by the server; and the
  // partial diagnostics the method found before failing ({"method", "usable": false,
  // "diagnostics", "warnings"}; null when none). Empty/null for other jobs.
  std::string error_reason;
  std::string error_title;
  std::string error_advice;
  nlohmann::json error_detail;
  nlohmann::json result;  // SPEC §4 result JSON; null when none (queued/running/failed)
  // The acceptance gate (succeeded jobs): accepted | rejected | revoked; kNone: taken from
  // result.verdict.status (no verdict: accepted). Only accepted results are served and compared.
  ServeState state = ServeState::kNone;
  std::vector<JobEventSummary> events;  // decisions, oldest first (the report shows them)
};

// The gate's state of a job as the pages show it: kNone (not succeeded), accepted, rejected or
// revoked.
ServeState GateState(const JobSummary& job);

// Filters of the history page, echoed into its form. Empty: no filter.
struct HistoryFilter {
  std::string device;
  std::string method;
  std::optional<JobStatus> status;
  std::optional<ServeState> verdict;  // the acceptance gate's state
};

// `/` — the calibration history.
struct HistoryView {
  std::vector<JobSummary> jobs;  // one page, newest first (rendered in the given order);
                                 // result may be null to save memory (key figures then "–")
  HistoryFilter filter;
  std::vector<std::string> devices;  // optional: device serials offered in the form (some)
  std::vector<std::string> methods;  // offered in the form's method filter (the registry's)
  std::string next_before;  // cursor for the next (older) page; empty: no older page. The link
                            // is "/?before=CURSOR" plus the active filters.
  int64_t total = -1;       // total matching jobs when known (-1: unknown)
  // The device filter when no device has exactly the serial typed (MatchDevices): the devices
  // whose calibrations are listed instead and how many more matched than were used; when none
  // matched, the server's hint, shown as is ("no device 'x'; did you mean ..."). All empty: the
  // serial was exact (or no device filter). The page says which devices it shows, linking each.
  std::vector<std::string> device_matches;
  size_t device_more = 0;
  bool device_more_at_least = false;  // device_more is a lower bound (the search stopped there)
  std::string device_hint;
};

// How the history's device filter reads what was typed: the exact serial when a device in
// `known` has it (exact = true, devices = {typed}); otherwise every device whose serial starts
// with `typed` ignoring ASCII case (so "sn-00" finds "SN-0001" and "SN-0002"), in `known`'s
// order, at most `limit` of them (`more` counts the rest). Empty `typed`: no match at all.
struct DeviceMatch {
  bool exact = false;
  std::vector<std::string> devices;
  size_t more = 0;
};
DeviceMatch MatchDevices(const std::string& typed, const std::vector<std::string>& known,
                         size_t limit = 20);

// `/jobs/{id}` — one calibration report.
struct JobView {
  JobSummary job;
  int64_t recording_id = 0;      // 0: unknown (no recording link)
  std::string recording_sha256;  // optional
  int64_t recording_bytes = -1;  // optional (-1 unknown)
  int64_t recording_rows = -1;   // optional (-1 unknown)
  nlohmann::json config;         // the job's config (SPEC §3) as given; null when unknown
  // A running job: how long it has run (the server's clock: now - started_at); -1 unknown.
  int64_t elapsed_ms = -1;
  // Whether writes need the server's token: the cancel form then asks for it.
  bool token_required = false;
};

// `/devices/{serial}` — one device's calibrations and the drift between them.
struct DeviceView {
  std::string serial;
  std::vector<JobSummary> jobs;  // the device's jobs in any order (sorted by the page); results
                                 // of succeeded jobs are needed for the drift tables and plots
};

// `/devices` — every device with its latest calibration per method.
struct DevicesView {
  struct Latest {
    std::string method;
    int64_t job_id = 0;
    std::string calibrated_at;  // timestamp as stored (see JobSummary)
  };
  struct Device {
    std::string serial;
    std::string first_seen;      // timestamp as stored; may be empty
    std::vector<Latest> latest;  // one per method with a calibration, any order
  };
  std::vector<Device> devices;       // rendered in the given order
  std::vector<std::string> methods;  // one column each (the registry's)
  std::string next_after;  // "" = the last page; else the next page is /devices?after=<this>
};

// The devices page: table.table-devices, one row per device (serial linking to its page, first
// seen, per method the latest calibration's time linking to its report, and its JSON). Times are
// UTC, said in the column heads.
std::string RenderDevicesPage(const DevicesView& view);

// `/products/{product}?method=M` — a product's fleet (server/fleet.h's JSON, SPEC §10).
struct FleetView {
  std::string product;
  std::string method;
  std::vector<std::string> methods;  // the registry's, one link each
  nlohmann::json fleet;              // FleetJson's document
};

// The fleet page: the units flagged as outliers (device links, parameters, |z|), then
// table.table-fleet, one row per parameter (name, units, median, robust spread, range, a
// histogram as an inline SVG, the outlier units with their z), the members and the monthly
// medians' count. Every user-controlled string is escaped.
std::string RenderFleetPage(const FleetView& view);

// The plan page (/plan, SPEC §10): the form as the person filled it and the plan it gave.
struct PlanView {
  std::vector<std::string> methods;     // the registry's, in the select
  std::string method;                   // selected
  std::string config;                   // JSON text of the config
  std::string orientations;             // free text: names or [x, y, z], separated by spaces
  std::vector<std::string> checked;     // the candidate directions ticked
  std::vector<std::string> candidates;  // every candidate direction's name (the checkboxes)
  std::string static_duration, rate, rotation_duration;  // as typed
  std::string t_min, t_max, temperature_rate, imus;      // thermal's warm-up, as typed
  std::string angular_rate, angular_acceleration, rotation_axis, duration;  // array's motion
  std::string error;    // the plan's error message (empty: none)
  nlohmann::json plan;  // PlanJson's answer; null before the form is sent
};

// The plan page: form.plan-form (GET, works without JS), then, once sent, table.table-plan (the
// predicted σ, one row per quantity), ul.undetermined (what the protocol cannot determine), the
// suggested orientations (thermal: p.suggested-ramp, the warm-up; array: p.suggested-motion) with
// their σ, and svg.sphere: the protocol's and the suggestion's orientations on the unit sphere seen
// from +z and from −z. Every user-controlled string is escaped.
std::string RenderPlanPage(const PlanView& view);

// The history page: filter form (GET, works without JS), table.table-history (device link,
// method, status badge, created time, key figures, warnings flag), "older" pagination link.
std::string RenderHistoryPage(const HistoryView& view);

// The report of one job: header (device, method, recording download, config, timings, status;
// a running job's elapsed time, and for a queued or running job a Cancel form),
// the model equation, parameters with uncertainties, downloads, plots, diagnostics and warnings.
// A failed job instead: the reason's title and code, the method's message and the reason's
// advice (each once, div.callout-error), then section#partial with what the method found before
// failing (MethodReport::Partial) and the diagnostics table of the partial result.
std::string RenderJobPage(const JobView& view);

// One device: its calibrations over time and the drift of every parameter between successive
// succeeded calibrations of the same method (tables and plots).
std::string RenderDevicePage(const DeviceView& view);

// A plain error page (404, 500, ...) with the escaped message and a link back to the history.
std::string RenderErrorPage(int status, const std::string& message);

// Key figures of a result for tables: pca "σ(scale) ≤ 0.12 % · gap 85", array
// "offset RMS 812 µm · σ ≤ 2.1 µm", imu "|a|−g RMS 1.2 mm/s² · χ²/ν 1.03 · 24 statics", noise
// "accel N ≤ 2.0 mm/s²/√Hz · gyro N ≤ 120 µrad/s/√Hz"; "–" when not available. Plain text
// (escape before use).
std::string KeyFigures(const std::string& method, const nlohmann::json& result);

namespace internal {
// The links to a method's latest calibration in JSON and in each of its export formats, under
// `base` (".../calibration?format="): "JSON · CSV · C header".
std::string ExportLinks(const std::string& base, const std::string& method);
}  // namespace internal

}  // namespace calibd::web

#endif  // CALIBD_WEB_PAGES_H_
