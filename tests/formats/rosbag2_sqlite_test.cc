// rosbag2 SQLite reader (formats/rosbag2_sqlite.h): .db3 files written here with rosbag2's
// schema (topics, messages) read back exactly; damaged and non-bag files refused.
#include "formats/rosbag2_sqlite.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "formats/recording.h"
#include "tests/formats/db3_writer.h"
#include "tests/formats/ros2_cdr_writer.h"

namespace calibd::server {
namespace {

// A .db3 of n messages each on /imu (stamps 10 s + i ms), /mag (no stamp) and /chatter.
std::string WriteDb3(const std::string& name, int n, bool short_imu = false) {
  testing::Db3Writer db(::testing::TempDir() + name);
  db.Topic(1, "/imu", "sensor_msgs/msg/Imu");
  db.Topic(2, "/mag", "sensor_msgs/msg/MagneticField");
  db.Topic(3, "/chatter", "std_msgs/msg/String");
  for (int i = 0; i < n; ++i) {
    const double accel[3] = {0.5 * i, 9.75, -0.25};
    const double gyro[3] = {0.125, -0.01 * i, 0};
    const double tesla[3] = {1e-5 * i, 2e-5, -4e-5};
    const int64_t t = 1'700'000'000'000'000'000 + 1000 * i;
    std::string imu = testing::ImuCdr(false, 10, 1'000'000u * i, accel, gyro);
    if (short_imu && i == n - 1) imu.resize(40);
    db.Add(1, t, imu);
    db.Add(2, t, testing::MagCdr(tesla));
    db.Add(3, t, std::string("\0\1\0\0\2\0\0\0a\0", 10));
  }
  db.Close();
  return db.path();
}

// An upload's bytes: recognised by "SQLite format 3", written to a private temporary file for
// SQLite (formats/log_readers.cc), read, assembled; the temporary file is gone afterwards.
TEST(RosBag2Sqlite, ItsBytesReachTheRecordingParserLikeAnyLog) {
  std::ifstream in(WriteDb3("bytes.db3", 30), std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string dir = ::testing::TempDir() + "db3-tmp";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  ::setenv("TMPDIR", dir.c_str(), 1);
  RecordingParser parser("upload", /*collect=*/true);
  ASSERT_TRUE(parser.Feed(bytes.substr(0, 7)).ok());  // recognised across small chunks
  ASSERT_TRUE(parser.Feed(bytes.substr(7)).ok());
  const Status s = parser.Finish();
  ::unsetenv("TMPDIR");
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(parser.summary().format, "rosbag2");
  ArrayRecording rec;
  ASSERT_TRUE(parser.TakeArray(&rec).ok());
  EXPECT_EQ(rec.t.size(), 30);
  EXPECT_EQ(rec.accel(3, 0), 1.5);
  EXPECT_EQ(rec.mag_names.size(), 1u);
  EXPECT_TRUE(std::filesystem::is_empty(dir));

  RecordingParser damaged("upload", /*collect=*/false);
  ASSERT_TRUE(damaged.Feed(bytes.substr(0, 4096)).ok());
  EXPECT_EQ(damaged.Finish().code(), StatusCode::kInvalidInput);
}

TEST(RosBag2Sqlite, ReadsTheSamplesWritten) {
  const int n = 25;
  SensorLog log;
  Status s = ReadRosBag2Sqlite(WriteDb3("a.db3", n), "a.db3", SensorLogLimits(), &log);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(log.format, "rosbag2");
  ASSERT_EQ(log.streams.size(), 3u);  // /imu accel, gyro; /mag
  const SensorStream& accel = log.streams[0];
  const SensorStream& gyro = log.streams[1];
  const SensorStream& mag = log.streams[2];
  EXPECT_EQ(accel.kind, StreamKind::kAccel);
  EXPECT_EQ(gyro.kind, StreamKind::kGyro);
  EXPECT_EQ(mag.topic, "/mag");
  EXPECT_EQ(accel.time_source, "header.stamp");
  for (const SensorStream* st : {&accel, &gyro, &mag}) ASSERT_EQ(st->samples(), n);
  EXPECT_EQ(mag.time_source, "record time");
  for (int i = 0; i < n; ++i) {
    EXPECT_EQ(mag.t_ns[i], 1'700'000'000'000'000'000 + 1000LL * i);
    EXPECT_EQ(accel.t_ns[i], 10'000'000'000 + 1'000'000LL * i);
    EXPECT_EQ(accel.values[3 * i], 0.5 * i);
    EXPECT_EQ(gyro.values[3 * i + 1], -0.01 * i);
    EXPECT_NEAR(mag.values[3 * i], 10.0 * i, 1e-9);
  }
}

TEST(RosBag2Sqlite, ShortMessageNamesItsRow) {
  SensorLog log;
  Status s = ReadRosBag2Sqlite(WriteDb3("b.db3", 5, true), "b.db3", SensorLogLimits(), &log);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("row 13"), std::string::npos) << s.message();
  EXPECT_TRUE(log.streams.empty());
}

TEST(RosBag2Sqlite, DamagedOrForeignFilesAreRefused) {
  std::string path = WriteDb3("c.db3", 200);
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  for (size_t keep : {size_t{100}, bytes.size() / 2}) {
    std::string cut = ::testing::TempDir() + "cut.db3";
    std::ofstream(cut, std::ios::binary) << bytes.substr(0, keep);
    SensorLog log;
    Status s = ReadRosBag2Sqlite(cut, "cut.db3", SensorLogLimits(), &log);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << keep;
    EXPECT_NE(s.message().find("cut.db3"), std::string::npos) << s.message();
  }
  SensorLog log;
  Status s =
      ReadRosBag2Sqlite(::testing::TempDir() + "absent.db3", "absent.db3", SensorLogLimits(), &log);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
}

}  // namespace
}  // namespace calibd::server
