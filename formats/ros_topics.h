// Samples of the ROS sensor messages calibd reads (sensor_msgs Imu, MagneticField, Temperature),
// gathered per topic by the bag readers (formats/rosbag1.h) and turned into SensorLog streams.
//
// Times: each message brings its header stamp and its record time (bag record time, MCAP
// log_time), both in ns. A topic uses its header stamps when every one of its messages has a
// non-zero stamp, else its record times (one clock per topic, never a mix); time_source says which.
#ifndef CALIBD_FORMATS_ROS_TOPICS_H_
#define CALIBD_FORMATS_ROS_TOPICS_H_

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "base/status.h"
#include "formats/sensor_log.h"

namespace calibd::server {

// The message types read; kOther topics are skipped.
enum class RosMessageType { kOther, kImu, kMagneticField, kTemperature };

// One decoded message, SI units of the message (m/s², rad/s, tesla, °C).
struct RosSample {
  int64_t stamp_ns = 0;   // header.stamp; 0 when the publisher left it unset
  int64_t record_ns = 0;  // the container's record time
  double accel[3] = {0, 0, 0};
  double gyro[3] = {0, 0, 0};
  bool has_accel = false;  // Imu: false when linear_acceleration_covariance[0] == -1 (ROS: absent)
  bool has_gyro = false;   // Imu: false when angular_velocity_covariance[0] == -1
  double mag_tesla[3] = {0, 0, 0};
  double temperature_c = 0;
};

// The fields after std_msgs/Header of the three message types, laid out alike in ROS 1 and in
// ROS 2's CDR: `Cursor` reads doubles in its encoding (F64() and F64s(out, n), with its own
// alignment rules). Returns false for kOther, else whether the cursor read them all (c.ok).
template <class Cursor>
bool ReadSensorFields(Cursor& c, RosMessageType type, RosSample* s) {
  double cov[9];
  switch (type) {
    case RosMessageType::kImu:
      c.F64s(cov, 4);  // orientation
      c.F64s(cov, 9);  // and its covariance
      c.F64s(s->gyro, 3);
      c.F64s(cov, 9);
      s->has_gyro = cov[0] != -1;
      c.F64s(s->accel, 3);
      c.F64s(cov, 9);
      s->has_accel = cov[0] != -1;
      break;
    case RosMessageType::kMagneticField:
      c.F64s(s->mag_tesla, 3);
      c.F64s(cov, 9);
      break;
    case RosMessageType::kTemperature:
      s->temperature_c = c.F64();
      c.F64();  // variance
      break;
    case RosMessageType::kOther:
      return false;
  }
  return c.ok;
}

// Collects samples topic by topic. Not thread-safe.
class RosTopicSamples {
 public:
  explicit RosTopicSamples(const SensorLogLimits& limits) : limits_(limits) {}
  // Adds one message of `type` on `topic`; kInvalidInput when SensorLogLimits::max_samples is
  // exceeded.
  Status Add(const std::string& topic, RosMessageType type, const RosSample& sample);
  // Appends the streams gathered (topics in name order; Imu gives kAccel then kGyro).
  void Finish(SensorLog* log);

 private:
  struct Topic {
    RosMessageType type = RosMessageType::kOther;
    std::vector<RosSample> samples;
  };
  SensorLogLimits limits_;
  int64_t total_ = 0;
  std::map<std::string, Topic> topics_;
};

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_ROS_TOPICS_H_
