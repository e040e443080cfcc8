// Routes of one stored recording beyond its metadata and data (SPEC §7):
//   GET /api/v1/recordings/{id}/segments?static_window=&min_static=&static_threshold=
//       &accel_unit=&gyro_unit=   the static intervals of an inertial log (JSON; 400 naming the
//       key for a bad option, 422 when the recording is not an inertial log, 404)
//   GET /recordings/{id}   the recording's HTML page (metadata, timeline with the statics shaded
//       and numbered, the jobs that used it, and with ?check=METHOD&<config keys> the check
//       before fitting of server/recording_check.h within `job_memory_bytes`)
#ifndef CALIBD_SERVER_RECORDING_ROUTES_H_
#define CALIBD_SERVER_RECORDING_ROUTES_H_

#include "server/http_util.h"
#include "storage/store.h"

namespace calibd::server {

class ColumnCache;  // server/column_cache.h

// `cache` (may be null): the parsed-columns cache /segments, the page and its check read from.
void RegisterRecordingRoutes(httplib::Server* http, storage::Store* store, int64_t job_memory_bytes,
                             ColumnCache* cache = nullptr);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_RECORDING_ROUTES_H_
