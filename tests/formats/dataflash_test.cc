// The DataFlash reader (formats/dataflash.h): logs from a writer of our own
// (tests/lib/dataflash_writer.h) for the edge cases, and a public ArduPilot log compared with
// pymavlink's DFReader as an independent reader (skipped when the log or pymavlink is absent).
#include "formats/dataflash.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "tests/lib/dataflash_writer.h"
#include "tests/lib/test_paths.h"

namespace calibd::server {
namespace {

using calibd::testing::DataFlashWriter;
using calibd::testing::kDfAcc;
using calibd::testing::kDfFmtu;
using calibd::testing::kDfImu;
using calibd::testing::kDfIsbd;
using calibd::testing::kDfIsbh;
using calibd::testing::kDfMag;
using calibd::testing::kDfMult;
using calibd::testing::kDfParm;
using calibd::testing::kDfUnit;

Status Read(const std::string& bytes, SensorLog* log, SensorLogLimits limits = {}) {
  return ReadDataFlash(bytes, "test.bin", limits, log);
}

const SensorStream* Find(const SensorLog& log, const std::string& name, StreamKind kind) {
  for (const SensorStream& s : log.streams)
    if (s.Name() == name && s.kind == kind) return &s;
  return nullptr;
}

// Accel, gyro and temperature of IMU instance i at sample n: distinct per instance and sample.
void ImuValues(int i, int n, double gyro[3], double accel[3], double* temp) {
  for (int k = 0; k < 3; ++k) {
    gyro[k] = 0.01 * (k + 1) + 0.1 * i + 1e-4 * n;
    accel[k] = (k == 2 ? -9.81 : 0.5 * k) + i + 1e-3 * n;
  }
  *temp = 30 + i + 0.01 * n;
}

// Three IMUs at 1 kHz and two magnetometers at 100 Hz, with ArduPilot's FMTU, UNIT, MULT and
// device id parameters, as a 4.x log has them; `junk` adds junk after the formats and after the
// first IMU message: stray bytes, a lone 0xA3, a header of an undefined type.
std::string ModernLog(int imu_samples, bool junk = false) {
  DataFlashWriter w;
  calibd::testing::WriteArduPilotFormats(&w);
  if (junk) w.Raw(std::string("\x01\x02\xA3\x00", 4));
  w.Message(kDfUnit, {0, static_cast<int>('o'), "m/s/s"});
  w.Message(kDfUnit, {0, static_cast<int>('E'), "rad/s"});
  w.Message(kDfUnit, {0, static_cast<int>('O'), "degC"});
  w.Message(kDfUnit, {0, static_cast<int>('G'), "Gauss"});
  w.Message(kDfMult, {0, static_cast<int>('0'), 1.0});
  w.Message(kDfMult, {0, static_cast<int>('C'), static_cast<double>(0.001f)});  // as logged
  w.Message(kDfFmtu, {0, kDfImu, "s#EEEooo--O--zz", "F-000000-----00"});
  w.Message(kDfFmtu, {0, kDfMag, "s#GGGGGGGGG-s", "F-CCCCCCCCC-F"});
  w.Message(kDfParm, {0, "INS_ACC_ID", 2753028, 0});
  w.Message(kDfParm, {0, "INS_GYR2_ID", 2752780, 0});
  w.Message(kDfParm, {0, "COMPASS_DEV_ID2", 131874, 0});
  for (int n = 0; n < imu_samples; ++n) {
    for (int i = 0; i < 3; ++i) {
      double gyro[3], accel[3], temp;
      ImuValues(i, n, gyro, accel, &temp);
      calibd::testing::WriteImu(&w, 1'000'000 + 1000 * n + i, i, gyro, accel, temp);
      if (junk && n == 0 && i == 0) w.Raw(std::string("\xA3\x95\xEE\xA3", 4));
    }
    if (n % 10 == 0)
      for (int i = 0; i < 2; ++i) {
        const int mg[3] = {200 + n, -100 + i, 450};
        calibd::testing::WriteMag(&w, 1'000'500 + 1000 * n, i, mg);
      }
  }
  return w.bytes();
}

TEST(DataFlashTest, ReadsImusPerInstanceAndMagsInMicrotesla) {
  SensorLog log;
  ASSERT_TRUE(Read(ModernLog(50), &log).ok());
  EXPECT_EQ(log.format, "dataflash");
  EXPECT_TRUE(log.warnings.empty()) << log.warnings[0];
  // IMU 0, 1, 2 (accel, gyro, temperature each), then MAG 0, 1.
  ASSERT_EQ(log.streams.size(), 11u);
  const std::vector<std::pair<std::string, StreamKind>> order = {
      {"IMU:0", StreamKind::kAccel},       {"IMU:0", StreamKind::kGyro},
      {"IMU:0", StreamKind::kTemperature}, {"IMU:1", StreamKind::kAccel},
      {"IMU:1", StreamKind::kGyro},        {"IMU:1", StreamKind::kTemperature},
      {"IMU:2", StreamKind::kAccel},       {"IMU:2", StreamKind::kGyro},
      {"IMU:2", StreamKind::kTemperature}, {"MAG:0", StreamKind::kMag},
      {"MAG:1", StreamKind::kMag}};
  for (size_t j = 0; j < order.size(); ++j) {
    EXPECT_EQ(log.streams[j].Name(), order[j].first) << j;
    EXPECT_EQ(log.streams[j].kind, order[j].second) << j;
  }
  for (int i = 0; i < 3; ++i) {
    const std::string name = "IMU:" + std::to_string(i);
    const SensorStream* accel = Find(log, name, StreamKind::kAccel);
    const SensorStream* gyro = Find(log, name, StreamKind::kGyro);
    const SensorStream* temp = Find(log, name, StreamKind::kTemperature);
    ASSERT_EQ(accel->samples(), 50);
    ASSERT_EQ(temp->values.size(), 50u);
    EXPECT_EQ(accel->time_source, "TimeUS");
    EXPECT_EQ(accel->unit, "m/s/s");
    EXPECT_EQ(gyro->unit, "rad/s");
    EXPECT_EQ(temp->unit, "degC");
    for (int n = 0; n < 50; ++n) {
      double g[3], a[3], t;
      ImuValues(i, n, g, a, &t);
      EXPECT_EQ(accel->t_ns[n], (1'000'000 + 1000 * n + i) * int64_t{1000});  // µs -> ns exact
      for (int k = 0; k < 3; ++k) {
        EXPECT_EQ(accel->values[3 * n + k], static_cast<double>(static_cast<float>(a[k])));
        EXPECT_EQ(gyro->values[3 * n + k], static_cast<double>(static_cast<float>(g[k])));
      }
      EXPECT_EQ(temp->values[n], static_cast<double>(static_cast<float>(t)));
    }
  }
  // Device ids where the log's parameters name them.
  EXPECT_EQ(Find(log, "IMU:0", StreamKind::kAccel)->device_id, 2753028);
  EXPECT_EQ(Find(log, "IMU:0", StreamKind::kTemperature)->device_id, 2753028);
  EXPECT_EQ(Find(log, "IMU:0", StreamKind::kGyro)->device_id, -1);
  EXPECT_EQ(Find(log, "IMU:1", StreamKind::kGyro)->device_id, 2752780);
  EXPECT_EQ(Find(log, "MAG:1", StreamKind::kMag)->device_id, 131874);
  const SensorStream* mag = Find(log, "MAG:1", StreamKind::kMag);
  ASSERT_EQ(mag->samples(), 5);
  EXPECT_EQ(mag->unit, "0.001 Gauss");
  EXPECT_NEAR(mag->values[3], 21.0, 1e-12);  // 210 mG = 21 µT
  EXPECT_NEAR(mag->values[4], -9.9, 1e-12);
  EXPECT_NEAR(mag->values[5], 45.0, 1e-12);
}

TEST(DataFlashTest, OlderLogsNameInstancesByMessageAndTimeInMilliseconds) {
  DataFlashWriter w;
  w.FmtOfFmt();
  w.Fmt(140, "IMU", "Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ");
  w.Fmt(141, "IMU2", "Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ");
  w.Fmt(142, "MAG", "Ihhh", "TimeMS,MagX,MagY,MagZ");
  for (int n = 0; n < 20; ++n) {
    w.Message(140, {63947 + 20 * n, 0.1, 0.2, 0.3, 1, 2, 3});
    w.Message(141, {63947 + 20 * n, -0.1, -0.2, -0.3, -1, -2, -3});
    w.Message(142, {63957 + 20 * n, 100, 200, -300});
  }
  SensorLog log;
  ASSERT_TRUE(Read(w.bytes(), &log).ok());
  const SensorStream* imu1 = Find(log, "IMU:1", StreamKind::kGyro);
  ASSERT_NE(imu1, nullptr);
  EXPECT_EQ(imu1->samples(), 20);
  EXPECT_EQ(imu1->time_source, "TimeMS");
  EXPECT_EQ(imu1->t_ns[1], 63967 * int64_t{1'000'000});
  EXPECT_EQ(imu1->values[0], static_cast<double>(-0.1f));
  EXPECT_NE(imu1->note.find("IMU2"), std::string::npos) << imu1->note;
  EXPECT_EQ(Find(log, "IMU:0", StreamKind::kAccel)->values[2], 3.0);
  EXPECT_EQ(Find(log, "IMU:0", StreamKind::kTemperature), nullptr);  // no T in this IMU
  const SensorStream* mag = Find(log, "MAG:0", StreamKind::kMag);
  ASSERT_NE(mag, nullptr);
  EXPECT_NEAR(mag->values[2], -30.0, 1e-12);  // milligauss without FMTU: -300 mG = -30 µT
}

TEST(DataFlashTest, SkipsJunkBetweenMessagesAndCountsIt) {
  SensorLog clean, junky;
  ASSERT_TRUE(Read(ModernLog(5), &clean).ok());
  ASSERT_TRUE(Read(ModernLog(5, /*junk=*/true), &junky).ok());
  ASSERT_EQ(clean.streams.size(), junky.streams.size());
  for (size_t j = 0; j < clean.streams.size(); ++j) {
    EXPECT_EQ(clean.streams[j].t_ns, junky.streams[j].t_ns);
    EXPECT_EQ(clean.streams[j].values, junky.streams[j].values);
  }
  DataFlashWriter formats;
  calibd::testing::WriteArduPilotFormats(&formats);
  ASSERT_EQ(junky.warnings.size(), 1u);
  EXPECT_NE(junky.warnings[0].find("skipped 8 bytes"), std::string::npos) << junky.warnings[0];
  EXPECT_NE(junky.warnings[0].find("in 2 places (the first at byte " +
                                   std::to_string(formats.size()) + ")"),
            std::string::npos)
      << junky.warnings[0];
}

TEST(DataFlashTest, SampleTimeWhereEverySampleHasOneElseLoggingTime) {
  for (const bool with_zero : {false, true}) {
    DataFlashWriter w;
    calibd::testing::WriteArduPilotFormats(&w);
    for (int n = 0; n < 10; ++n)
      w.Message(kDfAcc, {2000 + 10 * n, 1, (with_zero && n == 3) ? 0 : 1990 + 10 * n, 1, 2, 3});
    SensorLog log;
    ASSERT_TRUE(Read(w.bytes(), &log).ok());
    const SensorStream* acc = Find(log, "ACC:1", StreamKind::kAccel);
    ASSERT_NE(acc, nullptr);
    ASSERT_EQ(acc->samples(), 10);
    EXPECT_EQ(acc->time_source, with_zero ? "TimeUS" : "SampleUS");
    EXPECT_EQ(acc->t_ns[4], (with_zero ? 2040 : 2030) * int64_t{1000});
    EXPECT_EQ(acc->note.find("SampleUS is zero or absent in 1 of 10") != std::string::npos,
              with_zero)
        << acc->note;
  }
}

// The batch sampler: an ISBH per batch (sensor type, instance, multiplier, sample count, first
// sample's time, rate), then its samples 32 per ISBD.
TEST(DataFlashTest, ReadsBatchSamplerBatches) {
  DataFlashWriter w;
  calibd::testing::WriteArduPilotFormats(&w);
  // Row j of ISBD seqno q holds sample 32 q + j: x = 10 (32 q + j), y = -x, z = 7.
  const auto data = [&](int batch, int seqno) {
    std::vector<int16_t> x(32), y(32), z(32, 7);
    for (int j = 0; j < 32; ++j) x[j] = static_cast<int16_t>(10 * (32 * seqno + j)), y[j] = -x[j];
    w.Message(kDfIsbd, {5'000'000 + seqno, batch, seqno, x, y, z});
  };
  // Batch 7: accelerometer 1, 40 samples at 1 kHz from 2 s, multiplier 100.
  w.Message(kDfIsbh, {4'000'000, 7, 0, 1, 100, 40, 2'000'000, 1000.0});
  data(7, 0);
  data(7, 1);  // 8 of its 32 rows are samples
  data(7, 2);  // past the batch: not read
  data(9, 0);  // no ISBH 9: not read
  // Batch 8: gyroscope 0, 32 samples at 3 kHz (a period of 333.3 µs) from 3 s, multiplier 1000.
  w.Message(kDfIsbh, {6'000'000, 8, 1, 0, 1000, 32, 3'000'000, 3000.0});
  data(8, 0);
  SensorLog log;
  ASSERT_TRUE(Read(w.bytes(), &log).ok());
  const SensorStream* accel = Find(log, "ISBD:1", StreamKind::kAccel);
  const SensorStream* gyro = Find(log, "ISBD:0", StreamKind::kGyro);
  ASSERT_NE(accel, nullptr);
  ASSERT_NE(gyro, nullptr);
  EXPECT_EQ(log.streams.size(), 2u);
  ASSERT_EQ(accel->samples(), 40);
  EXPECT_EQ(accel->time_source, "SampleUS");
  EXPECT_EQ(accel->unit, "m/s/s");
  for (int k = 0; k < 40; ++k) {
    EXPECT_EQ(accel->t_ns[k], 2'000'000'000 + int64_t{1'000'000} * k);
    EXPECT_DOUBLE_EQ(accel->values[3 * k], 10.0 * k / 100);
    EXPECT_DOUBLE_EQ(accel->values[3 * k + 1], -10.0 * k / 100);
    EXPECT_DOUBLE_EQ(accel->values[3 * k + 2], 0.07);
  }
  ASSERT_EQ(gyro->samples(), 32);
  EXPECT_EQ(gyro->unit, "rad/s");
  EXPECT_EQ(gyro->t_ns[1], 3'000'333'333);  // rounded to the ns
  EXPECT_EQ(gyro->t_ns[3], 3'001'000'000);
  EXPECT_DOUBLE_EQ(gyro->values[3 * 5], 0.05);
  ASSERT_EQ(log.warnings.size(), 1u);
  EXPECT_NE(log.warnings[0].find("2 ISBD messages"), std::string::npos) << log.warnings[0];
}

// A log cut at every byte reads to its last whole message, with a warning naming the cut's
// offset exactly when the cut is inside a message; before the first FMT is whole there is nothing
// to read.
TEST(DataFlashTest, CutAtEveryByteReadsToTheLastWholeMessage) {
  DataFlashWriter w;
  calibd::testing::WriteArduPilotFormats(&w);
  std::vector<size_t> ends;        // message boundaries after the formats
  std::vector<int> samples_of{0};  // samples of the message ending at ends[j]
  const double g[3] = {0.1, 0.2, 0.3}, a[3] = {1, 2, 3};
  const int mg[3] = {1, 2, 3};
  ends.push_back(w.size());
  for (int n = 0; n < 6; ++n) {
    calibd::testing::WriteImu(&w, 1000 + n, n % 2, g, a, 25);
    ends.push_back(w.size());
    samples_of.push_back(3);  // accel, gyro, temperature
    if (n % 3 == 0) {
      calibd::testing::WriteMag(&w, 1000 + n, 0, mg);
      ends.push_back(w.size());
      samples_of.push_back(1);
    }
  }
  const std::string full = w.bytes();
  for (size_t cut = 0; cut <= full.size(); ++cut) {
    SensorLog log;
    const Status s = Read(full.substr(0, cut), &log);
    if (cut < static_cast<size_t>(dataflash::kFmtLength)) {
      EXPECT_FALSE(s.ok()) << cut;
      EXPECT_NE(s.message().find("no FMT message"), std::string::npos) << s.message();
      continue;
    }
    ASSERT_TRUE(s.ok()) << cut << ": " << s.message();
    int64_t samples = 0;
    for (const SensorStream& stream : log.streams) samples += stream.samples();
    // Whole data messages in the prefix: IMU messages give 3 streams' samples, MAG 1.
    int64_t expected = 0;
    for (size_t j = 1; j < ends.size() && ends[j] <= cut; ++j) expected += samples_of[j];
    EXPECT_EQ(samples, expected) << cut;
    size_t last_boundary = 0;
    for (size_t j = 0; j < ends.size(); ++j)
      if (ends[j] <= cut) last_boundary = ends[j];
    const bool at_boundary =
        cut == full.size() || std::find(ends.begin(), ends.end(), cut) != ends.end();
    if (cut < ends[0]) continue;  // inside the formats: FMT boundaries are not listed
    if (at_boundary) {
      EXPECT_TRUE(log.warnings.empty() || log.warnings[0].find("no IMU") != std::string::npos)
          << cut << ": " << log.warnings[0];
    } else {
      ASSERT_FALSE(log.warnings.empty()) << cut;
      EXPECT_NE(log.warnings[0].find("log cut at byte " + std::to_string(last_boundary)),
                std::string::npos)
          << cut << ": " << log.warnings[0];
    }
  }
}

TEST(DataFlashTest, DamagedFmtIsAnErrorNamingTheOffsetAndMessage) {
  struct Case {
    const char* format;
    int length;
    const char* columns;
    const char* says;
  };
  const Case cases[] = {
      {"Qfff", 10, "TimeUS,AccX,AccY,AccZ", "length 10 disagrees with its format"},
      {"Qfxf", -1, "TimeUS,AccX,AccY,AccZ", "format character 'x'"},
      {"Qfff", -1, "TimeUS,AccX,AccY", "3 column names for 4 format characters"},
  };
  for (const Case& c : cases) {
    DataFlashWriter w;
    calibd::testing::WriteArduPilotFormats(&w);  // 10 FMT messages
    const size_t offset = w.size();
    w.Fmt(171, "GYR", c.format, c.columns, c.length);
    SensorLog log;
    log.warnings.push_back("stale");
    const Status s = Read(w.bytes(), &log);
    ASSERT_EQ(s.code(), StatusCode::kInvalidInput) << c.says;
    EXPECT_NE(s.message().find("byte " + std::to_string(offset) + ", message 11:"),
              std::string::npos)
        << s.message();
    EXPECT_NE(s.message().find(c.says), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("\"GYR\""), std::string::npos) << s.message();
    EXPECT_EQ(s.file(), "test.bin");
    EXPECT_TRUE(log.streams.empty() && log.warnings.empty());
  }
  // FMT must stay the 89-byte BBnNZ it is.
  DataFlashWriter w;
  w.Fmt(128, "FMT", "BBnN", "Type,Length,Name,Format");
  SensorLog log;
  EXPECT_EQ(Read(w.bytes(), &log).code(), StatusCode::kInvalidInput);
}

TEST(DataFlashTest, BytesWithoutFmtAreNotADataFlashLog) {
  SensorLog log;
  const Status s = Read(std::string(1000, '\xA3'), &log);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("not a DataFlash log"), std::string::npos) << s.message();
  EXPECT_FALSE(Read("", &log).ok());
}

TEST(DataFlashTest, SampleLimitIsAnError) {
  SensorLogLimits limits;
  limits.max_samples = 100;
  SensorLog log;
  const Status s = Read(ModernLog(50), &log, limits);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("more than 100 samples"), std::string::npos) << s.message();
  limits.max_samples = 11 * 50;
  EXPECT_TRUE(Read(ModernLog(50), &log, limits).ok());  // 450 IMU + 10 MAG samples
}

TEST(DataFlashTest, FieldOfAnotherUnitIsNotRead) {
  DataFlashWriter w;
  calibd::testing::WriteArduPilotFormats(&w);
  w.Message(kDfFmtu, {0, kDfMag, "s#ddd------s", "F-000------F"});  // MagX in degrees
  const int mg[3] = {1, 2, 3};
  calibd::testing::WriteMag(&w, 5, 0, mg);
  SensorLog log;
  ASSERT_TRUE(Read(w.bytes(), &log).ok());
  EXPECT_TRUE(log.streams.empty());
  ASSERT_GE(log.warnings.size(), 1u);
  EXPECT_NE(log.warnings[0].find("MAG:0 magnetometer not read"), std::string::npos)
      << log.warnings[0];
}

// ---- A public ArduPilot log against pymavlink's DFReader --------------------------------------

std::string EnvOr(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return v && *v ? v : fallback;
}

// DFReader's reading of `path` (tests/formats/dataflash_reference.py), or null when it did not run.
nlohmann::json ReferenceReading(const std::string& path, const std::string& pymavlink) {
  const std::string command = "PYTHONPATH='" + pymavlink + "' python3 '" +
                              calibd::test_paths::SourceDir() +
                              "/tests/formats/dataflash_reference.py' '" + path + "' 2>/dev/null";
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return nullptr;
  std::string out;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) out.append(buf, n);
  if (pclose(pipe) != 0) return nullptr;
  return nlohmann::json::parse(out, nullptr, /*allow_exceptions=*/false);
}

// The pymavlink source to run, or "" with *why when pymavlink or python3 is absent.
std::string Pymavlink(std::string* why) {
  const std::string pymavlink = EnvOr("CALIBD_PYMAVLINK", "/work/data/pymavlink-src");
  if (!std::filesystem::exists(pymavlink + "/pymavlink/DFReader.py")) {
    *why = "no pymavlink source at " + pymavlink + " (its pymavlink/DFReader.py)";
    return "";
  }
  if (std::system("python3 -c '' >/dev/null 2>&1") != 0) {
    *why = "no python3";
    return "";
  }
  return pymavlink;
}

// Reads the log at `path` and compares every stream with DFReader's reading of it: count, first
// and last time, channel means.
void ExpectAgreesWithPymavlink(const std::string& path, const std::string& pymavlink) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream bytes;
  bytes << in.rdbuf();
  SensorLog log;
  const Status s = ReadDataFlash(bytes.str(), path, {}, &log);
  ASSERT_TRUE(s.ok()) << path << ": " << s.ToString();
  const nlohmann::json ref = ReferenceReading(path, pymavlink);
  ASSERT_TRUE(ref.is_object()) << "pymavlink's DFReader did not read " << path;
  EXPECT_EQ(ref.size(), log.streams.size()) << path;
  for (const SensorStream& stream : log.streams) {
    const std::string key = stream.Name() + " " + StreamKindName(stream.kind);
    ASSERT_TRUE(ref.contains(key)) << path << ": " << key;
    const nlohmann::json& r = ref[key];
    EXPECT_EQ(stream.samples(), r["samples"].get<int64_t>()) << key;
    EXPECT_EQ(stream.t_ns.front(), r["first_ns"].get<int64_t>()) << key;
    EXPECT_EQ(stream.t_ns.back(), r["last_ns"].get<int64_t>()) << key;
    const int dim = StreamDimension(stream.kind);
    for (int k = 0; k < dim; ++k) {
      double sum = 0;
      for (int64_t n = 0; n < stream.samples(); ++n) sum += stream.values[n * dim + k];
      const double mean = sum / stream.samples(), expected = r["means"][k].get<double>();
      // The same values summed in another order: agreement to rounding.
      EXPECT_NEAR(mean, expected, 1e-12 * (1 + std::fabs(expected))) << key << " " << k;
    }
  }
}

TEST(DataFlashTest, PublicLogsAgreeWithPymavlink) {
  const std::string dir = EnvOr("CALIBD_DATAFLASH_DATA", "/work/data/dataflash");
  std::string why;
  const std::string pymavlink = Pymavlink(&why);
  if (pymavlink.empty()) GTEST_SKIP() << why;
  if (!std::filesystem::is_directory(dir)) GTEST_SKIP() << "no DataFlash logs in " << dir;
  int logs = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    std::ifstream in(entry.path(), std::ios::binary);
    char head[3] = {};
    in.read(head, 3);
    if (SniffLogFormat(std::string_view(head, 3)) != LogFormat::kDataFlash) continue;
    ++logs;
    ExpectAgreesWithPymavlink(entry.path().string(), pymavlink);
  }
  if (logs == 0) GTEST_SKIP() << "no DataFlash log (0xA3 0x95 0x80 ...) in " << dir;
}

// Our writer's logs (every stream kind, the batch sampler, an older log) read alike by DFReader.
TEST(DataFlashTest, WrittenLogsAgreeWithPymavlink) {
  std::string why;
  const std::string pymavlink = Pymavlink(&why);
  if (pymavlink.empty()) GTEST_SKIP() << why;
  const std::string dir = calibd::test_paths::SourceDir() + "/tests/fuzz/corpus/fuzz_dataflash/";
  for (const char* seed : {"modern.bin", "batch.bin", "older.bin"})
    ExpectAgreesWithPymavlink(dir + seed, pymavlink);
}

}  // namespace
}  // namespace calibd::server
