// The sensor-log readers by format (formats/log_readers.h).
#include "formats/log_readers.h"

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "formats/dataflash.h"
#include "formats/mcap.h"
#include "formats/rosbag1.h"
#include "formats/rosbag2_sqlite.h"
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

namespace {

// SQLite reads files: the .db3's bytes go to a private temporary file ($TMPDIR), read, removed.
Status ReadRosBag2Bytes(std::string_view bytes, const std::string& file_name,
                        const SensorLogLimits& limits, SensorLog* log) {
  const char* dir = std::getenv("TMPDIR");
  std::string path =
      std::string(dir != nullptr && *dir != '\0' ? dir : "/tmp") + "/calibd-db3-XXXXXX";
  const int fd = ::mkstemp(path.data());
  if (fd < 0) return Status::IoError("cannot create a temporary file to read the ROS 2 bag");
  size_t written = 0;
  while (written < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + written, bytes.size() - written);
    if (n <= 0) break;
    written += static_cast<size_t>(n);
  }
  ::close(fd);
  Status s = written == bytes.size()
                 ? ReadRosBag2Sqlite(path, file_name, limits, log)
                 : Status::IoError("cannot write a temporary file to read the ROS 2 bag");
  std::remove(path.c_str());
  return s;
}

}  // namespace

Status ReadSensorLog(LogFormat format, std::string_view bytes, const std::string& file_name,
                     const SensorLogLimits& limits, SensorLog* log) {
  *log = {};
  switch (format) {
    case LogFormat::kDataFlash:
      return ReadDataFlash(bytes, file_name, limits, log);
    case LogFormat::kULog:
      return ReadULog(bytes, file_name, limits, log);
    case LogFormat::kRosBag1:
      return ReadRosBag1(bytes, file_name, limits, log);
    case LogFormat::kMcap:
      return ReadMcap(bytes, file_name, limits, log);
    case LogFormat::kSqlite:
      return ReadRosBag2Bytes(bytes, file_name, limits, log);
    case LogFormat::kUnknown:
      break;
  }
  return Status::Internal("ReadSensorLog: not a sensor log (calibd's CSV goes to its parser)");
}

}  // namespace calibd::server
