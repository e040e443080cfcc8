// Sensor logs: the shared vocabulary of the log readers (formats/sensor_log.h).
#include "formats/sensor_log.h"

namespace calibd::server {

const char* StreamKindName(StreamKind kind) {
  switch (kind) {
    case StreamKind::kAccel:
      return "accelerometer";
    case StreamKind::kGyro:
      return "gyroscope";
    case StreamKind::kMag:
      return "magnetometer";
    case StreamKind::kTemperature:
      return "temperature";
  }
  return "accelerometer";
}

int StreamDimension(StreamKind kind) { return kind == StreamKind::kTemperature ? 1 : 3; }

std::string SensorStream::Name() const {
  if (instance < 0) return topic;
  return topic + ":" + std::to_string(instance);
}

namespace {
bool StartsWith(std::string_view head, std::string_view magic) {
  return head.size() >= magic.size() && head.substr(0, magic.size()) == magic;
}
}  // namespace

LogFormat SniffLogFormat(std::string_view head) {
  // ULog: "ULog" 0x01 0x12 0x35, then the version byte (PX4 dev guide, "ULog File Format").
  if (StartsWith(head, std::string_view("ULog\x01\x12\x35", 7))) return LogFormat::kULog;
  // DataFlash: every message starts 0xA3 0x95; the first is a FMT (type 128) message.
  if (StartsWith(head, std::string_view("\xA3\x95\x80", 3))) return LogFormat::kDataFlash;
  if (StartsWith(head, "#ROSBAG V2.0\n")) return LogFormat::kRosBag1;
  if (StartsWith(head, std::string_view("SQLite format 3\0", 16))) return LogFormat::kSqlite;
  if (StartsWith(head, std::string_view("\x89MCAP0\r\n", 8))) return LogFormat::kMcap;
  return LogFormat::kUnknown;
}

}  // namespace calibd::server
