// The sensor topics of a ULog turned into SensorStreams (formats/ulog.h lists which and how).
// Internal to the ULog reader: formats/ulog.cc frames the messages and feeds the 'D' data of
// each subscription here.
#ifndef CALIBD_FORMATS_ULOG_SENSORS_H_
#define CALIBD_FORMATS_ULOG_SENSORS_H_

#include <cstdint>
#include <map>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "base/status.h"
#include "formats/sensor_log.h"
#include "formats/ulog_definitions.h"

namespace calibd::server::ulog {

// The topics read, best source first within accel and within gyro.
enum class Topic { kAccelFifo, kGyroFifo, kAccel, kGyro, kCombined, kMag };

// Collects the samples of the sensor topics. Not thread-safe.
class SensorStreams {
 public:
  explicit SensorStreams(const SensorLogLimits& limits) : limits_(limits) {}

  // For an 'A' message subscribing `topic` (the format's name) as `multi_id` with `layout`:
  // the handle to pass to Add, or -1 when the topic is not one read here or its format lacks a
  // field the reader needs (then a warning is appended to *warnings, once per topic).
  int Subscribe(const std::string& topic, int multi_id, const Layout& layout,
                std::vector<std::string>* warnings);

  // One 'D' message of subscription `handle`: `data` holds at least the layout's min_size
  // bytes (the msg_id stripped). kInvalidInput, without location, for a value that cannot be
  // used (a time stamp beyond 2^63 ns, a fifo count beyond its arrays, a dt not finite or
  // negative) or when the samples exceed limits.max_samples.
  Status Add(int handle, const uint8_t* data);

  // Moves the chosen streams (formats/ulog.h) into log->streams, in the order accel, gyro, mag,
  // temperature, each by instance; sets time sources and notes.
  void Finish(SensorLog* log);

 private:
  // One stream being built: samples with times from `timestamp_sample` where the format has
  // it, and the same samples' times from `timestamp`, used if any timestamp_sample is zero.
  struct Builder {
    SensorStream stream;
    std::vector<int64_t> fallback_ns;
    bool sample_time = true;  // every message so far had a non-zero timestamp_sample
    bool device_set = false;
  };
  // A subscription: where the fields are, and the builders it feeds.
  struct Decoder {
    Topic topic = Topic::kAccel;
    FieldSlot timestamp, timestamp_sample, device_id, temperature;  // type kNested: absent
    FieldSlot x, y, z;                 // the values (fifo: int16 arrays)
    FieldSlot dt, scale, samples;      // fifo only
    FieldSlot gyro, accel, accel_rel;  // sensor_combined only
    Builder* values = nullptr;         // accel, gyro or mag (sensor_combined: its gyro)
    Builder* accel_values = nullptr;   // sensor_combined: its accelerometer
    Builder* temperatures = nullptr;   // when the format has `temperature`
  };

  // A message's times in ns: `timestamp`, and `timestamp_sample` where non-zero, else the same.
  struct MessageTime {
    int64_t published = 0;
    int64_t sampled = 0;
  };

  Builder* BuilderFor(Topic topic, int instance, StreamKind kind, bool sample_time);
  Status AddTriad(const Decoder& d, const uint8_t* data, MessageTime time);
  Status AddFifo(const Decoder& d, const uint8_t* data, MessageTime time);
  Status AddCombined(const Decoder& d, const uint8_t* data, MessageTime time);
  Status Count(int64_t samples);

  SensorLogLimits limits_;
  std::vector<Decoder> decoders_;
  std::map<std::pair<Topic, int>, int> handles_;  // decoders_ index by (topic, multi_id)
  // By (topic, instance, kind); std::map keeps the Builder addresses stable.
  std::map<std::tuple<Topic, int, StreamKind>, Builder> builders_;
  std::map<std::string, bool> warned_;
  int64_t total_samples_ = 0;
};

}  // namespace calibd::server::ulog

#endif  // CALIBD_FORMATS_ULOG_SENSORS_H_
