// The sensor-log readers by format (formats/log_readers.h).
#include "formats/log_readers.h"

#include "formats/dataflash.h"
#include "formats/ulog.h"

namespace calibd::server {

const char* LogFormatName(LogFormat format) {
  switch (format) {
    case LogFormat::kULog:
      return "ulog";
    case LogFormat::kDataFlash:
      return "dataflash";
    case LogFormat::kRosBag1:
      return "rosbag1";
    case LogFormat::kSqlite:
      return "rosbag2";
    case LogFormat::kMcap:
      return "mcap";
    case LogFormat::kUnknown:
      break;
  }
  return "csv";
}

Status ReadSensorLog(LogFormat format, std::string_view bytes, const std::string& file_name,
                     const SensorLogLimits& limits, SensorLog* log) {
  *log = {};
  switch (format) {
    case LogFormat::kDataFlash:
      return ReadDataFlash(bytes, file_name, limits, log);
    case LogFormat::kULog:
      return ReadULog(bytes, file_name, limits, log);
    default:
      break;
  }
  return Status::InvalidInput(std::string("this looks like a ") + LogFormatName(format) +
                              " log (by its first bytes), which this calibd cannot read yet")
      .WithFile(file_name);
}

}  // namespace calibd::server
