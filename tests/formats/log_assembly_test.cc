// From a sensor log's streams to the recording the methods read (formats/log_assembly.h).
#include "formats/log_assembly.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

namespace calibd::server {
namespace {

using nlohmann::json;

// A stream of n samples every `period_ns` from t0, value k of sample i = base + i + k/10.
SensorStream Stream(StreamKind kind, std::string topic, int instance, int64_t t0, int64_t period_ns,
                    int n, double base, int64_t device_id = -1) {
  SensorStream s;
  s.kind = kind;
  s.topic = std::move(topic);
  s.instance = instance;
  s.device_id = device_id;
  s.time_source = "timestamp_sample";
  const int d = StreamDimension(kind);
  for (int i = 0; i < n; ++i) {
    s.t_ns.push_back(t0 + i * period_ns);
    for (int k = 0; k < d; ++k) s.values.push_back(base + i + k / 10.0);
  }
  return s;
}

TEST(LogAssembly, PairsAccelAndGyroOfOneMessageSampleBySample) {
  SensorLog log;
  log.format = "dataflash";
  log.streams.push_back(Stream(StreamKind::kAccel, "IMU", 0, 1000, 1000000, 50, 0));
  log.streams.push_back(Stream(StreamKind::kGyro, "IMU", 0, 1000, 1000000, 50, 100));
  log.streams.push_back(Stream(StreamKind::kTemperature, "IMU", 0, 1000, 1000000, 50, 40));
  AssembledLog out;
  ASSERT_TRUE(AssembleLog(log, {}, "f.bin", &out).ok());
  const ArrayRecording& r = out.recording;
  ASSERT_EQ(r.t.size(), 50);
  EXPECT_EQ(r.accel_names, std::vector<std::string>{"a0"});
  EXPECT_EQ(r.gyro_names, std::vector<std::string>{"g0"});
  EXPECT_EQ(r.temp_names, std::vector<std::string>{"temp0"});
  EXPECT_DOUBLE_EQ(r.t(0), 1e-6);
  EXPECT_DOUBLE_EQ(r.t(49) - r.t(0), 49e-3);
  EXPECT_DOUBLE_EQ(r.accel(7, 2), 7.2);
  EXPECT_DOUBLE_EQ(r.gyro(7, 1), 107.1);
  EXPECT_DOUBLE_EQ(r.temperature(7, 0), 47);
  EXPECT_TRUE(out.description["imus"][0]["resampled"].empty());
  EXPECT_EQ(out.description["format"], "dataflash");
  EXPECT_EQ(out.description["streams"].size(), 3u);
  EXPECT_NEAR(out.description["streams"][0]["rate"].get<double>(), 1000, 1e-9);
}

TEST(LogAssembly, PairsUlogTopicsByDeviceIdThenByInstance) {
  SensorLog log;
  log.format = "ulog";
  // Instance 0's gyro carries the device id of accel instance 1: device ids decide first.
  log.streams.push_back(Stream(StreamKind::kAccel, "sensor_accel", 0, 0, 1000000, 20, 0, 11));
  log.streams.push_back(Stream(StreamKind::kAccel, "sensor_accel", 1, 0, 1000000, 20, 0, 22));
  log.streams.push_back(Stream(StreamKind::kGyro, "sensor_gyro", 0, 0, 1000000, 20, 0, 22));
  log.streams.push_back(Stream(StreamKind::kGyro, "sensor_gyro", 1, 0, 1000000, 20, 0, 11));
  AssembledLog out;
  ASSERT_TRUE(AssembleLog(log, {}, "f.ulg", &out).ok());
  ASSERT_EQ(out.description["imus"].size(), 2u);
  EXPECT_EQ(out.description["imus"][0]["gyro"], "sensor_gyro:1");
  EXPECT_EQ(out.description["imus"][1]["gyro"], "sensor_gyro:0");

  // Without device ids, instance k pairs with instance k.
  for (SensorStream& s : log.streams) s.device_id = -1;
  ASSERT_TRUE(AssembleLog(log, {}, "f.ulg", &out).ok());
  EXPECT_EQ(out.description["imus"][0]["gyro"], "sensor_gyro:0");
  EXPECT_EQ(out.description["imus"][1]["gyro"], "sensor_gyro:1");
}

TEST(LogAssembly, InterpolatesAnAccelOnOtherInstantsOntoTheGyroTimesAndSaysSo) {
  SensorLog log;
  log.format = "rosbag1";
  // Accel at 250 Hz, gyro at 400 Hz; values linear in time, so interpolation is exact.
  SensorStream accel = Stream(StreamKind::kAccel, "/accel", -1, 0, 4000000, 100, 0);
  for (size_t i = 0; i < accel.t_ns.size(); ++i) {
    for (int k = 0; k < 3; ++k) accel.values[3 * i + k] = accel.t_ns[i] * 1e-9 + k;
  }
  log.streams.push_back(accel);
  log.streams.push_back(Stream(StreamKind::kGyro, "/gyro", -1, 0, 2500000, 150, 0));
  LogStreamSelection pick;
  ASSERT_TRUE(ParseLogStreams(json::parse(R"({"streams": {"imus": [{"accel": "/accel",
      "gyro": "/gyro"}]}})"),
                              &pick)
                  .ok());
  AssembledLog out;
  ASSERT_TRUE(AssembleLog(log, pick, "b.bag", &out).ok());
  const ArrayRecording& r = out.recording;
  ASSERT_EQ(r.t.size(), 150);
  for (Eigen::Index i = 0; i < r.t.size(); ++i) {
    if (r.t(i) > 0.396) break;  // within the accel's span
    EXPECT_NEAR(r.accel(i, 1), r.t(i) + 1, 1e-12) << i;
  }
  EXPECT_EQ(out.description["imus"][0]["resampled"], json::array({"/accel"}));
  EXPECT_NE(out.description["warnings"].dump().find("interpolated"), std::string::npos);
}

TEST(LogAssembly, ImusOnOtherTimeBasesAreLeftOutByDefaultAndRefusedWhenAskedFor) {
  SensorLog log;
  log.format = "dataflash";
  log.streams.push_back(Stream(StreamKind::kAccel, "IMU", 0, 0, 1000000, 30, 0));
  log.streams.push_back(Stream(StreamKind::kGyro, "IMU", 0, 0, 1000000, 30, 0));
  log.streams.push_back(Stream(StreamKind::kAccel, "IMU", 1, 300, 1000000, 30, 0));
  log.streams.push_back(Stream(StreamKind::kGyro, "IMU", 1, 300, 1000000, 30, 0));
  AssembledLog out;
  ASSERT_TRUE(AssembleLog(log, {}, "f.bin", &out).ok());
  EXPECT_EQ(out.recording.accel_names.size(), 1u);
  EXPECT_NE(out.description["warnings"].dump().find("IMU:1"), std::string::npos);

  LogStreamSelection both;
  ASSERT_TRUE(ParseLogStreams(json::parse(R"({"streams": {"imus": [
      {"accel": "IMU:0", "gyro": "IMU:0"}, {"accel": "IMU:1", "gyro": "IMU:1"}]}})"),
                              &both)
                  .ok());
  const Status s = AssembleLog(log, both, "f.bin", &out);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.field(), "streams");
  EXPECT_NE(s.message().find("streams.imus[1]"), std::string::npos) << s.message();

  // IMU 1 alone in its own job is fine.
  LogStreamSelection second;
  ASSERT_TRUE(ParseLogStreams(json::parse(R"({"streams": {"imus": [{"gyro": "IMU:1",
      "accel": "IMU:1"}]}})"),
                              &second)
                  .ok());
  ASSERT_TRUE(AssembleLog(log, second, "f.bin", &out).ok());
  EXPECT_DOUBLE_EQ(out.recording.t(0), 300e-9);
}

TEST(LogAssembly, DropsSamplesWhoseTimeDoesNotIncreaseAndCountsThem) {
  SensorLog log;
  log.format = "ulog";
  SensorStream a = Stream(StreamKind::kAccel, "sensor_accel", 0, 0, 1000000, 10, 0);
  a.t_ns[5] = a.t_ns[4];  // a repeated stamp
  log.streams.push_back(a);
  AssembledLog out;
  ASSERT_TRUE(AssembleLog(log, {}, "f.ulg", &out).ok());
  EXPECT_EQ(out.recording.t.size(), 9);
  EXPECT_EQ(out.description["imus"][0]["dropped"], 1);
}

TEST(LogAssembly, EpochStampsCountFromTheirWholeSecondWithoutLosingNanoseconds) {
  SensorLog log;
  log.format = "rosbag1";
  const int64_t t0 = 1'700'000'000'123'456'789;
  log.streams.push_back(Stream(StreamKind::kGyro, "/imu", -1, t0, 1000001, 10, 0));
  AssembledLog out;
  ASSERT_TRUE(AssembleLog(log, {}, "b.bag", &out).ok());
  EXPECT_EQ(out.time_origin, 1'700'000'000);
  EXPECT_DOUBLE_EQ(out.recording.t(0), 0.123456789);
  EXPECT_DOUBLE_EQ(out.recording.t(9), 0.123456789 + 9 * 0.001000001);
}

TEST(LogAssembly, AChoiceTheLogCannotSatisfyNamesTheKeyAndListsTheStreams) {
  SensorLog log;
  log.format = "ulog";
  log.streams.push_back(Stream(StreamKind::kAccel, "sensor_accel", 0, 0, 1000000, 10, 0));
  LogStreamSelection pick;
  ASSERT_TRUE(
      ParseLogStreams(json::parse(R"({"streams": {"imus": [{"gyro": "sensor_gyro:3"}]}})"), &pick)
          .ok());
  AssembledLog out;
  const Status s = AssembleLog(log, pick, "f.ulg", &out);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("streams.imus[0].gyro"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("sensor_accel:0 (accelerometer)"), std::string::npos) << s.message();

  SensorLog empty;
  empty.format = "ulog";
  EXPECT_EQ(AssembleLog(empty, {}, "f.ulg", &out).code(), StatusCode::kInvalidInput);
}

TEST(LogAssembly, MagnetometersFollowTheImuOrBecomeTheTimeBase) {
  SensorLog log;
  log.format = "ulog";
  log.streams.push_back(Stream(StreamKind::kAccel, "sensor_accel", 0, 0, 1000000, 1000, 0, 7));
  log.streams.push_back(Stream(StreamKind::kGyro, "sensor_gyro", 0, 0, 1000000, 1000, 0, 7));
  // 100 Hz, values linear in time: interpolation is exact.
  SensorStream mag = Stream(StreamKind::kMag, "sensor_mag", 0, 500000, 10000000, 99, 0);
  for (size_t i = 0; i < mag.t_ns.size(); ++i) {
    for (int k = 0; k < 3; ++k) mag.values[3 * i + k] = 20 + 1e-9 * mag.t_ns[i] + k;
  }
  log.streams.push_back(mag);
  AssembledLog out;
  ASSERT_TRUE(AssembleLog(log, {}, "f.ulg", &out).ok());
  EXPECT_EQ(out.recording.t.size(), 1000);  // the IMU's times
  EXPECT_EQ(out.recording.mag_names, std::vector<std::string>{"m0"});
  EXPECT_NEAR(out.recording.mag(100, 2), 22 + out.recording.t(100), 1e-12);
  EXPECT_EQ(out.description["mags"][0]["resampled"], json::array({"sensor_mag:0"}));

  LogStreamSelection on_mag;
  on_mag.mag_time_base = true;
  ASSERT_TRUE(AssembleLog(log, on_mag, "f.ulg", &out).ok());
  ASSERT_EQ(out.recording.t.size(), 99);  // the magnetometer's times, each sample once
  EXPECT_DOUBLE_EQ(out.recording.t(0), 0.0005);
  EXPECT_DOUBLE_EQ(out.recording.mag(3, 0), mag.values[9]);
  EXPECT_EQ(out.description["time_base"], "sensor_mag:0 (timestamp_sample)");
  EXPECT_EQ(out.description["imus"][0]["resampled"].size(), 2u);
  // Accel value at t = 30.5 ms lies between samples 30 and 31 (base + i + k/10).
  EXPECT_NEAR(out.recording.accel(3, 0), 30.5, 1e-9);

  LogStreamSelection unknown;
  ASSERT_TRUE(
      ParseLogStreams(json::parse(R"({"streams": {"mags": ["sensor_mag:4"]}})"), &unknown).ok());
  const Status s = AssembleLog(log, unknown, "f.ulg", &out);
  EXPECT_NE(s.message().find("streams.mags[0]"), std::string::npos) << s.message();
}

TEST(LogAssembly, StreamsConfigOfTheWrongShapeNamesThePath) {
  LogStreamSelection pick;
  for (const char* bad :
       {R"({"streams": 3})", R"({"streams": {"imu": []}})", R"({"streams": {"imus": [{}]}})",
        R"({"streams": {"imus": [{"gyro": 1}]}})",
        R"({"streams": {"imus": [{"gyro": "x", "acc": "y"}]}})",
        R"({"streams": {"mags": [""]}})"}) {
    const Status s = ParseLogStreams(json::parse(bad), &pick);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << bad;
    EXPECT_EQ(s.field(), "streams") << bad;
  }
  ASSERT_TRUE(ParseLogStreams(json::parse(R"({"method": "noise"})"), &pick).ok());
  EXPECT_FALSE(pick.given);
}

}  // namespace
}  // namespace calibd::server
