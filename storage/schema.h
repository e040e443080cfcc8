// The database schema and its forward-only migrations, versioned by PRAGMA user_version.
//
// Version history (the DDL of every version stays in schema.cc, so tests can build an old file
// and migrate it):
//   0  empty file
//   1  recordings (+ their bytes in recording_data), jobs with leases, result JSON inside jobs
//   2  retry back-off (jobs.not_before), results in their own table with a sha256 (ETag),
//      devices and the latest calibration per device and method, lease index
//   3  the acceptance gate: results.verdict (the gate's, from the result JSON), results.decision
//      (a person's revoke/accept), job_events (who/when/why); device_calibrations holds the
//      latest served (accepted, not revoked) result
//   4  failure reasons: jobs.error_reason (the reason code of a failure) and
//      jobs.error_detail_json (the partial diagnostics of a failed calibration)
//   5  stopping jobs: a running job's cancel request (jobs.cancel_requested_at, cancel_reason,
//      cancel_actor) and the job_events action 'cancel'
//   6  "latest" without host clocks: results.seq, the order results were stored in (unique),
//      which picks a device's latest served result instead of finished_at
//   7  lists: results_by_state, results by their standing, read by ?verdict= listings
//
// Thread-safety: functions take a Db the caller owns (one thread at a time).
#ifndef CALIBD_STORAGE_SCHEMA_H_
#define CALIBD_STORAGE_SCHEMA_H_

#include <cstdint>

#include "core/status.h"
#include "storage/db.h"

namespace calibd::storage {

inline constexpr int kSchemaVersion = 8;

// Reads PRAGMA user_version.
Status SchemaVersion(Db* db, int64_t* version);

// Brings the schema from its current version up to `target` (default: the latest), all steps in
// one BEGIN IMMEDIATE transaction, so a crash or a concurrent opener sees either the old or the
// new schema, and two processes opening one file at once migrate it once. Forward only: a file at
// a higher version than `target` is left alone; one newer than this build knows (kSchemaVersion)
// fails with kConflict. Errors: kBusy, kIoError (e.g. read-only file), kCorruption.
Status MigrateSchema(Db* db, int target = kSchemaVersion);

}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_SCHEMA_H_
