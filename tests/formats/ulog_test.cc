// The PX4 ULog reader (formats/ulog.h): logs built by tests/lib/ulog_writer.h for the edge cases
// (nested types, padding, multi-instance, fifo bursts, zero timestamp_sample, appended data, a
// cut at every byte, damage), and pyulog's sample logs compared with pyulog itself.
#include "formats/ulog.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "tests/lib/test_paths.h"
#include "tests/lib/ulog_writer.h"

namespace calibd::server {
namespace {

using testing::CombinedData;
using testing::FifoData;
using testing::TriadData;
using testing::ULogWriter;

const SensorStream* Find(const SensorLog& log, const std::string& name, StreamKind kind) {
  for (const SensorStream& s : log.streams)
    if (s.Name() == name && s.kind == kind) return &s;
  return nullptr;
}

SensorLog ReadOk(const std::string& bytes) {
  SensorLog log;
  Status status = ReadULog(bytes, "test.ulg", SensorLogLimits(), &log);
  EXPECT_TRUE(status.ok()) << status.ToString();
  return log;
}

Status ReadError(const std::string& bytes) {
  SensorLog log;
  Status status = ReadULog(bytes, "test.ulg", SensorLogLimits(), &log);
  EXPECT_FALSE(status.ok());
  EXPECT_EQ(status.code(), StatusCode::kInvalidInput);
  EXPECT_TRUE(log.streams.empty());
  return status;
}

// Two accelerometers and a gyroscope at 1 kHz, a magnetometer at 100 Hz, each with a
// temperature; instance 1's accelerometer at 5 Hz.
ULogWriter TriadLog(int seconds_ms = 20) {
  ULogWriter w;
  w.FlagBits(0).Info("char[7] sys_name", "PX4 sim");
  w.Format(testing::kSensorAccelFormat).Format(testing::kSensorGyroFormat);
  w.Format(testing::kSensorMagFormat);
  w.Subscribe(0, 10, "sensor_accel").Subscribe(1, 11, "sensor_accel");
  w.Subscribe(0, 12, "sensor_gyro").Subscribe(0, 13, "sensor_mag");
  for (int k = 0; k < seconds_ms; ++k) {
    const uint64_t t = 1'000'000 + 1000 * k;
    w.Data(10, TriadData(t + 7, t, 0x1001, 0.5f * k, 1, 9.81f, 40 + 0.01f * k));
    if (k % 200 == 0) w.Data(11, TriadData(t + 7, t, 0x1002, 0.25f, -1, 9.8f, 30));
    w.Data(12, TriadData(t + 7, t + 1, 0x1001, 0.01f, 0.02f, 0.03f, 40));
    if (k % 10 == 0) {
      w.Text(t, "a log text");
      w.Data(13, TriadData(t + 9, t + 2, 0x2001, 0.2f, -0.1f, 0.45f, NAN, true));
    }
  }
  return w;
}

TEST(ULogTest, ReadsTriadsInstancesTemperaturesAndUnits) {
  const SensorLog log = ReadOk(TriadLog(1000).bytes());
  EXPECT_EQ(log.format, "ulog");
  const SensorStream* a0 = Find(log, "sensor_accel:0", StreamKind::kAccel);
  ASSERT_NE(a0, nullptr);
  ASSERT_EQ(a0->samples(), 1000);
  EXPECT_EQ(a0->t_ns[0], 1'000'000'000);  // timestamp_sample µs → ns, exact
  EXPECT_EQ(a0->t_ns[999], 1'999'000'000);
  EXPECT_EQ(a0->time_source, "timestamp_sample");
  EXPECT_EQ(a0->device_id, 0x1001);
  EXPECT_EQ(a0->unit, "m/s^2");
  EXPECT_EQ(a0->values[3 * 7], 3.5);
  EXPECT_FLOAT_EQ(a0->values[3 * 7 + 2], 9.81f);
  EXPECT_TRUE(a0->note.empty()) << a0->note;
  const SensorStream* a1 = Find(log, "sensor_accel:1", StreamKind::kAccel);
  ASSERT_NE(a1, nullptr);
  EXPECT_EQ(a1->samples(), 5);
  EXPECT_EQ(a1->device_id, 0x1002);
  EXPECT_NE(a1->note.find("logged at 5 Hz"), std::string::npos) << a1->note;
  EXPECT_NE(a1->note.find("SDLOG_PROFILE"), std::string::npos);
  const SensorStream* mag = Find(log, "sensor_mag:0", StreamKind::kMag);
  ASSERT_NE(mag, nullptr);
  EXPECT_EQ(mag->unit, "gauss");
  EXPECT_EQ(mag->samples(), 100);
  EXPECT_NEAR(mag->values[0], 20, 1e-5);  // 0.2 gauss = 20 µT
  EXPECT_NEAR(mag->values[2], 45, 1e-5);
  EXPECT_EQ(mag->t_ns[1], 1'010'002'000);
  const SensorStream* temp = Find(log, "sensor_accel:0", StreamKind::kTemperature);
  ASSERT_NE(temp, nullptr);
  EXPECT_EQ(temp->samples(), 1000);
  EXPECT_FLOAT_EQ(temp->values[100], 41);
  EXPECT_EQ(temp->unit, "degC");
  // The magnetometer's NaN temperature ("no sensor") gives no stream.
  EXPECT_EQ(Find(log, "sensor_mag:0", StreamKind::kTemperature), nullptr);
  // Order: accel, gyro, mag, temperature.
  ASSERT_EQ(log.streams.size(), 7u);
  EXPECT_EQ(log.streams[0].Name(), "sensor_accel:0");
  EXPECT_EQ(log.streams[2].kind, StreamKind::kGyro);
  EXPECT_EQ(log.streams[3].kind, StreamKind::kMag);
  EXPECT_EQ(log.streams[4].kind, StreamKind::kTemperature);
  EXPECT_TRUE(log.warnings.empty());
}

TEST(ULogTest, ZeroTimestampSampleFallsBackToTimestampForTheStream) {
  ULogWriter w;
  w.Format(testing::kSensorGyroFormat).Subscribe(0, 3, "sensor_gyro");
  for (int k = 0; k < 10; ++k) {
    const uint64_t t = 5000 + 1000 * k;
    w.Data(3, TriadData(t + 50, k == 6 ? 0 : t, 7, 0, 0, 0, 25));
  }
  const SensorLog log = ReadOk(w.bytes());
  const SensorStream* g = Find(log, "sensor_gyro:0", StreamKind::kGyro);
  ASSERT_NE(g, nullptr);
  EXPECT_EQ(g->time_source, "timestamp");
  for (int k = 0; k < 10; ++k) EXPECT_EQ(g->t_ns[k], (5050 + 1000 * k) * 1000);
  EXPECT_EQ(Find(log, "sensor_gyro:0", StreamKind::kTemperature)->time_source, "timestamp");
}

TEST(ULogTest, FifoBurstsExpandToSampleTimesAndWinOverSensorAccel) {
  ULogWriter w;
  w.Format(testing::kSensorAccelFifoFormat).Format(testing::kSensorAccelFormat);
  w.Format(testing::kSensorGyroFifoFormat);
  w.Subscribe(0, 1, "sensor_accel_fifo").Subscribe(0, 2, "sensor_accel");
  w.Subscribe(1, 3, "sensor_gyro_fifo");
  const float scale = 9.81f / 2048;
  for (int m = 0; m < 4; ++m) {
    std::vector<std::vector<int16_t>> burst;
    for (int i = 0; i < 8; ++i)
      burst.push_back({static_cast<int16_t>(8 * m + i), -1, static_cast<int16_t>(2048)});
    const uint64_t last = 10'000 + 1000 * m;  // 8 readings 125 µs apart end here
    w.Data(1, FifoData(last + 20, last, 0x300, 125, scale, burst));
    w.Data(2, TriadData(last + 30, last, 0x300, 1, 2, 3, 45));
    burst.resize(m + 1);  // a burst may hold fewer readings
    w.Data(3, FifoData(last + 20, last, 0x301, 250.5f, 0.001f, burst));
  }
  const SensorLog log = ReadOk(w.bytes());
  EXPECT_EQ(Find(log, "sensor_accel:0", StreamKind::kAccel), nullptr);  // fifo chosen
  const SensorStream* a = Find(log, "sensor_accel_fifo:0", StreamKind::kAccel);
  ASSERT_NE(a, nullptr);
  ASSERT_EQ(a->samples(), 32);
  for (int j = 0; j < 32; ++j) {
    const int m = j / 8, i = j % 8;
    EXPECT_EQ(a->t_ns[j], (10'000 + 1000 * m) * 1000 - (7 - i) * 125'000) << j;
    EXPECT_DOUBLE_EQ(a->values[3 * j], j * static_cast<double>(scale));
    EXPECT_DOUBLE_EQ(a->values[3 * j + 2], 2048 * static_cast<double>(scale));
  }
  EXPECT_EQ(a->device_id, 0x300);
  const SensorStream* g = Find(log, "sensor_gyro_fifo:1", StreamKind::kGyro);
  ASSERT_NE(g, nullptr);
  EXPECT_EQ(g->samples(), 1 + 2 + 3 + 4);
  EXPECT_EQ(g->t_ns[1], 11'000'000 - 250'500);  // the second message's first of two readings
  // sensor_accel's temperature is read though its values are not.
  const SensorStream* temp = Find(log, "sensor_accel:0", StreamKind::kTemperature);
  ASSERT_NE(temp, nullptr);
  EXPECT_EQ(temp->samples(), 4);
}

TEST(ULogTest, SensorCombinedWhenNothingElseWithANote) {
  ULogWriter w;
  w.Format(testing::kSensorCombinedFormat).Subscribe(0, 4, "sensor_combined");
  const float gyro[3] = {0.1f, 0.2f, 0.3f}, accel[3] = {0, 0, -9.8f};
  w.Data(4, CombinedData(1000, gyro, -500, accel));
  w.Data(4, CombinedData(2000, gyro, 0x7fffffff, accel));  // no accelerometer sample
  w.Data(4, CombinedData(3000, gyro, 200, accel));
  const SensorLog log = ReadOk(w.bytes());
  const SensorStream* g = Find(log, "sensor_combined:0", StreamKind::kGyro);
  const SensorStream* a = Find(log, "sensor_combined:0", StreamKind::kAccel);
  ASSERT_TRUE(g && a);
  EXPECT_EQ(g->samples(), 3);
  ASSERT_EQ(a->samples(), 2);
  EXPECT_EQ(a->t_ns[0], 500'000);
  EXPECT_EQ(a->t_ns[1], 3'200'000);
  EXPECT_EQ(g->device_id, -1);
  EXPECT_NE(a->note.find("already corrected"), std::string::npos);
  EXPECT_FLOAT_EQ(a->values[2], -9.8f);
}

TEST(ULogTest, NestedTypesArraysAndPaddingAreLaidOut) {
  ULogWriter w;
  // x, y, z after a nested array of a nested type that itself has padding in the middle.
  w.Format("inner_s:uint8_t a;uint8_t[3] _padding0;double[2] b;");
  w.Format("outer_s:inner_s[2] pair;char[5] label;");
  w.Format(
      "sensor_gyro:uint64_t timestamp;outer_s[3] blocks;uint16_t device_id;float x;float y;"
      "float z;uint8_t[6] _padding0;");
  w.Subscribe(2, 9, "sensor_gyro");
  testing::Packer p;
  p.Put(uint64_t{123}).Zeros(3 * (2 * 20 + 5)).Put(uint16_t{77});
  p.Put(1.5f).Put(-2.5f).Put(3.5f);
  w.Data(9, p.str());           // without the trailing padding
  w.Data(9, p.Zeros(6).str());  // with it
  const SensorLog log = ReadOk(w.bytes());
  const SensorStream* g = Find(log, "sensor_gyro:2", StreamKind::kGyro);
  ASSERT_NE(g, nullptr);
  ASSERT_EQ(g->samples(), 2);
  EXPECT_EQ(g->values[0], 1.5);
  EXPECT_EQ(g->values[5], 3.5);
  EXPECT_EQ(g->device_id, 77);
  EXPECT_EQ(g->time_source, "timestamp");
  EXPECT_EQ(g->t_ns[0], 123'000);
}

TEST(ULogTest, UnknownTypesSyncDropoutsAndRemovalsAreHandled) {
  ULogWriter w(1000, 2);  // a newer version: read with a warning
  w.Format(testing::kSensorAccelFormat).Subscribe(0, 1, "sensor_accel");
  w.Format(testing::kSensorAccelFormat);  // the same definition again: ignored
  w.Message('Z', "a future message type").Sync().Dropout(20);
  w.Data(1, TriadData(10, 10, 1, 0, 0, 9.8f, 30));
  w.Unsubscribe(1).Subscribe(0, 1, "sensor_accel");  // resubscribed: the same stream continues
  w.Data(1, TriadData(20, 20, 1, 0, 0, 9.8f, 30));
  const SensorLog log = ReadOk(w.bytes());
  EXPECT_EQ(Find(log, "sensor_accel:0", StreamKind::kAccel)->samples(), 2);
  ASSERT_EQ(log.warnings.size(), 1u);
  EXPECT_NE(log.warnings[0].find("version 2"), std::string::npos);
}

TEST(ULogTest, ASensorFormatWithoutTheFieldsNeededIsSkippedWithAWarning) {
  ULogWriter w;
  w.Format("sensor_gyro:uint64_t timestamp;float x;float y;");
  w.Format(
      "sensor_accel_fifo:uint64_t timestamp;float dt;float scale;float samples;"
      "int16_t[4] x;int16_t[4] y;int16_t[4] z;");
  w.Subscribe(0, 1, "sensor_gyro").Subscribe(1, 2, "sensor_gyro");
  w.Subscribe(0, 3, "sensor_accel_fifo");
  w.Data(1, testing::Packer().Put(uint64_t{5}).Put(1.f).Put(2.f).str());
  const SensorLog log = ReadOk(w.bytes());
  EXPECT_TRUE(log.streams.empty());
  ASSERT_EQ(log.warnings.size(), 2u);  // once per topic
  EXPECT_NE(log.warnings[0].find("sensor_gyro not read: its format (sensor_gyro) lacks z"),
            std::string::npos)
      << log.warnings[0];
  EXPECT_NE(log.warnings[1].find("lacks an integer samples"), std::string::npos) << log.warnings[1];
}

TEST(ULogTest, AppendedDataIsReadAfterACutMainLog) {
  ULogWriter w;
  w.FlagBits(1, {0});  // offset patched below
  w.Format(testing::kSensorAccelFormat).Subscribe(0, 1, "sensor_accel");
  for (int k = 0; k < 3; ++k) w.Data(1, TriadData(100 + k, 100 + k, 1, k, 0, 0, 20));
  std::string& bytes = w.mutable_bytes();
  bytes.resize(bytes.size() - 5);  // the last message cut: the logger crashed
  const uint64_t offset = bytes.size();
  std::memcpy(&bytes[16 + 3 + 16], &offset, 8);
  w.Data(1, TriadData(500, 500, 1, 7, 0, 0, 20));  // appended (e.g. by the hardfault handler)
  const SensorLog log = ReadOk(w.bytes());
  const SensorStream* a = Find(log, "sensor_accel:0", StreamKind::kAccel);
  ASSERT_NE(a, nullptr);
  ASSERT_EQ(a->samples(), 3);
  EXPECT_EQ(a->values[6], 7);
  EXPECT_EQ(a->t_ns[2], 500'000);
  ASSERT_EQ(log.warnings.size(), 1u);
  EXPECT_NE(log.warnings[0].find("before data appended at byte " + std::to_string(offset)),
            std::string::npos)
      << log.warnings[0];
}

// TriadLog's messages with the last third as data appended to a main log cut mid-message.
std::string AppendedLog() {
  ULogWriter w;
  w.FlagBits(1, {0});
  const std::string triads = TriadLog(40).bytes().substr(16 + 3 + 40);  // after header and 'B'
  const size_t split = 2 * triads.size() / 3;
  std::string& bytes = w.mutable_bytes();
  bytes += triads.substr(0, split);
  bytes += std::string(
      "\x30\x00"
      "D\x0a",
      4);  // a message cut after its header
  const uint64_t offset = bytes.size();
  std::memcpy(&bytes[16 + 3 + 16], &offset, 8);
  // The appended part starts on a message boundary of TriadLog.
  size_t at = 0;
  while (at < split)
    at += 3 + static_cast<uint8_t>(triads[at]) + 256 * static_cast<uint8_t>(triads[at + 1]);
  bytes += triads.substr(at);
  return bytes;
}

TEST(ULogTest, ACutAtEveryByteReadsToTheLastWholeMessage) {
  const std::string logs[] = {TriadLog(40).bytes(), AppendedLog()};
  for (const std::string& full : logs) {
    const SensorLog whole = ReadOk(full);
    // The appended log's main part ends mid-message: one warning; the other log is whole.
    EXPECT_EQ(whole.warnings.size(), &full == &logs[1] ? 1u : 0u);
    for (size_t cut = 0; cut < full.size(); ++cut) {
      SensorLog log;
      Status status =
          ReadULog(std::string_view(full).substr(0, cut), "cut.ulg", SensorLogLimits(), &log);
      if (cut < 16) {  // the header itself is incomplete: not a log
        ASSERT_FALSE(status.ok());
        EXPECT_NE(status.message().find("not a ULog"), std::string::npos);
        continue;
      }
      ASSERT_TRUE(status.ok()) << cut << ": " << status.ToString();
      for (const SensorStream& s : log.streams) {
        const SensorStream* same = Find(whole, s.Name(), s.kind);
        ASSERT_NE(same, nullptr) << cut << " " << s.Name();
        EXPECT_LE(s.samples(), same->samples());
        for (int64_t i = 0; i < s.samples(); ++i) ASSERT_EQ(s.t_ns[i], same->t_ns[i]);
      }
      // A cut on a message boundary is a whole log; any other names its offset.
      for (const std::string& warning : log.warnings) {
        const bool expected = warning.find("log cut at byte") != std::string::npos ||
                              warning.find("is missing: the file ends") != std::string::npos;
        EXPECT_TRUE(expected) << warning;
      }
    }
  }
}

TEST(ULogTest, DamageIsAnErrorNamingOffsetAndMessage) {
  const std::string header_and_format = [] {
    ULogWriter w;
    w.Format(testing::kSensorAccelFormat);
    return w.bytes();
  }();
  const size_t a_at = header_and_format.size();  // where the message after the format starts
  struct Case {
    const char* what;
    std::function<void(ULogWriter*)> write;
    const char* expect;
  };
  const std::vector<Case> cases = {
      {"unsubscribed", [](ULogWriter* w) { w->Data(5, TriadData(1, 1, 1, 0, 0, 0, 0)); },
       "msg_id 5 is not subscribed"},
      {"too long",
       [](ULogWriter* w) {
         w->Subscribe(0, 1, "sensor_accel").Data(1, TriadData(1, 1, 1, 0, 0, 0, 0) + "12345");
       },
       "49 bytes of sensor_accel data, its format holds 44 to 48"},
      {"too short",
       [](ULogWriter* w) { w->Subscribe(0, 1, "sensor_accel").Data(1, std::string(10, '\0')); },
       "10 bytes of sensor_accel data"},
      {"undefined", [](ULogWriter* w) { w->Subscribe(0, 1, "sensor_gyro"); },
       "type 'sensor_gyro' is not defined"},
      {"cycle",
       [](ULogWriter* w) {
         w->Format("a_s:b_s x;").Format("b_s:a_s[2] y;").Format("t:a_s v;").Subscribe(0, 1, "t");
       },
       "contains itself"},
      {"huge",
       [](ULogWriter* w) {
         w->Format("a_s:double[60000] x;").Format("t:a_s[60000] v;").Subscribe(0, 1, "t");
       },
       "larger than a message can hold"},
      {"array size", [](ULogWriter* w) { w->Format("t:float[99999999999999999999] v;"); },
       "malformed array size"},
      {"redefined", [](ULogWriter* w) { w->Format("sensor_accel:uint64_t timestamp;"); },
       "defined twice, differently"},
      {"too many fields",
       [](ULogWriter* w) {
         std::string fields;
         for (int i = 0; i < 5000; ++i) fields += "int8_t a" + std::to_string(i) + ";";
         for (int k = 0; k < 60; ++k) w->Format("t" + std::to_string(k) + ":" + fields);
       },
       "more than 250000 fields"},
      {"flags", [](ULogWriter* w) { w->FlagBits(2); }, "must be the first message"},
      {"type 0", [](ULogWriter* w) { w->Message('\0', "xyz"); }, "type 0"},
      {"bad key",
       [](ULogWriter* w) {
         w->Message('I',
                    "\x09"
                    "ab");
       },
       "key length"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    ULogWriter w;
    w.Format(testing::kSensorAccelFormat);
    c.write(&w);
    const Status status = ReadError(w.bytes());
    EXPECT_NE(status.message().find(c.expect), std::string::npos) << status.message();
    EXPECT_NE(status.message().find("at byte "), std::string::npos);
    EXPECT_NE(status.message().find("(message "), std::string::npos);
    EXPECT_EQ(status.file(), "test.ulg");
  }
  ULogWriter w;
  w.Format(testing::kSensorAccelFormat).Data(5, "xx");
  const Status status = ReadError(w.bytes());
  EXPECT_NE(status.message().find("at byte " + std::to_string(a_at) + " (message 1, 'D'"),
            std::string::npos)
      << status.message();
  // Unknown incompatible flags: refused.
  ULogWriter newer;
  newer.FlagBits(0x3);
  EXPECT_NE(ReadError(newer.bytes()).message().find("incompatible"), std::string::npos);
  EXPECT_NE(ReadError("ULog").message().find("not a ULog"), std::string::npos);
}

TEST(ULogTest, MoreSamplesThanTheLimitIsAnError) {
  SensorLogLimits limits;
  limits.max_samples = 100;
  SensorLog log;
  const Status status = ReadULog(TriadLog(200).bytes(), "big.ulg", limits, &log);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find("max_samples"), std::string::npos);
  EXPECT_TRUE(log.streams.empty());
}

// pyulog's sample logs, read by calibd and by pyulog (tests/formats/ulog_pyulog_summary.py):
// per stream the count, first and last time and channel means agree.
struct Reference {
  int64_t count = 0, first = 0, last = 0;
  std::vector<double> means;
};

std::string RunCommand(const std::string& command) {
  std::string out;
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return out;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) out.append(buf, n);
  pclose(pipe);
  return out;
}

TEST(ULogTest, AgreesWithPyulogOnItsSampleLogs) {
  const std::string data_dir = "/work/data/ulog";
  const char* env = std::getenv("CALIBD_PYULOG_PATH");
  const std::string pyulog = env != nullptr ? env : "/work/data/pyulog";
  if (!std::filesystem::is_directory(data_dir)) GTEST_SKIP() << data_dir << " is absent";
  if (!std::filesystem::exists(pyulog + "/pyulog/core.py"))
    GTEST_SKIP() << "pyulog is absent (" << pyulog << "/pyulog; set CALIBD_PYULOG_PATH)";
  std::string python;
  for (const char* candidate : {"python3", "/usr/bin/python3"})
    if (std::system((std::string(candidate) + " -c 'import numpy' 2>/dev/null").c_str()) == 0) {
      python = candidate;
      break;
    }
  if (python.empty()) GTEST_SKIP() << "no python3 with numpy for pyulog";
  const std::string script =
      calibd::test_paths::SourceDir() + "/tests/formats/ulog_pyulog_summary.py";
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(data_dir)) {
    if (entry.path().extension() != ".ulg") continue;
    SCOPED_TRACE(entry.path().string());
    ++files;
    std::ifstream in(entry.path(), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), {});
    const SensorLog log = ReadOk(bytes);
    std::map<std::string, Reference> reference;  // "topic:instance kind"
    std::istringstream lines(RunCommand("PYTHONPATH=" + pyulog + " " + python + " " + script + " " +
                                        entry.path().string()));
    std::string line;
    while (std::getline(lines, line)) {
      std::istringstream fields(line);
      std::string name, kind;
      Reference r;
      fields >> name >> kind >> r.count >> r.first >> r.last;
      for (double m; fields >> m;) r.means.push_back(m);
      reference[name + " " + kind] = r;
    }
    ASSERT_FALSE(reference.empty()) << "pyulog printed nothing";
    for (const SensorStream& s : log.streams) {
      SCOPED_TRACE(s.Name() + " " + StreamKindName(s.kind));
      auto it = reference.find(s.Name() + " " + StreamKindName(s.kind));
      ASSERT_NE(it, reference.end());
      const Reference& r = it->second;
      EXPECT_EQ(s.samples(), r.count);
      EXPECT_EQ(s.t_ns.front(), r.first);
      EXPECT_EQ(s.t_ns.back(), r.last);
      const int dim = StreamDimension(s.kind);
      ASSERT_EQ(static_cast<int>(r.means.size()), dim);
      for (int c = 0; c < dim; ++c) {
        double sum = 0;
        for (int64_t i = 0; i < s.samples(); ++i) sum += s.values[i * dim + c];
        // Both sum the same float values in double: only the order of the sums differs.
        EXPECT_NEAR(sum / s.samples(), r.means[c], 1e-9 * (1 + std::abs(r.means[c])));
      }
    }
    // Every stream pyulog has of the topics calibd chose is read.
    for (const auto& [key, r] : reference) {
      const std::string name = key.substr(0, key.find(' '));
      const std::string topic = name.substr(0, name.find(':'));
      bool chosen_topic = false, present = false;
      for (const SensorStream& s : log.streams) {
        const bool same_kind = key.substr(key.find(' ') + 1) == StreamKindName(s.kind);
        chosen_topic = chosen_topic || (s.topic == topic && same_kind);
        present = present || (s.Name() == name && same_kind);
      }
      EXPECT_TRUE(present || !chosen_topic) << key;
    }
  }
  if (files == 0) GTEST_SKIP() << "no .ulg files in " << data_dir;
}

}  // namespace
}  // namespace calibd::server
