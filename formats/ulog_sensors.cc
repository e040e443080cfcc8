// ULog sensor topics to SensorStreams (formats/ulog_sensors.h).
#include "formats/ulog_sensors.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

namespace calibd::server::ulog {

namespace {

constexpr double kMicroteslaPerGauss = 100;
// µs beyond this do not fit int64 ns.
constexpr uint64_t kMaxMicros = uint64_t{std::numeric_limits<int64_t>::max()} / 1000;
// sensor_combined's accelerometer_timestamp_relative when there is no accelerometer sample.
constexpr int64_t kRelativeTimestampInvalid = 0x7fffffff;
// sensor_accel / sensor_gyro at or below this rate get a note (PX4's default profile: 1-10 Hz).
constexpr double kLowRateHz = 50;

struct TopicName {
  const char* name;
  Topic topic;
};
constexpr TopicName kTopics[] = {
    {"sensor_accel_fifo", Topic::kAccelFifo}, {"sensor_gyro_fifo", Topic::kGyroFifo},
    {"sensor_accel", Topic::kAccel},          {"sensor_gyro", Topic::kGyro},
    {"sensor_combined", Topic::kCombined},    {"sensor_mag", Topic::kMag},
};

const char* NameOf(Topic topic) {
  for (const TopicName& t : kTopics)
    if (t.topic == topic) return t.name;
  return "";
}

template <typename T>
T Load(const uint8_t* p) {
  T value;
  std::memcpy(&value, p, sizeof value);  // little-endian hosts only (static_assert in ulog.cc)
  return value;
}

// A basic-typed value as a double (integers exactly up to 2^53).
double ReadReal(const uint8_t* p, BasicType type) {
  switch (type) {
    case BasicType::kInt8:
      return Load<int8_t>(p);
    case BasicType::kUInt8:
    case BasicType::kBool:
    case BasicType::kChar:
      return Load<uint8_t>(p);
    case BasicType::kInt16:
      return Load<int16_t>(p);
    case BasicType::kUInt16:
      return Load<uint16_t>(p);
    case BasicType::kInt32:
      return Load<int32_t>(p);
    case BasicType::kUInt32:
      return Load<uint32_t>(p);
    case BasicType::kInt64:
      return static_cast<double>(Load<int64_t>(p));
    case BasicType::kUInt64:
      return static_cast<double>(Load<uint64_t>(p));
    case BasicType::kFloat:
      return Load<float>(p);
    case BasicType::kDouble:
      return Load<double>(p);
    case BasicType::kNested:
      break;
  }
  return 0;
}

// An integer-typed value (negative signed values are returned as such).
int64_t ReadInteger(const uint8_t* p, BasicType type) {
  switch (type) {
    case BasicType::kInt64:
      return Load<int64_t>(p);
    case BasicType::kUInt64: {
      const uint64_t v = Load<uint64_t>(p);
      return v > uint64_t{std::numeric_limits<int64_t>::max()} ? std::numeric_limits<int64_t>::max()
                                                               : static_cast<int64_t>(v);
    }
    default: {
      // Integers of 32 bits or less convert exactly; a floating type (never passed) saturates.
      const double v = ReadReal(p, type);
      return std::isfinite(v) && std::abs(v) < 9e18 ? static_cast<int64_t>(v) : 0;
    }
  }
}

bool IsInteger(BasicType type) {
  return type != BasicType::kFloat && type != BasicType::kDouble && type != BasicType::kNested;
}

// A µs time stamp field → ns; kInvalidInput when negative or beyond int64 ns.
Status ReadMicros(const uint8_t* data, const FieldSlot& slot, const char* name, int64_t* ns) {
  const int64_t us = ReadInteger(data + slot.offset, slot.type);
  if (us < 0 || static_cast<uint64_t>(us) > kMaxMicros)
    return Status::InvalidInput(std::string(name) + " " + std::to_string(us) +
                                " µs is outside 0 to 2^63 ns");
  *ns = us * 1000;
  return Status::Ok();
}

// Finds top-level field `name` with a basic type, scalar (min_array 0) or an array of at
// least min_array elements; adds its name to *missing when absent or of another shape.
FieldSlot Require(const Layout& layout, const char* name, int64_t min_array, std::string* missing) {
  const FieldSlot* slot = layout.Find(name);
  const bool fits =
      slot != nullptr && (min_array == 0 ? slot->array == 0 : slot->array >= min_array);
  if (fits) return *slot;
  *missing += std::string(missing->empty() ? "" : ", ") + name;
  return FieldSlot{};
}

FieldSlot Optional(const Layout& layout, const char* name) {
  const FieldSlot* slot = layout.Find(name);
  return slot != nullptr && slot->array == 0 ? *slot : FieldSlot{};
}

bool Present(const FieldSlot& slot) { return slot.type != BasicType::kNested; }

StreamKind KindOf(Topic topic) {
  switch (topic) {
    case Topic::kAccelFifo:
    case Topic::kAccel:
      return StreamKind::kAccel;
    case Topic::kMag:
      return StreamKind::kMag;
    default:
      return StreamKind::kGyro;  // the gyro topics, and sensor_combined's first stream
  }
}

const char* UnitOf(StreamKind kind) {
  switch (kind) {
    case StreamKind::kAccel:
      return "m/s^2";
    case StreamKind::kGyro:
      return "rad/s";
    case StreamKind::kMag:
      return "gauss";
    case StreamKind::kTemperature:
      return "degC";
  }
  return "";
}

}  // namespace

SensorStreams::Builder* SensorStreams::BuilderFor(Topic topic, int instance, StreamKind kind,
                                                  bool sample_time) {
  Builder& b = builders_[{topic, instance, kind}];
  if (b.stream.topic.empty()) {
    b.stream.kind = kind;
    b.stream.topic = NameOf(topic);
    b.stream.instance = instance;
    b.stream.unit = UnitOf(kind);
  }
  // A later subscription of the same stream without timestamp_sample: times from `timestamp`.
  b.sample_time = b.sample_time && sample_time;
  return &b;
}

int SensorStreams::Subscribe(const std::string& topic_name, int multi_id, const Layout& layout,
                             std::vector<std::string>* warnings) {
  const TopicName* found = nullptr;
  for (const TopicName& t : kTopics)
    if (topic_name == t.name) found = &t;
  if (found == nullptr) return -1;
  // The layout of a name never changes (ulog::Definitions): one decoder per topic and instance.
  auto known = handles_.find({found->topic, multi_id});
  if (known != handles_.end()) return known->second;
  Decoder d;
  d.topic = found->topic;
  std::string missing;
  d.timestamp = Require(layout, "timestamp", 0, &missing);
  if (Present(d.timestamp) && !IsInteger(d.timestamp.type)) missing = "an integer timestamp";
  d.timestamp_sample = Optional(layout, "timestamp_sample");
  if (!IsInteger(d.timestamp_sample.type)) d.timestamp_sample = FieldSlot{};
  d.device_id = Optional(layout, "device_id");
  if (!IsInteger(d.device_id.type)) d.device_id = FieldSlot{};
  d.temperature = Optional(layout, "temperature");
  const bool fifo = d.topic == Topic::kAccelFifo || d.topic == Topic::kGyroFifo;
  if (d.topic == Topic::kCombined) {
    d.gyro = Require(layout, "gyro_rad", 3, &missing);
    d.accel = Require(layout, "accelerometer_m_s2", 3, &missing);
    d.accel_rel = Optional(layout, "accelerometer_timestamp_relative");
    if (!IsInteger(d.accel_rel.type)) d.accel_rel = FieldSlot{};
  } else {
    const int64_t array = fifo ? 1 : 0;
    d.x = Require(layout, "x", array, &missing);
    d.y = Require(layout, "y", array, &missing);
    d.z = Require(layout, "z", array, &missing);
  }
  if (fifo) {
    d.dt = Require(layout, "dt", 0, &missing);
    d.scale = Require(layout, "scale", 0, &missing);
    d.samples = Require(layout, "samples", 0, &missing);
    if (Present(d.samples) && !IsInteger(d.samples.type))
      missing += std::string(missing.empty() ? "" : ", ") + "an integer samples";
  }
  if (!missing.empty()) {
    if (!warned_[topic_name])
      warnings->push_back(topic_name + " not read: its format (" + topic_name + ") lacks " +
                          missing);
    warned_[topic_name] = true;
    handles_[{found->topic, multi_id}] = -1;
    return -1;
  }
  const bool sample_time = Present(d.timestamp_sample);
  d.values = BuilderFor(d.topic, multi_id, KindOf(d.topic), sample_time);
  if (d.topic == Topic::kCombined)
    d.accel_values = BuilderFor(d.topic, multi_id, StreamKind::kAccel, false);
  if (Present(d.temperature))
    d.temperatures = BuilderFor(d.topic, multi_id, StreamKind::kTemperature, sample_time);
  decoders_.push_back(d);
  const int handle = static_cast<int>(decoders_.size()) - 1;
  handles_[{found->topic, multi_id}] = handle;
  return handle;
}

Status SensorStreams::Count(int64_t samples) {
  total_samples_ += samples;
  if (total_samples_ > limits_.max_samples)
    return Status::InvalidInput("the log holds more than " + std::to_string(limits_.max_samples) +
                                " sensor samples (the limit max_samples)");
  return Status::Ok();
}

Status SensorStreams::Add(int handle, const uint8_t* data) {
  const Decoder& d = decoders_[handle];
  int64_t published = 0, sampled = 0;
  Status status = ReadMicros(data, d.timestamp, "timestamp", &published);
  if (!status.ok()) return status;
  if (Present(d.timestamp_sample)) {
    status = ReadMicros(data, d.timestamp_sample, "timestamp_sample", &sampled);
    if (!status.ok()) return status;
  }
  const MessageTime time{published, sampled != 0 ? sampled : published};
  for (Builder* b : {d.values, d.temperatures}) {
    if (b == nullptr) continue;
    if (sampled == 0) b->sample_time = false;
    if (!b->device_set && Present(d.device_id)) {
      b->stream.device_id = ReadInteger(data + d.device_id.offset, d.device_id.type);
      b->device_set = true;
    }
  }
  if (d.temperatures != nullptr) {
    const double celsius = ReadReal(data + d.temperature.offset, d.temperature.type);
    if (std::isfinite(celsius)) {
      status = Count(1);
      if (!status.ok()) return status;
      d.temperatures->stream.t_ns.push_back(time.sampled);
      d.temperatures->fallback_ns.push_back(time.published);
      d.temperatures->stream.values.push_back(celsius);
    }
  }
  switch (d.topic) {
    case Topic::kAccelFifo:
    case Topic::kGyroFifo:
      return AddFifo(d, data, time);
    case Topic::kCombined:
      return AddCombined(d, data, time);
    default:
      return AddTriad(d, data, time);
  }
}

// sensor_accel, sensor_gyro, sensor_mag: one reading per message.
Status SensorStreams::AddTriad(const Decoder& d, const uint8_t* data, MessageTime time) {
  Status status = Count(1);
  if (!status.ok()) return status;
  const double scale = d.topic == Topic::kMag ? kMicroteslaPerGauss : 1;
  Builder* b = d.values;
  b->stream.t_ns.push_back(time.sampled);
  b->fallback_ns.push_back(time.published);
  for (const FieldSlot* axis : {&d.x, &d.y, &d.z})
    b->stream.values.push_back(ReadReal(data + axis->offset, axis->type) * scale);
  return Status::Ok();
}

// sensor_accel_fifo, sensor_gyro_fifo: `samples` readings x[i]·scale, dt µs apart, the last at
// the message's time.
Status SensorStreams::AddFifo(const Decoder& d, const uint8_t* data, MessageTime time) {
  const int64_t n = ReadInteger(data + d.samples.offset, d.samples.type);
  const int64_t capacity = std::min({d.x.array, d.y.array, d.z.array});
  if (n < 0 || n > capacity)
    return Status::InvalidInput("samples = " + std::to_string(n) + " but the arrays x, y, z hold " +
                                std::to_string(capacity));
  const double dt_us = ReadReal(data + d.dt.offset, d.dt.type);
  if (!std::isfinite(dt_us) || dt_us < 0 || dt_us > 1e9)
    return Status::InvalidInput("dt = " + std::to_string(dt_us) + " µs is not a sample interval");
  const double scale = ReadReal(data + d.scale.offset, d.scale.type);
  Status status = Count(n);
  if (!status.ok()) return status;
  const int size = BasicTypeSize(d.x.type);
  Builder* b = d.values;
  for (int64_t i = 0; i < n; ++i) {
    const int64_t back = std::llround(static_cast<double>(n - 1 - i) * dt_us * 1000);
    b->stream.t_ns.push_back(time.sampled - back);
    b->fallback_ns.push_back(time.published - back);
    for (const FieldSlot* axis : {&d.x, &d.y, &d.z})
      b->stream.values.push_back(ReadReal(data + axis->offset + i * size, axis->type) * scale);
  }
  return Status::Ok();
}

// sensor_combined: gyro_rad at `timestamp`, accelerometer_m_s2 at timestamp +
// accelerometer_timestamp_relative (left out when that says "invalid").
Status SensorStreams::AddCombined(const Decoder& d, const uint8_t* data, MessageTime time) {
  const int64_t published = time.published;
  int64_t relative = 0;
  if (Present(d.accel_rel)) relative = ReadInteger(data + d.accel_rel.offset, d.accel_rel.type);
  const bool accel_valid = relative != kRelativeTimestampInvalid;
  Status status = Count(accel_valid ? 2 : 1);
  if (!status.ok()) return status;
  const int size = BasicTypeSize(d.gyro.type);
  d.values->stream.t_ns.push_back(published);
  d.values->fallback_ns.push_back(published);
  for (int k = 0; k < 3; ++k)
    d.values->stream.values.push_back(ReadReal(data + d.gyro.offset + k * size, d.gyro.type));
  if (!accel_valid) return Status::Ok();
  const int accel_size = BasicTypeSize(d.accel.type);
  int64_t relative_ns = 0, t = 0;  // PX4 writes an int32, a format may declare any integer
  if (__builtin_mul_overflow(relative, 1000, &relative_ns) ||
      __builtin_add_overflow(published, relative_ns, &t))
    return Status::InvalidInput("accelerometer_timestamp_relative puts the sample beyond 2^63 ns");
  d.accel_values->stream.t_ns.push_back(t);
  d.accel_values->fallback_ns.push_back(t);
  for (int k = 0; k < 3; ++k)
    d.accel_values->stream.values.push_back(
        ReadReal(data + d.accel.offset + k * accel_size, d.accel.type));
  return Status::Ok();
}

void SensorStreams::Finish(SensorLog* log) {
  // The best source per kind: the first topic (in Topic order) with samples of that kind.
  std::map<StreamKind, Topic> chosen;
  for (auto& [key, b] : builders_) {
    const auto& [topic, instance, kind] = key;
    if (b.stream.samples() == 0 || kind == StreamKind::kTemperature) continue;
    auto it = chosen.find(kind);
    if (it == chosen.end() || topic < it->second) chosen[kind] = topic;
  }
  for (StreamKind kind :
       {StreamKind::kAccel, StreamKind::kGyro, StreamKind::kMag, StreamKind::kTemperature}) {
    for (auto& [key, b] : builders_) {
      const auto& [topic, instance, stream_kind] = key;
      if (stream_kind != kind || b.stream.samples() == 0) continue;
      if (kind != StreamKind::kTemperature && chosen[kind] != topic) continue;
      SensorStream& s = b.stream;
      const bool sample_time = b.sample_time && topic != Topic::kCombined;
      if (!sample_time) s.t_ns.swap(b.fallback_ns);
      s.time_source = sample_time ? "timestamp_sample" : "timestamp";
      if (topic == Topic::kCombined && kind == StreamKind::kAccel)
        s.time_source = "timestamp + accelerometer_timestamp_relative";
      // In double: times of a damaged log may span more than int64 holds.
      const double span = static_cast<double>(s.t_ns.back()) - static_cast<double>(s.t_ns.front());
      const double rate = span > 0 ? (s.samples() - 1) * 1e9 / span : 0;
      char hz[32];
      std::snprintf(hz, sizeof hz, "%.3g", rate);
      const std::string logged = span > 0 ? "logged at " + std::string(hz) + " Hz"
                                          : "logged " + std::to_string(s.samples()) + " time(s)";
      if ((topic == Topic::kAccel || topic == Topic::kGyro) && kind != StreamKind::kTemperature &&
          rate <= kLowRateHz)
        s.note = logged + ": PX4 logs " + s.topic +
                 " at 1–10 Hz unless the logging profile is raised (SDLOG_PROFILE high rate or "
                 "sensor comparison)";
      if (topic == Topic::kCombined)
        s.note =
            "already corrected by the autopilot's calibration (sensor_combined): the raw "
            "sensor_accel/sensor_gyro topics were not logged";
      log->streams.push_back(std::move(s));
    }
  }
  builders_.clear();
  decoders_.clear();
  handles_.clear();
}

}  // namespace calibd::server::ulog
