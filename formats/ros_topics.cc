// Per-topic samples of ROS sensor messages to SensorLog streams (formats/ros_topics.h).
#include "formats/ros_topics.h"

#include <utility>

namespace calibd::server {

Status RosTopicSamples::Add(const std::string& topic, RosMessageType type,
                            const RosSample& sample) {
  if (type == RosMessageType::kOther) return Status::Ok();
  total_ += type == RosMessageType::kImu ? 2 : 1;
  if (total_ > limits_.max_samples) {
    return Status::InvalidInput("the log holds more than max_samples (" +
                                std::to_string(limits_.max_samples) + ") samples");
  }
  Topic& t = topics_[topic];
  t.type = type;
  t.samples.push_back(sample);
  return Status::Ok();
}

namespace {

// One stream of `kind` from the samples for which `take` is true; `value` writes its values.
template <typename Take, typename Value>
void AppendStream(const std::string& topic, StreamKind kind, const char* unit, bool use_stamp,
                  const std::vector<RosSample>& samples, Take take, Value value, SensorLog* log) {
  SensorStream s;
  s.kind = kind;
  s.topic = topic;
  s.instance = -1;
  s.unit = unit;
  s.time_source = use_stamp ? "header.stamp" : "record time";
  for (const RosSample& m : samples) {
    if (!take(m)) continue;
    s.t_ns.push_back(use_stamp ? m.stamp_ns : m.record_ns);
    value(m, &s.values);
  }
  if (!s.t_ns.empty()) log->streams.push_back(std::move(s));
}

void Push3(const double* v, double scale, std::vector<double>* out) {
  for (int i = 0; i < 3; ++i) out->push_back(v[i] * scale);
}

}  // namespace

void RosTopicSamples::Finish(SensorLog* log) {
  for (auto& [name, topic] : topics_) {
    bool use_stamp = true;
    for (const RosSample& m : topic.samples) use_stamp = use_stamp && m.stamp_ns != 0;
    const auto& samples = topic.samples;
    auto all = [](const RosSample&) { return true; };
    switch (topic.type) {
      case RosMessageType::kImu:
        AppendStream(
            name, StreamKind::kAccel, "m/s^2", use_stamp, samples,
            [](const RosSample& m) { return m.has_accel; },
            [](const RosSample& m, std::vector<double>* v) { Push3(m.accel, 1, v); }, log);
        AppendStream(
            name, StreamKind::kGyro, "rad/s", use_stamp, samples,
            [](const RosSample& m) { return m.has_gyro; },
            [](const RosSample& m, std::vector<double>* v) { Push3(m.gyro, 1, v); }, log);
        break;
      case RosMessageType::kMagneticField:
        AppendStream(
            name, StreamKind::kMag, "T", use_stamp, samples, all,
            [](const RosSample& m, std::vector<double>* v) { Push3(m.mag_tesla, 1e6, v); }, log);
        break;
      case RosMessageType::kTemperature:
        AppendStream(
            name, StreamKind::kTemperature, "degC", use_stamp, samples, all,
            [](const RosSample& m, std::vector<double>* v) { v->push_back(m.temperature_c); }, log);
        break;
      case RosMessageType::kOther:
        break;
    }
  }
  topics_.clear();
}

}  // namespace calibd::server
