// Sensor logs as flight controllers and robots write them (SPEC §9): PX4 ULog, ArduPilot
// DataFlash, ROS bags. Each reader turns one log into a SensorLog, a neutral list of streams of
// timed samples in SI units; formats/log_assembly.h then chooses the streams that form each IMU
// (config `streams`) and builds the recording the methods read.
//
// The contract every reader keeps:
//   - Recognition by content only (a magic number at offset 0; Sniff* functions).
//   - Each sample's own sampling time where the format has one (ULog `timestamp_sample`,
//     DataFlash `SampleUS`, a ROS header stamp), else the logging/record time; the stream says
//     which (`time_source`). Times are integers in ns on the log's own clock, not rebased.
//   - Values in SI: m/s² (kAccel), rad/s (kGyro), µT (kMag, converted from the format's gauss,
//     milligauss or tesla), °C (kTemperature). `unit` says what the format wrote.
//   - A log cut short (the last message incomplete: a power-off) is read up to its last whole
//     message and SensorLog::warnings names the byte offset of the cut. Damage inside a log (an
//     impossible size, a message of an undefined type, a bad chunk) is kInvalidInput naming the
//     byte offset and the message index; nothing is returned then.
//   - Bounded work and memory: SensorLogLimits; exceeding one is kInvalidInput naming it.
#ifndef CALIBD_FORMATS_SENSOR_LOG_H_
#define CALIBD_FORMATS_SENSOR_LOG_H_

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"

namespace calibd::server {

enum class StreamKind { kAccel, kGyro, kMag, kTemperature };
// "accelerometer", "gyroscope", "magnetometer", "temperature"
const char* StreamKindName(StreamKind kind);
// Values per sample: 3, or 1 for kTemperature.
int StreamDimension(StreamKind kind);

// One sensor's samples as the log holds them.
struct SensorStream {
  StreamKind kind = StreamKind::kAccel;
  // The format's name of the source: ULog topic ("sensor_accel"), DataFlash message ("IMU"),
  // ROS topic ("/imu/data"). With `instance` it names the stream in config `streams`
  // ("sensor_accel:1", "IMU:0", "/imu/data").
  std::string topic;
  int instance = 0;        // ULog multi_id, DataFlash instance `I`; -1 for bags (topics)
  int64_t device_id = -1;  // the format's device id where it has one (ULog device_id), else -1
  // Where the times come from: "timestamp_sample", "timestamp", "SampleUS", "TimeUS",
  // "header.stamp", "record time".
  std::string time_source;
  std::string unit;  // what the format wrote, before conversion: "m/s^2", "rad/s", "gauss", ...
  std::vector<int64_t> t_ns;   // N sample times, ns on the log's clock
  std::vector<double> values;  // N × StreamDimension(kind), row-major, SI (above)
  // A reader's note about this stream, shown with it ("already corrected by the autopilot:
  // sensor_combined", "logged at 5 Hz: raise the logging profile"); empty when none.
  std::string note;

  int64_t samples() const { return static_cast<int64_t>(t_ns.size()); }
  // "topic:instance" (ULog, DataFlash), or the topic alone when instance < 0 (bags set -1).
  std::string Name() const;
};

struct SensorLog {
  std::string format;  // "ulog", "dataflash", "rosbag1", "rosbag2", "mcap"
  std::vector<SensorStream> streams;
  // Things the user should know that do not stop the reading, e.g. "log cut at byte 1234567 in
  // the middle of a message (a power-off?): read up to there".
  std::vector<std::string> warnings;
};

struct SensorLogLimits {
  // More samples over all streams is an error (memory: ~32 B per 3-axis sample).
  int64_t max_samples = 200'000'000;
  // More bytes after decompression (ROS bag chunks) is an error (a decompression bomb).
  int64_t max_decompressed_bytes = int64_t{8} << 30;
};

// The formats recognised by content (SPEC §9). kUnknown covers calibd's CSV (the CSV parser
// decides) and anything else.
enum class LogFormat { kUnknown, kULog, kDataFlash, kRosBag1, kSqlite, kMcap };
// From the first bytes of a file (at least 16 when the file has them).
LogFormat SniffLogFormat(std::string_view head);

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_SENSOR_LOG_H_
