// The time column's unit (issue 26, item 1): config `time_unit` (s, ms, us, ns) read by the parser
// so every method sees seconds; a time column that does not look like seconds refused at once
// without it (400 at upload with nothing stored, exit 2 offline, a failed job for a stored log);
// epoch stamps read without losing precision; numbers in query strings for the keys that take a
// number or a name.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "formats/inertial_log.h"
#include "formats/recording.h"
#include "methods/imu/imu_method.h"
#include "methods/noise/noise_method.h"
#include "server/config.h"
#include "tests/lib/sanitizer.h"
#include "tests/server/http_test_util.h"
#include "tests/lib/test_paths.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

constexpr int64_t kEpochNs = 1700000000LL * 1000000000LL;  // 2023-11-14, a whole second

// `ns` nanoseconds written exactly in `unit`: "0.010000000" s, "10.000000" ms, "10000" us,
// "10000000" ns (non-negative).
std::string TimeText(int64_t ns, TimeUnit unit) {
  const int fraction_digits = 9 - TimeUnitDigits(unit);
  int64_t div = 1;
  for (int i = 0; i < fraction_digits; ++i) div *= 10;
  std::string out = std::to_string(ns / div);
  if (fraction_digits > 0) {
    std::string frac = std::to_string(ns % div);
    out += "." + std::string(static_cast<size_t>(fraction_digits) - frac.size(), '0') + frac;
  }
  return out;
}

// `csv` (t in its first column) with row k's t replaced by origin_ns + k * period_ns written in
// `unit`.
std::string Retime(const std::string& csv, int64_t period_ns, TimeUnit unit,
                   int64_t origin_ns = 0) {
  std::istringstream in(csv);
  std::string out, line;
  bool header = false;
  int64_t k = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || !header) {
      if (!line.empty() && line[0] != '#') {
        header = true;
        EXPECT_EQ(line.rfind("t,", 0), 0u) << line;
      }
      out += line + "\n";
      continue;
    }
    out += TimeText(origin_ns + k++ * period_ns, unit) + line.substr(line.find(',')) + "\n";
  }
  return out;
}

std::string ImuLog(json* config) {
  core::ImuSimulationOptions sim;
  sim.statics = 14;
  sim.seed = 5;
  std::string csv;
  json truth;
  EXPECT_TRUE(SimulateImuFiles(sim, &csv, config, &truth).ok());
  EXPECT_EQ(sim.rate, 100);
  return Retime(csv, 10000000, TimeUnit::kSeconds);  // exact decimals of k / 100 s
}

std::string NoiseLog(json* config) {
  NoiseSimulationFileOptions sim;
  sim.rate = 100;
  sim.seconds = 120;
  std::string csv;
  json truth;
  EXPECT_TRUE(SimulateNoiseFiles(sim, &csv, config, &truth).ok());
  return Retime(csv, 10000000, TimeUnit::kSeconds);
}

Eigen::VectorXd ParsedTimes(const std::string& csv, TimeUnit unit, bool one_pass,
                            RecordingSummary* summary = nullptr) {
  RecordingLimits limits;
  limits.one_pass_rows = one_pass;
  RecordingParser parser("log.csv", /*collect=*/true, limits);
  parser.SetTimeUnit(unit);
  Status s = ParseRecording(csv, &parser);
  EXPECT_TRUE(s.ok()) << s.ToString();
  ArrayRecording rec;
  s = parser.TakeArray(&rec);
  EXPECT_TRUE(s.ok()) << s.ToString();
  if (summary != nullptr) *summary = parser.summary();
  return rec.t;
}

// The result without what may differ between equal runs: the time origin of an epoch log.
json Comparable(json result) {
  if (result.contains("diagnostics")) result["diagnostics"].erase("time_origin");
  result.erase("verdict");
  return result;
}

// ----- The parser.

TEST(TimeUnitParser, EveryUnitGivesTheSecondsLogsTimesBitForBit) {
  std::string csv = "t,a0_x,a0_y,a0_z\n";
  for (int k = 0; k < 300; ++k) csv += "0,1,2,3\n";
  for (bool one_pass : {true, false}) {
    // Periods that are not binary fractions, and a jittered one.
    for (int64_t period : {int64_t{10000000}, int64_t{2500000}, int64_t{1234567}}) {
      const Eigen::VectorXd s =
          ParsedTimes(Retime(csv, period, TimeUnit::kSeconds), TimeUnit::kSeconds, one_pass);
      for (TimeUnit unit :
           {TimeUnit::kMilliseconds, TimeUnit::kMicroseconds, TimeUnit::kNanoseconds}) {
        SCOPED_TRACE(std::string(TimeUnitName(unit)) + " period " + std::to_string(period));
        RecordingSummary summary;
        const Eigen::VectorXd t = ParsedTimes(Retime(csv, period, unit), unit, one_pass, &summary);
        ASSERT_EQ(t.size(), s.size());
        for (Eigen::Index i = 0; i < t.size(); ++i) ASSERT_EQ(t[i], s[i]) << "row " << i;
        EXPECT_EQ(summary.time_origin, 0);
        // The summary's figures are in the file's unit.
        const double step = period * std::pow(10.0, TimeUnitDigits(unit) - 9);
        EXPECT_NEAR(summary.t_median_step, step, 1e-9 * step);
      }
    }
  }
  // The exponent form is moved too: 1.5e1 ms is 0.015 s.
  const Eigen::VectorXd t =
      ParsedTimes("t,a0_x,a0_y,a0_z\n1.5e1,0,0,0\n+2.5E+1,0,0,0\n", TimeUnit::kMilliseconds, true);
  EXPECT_EQ(t[0], 0.015);
  EXPECT_EQ(t[1], 0.025);
}

TEST(TimeUnitParser, EpochStampsKeepEveryNanosecond) {
  // 1 kHz with a 1 ns jitter pattern, from 1.7e18 ns + 0.123456789 s: a double holding the
  // stamps has a 256 ns resolution.
  std::string ns = "t,a0_x,a0_y,a0_z\n";
  std::vector<int64_t> stamps;
  for (int k = 0; k < 2000; ++k) {
    stamps.push_back(kEpochNs + 123456789 + k * 1000000LL + (k % 3));
    ns += std::to_string(stamps.back()) + ",0,0,9.8\n";
  }
  for (bool one_pass : {true, false}) {
    RecordingSummary summary;
    const Eigen::VectorXd t = ParsedTimes(ns, TimeUnit::kNanoseconds, one_pass, &summary);
    EXPECT_EQ(summary.time_origin, 1700000000);
    ASSERT_EQ(t.size(), 2000);
    for (int k = 0; k < 2000; ++k) {
      // (stamp - origin) is exact as an integer; divided by 1e9 it is correctly rounded.
      const double expected = static_cast<double>(stamps[k] - kEpochNs) / 1e9;
      ASSERT_EQ(t[k], expected) << "row " << k;
    }
    // Steps of 1 ms ± 2 ns are seen to the nanosecond (a double of the stamps would say 0, 256
    // or 512 ns off).
    EXPECT_NEAR(t[2] - t[1], 1e-3 + 1e-9, 1e-15);
  }
  // The same stamps as epoch seconds with 9 decimals, and as epoch microseconds with 3.
  std::string s = "t,a0_x,a0_y,a0_z\n", us = s;
  for (int64_t stamp : stamps) {
    s += TimeText(stamp, TimeUnit::kSeconds) + ",0,0,9.8\n";
    us += TimeText(stamp, TimeUnit::kMicroseconds) + ",0,0,9.8\n";
  }
  RecordingSummary summary;
  const Eigen::VectorXd ts = ParsedTimes(s, TimeUnit::kSeconds, true, &summary);
  EXPECT_EQ(summary.time_origin, 1700000000);
  const Eigen::VectorXd tus = ParsedTimes(us, TimeUnit::kMicroseconds, true);
  for (int k = 0; k < 2000; ++k) {
    const double expected = static_cast<double>(stamps[k] - kEpochNs) / 1e9;
    // One rounding of the fraction plus one of the sum: within 2 ulp of ~2 s.
    ASSERT_NEAR(ts[k], expected, 1e-15) << "row " << k;
    ASSERT_NEAR(tus[k], expected, 1e-15) << "row " << k;
  }
}

TEST(TimeUnitParser, LogsStartingNearZeroAreReadAsBefore) {
  // Seconds from 0: each t is the number as parsed (no origin subtracted).
  const std::string csv = "t,a0_x,a0_y,a0_z\n0.1,0,0,0\n0.30000000000000004,0,0,0\n999999,0,0,0\n";
  RecordingSummary summary;
  const Eigen::VectorXd t = ParsedTimes(csv, TimeUnit::kSeconds, true, &summary);
  EXPECT_EQ(t[0], 0.1);
  EXPECT_EQ(t[1], 0.30000000000000004);
  EXPECT_EQ(t[2], 999999.0);
  EXPECT_EQ(summary.time_origin, 0);
  // From kTimeOriginSeconds on, the first stamp's whole second is the origin.
  ParsedTimes("t,a0_x,a0_y,a0_z\n1000000.25,0,0,0\n1000000.5,0,0,0\n", TimeUnit::kSeconds, true,
              &summary);
  EXPECT_EQ(summary.time_origin, 1000000);
}

// ----- The plausibility rule.

RecordingSummary Summary(const std::string& csv) {
  RecordingParser parser("log.csv", /*collect=*/false);
  EXPECT_TRUE(ParseRecording(csv, &parser).ok());
  return parser.summary();
}

std::string Log(int64_t origin_ns, int64_t period_ns, TimeUnit unit, int rows = 50) {
  std::string csv = "# a comment\nt,a0_x,a0_y,a0_z\n";
  for (int k = 0; k < rows; ++k) csv += "0,0,0,9.8\n";
  return Retime(csv, period_ns, unit, origin_ns);
}

TEST(TimeUnitRule, NamesTheLikelyUnitItsRateAndTheKey) {
  struct Case {
    int64_t origin_ns, period_ns;
    TimeUnit written;
    const char* likely;  // nullptr: plausible seconds
    const char* rate;
  } cases[] = {
      {0, 10000000, TimeUnit::kSeconds, nullptr, ""},            // 100 Hz in s
      {0, 1000000, TimeUnit::kSeconds, nullptr, ""},             // 1 kHz in s
      {kEpochNs, 5000000, TimeUnit::kSeconds, nullptr, ""},      // epoch seconds, 200 Hz
      {0, 10000000, TimeUnit::kMilliseconds, "ms", "(100 Hz)"},  // 100 Hz in ms
      {0, 1000000, TimeUnit::kMilliseconds, "ms", "(1000 Hz)"},  // 1 kHz in ms: a step of 1
      {0, 100000, TimeUnit::kMilliseconds, "ms", "(10000 Hz)"},  // 10 kHz in ms: 0.1
      {kEpochNs, 10000000, TimeUnit::kMilliseconds, "ms", "(100 Hz)"},
      {0, 5000000, TimeUnit::kMicroseconds, "us", "(200 Hz)"},  // from boot, us
      {kEpochNs, 2500000, TimeUnit::kMicroseconds, "us", "(400 Hz)"},
      {0, 1000000, TimeUnit::kNanoseconds, "ns", "(1000 Hz)"},         // from boot, ns
      {kEpochNs, 10000000, TimeUnit::kNanoseconds, "ns", "(100 Hz)"},  // ROS
  };
  for (const Case& c : cases) {
    const RecordingSummary summary = Summary(Log(c.origin_ns, c.period_ns, c.written));
    const Status s = CheckTimeUnit(summary, "log.csv");
    SCOPED_TRACE(std::string(TimeUnitName(c.written)) + " period " + std::to_string(c.period_ns) +
                 " ns from " + std::to_string(c.origin_ns));
    if (c.likely == nullptr) {
      EXPECT_TRUE(s.ok()) << s.ToString();
      continue;
    }
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
    EXPECT_EQ(s.reason(), Reason::kImplausibleTimeUnit);
    EXPECT_EQ(s.field(), "time_unit");
    EXPECT_EQ(s.file(), "log.csv");
    EXPECT_EQ(s.line(), 3);  // the first data row (after the comment and the header)
    EXPECT_EQ(s.column(), 1);
    const std::string m = s.message();
    EXPECT_NE(m.find(std::string("time_unit to \"") + c.likely + "\""), std::string::npos) << m;
    EXPECT_NE(m.find(c.rate), std::string::npos) << m;
  }
  // 5 Hz in seconds is refused too (no calibration log is that slow), with the way out.
  const Status slow = CheckTimeUnit(Summary(Log(0, 200000000, TimeUnit::kSeconds)), "x.csv");
  EXPECT_EQ(slow.reason(), Reason::kImplausibleTimeUnit);
  EXPECT_NE(slow.message().find("or to \"s\""), std::string::npos) << slow.message();
  // A log without t, or of one row, passes (the methods needing t say so).
  EXPECT_TRUE(CheckTimeUnit(Summary("a0_x,a0_y,a0_z\n0,0,9.8\n"), "x").ok());
  EXPECT_TRUE(CheckTimeUnit(Summary("t,a0_x,a0_y,a0_z\n5,0,0,9.8\n"), "x").ok());
}

TEST(TimeUnitRule, LooksAtTheFirstRowsOnlySoALargeLogIsRefusedAtOnce) {
  // 2 million rows of a 100 Hz log in ms (~40 MB): the whole refusal, parse included, is the
  // parse's time; the rule itself is the summary's figures.
  std::string csv = "t,a0_x,a0_y,a0_z\n";
  csv.reserve(2000000 * 20);
  for (int64_t k = 0; k < 2000000; ++k) csv += std::to_string(k * 10) + ",0.01,-0.02,9.81\n";
  const auto start = std::chrono::steady_clock::now();
  json result;
  const Status s = Calibrate(csv, "big.csv", json{{"method", "noise"}}, &result);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(s.reason(), Reason::kImplausibleTimeUnit) << s.ToString();
  EXPECT_LT(seconds, 2.0 * sanitizer::kComputeSlowdown);
}

// ----- Methods, offline.

TEST(TimeUnitCalibrate, ImuLogInMsUsNsGivesTheSecondsResult) {
  json config;
  const std::string csv = ImuLog(&config);
  json reference;
  Status s = Calibrate(csv, "imu.csv", config, &reference);
  ASSERT_TRUE(s.ok()) << s.ToString();
  for (TimeUnit unit : {TimeUnit::kMilliseconds, TimeUnit::kMicroseconds, TimeUnit::kNanoseconds}) {
    SCOPED_TRACE(TimeUnitName(unit));
    const std::string log = Retime(csv, 10000000, unit);
    json result;
    s = Calibrate(log, "imu.csv", config, &result);
    EXPECT_EQ(s.reason(), Reason::kImplausibleTimeUnit) << s.ToString();
    EXPECT_NE(s.message().find(std::string("\"") + TimeUnitName(unit) + "\""), std::string::npos)
        << s.message();
    json with_unit = config;
    with_unit["time_unit"] = TimeUnitName(unit);
    s = Calibrate(log, "imu.csv", with_unit, &result);
    ASSERT_TRUE(s.ok()) << s.ToString();
    EXPECT_EQ(Comparable(result), Comparable(reference));
  }
  // Epoch nanoseconds (ROS): the same result, and the origin reported.
  json with_unit = config;
  with_unit["time_unit"] = "ns";
  json result;
  s = Calibrate(Retime(csv, 10000000, TimeUnit::kNanoseconds, kEpochNs), "imu.csv", with_unit,
                &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(result["diagnostics"]["time_origin"], 1700000000);
  EXPECT_EQ(Comparable(result), Comparable(reference));
  EXPECT_FALSE(reference["diagnostics"].contains("time_origin"));
}

TEST(TimeUnitCalibrate, NoiseLogInEpochNsGivesTheSecondsResult) {
  json config;
  const std::string csv = NoiseLog(&config);
  json reference;
  Status s = Calibrate(csv, "noise.csv", config, &reference);
  ASSERT_TRUE(s.ok()) << s.ToString();
  const std::string ns = Retime(csv, 10000000, TimeUnit::kNanoseconds, kEpochNs);
  json result;
  s = Calibrate(ns, "noise.csv", config, &result);
  EXPECT_EQ(s.reason(), Reason::kImplausibleTimeUnit) << s.ToString();
  EXPECT_NE(s.message().find("\"ns\""), std::string::npos) << s.message();
  config["time_unit"] = "ns";
  s = Calibrate(ns, "noise.csv", config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(Comparable(result), Comparable(reference));
  config["time_unit"] = "ms";
  s = Calibrate(Retime(csv, 10000000, TimeUnit::kMilliseconds), "noise.csv", config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(Comparable(result), Comparable(reference));
}

TEST(TimeUnitConfig, BadValuesAndMethodsWithoutTimeAreRefusedNamingTheKey) {
  CommonConfig common;
  for (const json& bad : {json("min"), json(5), json("S"), json(nullptr), json::array()}) {
    const Status s = ValidateConfig(json{{"method", "noise"}, {"time_unit", bad}}, &common);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << bad.dump();
    EXPECT_EQ(s.field(), "time_unit") << bad.dump();
    EXPECT_NE(s.message().find("\"ms\""), std::string::npos) << s.message();
  }
  const Status pca = ValidateConfig(json{{"method", "pca"}, {"time_unit", "ms"}}, &common);
  EXPECT_EQ(pca.field(), "time_unit");
  for (const char* unit : {"s", "ms", "us", "ns"}) {
    EXPECT_TRUE(ValidateConfig(json{{"method", "noise"}, {"time_unit", unit}}, &common).ok());
  }
  // The methods never see it (their own key checks would refuse it).
  EXPECT_FALSE(
      WithoutAcceptance(json{{"method", "imu"}, {"time_unit", "ms"}}).contains("time_unit"));
}

// `calibd calibrate` on a log in ms: exit 2 (bad input), the message on stderr.
int RunCalibrate(const std::string& csv, const json& config, std::string* err) {
  testing::TempDir dir;
  const std::string csv_path = (dir.path() / "log.csv").string();
  const std::string config_path = (dir.path() / "config.json").string();
  std::ofstream(csv_path) << csv;
  std::ofstream(config_path) << config.dump();
  FILE* pipe = ::popen((calibd::test_paths::CalibdBinary() + " calibrate " + csv_path + " --config " +
                        config_path + " 2>&1 >/dev/null")
                           .c_str(),
                       "r");
  if (pipe == nullptr) return -1;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) err->append(buf, n);
  const int status = ::pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(TimeUnitCalibrate, CommandLineExitsWithBadInput) {
  json config;
  const std::string ms = Retime(ImuLog(&config), 10000000, TimeUnit::kMilliseconds);
  std::string err;
  EXPECT_EQ(RunCalibrate(ms, config, &err), 2) << err;
  EXPECT_NE(err.find("time_unit to \"ms\""), std::string::npos) << err;
  EXPECT_NE(err.find("implausible_time_unit"), std::string::npos) << err;
  EXPECT_NE(err.find("log.csv"), std::string::npos) << err;
  config["time_unit"] = "ms";
  err.clear();
  EXPECT_EQ(RunCalibrate(ms, config, &err), 0) << err;
}

// imu_tk's own Xsens recording (tests/core/imu_tk_data_test.cc; $CALIBD_IMU_TK_DATA, default
// /work/data/imu_tk; skipped when absent), written with t in ms: refused without time_unit, the
// seconds result with it.
std::string ImuTkDir() {
  const char* env = std::getenv("CALIBD_IMU_TK_DATA");
  return env != nullptr && *env != '\0' ? env : "/work/data/imu_tk";
}

// The Xsens log as calibd CSV with t written in `unit` (exact decimals of the file's stamps,
// which have at most 9 decimals in seconds); empty when the files are absent.
std::string XsensCsv(TimeUnit unit) {
  std::ifstream acc(ImuTkDir() + "/xsens_acc.mat"), gyr(ImuTkDir() + "/xsens_gyro.mat");
  if (!acc || !gyr) return "";
  std::string csv = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n";
  double t, ax, ay, az, tg, gx, gy, gz;
  char buf[200];
  while ((acc >> t >> ax >> ay >> az) && (gyr >> tg >> gx >> gy >> gz)) {
    EXPECT_EQ(t, tg);
    std::snprintf(buf, sizeof buf, ",%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", ax, ay, az, gx, gy,
                  gz);
    csv += TimeText(std::llround(t * 1e9), unit) + buf;
  }
  return csv;
}

TEST(TimeUnitCalibrate, ImuTkXsensRecordingInMs) {
  const std::string seconds = XsensCsv(TimeUnit::kSeconds);
  if (seconds.empty()) GTEST_SKIP() << "imu_tk's xsens_*.mat not found in " << ImuTkDir();
  // As tests/core/imu_tk_data_test.cc: ±8 g over 16 bits, imu_tk's gyroscope guess, offset binary.
  json config = {{"method", "imu"},
                 {"accel_unit", 8 * 9.80665 / 32768},
                 {"gyro_unit", 1.0 / 6258},
                 {"gravity", 9.81744},
                 {"max_scale_deviation", 0.5},
                 {"nominal_accel_bias", 32768},
                 {"nominal_gyro_bias", 32768}};
  json reference;
  Status s = Calibrate(seconds, "xsens.csv", config, &reference);
  ASSERT_TRUE(s.ok()) << s.ToString();
  const std::string ms = XsensCsv(TimeUnit::kMilliseconds);
  json result;
  const auto start = std::chrono::steady_clock::now();
  s = Calibrate(ms, "xsens.csv", config, &result);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
            2.0 * sanitizer::kComputeSlowdown);
  EXPECT_EQ(s.reason(), Reason::kImplausibleTimeUnit) << s.ToString();
  EXPECT_NE(s.message().find("time_unit to \"ms\""), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("(100 Hz)"), std::string::npos) << s.message();
  config["time_unit"] = "ms";
  s = Calibrate(ms, "xsens.csv", config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(Comparable(result), Comparable(reference));
}

// ----- Over HTTP.

std::string Encode(const std::string& s) {
  std::string out;
  for (unsigned char c : s) {
    if (std::isalnum(c) || c == '-' || c == '_' || c == '.' || c == '~') {
      out += static_cast<char>(c);
    } else {
      char buf[4];
      std::snprintf(buf, sizeof buf, "%%%02X", c);
      out += buf;
    }
  }
  return out;
}

// The config as a query string (strings as they are, everything else as JSON text).
std::string Query(const json& config) {
  std::string q;
  for (const auto& [key, value] : config.items()) {
    q += (q.empty() ? "?" : "&") + key + "=" +
         Encode(value.is_string() ? value.get<std::string>() : value.dump());
  }
  return q;
}

json Post(const TestServer& server, const std::string& target, const std::string& csv,
          int* status) {
  auto res = server.Client().Post(target.c_str(), csv, "text/csv");
  if (!res) {
    *status = -1;
    return nullptr;
  }
  *status = res->status;
  return json::parse(res->body, nullptr, false);
}

TEST(TimeUnitHttp, UploadInMsIsA400NamingTheUnitAndNothingIsStored) {
  json config;
  const std::string csv = ImuLog(&config);
  const std::string ms = Retime(csv, 10000000, TimeUnit::kMilliseconds);
  TestServer server;
  ASSERT_EQ(server.error(), "");
  int status = 0;
  json e = Post(server, "/api/v1/recordings" + Query(config), ms, &status);
  EXPECT_EQ(status, 400) << e.dump();
  EXPECT_EQ(e["error"]["field"], "time_unit") << e.dump();
  EXPECT_NE(e["error"]["message"].get<std::string>().find("time_unit to \"ms\""), std::string::npos)
      << e.dump();
  EXPECT_NE(e["error"]["message"].get<std::string>().find("100 Hz"), std::string::npos);
  EXPECT_EQ(server.Client().Get("/api/v1/recordings/1")->status, 404);
  // Bad values of the key itself.
  for (const char* bad : {"min", "5"}) {
    e = Post(server, "/api/v1/recordings?method=imu&time_unit=" + std::string(bad), ms, &status);
    EXPECT_EQ(status, 400) << e.dump();
    EXPECT_EQ(e["error"]["field"], "time_unit") << e.dump();
  }
  e = Post(server, "/api/v1/recordings?method=pca&time_unit=ms", ms, &status);
  EXPECT_EQ(status, 400) << e.dump();
  EXPECT_EQ(server.Client().Get("/api/v1/recordings/1")->status, 404);

  // With time_unit, as a query parameter and in the JSON config part: the seconds result.
  const json reference = server.UploadAndWait(csv, config);
  ASSERT_EQ(reference["status"], "succeeded") << reference.dump();
  json with_unit = config;
  with_unit["time_unit"] = "ms";
  e = Post(server, "/api/v1/recordings" + Query(with_unit), ms, &status);
  ASSERT_EQ(status, 201) << e.dump();
  const json by_query = server.WaitForJob(e["job"]["id"].get<int64_t>());
  ASSERT_EQ(by_query["status"], "succeeded") << by_query.dump();
  EXPECT_EQ(Comparable(by_query["result"]), Comparable(reference["result"]));
  const json by_part = server.UploadAndWait(ms, with_unit);
  ASSERT_EQ(by_part["status"], "succeeded") << by_part.dump();
  EXPECT_EQ(Comparable(by_part["result"]), Comparable(reference["result"]));
  // Epoch nanoseconds.
  with_unit["time_unit"] = "ns";
  const json epoch =
      server.UploadAndWait(Retime(csv, 10000000, TimeUnit::kNanoseconds, kEpochNs), with_unit);
  ASSERT_EQ(epoch["status"], "succeeded") << epoch.dump();
  EXPECT_EQ(epoch["result"]["diagnostics"]["time_origin"], 1700000000);
  EXPECT_EQ(Comparable(epoch["result"]), Comparable(reference["result"]));
}

TEST(TimeUnitHttp, AJobOnAStoredLogInMsFailsAsImplausibleTimeUnit) {
  json config;
  const std::string ms = Retime(ImuLog(&config), 10000000, TimeUnit::kMilliseconds);
  TestServer server;
  ASSERT_EQ(server.error(), "");
  int status = 0;
  // Stored without a method (nothing reads its times yet).
  json e = Post(server, "/api/v1/recordings", ms, &status);
  ASSERT_EQ(status, 201) << e.dump();
  const int64_t recording = e["recording"]["id"].get<int64_t>();
  auto res = server.Client().Post("/api/v1/jobs",
                                  json{{"recording_id", recording}, {"config", config}}.dump(),
                                  "application/json");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 202) << res->body;
  json job = server.WaitForJob(json::parse(res->body)["job"]["id"].get<int64_t>());
  EXPECT_EQ(job["status"], "failed") << job.dump();
  EXPECT_EQ(job["error"]["reason"], "implausible_time_unit") << job.dump();
  EXPECT_NE(job["error"]["message"].get<std::string>().find("time_unit to \"ms\""),
            std::string::npos)
      << job.dump();
  // With the key, the same stored log calibrates.
  config["time_unit"] = "ms";
  res = server.Client().Post("/api/v1/jobs",
                             json{{"recording_id", recording}, {"config", config}}.dump(),
                             "application/json");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 202) << res->body;
  job = server.WaitForJob(json::parse(res->body)["job"]["id"].get<int64_t>());
  EXPECT_EQ(job["status"], "succeeded") << job.dump();
}

TEST(TimeUnitHttp, StaticSegmentsOfALogInMsTakeTheKeyToo) {
  json config;
  const std::string csv = ImuLog(&config);
  TestServer server;
  ASSERT_EQ(server.error(), "");
  int status = 0;
  const json s = Post(server, "/api/v1/recordings", csv, &status);
  ASSERT_EQ(status, 201) << s.dump();
  const json ms =
      Post(server, "/api/v1/recordings", Retime(csv, 10000000, TimeUnit::kMilliseconds), &status);
  ASSERT_EQ(status, 201) << ms.dump();
  auto segments = [&](const json& upload, const std::string& query, int* code) {
    auto res = server.Client().Get(
        ("/api/v1/recordings/" + upload["recording"]["id"].dump() + "/segments" + query).c_str());
    *code = res ? res->status : -1;
    return res ? json::parse(res->body, nullptr, false) : json();
  };
  const json reference = segments(s, "", &status);
  ASSERT_EQ(status, 200) << reference.dump();
  ASSERT_GE(reference["intervals"].size(), 10u);
  const json in_ms = segments(ms, "?time_unit=ms", &status);
  ASSERT_EQ(status, 200) << in_ms.dump();
  EXPECT_EQ(in_ms["intervals"], reference["intervals"]);
  EXPECT_EQ(reference["time_origin"], 0);
  // Epoch nanoseconds: the intervals are seconds after the origin the answer names (the times
  // alone would not map back to the log).
  const json ns = Post(server, "/api/v1/recordings",
                       Retime(csv, 10000000, TimeUnit::kNanoseconds, kEpochNs), &status);
  ASSERT_EQ(status, 201) << ns.dump();
  const json in_ns = segments(ns, "?time_unit=ns", &status);
  ASSERT_EQ(status, 200) << in_ns.dump();
  EXPECT_EQ(in_ns["time_origin"], kEpochNs / 1000000000) << in_ns.dump().substr(0, 300);
  ASSERT_EQ(in_ns["intervals"].size(), reference["intervals"].size());
  const double offset = kEpochNs % 1000000000 * 1e-9;  // the origin's fraction of a second
  for (size_t i = 0; i < reference["intervals"].size(); ++i) {
    EXPECT_NEAR(in_ns["intervals"][i]["start"].get<double>(),
                reference["intervals"][i]["start"].get<double>() + offset, 1e-9);
  }
  const json bad = segments(ms, "?time_unit=min", &status);
  EXPECT_EQ(status, 400) << bad.dump();
  EXPECT_EQ(bad["error"]["field"], "time_unit") << bad.dump();
}

// ----- accel_noise / gyro_noise 0 (issue 26, item 7): refused wherever given, saying how to have
// the noise estimated from the statics (the key left out).

TEST(NoiseLevelZero, IsRefusedWithTheWayToEstimateIt) {
  CommonConfig common;
  for (const char* key : {"accel_noise", "gyro_noise"}) {
    const Status s = ValidateConfig(json{{"method", "imu"}, {key, 0}}, &common);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << key;
    EXPECT_EQ(s.field(), key);
    EXPECT_NE(s.message().find("leave it out"), std::string::npos) << s.message();
    EXPECT_TRUE(ValidateConfig(json{{"method", "imu"}, {key, 0.01}}, &common).ok()) << key;
  }
}

// ----- Numbers in query strings (issue 26, item 7).

TEST(QueryNumbers, KeysTakingANumberOrANameGetTheNumber) {
  json config;
  ASSERT_TRUE(ConfigFromQuery({{"method", "noise"},
                               {"accel_unit", "0.00479"},
                               {"gyro_unit", "0.0001598"},
                               {"device", "123"}},
                              &config)
                  .ok());
  EXPECT_EQ(config["accel_unit"], 0.00479);
  EXPECT_EQ(config["gyro_unit"], 0.0001598);
  EXPECT_EQ(config["device"], "123");  // a name, even when it reads as a number
  ASSERT_TRUE(
      ConfigFromQuery({{"method", "noise"}, {"accel_unit", "g"}, {"gyro_unit", "deg/s"}}, &config)
          .ok());
  EXPECT_EQ(config["accel_unit"], "g");
  EXPECT_EQ(config["gyro_unit"], "deg/s");
  CommonConfig common;
  EXPECT_TRUE(ValidateConfig(config, &common).ok());

  // Through the server, for each method taking them: accepted and stored as numbers.
  json noise_config;
  const std::string csv = NoiseLog(&noise_config);
  TestServer server;
  ASSERT_EQ(server.error(), "");
  for (const char* method : {"noise", "imu"}) {
    for (const char* key : {"accel_unit", "gyro_unit"}) {
      int status = 0;
      const std::string target =
          std::string("/api/v1/recordings?method=") + method + "&" + key + "=0.0001598&time_unit=s";
      const json e = Post(server, target, csv, &status);
      ASSERT_EQ(status, 201) << method << " " << key << ": " << e.dump();
      auto res = server.Client().Get(e["job"]["url"].get<std::string>().c_str());
      ASSERT_TRUE(res);
      const json job = json::parse(res->body);
      EXPECT_EQ(job["config"][key], 0.0001598) << job.dump();
    }
  }
}

}  // namespace
}  // namespace calibd::server
