// Bags through the real server (issue 30, SPEC §9): an MCAP file or a ROS 2 .db3 of
// sensor_msgs/Imu uploaded under a neutral file name is recognised by its bytes, its samples read
// agree with what was written (count, rate, first and last stamps), and `imu` and `noise` jobs run
// on it end to end; zero header stamps fall back to the record time and the recording says so.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "formats/recording.h"
#include "methods/imu/imu_method.h"
#include "tests/formats/db3_writer.h"
#include "tests/formats/mcap_writer.h"
#include "tests/formats/ros2_cdr_writer.h"
#include "tests/lib/test_paths.h"
#include "tests/server/http_test_util.h"
#include "tests/server/simulated_imu.h"

namespace calibd::server {
namespace {

using json = nlohmann::json;
using testing::TestServer;

// The bag formats written here: MCAP and ROS 2 .db3 by the tests' own writers, ROS 1 by Debian's
// python3-rosbag (tests/formats/write_rosbag1_imu.py: an independent writer).
enum class Bag { kMcap, kDb3, kRos1 };

// One record of a bag: its record (log) time, the message's header stamp and values, and the
// message as CDR (ROS 2).
struct BagMessage {
  uint64_t record_ns;
  int32_t sec;
  uint32_t nsec;
  double a[3], g[3];
  std::string cdr;
};

bool HavePythonRosbag() {
  return std::system("/usr/bin/python3 -c 'import rosbag, sensor_msgs.msg' 2>/dev/null") == 0;
}

// The messages as a ROS 1 bag with lz4 chunks, written by python3-rosbag.
std::string Ros1Bag(const std::vector<BagMessage>& messages) {
  const std::string stem = ::testing::TempDir() + "upload-" + std::to_string(::getpid());
  {
    std::ofstream samples(stem + ".txt");
    char line[512];
    for (const BagMessage& m : messages) {
      std::snprintf(line, sizeof line, "%llu %d %u %.17g %.17g %.17g %.17g %.17g %.17g\n",
                    static_cast<unsigned long long>(m.record_ns), m.sec, m.nsec, m.a[0], m.a[1],
                    m.a[2], m.g[0], m.g[1], m.g[2]);
      samples << line;
    }
  }
  const std::string command = "/usr/bin/python3 " + calibd::test_paths::SourceDir() +
                              "/tests/formats/write_rosbag1_imu.py " + stem + ".bag lz4 " + stem +
                              ".txt";
  EXPECT_EQ(std::system(command.c_str()), 0) << command;
  std::ifstream in(stem + ".bag", std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::remove((stem + ".txt").c_str());
  std::remove((stem + ".bag").c_str());
  return bytes;
}

// Samples of one IMU as sensor_msgs/msg/Imu messages at times `t` (s) plus 1 s: in the header
// stamp with the record time 2 s later, or, when `zero_stamps`, only in the record time (stamps 0).
std::vector<BagMessage> ImuMessages(const Eigen::VectorXd& t, const Eigen::MatrixXd& accel,
                                    const Eigen::MatrixXd& gyro, bool zero_stamps) {
  std::vector<BagMessage> out;
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    const int64_t ns = std::llround((1.0 + t(i)) * 1e9);
    const double a[3] = {accel(i, 0), accel(i, 1), accel(i, 2)};
    const double g[3] = {gyro(i, 0), gyro(i, 1), gyro(i, 2)};
    const auto sec = static_cast<int32_t>(zero_stamps ? 0 : ns / 1'000'000'000);
    const auto nsec = static_cast<uint32_t>(zero_stamps ? 0 : ns % 1'000'000'000);
    out.push_back({static_cast<uint64_t>(ns + (zero_stamps ? 0 : 2'000'000'000)),
                   sec,
                   nsec,
                   {a[0], a[1], a[2]},
                   {g[0], g[1], g[2]},
                   testing::ImuCdr(false, sec, nsec, a, g)});
  }
  return out;
}

// The messages on topic /imu as a bag: MCAP with lz4 chunks of 500 messages, a ROS 2 .db3, or
// a ROS 1 bag with lz4 chunks.
std::string AsBag(Bag format, const std::vector<BagMessage>& messages) {
  if (format == Bag::kRos1) return Ros1Bag(messages);
  if (format == Bag::kDb3) {
    testing::Db3Writer db(::testing::TempDir() + "upload.db3");
    db.Topic(1, "/imu", "sensor_msgs/msg/Imu");
    for (const BagMessage& m : messages) db.Add(1, static_cast<int64_t>(m.record_ns), m.cdr);
    return db.Bytes();
  }
  std::string file = testing::McapBegin();
  std::string records = testing::Schema(1, "sensor_msgs/msg/Imu") + testing::Channel(1, 1, "/imu");
  for (size_t i = 0; i < messages.size(); ++i) {
    records += testing::Message(1, messages[i].record_ns, messages[i].cdr);
    if (i % 500 == 499 || i + 1 == messages.size()) {
      file += testing::Chunk(records, "lz4");
      records.clear();
    }
  }
  return file + testing::McapEnd();
}

// A simulated hand-held imu log with `statics` holds (tests/server/simulated_imu.h).
using testing::SimulatedImu;
SimulatedImu Simulate(int statics, uint64_t seed) { return testing::SimulateImuLog(statics, seed); }

json GetJson(const TestServer& server, const std::string& path) {
  auto res = server.Client().Get(path.c_str());
  if (!res || res->status != 200) return nullptr;
  return json::parse(res->body, nullptr, false);
}

// The recording's stream `kind` of topic /imu: count, first and last stamps (s) and rate as
// written.
void ExpectImuStream(const json& recording, const char* kind, const Eigen::VectorXd& t,
                     const char* time_source) {
  ASSERT_TRUE(recording["streams"].is_array()) << recording.dump();
  bool found = false;
  for (const json& s : recording["streams"]) {
    if (s["name"] != "/imu" || s["kind"] != kind) continue;
    found = true;
    const Eigen::Index n = t.size();
    EXPECT_EQ(s["samples"], n);
    EXPECT_NEAR(s["start"].get<double>(), 1.0 + t(0), 1e-9);
    EXPECT_NEAR(s["end"].get<double>(), 1.0 + t(n - 1), 1e-9);
    const double rate = (n - 1) / (t(n - 1) - t(0));
    EXPECT_NEAR(s["rate"].get<double>(), rate, 0.01 * rate);
    EXPECT_EQ(s["time_source"], time_source) << s.dump();
  }
  EXPECT_TRUE(found) << recording["streams"].dump();
}

struct Case {
  Bag format;
  bool zero_stamps;
};
class BagUpload : public ::testing::TestWithParam<Case> {};

TEST_P(BagUpload, AnImuJobRecoversTheTruthAndTheRecordingSaysWhatWasRead) {
  const auto [format, zero_stamps] = GetParam();
  if (format == Bag::kRos1 && !HavePythonRosbag()) GTEST_SKIP() << "no python3-rosbag";
  const char* format_name = format == Bag::kMcap  ? "mcap"
                            : format == Bag::kDb3 ? "rosbag2"
                                                  : "rosbag1";
  SimulatedImu sim = Simulate(24, 21);
  const ArrayRecording& rec = sim.rec;
  const std::string bag = AsBag(format, ImuMessages(rec.t, rec.accel, rec.gyro, zero_stamps));
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const json job = server.UploadAndWait(bag, sim.config, "upload.bin");  // a neutral name
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "succeeded") << job.dump().substr(0, 2000);
  const json& r = job["result"];
  // 5σ per entry: the bag holds float64.
  testing::ExpectImuRecoversTheTruth(r, sim.truth);
  EXPECT_EQ(r["diagnostics"]["log"]["format"], format_name);
  const std::string id = std::to_string(job["recording_id"].get<int64_t>());
  const json recording = GetJson(server, "/api/v1/recordings/" + id);
  ASSERT_TRUE(recording.is_object());
  EXPECT_EQ(recording["format"], format_name);
  EXPECT_EQ(recording["rows"], rec.t.size());
  const char* source = zero_stamps ? "record time" : "header.stamp";
  ExpectImuStream(recording, "accelerometer", rec.t, source);
  ExpectImuStream(recording, "gyroscope", rec.t, source);
  auto data = server.Client().Get(("/api/v1/recordings/" + id + "/data").c_str());
  ASSERT_TRUE(data);
  EXPECT_EQ(data->body, bag);
}

INSTANTIATE_TEST_SUITE_P(Mcap, BagUpload,
                         ::testing::Values(Case{Bag::kMcap, false}, Case{Bag::kMcap, true}));
// (A first version seemed to hang on .db3: its test writer committed, and synced, every message
// on its own: seconds here, minutes on a loaded machine. The writer now uses one transaction.)
INSTANTIATE_TEST_SUITE_P(Db3, BagUpload,
                         ::testing::Values(Case{Bag::kDb3, false}, Case{Bag::kDb3, true}));
INSTANTIATE_TEST_SUITE_P(Ros1, BagUpload,
                         ::testing::Values(Case{Bag::kRos1, false}, Case{Bag::kRos1, true}));

class BagNoiseUpload : public ::testing::TestWithParam<Bag> {};

TEST_P(BagNoiseUpload, ANoiseJobFindsTheWhiteNoiseDensity) {
  if (GetParam() == Bag::kRos1 && !HavePythonRosbag()) GTEST_SKIP() << "no python3-rosbag";
  const testing::WhiteNoiseLog still = testing::SimulateWhiteNoise(8);
  const ArrayRecording& rec = still.rec;
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const json job =
      server.UploadAndWait(AsBag(GetParam(), ImuMessages(rec.t, rec.accel, rec.gyro, false)),
                           {{"method", "noise"}}, "upload.bin");
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "succeeded") << job.dump().substr(0, 2000);
  testing::ExpectWhiteNoiseDensity(job["result"]);
}

INSTANTIATE_TEST_SUITE_P(Mcap, BagNoiseUpload, ::testing::Values(Bag::kMcap));
INSTANTIATE_TEST_SUITE_P(Db3, BagNoiseUpload, ::testing::Values(Bag::kDb3));
INSTANTIATE_TEST_SUITE_P(Ros1, BagNoiseUpload, ::testing::Values(Bag::kRos1));

}  // namespace
}  // namespace calibd::server
