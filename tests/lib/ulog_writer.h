// A small PX4 ULog writer for tests, the fuzz seed corpus and the benchmark (header-only):
// messages byte by byte as the format defines them (PX4 dev guide, "ULog File Format"), so that
// tests can build edge cases (nested types, padding, appended data, damage) the reader must meet.
#ifndef CALIBD_TESTS_LIB_ULOG_WRITER_H_
#define CALIBD_TESTS_LIB_ULOG_WRITER_H_

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace calibd::testing {

// Little-endian packed fields appended to a string.
class Packer {
 public:
  template <typename T>
  Packer& Put(T value) {
    char raw[sizeof(T)];
    std::memcpy(raw, &value, sizeof(T));  // little-endian hosts (as the reader)
    bytes_.append(raw, sizeof(T));
    return *this;
  }
  Packer& Bytes(const std::string& bytes) {
    bytes_ += bytes;
    return *this;
  }
  Packer& Zeros(size_t n) {
    bytes_.append(n, '\0');
    return *this;
  }
  const std::string& str() const { return bytes_; }

 private:
  std::string bytes_;
};

// PX4's formats of the sensor topics (as of v1.14; the fifo's trailing padding left in to test
// short 'D' messages).
inline const char kSensorAccelFormat[] =
    "sensor_accel:uint64_t timestamp;uint64_t timestamp_sample;uint32_t device_id;float x;"
    "float y;float z;float temperature;uint32_t error_count;uint8_t[3] clip_counter;"
    "uint8_t samples;uint8_t[4] _padding0;";
inline const char kSensorGyroFormat[] =
    "sensor_gyro:uint64_t timestamp;uint64_t timestamp_sample;uint32_t device_id;float x;"
    "float y;float z;float temperature;uint32_t error_count;uint8_t[3] clip_counter;"
    "uint8_t samples;uint8_t[4] _padding0;";
inline const char kSensorMagFormat[] =
    "sensor_mag:uint64_t timestamp;uint64_t timestamp_sample;uint32_t device_id;float x;"
    "float y;float z;float temperature;uint32_t error_count;bool is_external;"
    "uint8_t[7] _padding0;";
// Fifo topics: int16 x[32], y[32], z[32] readings times `scale`, `dt` µs apart.
inline const char kSensorAccelFifoFormat[] =
    "sensor_accel_fifo:uint64_t timestamp;uint64_t timestamp_sample;uint32_t device_id;"
    "float dt;float scale;uint8_t samples;int16_t[32] x;int16_t[32] y;int16_t[32] z;"
    "uint8_t[3] _padding0;";
inline const char kSensorGyroFifoFormat[] =
    "sensor_gyro_fifo:uint64_t timestamp;uint64_t timestamp_sample;uint32_t device_id;"
    "float dt;float scale;uint8_t samples;int16_t[32] x;int16_t[32] y;int16_t[32] z;"
    "uint8_t[3] _padding0;";
inline const char kSensorCombinedFormat[] =
    "sensor_combined:uint64_t timestamp;float[3] gyro_rad;uint32_t gyro_integral_dt;"
    "int32_t accelerometer_timestamp_relative;float[3] accelerometer_m_s2;"
    "uint32_t accelerometer_integral_dt;uint8_t accelerometer_clipping;uint8_t[3] _padding0;";

// The data of a sensor_accel / sensor_gyro / sensor_mag message (layouts above), without the
// trailing padding as PX4 writes it.
inline std::string TriadData(uint64_t timestamp, uint64_t timestamp_sample, uint32_t device_id,
                             float x, float y, float z, float temperature, bool mag = false) {
  Packer p;
  p.Put(timestamp).Put(timestamp_sample).Put(device_id).Put(x).Put(y).Put(z).Put(temperature);
  p.Put(uint32_t{0});
  if (mag) return p.Put(uint8_t{0}).str();
  return p.Zeros(3).Put(uint8_t{1}).str();
}

// The data of a fifo message: readings[i] = {x, y, z} counts.
inline std::string FifoData(uint64_t timestamp, uint64_t timestamp_sample, uint32_t device_id,
                            float dt_us, float scale,
                            const std::vector<std::vector<int16_t>>& readings) {
  Packer p;
  p.Put(timestamp).Put(timestamp_sample).Put(device_id).Put(dt_us).Put(scale);
  p.Put(static_cast<uint8_t>(readings.size()));
  for (int axis = 0; axis < 3; ++axis)
    for (size_t i = 0; i < 32; ++i)
      p.Put(static_cast<int16_t>(i < readings.size() ? readings[i][axis] : 0));
  return p.str();
}

inline std::string CombinedData(uint64_t timestamp, const float gyro[3], int32_t accel_relative,
                                const float accel[3]) {
  Packer p;
  p.Put(timestamp).Put(gyro[0]).Put(gyro[1]).Put(gyro[2]).Put(uint32_t{4000});
  p.Put(accel_relative).Put(accel[0]).Put(accel[1]).Put(accel[2]).Put(uint32_t{4000});
  return p.Put(uint8_t{0}).str();
}

// Builds a ULog file in memory: the header at construction, then messages in call order.
class ULogWriter {
 public:
  explicit ULogWriter(uint64_t start_us = 1000, uint8_t version = 1) {
    bytes_ = std::string("ULog\x01\x12\x35", 7);
    bytes_ += static_cast<char>(version);
    bytes_ += Packer().Put(start_us).str();
  }
  // Any message: the 3-byte header and the payload.
  ULogWriter& Message(char type, const std::string& payload) {
    bytes_ += Packer().Put(static_cast<uint16_t>(payload.size())).str();
    bytes_ += type;
    bytes_ += payload;
    return *this;
  }
  // 'B' with incompat_flags[0] = incompat0 and up to three appended-data offsets.
  ULogWriter& FlagBits(uint8_t incompat0, std::vector<uint64_t> offsets = {}) {
    Packer p;
    p.Zeros(8).Put(incompat0).Zeros(7);
    offsets.resize(3, 0);
    for (uint64_t offset : offsets) p.Put(offset);
    return Message('B', p.str());
  }
  ULogWriter& Format(const std::string& text) { return Message('F', text); }
  ULogWriter& Info(const std::string& key, const std::string& value) {
    return Message('I', Packer().Put(static_cast<uint8_t>(key.size())).Bytes(key + value).str());
  }
  ULogWriter& Subscribe(uint8_t multi_id, uint16_t msg_id, const std::string& name) {
    return Message('A', Packer().Put(multi_id).Put(msg_id).Bytes(name).str());
  }
  ULogWriter& Unsubscribe(uint16_t msg_id) { return Message('R', Packer().Put(msg_id).str()); }
  ULogWriter& Data(uint16_t msg_id, const std::string& data) {
    return Message('D', Packer().Put(msg_id).Bytes(data).str());
  }
  ULogWriter& Text(uint64_t timestamp, const std::string& text) {
    return Message('L', Packer().Put(uint8_t{'6'}).Put(timestamp).Bytes(text).str());
  }
  ULogWriter& Sync() { return Message('S', std::string("\x2F\x73\x13\x20\x25\x0C\xBB\x12", 8)); }
  ULogWriter& Dropout(uint16_t ms) { return Message('O', Packer().Put(ms).str()); }

  const std::string& bytes() const { return bytes_; }
  std::string& mutable_bytes() { return bytes_; }

 private:
  std::string bytes_;
};

}  // namespace calibd::testing

#endif  // CALIBD_TESTS_LIB_ULOG_WRITER_H_
