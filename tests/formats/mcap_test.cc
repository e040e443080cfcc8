// MCAP reader (formats/mcap.h) and CDR decoding (formats/cdr.h): files of the test's own writer
// (uncompressed, lz4 and zstd chunks; little- and big-endian CDR) read back exactly, cut at every
// byte and damaged.
#include "formats/mcap.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "tests/formats/mcap_writer.h"
#include "tests/formats/ros2_cdr_writer.h"

namespace calibd::server {
namespace {

using testing::Channel;
using testing::Chunk;
using testing::ImuCdr;
using testing::MagCdr;
using testing::McapBegin;
using testing::McapEnd;
using testing::Message;
using testing::Schema;
using testing::TemperatureCdr;

// n samples on /imu (stamps 50 s + 2 ms i + 3 ns), /mag (no stamp: log time 7 s + i µs), /temp,
// in chunks of 10 samples; schemas and channels in the first chunk.
std::string OwnMcap(int n, const std::string& compression, bool big_endian) {
  std::string file = McapBegin();
  std::string records = Schema(1, "sensor_msgs/msg/Imu") +
                        Schema(2, "sensor_msgs/msg/MagneticField") +
                        Schema(3, "sensor_msgs/msg/Temperature") +
                        Schema(4, "std_msgs/msg/String") + Channel(1, 1, "/imu") +
                        Channel(2, 2, "/mag") + Channel(3, 3, "/temp") + Channel(4, 4, "/chatter");
  for (int i = 0; i < n; ++i) {
    const double accel[3] = {0.1 * i, -9.8, 0.25};
    const double gyro[3] = {0.01 * i, 0.5, -0.125};
    const double tesla[3] = {2e-5 + 1e-9 * i, -3e-6, 4.5e-5};
    const uint64_t log_time = 7'000'000'000 + 1000ull * i;
    records += Message(1, log_time, ImuCdr(big_endian, 50, 2'000'000u * i + 3, accel, gyro));
    records += Message(2, log_time, MagCdr(tesla));
    records += Message(3, log_time, TemperatureCdr(50, 2'000'000u * i, 20 + 0.5 * i));
    records += Message(4, log_time, std::string("\0\1\0\0\2\0\0\0a\0", 10));
    if (i % 10 == 9 || i == n - 1) {
      file += Chunk(records, compression);
      records.clear();
    }
  }
  return file + McapEnd();
}

const SensorStream* Find(const SensorLog& log, const std::string& topic, StreamKind kind) {
  for (const SensorStream& s : log.streams) {
    if (s.topic == topic && s.kind == kind) return &s;
  }
  return nullptr;
}

struct Case {
  const char* compression;
  bool big_endian;
};
class OwnMcapTest : public ::testing::TestWithParam<Case> {};

TEST_P(OwnMcapTest, ReadsTheSamplesWritten) {
  const int n = 35;
  SensorLog log;
  Status s = ReadMcap(OwnMcap(n, GetParam().compression, GetParam().big_endian), "x.mcap",
                      SensorLogLimits(), &log);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_TRUE(log.warnings.empty());
  EXPECT_EQ(log.format, "mcap");
  ASSERT_EQ(log.streams.size(), 4u);
  const SensorStream* accel = Find(log, "/imu", StreamKind::kAccel);
  const SensorStream* gyro = Find(log, "/imu", StreamKind::kGyro);
  const SensorStream* mag = Find(log, "/mag", StreamKind::kMag);
  const SensorStream* temp = Find(log, "/temp", StreamKind::kTemperature);
  ASSERT_TRUE(accel && gyro && mag && temp);
  EXPECT_EQ(accel->time_source, "header.stamp");
  EXPECT_EQ(mag->time_source, "record time");
  EXPECT_EQ(temp->time_source, "header.stamp");
  for (const SensorStream* st : {accel, gyro, mag, temp}) ASSERT_EQ(st->samples(), n);
  for (int i = 0; i < n; ++i) {
    EXPECT_EQ(accel->t_ns[i], 50'000'000'000 + 2'000'000LL * i + 3);
    EXPECT_EQ(mag->t_ns[i], 7'000'000'000 + 1000LL * i);
    EXPECT_EQ(accel->values[3 * i], 0.1 * i);
    EXPECT_EQ(accel->values[3 * i + 1], -9.8);
    EXPECT_EQ(gyro->values[3 * i], 0.01 * i);
    EXPECT_EQ(gyro->values[3 * i + 2], -0.125);
    EXPECT_NEAR(mag->values[3 * i], (2e-5 + 1e-9 * i) * 1e6, 1e-12);
    EXPECT_EQ(temp->values[i], 20 + 0.5 * i);
  }
}

INSTANTIATE_TEST_SUITE_P(Chunks, OwnMcapTest,
                         ::testing::Values(Case{"", false}, Case{"lz4", false}, Case{"zstd", false},
                                           Case{"zstd", true}));

TEST(Mcap, CutAtEveryByteReadsWholeChunksWithAWarning) {
  const std::string file = OwnMcap(30, "zstd", false);
  for (size_t n = 8; n < file.size() - 8; ++n) {  // every cut before the footer's magic
    SensorLog log;
    Status s = ReadMcap(std::string_view(file).substr(0, n), "x.mcap", SensorLogLimits(), &log);
    ASSERT_TRUE(s.ok()) << n << ": " << s.message();
    const SensorStream* accel = Find(log, "/imu", StreamKind::kAccel);
    const int64_t samples = accel ? accel->samples() : 0;
    EXPECT_EQ(samples % 10, 0) << n;
    const bool closed = n >= file.size() - 8 - 29;  // DataEnd and Footer read
    EXPECT_EQ(log.warnings.size(), closed ? 0u : 1u) << n;
  }
}

TEST(Mcap, DamageNamesTheByteOffset) {
  const std::string file = OwnMcap(10, "lz4", false);
  const size_t chunk = file.find('\x06', 8 + 17);  // after the magic and the header record
  {
    std::string b = file;  // the chunk's uncompressed_size one too large
    uint64_t size;
    std::memcpy(&size, b.data() + chunk + 9 + 16, 8);
    ++size;
    std::memcpy(b.data() + chunk + 9 + 16, &size, 8);
    SensorLog log;
    Status s = ReadMcap(b, "x.mcap", SensorLogLimits(), &log);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
    EXPECT_NE(s.message().find("does not decompress to its stated size"), std::string::npos)
        << s.message();
    EXPECT_NE(s.message().find("at byte " + std::to_string(chunk)), std::string::npos)
        << s.message();
  }
  {
    std::string b = file;  // an impossible record length
    uint64_t huge = uint64_t{1} << 60;
    std::memcpy(b.data() + chunk + 1, &huge, 8);
    SensorLog log;
    Status s = ReadMcap(b, "x.mcap", SensorLogLimits(), &log);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
    EXPECT_NE(s.message().find("record length"), std::string::npos) << s.message();
  }
  {
    SensorLogLimits limits;  // the decompression bound
    limits.max_decompressed_bytes = 1000;
    SensorLog log;
    Status s = ReadMcap(file, "x.mcap", limits, &log);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
    EXPECT_NE(s.message().find("max_decompressed_bytes"), std::string::npos) << s.message();
  }
}

TEST(Mcap, RandomDamageNeverCrashes) {
  for (const char* compression : {"", "zstd"}) {
    const std::string file = OwnMcap(12, compression, false);
    std::mt19937 rng(11);
    for (int trial = 0; trial < 2000; ++trial) {
      std::string b = file;
      for (int k = 0; k < 3; ++k) b[8 + rng() % (b.size() - 8)] = static_cast<char>(rng());
      SensorLog log;
      Status s = ReadMcap(b, "x.mcap", SensorLogLimits(), &log);
      if (!s.ok()) {
        EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
      }
    }
  }
}

}  // namespace
}  // namespace calibd::server
