// The sensor-log readers by format (SPEC §9): one entry point for the recording parser, so a
// new reader is one case here.
#ifndef CALIBD_FORMATS_LOG_READERS_H_
#define CALIBD_FORMATS_LOG_READERS_H_

#include <string>
#include <string_view>

#include "base/status.h"
#include "formats/sensor_log.h"

namespace calibd::server {

// "ulog", "dataflash", "rosbag1", "rosbag2" (the SQLite storage), "mcap"; "csv" for kUnknown.
const char* LogFormatName(LogFormat format);

// Reads a whole log of a recognised format (SniffLogFormat; not kUnknown). kInvalidInput naming
// the file, the byte offset and what is wrong for a damaged log.
Status ReadSensorLog(LogFormat format, std::string_view bytes, const std::string& file_name,
                     const SensorLogLimits& limits, SensorLog* log);

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_LOG_READERS_H_
