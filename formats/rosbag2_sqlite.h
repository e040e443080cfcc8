// ROS 2 bags in rosbag2's SQLite storage (.db3): the CDR-encoded sensor_msgs/msg Imu,
// MagneticField and Temperature messages as a SensorLog (formats/sensor_log.h, format
// "rosbag2"; SPEC §9).
//
// SQLite reads files, not memory: the caller hands a path (an upload is staged to a file first).
// The file is opened read-only; tables topics(id, name, type, serialization_format) and
// messages(topic_id, timestamp, data) are read in row order, messages of topics whose
// serialization_format is "cdr" and whose type is one of the three decoded by formats/cdr.h.
// Record time is the messages.timestamp column (ns). A file SQLite cannot read (cut, damaged, not
// a rosbag2 database) is kInvalidInput with SQLite's words; a message too short for its type is
// kInvalidInput naming its row.
#ifndef CALIBD_FORMATS_ROSBAG2_SQLITE_H_
#define CALIBD_FORMATS_ROSBAG2_SQLITE_H_

#include <string>

#include "base/status.h"
#include "formats/sensor_log.h"

namespace calibd::server {

// Reads the .db3 file at `path` into `*log` (replaced). `file_name` names it in messages.
// Thread-safe (one SQLite connection per call).
Status ReadRosBag2Sqlite(const std::string& path, const std::string& file_name,
                         const SensorLogLimits& limits, SensorLog* log);

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_ROSBAG2_SQLITE_H_
