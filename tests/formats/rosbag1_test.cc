// ROS 1 bag reader (formats/rosbag1.h): bags written by Debian's python3-rosbag (an independent
// writer; uncompressed, bz2, lz4 chunks) read back to the samples written, and bags of the test's
// own writer cut and damaged.
#include "formats/rosbag1.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "tests/lib/test_paths.h"

namespace calibd::server {
namespace {

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

bool HavePythonRosbag() {
  return std::system("/usr/bin/python3 -c 'import rosbag, sensor_msgs.msg' 2>/dev/null") == 0;
}

// A bag of `n` samples per topic written by tests/formats/write_rosbag1.py.
std::string WritePythonBag(const std::string& compression, int n) {
  std::string path = ::testing::TempDir() + "rosbag1_" + compression + ".bag";
  std::string cmd = "cd " + ::testing::TempDir() + " && /usr/bin/python3 " +
                    calibd::test_paths::SourceDir() + "/tests/formats/write_rosbag1.py " + path +
                    " " + compression + " " + std::to_string(n);
  EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
  return ReadFile(path);
}

const SensorStream* Find(const SensorLog& log, const std::string& topic, StreamKind kind) {
  for (const SensorStream& s : log.streams) {
    if (s.topic == topic && s.kind == kind) return &s;
  }
  return nullptr;
}

// The samples write_rosbag1.py writes, read back exactly (ns times) or to double rounding.
void ExpectPythonSamples(const SensorLog& log, int n) {
  ASSERT_EQ(log.format, "rosbag1");
  ASSERT_EQ(log.streams.size(), 4u);  // /imu accel and gyro, /mag, /temp; /chatter skipped
  const SensorStream* accel = Find(log, "/imu", StreamKind::kAccel);
  const SensorStream* gyro = Find(log, "/imu", StreamKind::kGyro);
  const SensorStream* mag = Find(log, "/mag", StreamKind::kMag);
  const SensorStream* temp = Find(log, "/temp", StreamKind::kTemperature);
  ASSERT_TRUE(accel && gyro && mag && temp);
  for (const SensorStream* s : {accel, gyro, mag, temp}) {
    ASSERT_EQ(s->samples(), n) << s->topic;
    EXPECT_EQ(s->instance, -1);
    EXPECT_EQ(s->Name(), s->topic);
  }
  EXPECT_EQ(accel->time_source, "header.stamp");
  EXPECT_EQ(mag->time_source, "record time");
  EXPECT_EQ(temp->time_source, "header.stamp");
  EXPECT_EQ(accel->unit, "m/s^2");
  EXPECT_EQ(gyro->unit, "rad/s");
  EXPECT_EQ(mag->unit, "T");
  for (int i = 0; i < n; ++i) {
    EXPECT_EQ(accel->t_ns[i], 100'000'000'000 + i * 5'000'000LL + 7);
    EXPECT_EQ(gyro->t_ns[i], accel->t_ns[i]);
    EXPECT_EQ(mag->t_ns[i], 1000'000'000'000 + i * 1'000'000LL);
    EXPECT_EQ(temp->t_ns[i], 100'000'000'000 + i * 5'000'000LL);
    EXPECT_DOUBLE_EQ(accel->values[3 * i], 0.1 * i);
    EXPECT_DOUBLE_EQ(accel->values[3 * i + 1], -9.81 + 0.001 * i);
    EXPECT_DOUBLE_EQ(accel->values[3 * i + 2], 0.5);
    EXPECT_DOUBLE_EQ(gyro->values[3 * i], 0.01 * i);
    EXPECT_DOUBLE_EQ(gyro->values[3 * i + 1], -0.02 * i);
    EXPECT_DOUBLE_EQ(gyro->values[3 * i + 2], 0.003);
    EXPECT_NEAR(mag->values[3 * i], (2e-5 + 1e-9 * i) * 1e6, 1e-12);  // µT
    EXPECT_NEAR(mag->values[3 * i + 1], -3.0, 1e-12);
    EXPECT_NEAR(mag->values[3 * i + 2], 45.0, 1e-12);
    EXPECT_DOUBLE_EQ(temp->values[i], 25 + 0.01 * i);
  }
}

class PythonBagTest : public ::testing::TestWithParam<const char*> {};

TEST_P(PythonBagTest, ReadsTheSamplesWritten) {
  if (!HavePythonRosbag()) GTEST_SKIP() << "python3-rosbag absent (scripts/setup.sh installs it)";
  const int n = 300;  // several chunks (chunk_threshold 4096 bytes)
  std::string bag = WritePythonBag(GetParam(), n);
  SensorLog log;
  Status s = ReadRosBag1(bag, "x.bag", SensorLogLimits(), &log);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_TRUE(log.warnings.empty());
  ExpectPythonSamples(log, n);
}

INSTANTIATE_TEST_SUITE_P(Compressions, PythonBagTest, ::testing::Values("none", "bz2", "lz4"));

TEST(RosBag1, CutBagReadsToTheLastWholeChunkWithAWarning) {
  if (!HavePythonRosbag()) GTEST_SKIP() << "python3-rosbag absent";
  std::string bag = WritePythonBag("lz4", 300);
  std::string cut = bag.substr(0, bag.size() / 2);
  SensorLog log;
  Status s = ReadRosBag1(cut, "x.bag", SensorLogLimits(), &log);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(log.warnings.size(), 1u);
  EXPECT_NE(log.warnings[0].find("bag cut at byte "), std::string::npos) << log.warnings[0];
  const SensorStream* accel = Find(log, "/imu", StreamKind::kAccel);
  ASSERT_NE(accel, nullptr);
  EXPECT_GT(accel->samples(), 0);
  EXPECT_LT(accel->samples(), 300);
}

TEST(RosBag1, ChunkNotDecompressingToItsStatedSizeIsDamage) {
  if (!HavePythonRosbag()) GTEST_SKIP() << "python3-rosbag absent";
  for (const char* compression : {"bz2", "lz4"}) {
    std::string bag = WritePythonBag(compression, 50);
    size_t at = bag.find("size=");  // the first chunk's header (the bag header has no size)
    ASSERT_NE(at, std::string::npos);
    uint32_t size;
    std::memcpy(&size, bag.data() + at + 5, 4);
    for (uint32_t wrong : {size + 1, size - 1}) {
      std::memcpy(bag.data() + at + 5, &wrong, 4);
      SensorLog log;
      Status s = ReadRosBag1(bag, "x.bag", SensorLogLimits(), &log);
      EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << compression;
      EXPECT_NE(s.message().find("does not decompress to its stated size"), std::string::npos)
          << s.message();
      EXPECT_TRUE(log.streams.empty());
    }
  }
}

TEST(RosBag1, DecompressionBoundedByTheLimit) {
  if (!HavePythonRosbag()) GTEST_SKIP() << "python3-rosbag absent";
  std::string bag = WritePythonBag("bz2", 300);
  SensorLogLimits limits;
  limits.max_decompressed_bytes = 10000;
  SensorLog log;
  Status s = ReadRosBag1(bag, "x.bag", limits, &log);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("max_decompressed_bytes"), std::string::npos) << s.message();
}

// --- The test's own writer: records by hand, uncompressed chunks. ---

void PutU32(uint32_t v, std::string* out) { out->append(reinterpret_cast<char*>(&v), 4); }
void PutF64(double v, std::string* out) { out->append(reinterpret_cast<char*>(&v), 8); }
std::string U32Bytes(uint32_t v) {
  std::string s;
  PutU32(v, &s);
  return s;
}

std::string Fields(const std::vector<std::pair<std::string, std::string>>& fields) {
  std::string out;
  for (const auto& [name, value] : fields) {
    PutU32(static_cast<uint32_t>(name.size() + 1 + value.size()), &out);
    out += name + "=" + value;
  }
  return out;
}

std::string Record(const std::vector<std::pair<std::string, std::string>>& header,
                   const std::string& data) {
  std::string h = Fields(header);
  std::string out;
  PutU32(static_cast<uint32_t>(h.size()), &out);
  out += h;
  PutU32(static_cast<uint32_t>(data.size()), &out);
  return out + data;
}

std::string TemperatureMessage(uint32_t sec, uint32_t nsec, double celsius) {
  std::string m;
  PutU32(0, &m);  // seq
  PutU32(sec, &m);
  PutU32(nsec, &m);
  PutU32(4, &m);
  m += "base";
  PutF64(celsius, &m);
  PutF64(0.01, &m);
  return m;
}

// A bag of one /temp topic: `per_chunk` messages in each of `chunks` uncompressed chunks.
std::string OwnBag(int chunks, int per_chunk) {
  std::string bag = "#ROSBAG V2.0\n";
  bag += Record({{"op", "\x03"}}, std::string(16, ' '));
  std::string connection = Record({{"op", "\x07"}, {"conn", U32Bytes(0)}, {"topic", "/temp"}},
                                  Fields({{"type", "sensor_msgs/Temperature"},
                                          {"md5sum", "ff71b307acdbe7c871a5a6d7ed359100"}}));
  int i = 0;
  for (int c = 0; c < chunks; ++c) {
    std::string records = c == 0 ? connection : "";
    for (int k = 0; k < per_chunk; ++k, ++i) {
      std::string time = U32Bytes(5) + U32Bytes(i);
      records += Record({{"op", "\x02"}, {"conn", U32Bytes(0)}, {"time", time}},
                        TemperatureMessage(0, 0, 20 + i));
    }
    bag += Record({{"op", "\x05"},
                   {"compression", "none"},
                   {"size", U32Bytes(static_cast<uint32_t>(records.size()))}},
                  records);
  }
  return bag;
}

TEST(RosBag1, OwnWriterZeroStampsUseRecordTime) {
  SensorLog log;
  Status s = ReadRosBag1(OwnBag(2, 3), "own.bag", SensorLogLimits(), &log);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(log.streams.size(), 1u);
  const SensorStream& t = log.streams[0];
  EXPECT_EQ(t.time_source, "record time");
  ASSERT_EQ(t.samples(), 6);
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(t.t_ns[i], 5'000'000'000LL + i);
    EXPECT_EQ(t.values[i], 20 + i);
  }
}

TEST(RosBag1, CutAtEveryByteReadsWholeChunksOnly) {
  std::string bag = OwnBag(3, 4);
  // Where records start (a cut there is no cut inside a record): the bag header, each chunk.
  std::vector<size_t> boundaries = {13, bag.size()};
  for (size_t at = bag.find(std::string("op=\x05", 4)); at != std::string::npos;
       at = bag.find(std::string("op=\x05", 4), at + 1)) {
    boundaries.push_back(at - 8);
  }
  ASSERT_EQ(boundaries.size(), 5u);
  for (size_t n = 13; n < bag.size(); ++n) {
    SensorLog log;
    Status s = ReadRosBag1(std::string_view(bag).substr(0, n), "own.bag", SensorLogLimits(), &log);
    ASSERT_TRUE(s.ok()) << n << ": " << s.message();
    bool boundary = std::find(boundaries.begin(), boundaries.end(), n) != boundaries.end();
    ASSERT_EQ(log.warnings.size(), boundary ? 0u : 1u) << n;
    if (!boundary) {
      EXPECT_NE(log.warnings[0].find("at byte "), std::string::npos);
    }
    int64_t samples = log.streams.empty() ? 0 : log.streams[0].samples();
    EXPECT_EQ(samples % 4, 0) << n;  // whole chunks only
  }
}

TEST(RosBag1, DamageNamesTheByteOffset) {
  std::string bag = OwnBag(1, 2);
  // The chunk record: its header length, then the header's first field ("op", 4 + 4 bytes).
  size_t chunk = bag.find(std::string("op=\x05", 4)) - 4 - 4;
  {
    std::string b = bag;
    b[b.find(std::string("op=\x05", 4)) + 3] = 0x09;
    SensorLog log;
    Status s = ReadRosBag1(b, "own.bag", SensorLogLimits(), &log);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
    EXPECT_NE(s.message().find("unknown op 9"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("at byte " + std::to_string(chunk)), std::string::npos)
        << s.message();
  }
  {
    std::string b = bag;
    uint32_t huge = 0xfffffff0u;
    std::memcpy(b.data() + chunk, &huge, 4);
    SensorLog log;
    Status s = ReadRosBag1(b, "own.bag", SensorLogLimits(), &log);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
    EXPECT_NE(s.message().find("header length"), std::string::npos) << s.message();
  }
  {
    std::string b = bag;  // a message too short: its record's data length cut to 10 bytes
    size_t msg = b.find(std::string("op=\x02", 4));
    size_t header_len_at = msg - 4 - 4;
    uint32_t header_len;
    std::memcpy(&header_len, b.data() + header_len_at, 4);
    size_t data_len_at = header_len_at + 4 + header_len;
    uint32_t data_len;
    std::memcpy(&data_len, b.data() + data_len_at, 4);
    uint32_t short_len = 10;
    std::memcpy(b.data() + data_len_at, &short_len, 4);
    b.erase(data_len_at + 4 + 10, data_len - 10);
    uint32_t chunk_size_fix;  // keep the chunk's stated size and data length consistent
    size_t size_at = b.find("size=") + 5;
    std::memcpy(&chunk_size_fix, b.data() + size_at, 4);
    chunk_size_fix -= data_len - 10;
    std::memcpy(b.data() + size_at, &chunk_size_fix, 4);
    size_t chunk_data_len_at = size_at + 4;
    uint32_t chunk_data_len;
    std::memcpy(&chunk_data_len, b.data() + chunk_data_len_at, 4);
    chunk_data_len -= data_len - 10;
    std::memcpy(b.data() + chunk_data_len_at, &chunk_data_len, 4);
    SensorLog log;
    Status s = ReadRosBag1(b, "own.bag", SensorLogLimits(), &log);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
    EXPECT_NE(s.message().find("too short for its type"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("of the chunk at byte " + std::to_string(chunk)), std::string::npos)
        << s.message();
  }
}

TEST(RosBag1, NotABag) {
  SensorLog log;
  Status s = ReadRosBag1("#ROSBAG V1.2\n", "x.bag", SensorLogLimits(), &log);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
}

TEST(RosBag1, SampleLimit) {
  SensorLogLimits limits;
  limits.max_samples = 5;
  SensorLog log;
  Status s = ReadRosBag1(OwnBag(2, 3), "own.bag", limits, &log);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("max_samples"), std::string::npos) << s.message();
}

// Random byte flips: every outcome is success or kInvalidInput with a message, never a crash
// (the fuzz target tests/fuzz/fuzz_rosbag1.cc searches further).
TEST(RosBag1, RandomDamageNeverCrashes) {
  std::string bag = OwnBag(3, 4);
  std::mt19937 rng(7);
  for (int trial = 0; trial < 3000; ++trial) {
    std::string b = bag;
    for (int k = 0; k < 3; ++k) b[13 + rng() % (b.size() - 13)] = static_cast<char>(rng());
    SensorLog log;
    Status s = ReadRosBag1(b, "own.bag", SensorLogLimits(), &log);
    if (!s.ok()) {
      EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
      EXPECT_FALSE(s.message().empty());
    }
  }
}

}  // namespace
}  // namespace calibd::server
