// MCAP and ROS 2 .db3 files read by calibd agree with an independent reader of the same files
// (issue 30, #24): tests/formats/bag_reference.js, on foxglove's @mcap/core, sql.js and
// @foxglove/rosmsg2-serialization under node. Those packages are peers' tools, not calibd's
// dependencies: they are installed outside the repository (scripts/fetch_peer_tools.sh, into
// $CALIBD_NODE_MODULES, default /work/data/node/node_modules) and the test skips when they or
// node are absent. Compared per Imu topic: the count, the first and last header stamps (ns,
// exactly) and record times, and the channel means (to 1e-12 relative: the same float64 values
// summed in the same order up to rounding).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "formats/mcap.h"
#include "formats/rosbag2_sqlite.h"
#include "formats/sensor_log.h"
#include "tests/formats/db3_writer.h"
#include "tests/formats/mcap_writer.h"
#include "tests/formats/ros2_cdr_writer.h"
#include "tests/lib/test_paths.h"

namespace calibd::server {
namespace {

using nlohmann::json;

std::string NodeModules() {
  const char* env = std::getenv("CALIBD_NODE_MODULES");
  return env != nullptr && *env != '\0' ? env : "/work/data/node/node_modules";
}

// Why the peer reader cannot run here ("" when it can).
std::string PeerMissing() {
  if (std::system("node --version >/dev/null 2>&1") != 0) return "no node";
  for (const char* package :
       {"@mcap/core", "lz4js", "sql.js", "@foxglove/rosmsg", "@foxglove/rosmsg2-serialization"}) {
    if (!std::filesystem::exists(NodeModules() + "/" + package)) {
      return std::string("no ") + package + " in " + NodeModules() +
             " (scripts/fetch_peer_tools.sh installs the peers' tools)";
    }
  }
  return "";
}

// The peer's reading of `path`.
json PeerReading(const std::string& path) {
  const std::string command = "NODE_PATH='" + NodeModules() + "' node '" +
                              calibd::test_paths::SourceDir() +
                              "/tests/formats/bag_reference.js' '" + path + "'";
  FILE* pipe = ::popen(command.c_str(), "r");
  std::string out;
  char buf[4096];
  size_t n;
  while (pipe != nullptr && (n = std::fread(buf, 1, sizeof buf, pipe)) > 0) out.append(buf, n);
  const int status = pipe != nullptr ? ::pclose(pipe) : -1;
  EXPECT_EQ(status, 0) << command;
  return json::parse(out, nullptr, false);
}

// n Imu messages on /imu (stamps 100 s + 5 ms·i + 7 ns, record times 1000 s + 1 ms·i, values
// that vary) and, for the .db3, on /imu2 too.
struct Messages {
  std::vector<std::string> cdr;
  std::vector<uint64_t> record_ns;
};
Messages ImuMessages(int n) {
  Messages m;
  for (int i = 0; i < n; ++i) {
    const double a[3] = {0.1 * std::sin(0.01 * i), -9.81 + 1e-3 * i, 0.5 * std::cos(0.02 * i)};
    const double g[3] = {1e-3 * i, -0.02 * std::sin(0.03 * i), 0.003};
    const int64_t stamp = 100'000'000'000 + 5'000'000LL * i + 7;
    m.cdr.push_back(testing::ImuCdr(i % 2 == 1, static_cast<int32_t>(stamp / 1'000'000'000),
                                    static_cast<uint32_t>(stamp % 1'000'000'000), a, g));
    m.record_ns.push_back(1'000'000'000'000ull + 1'000'000ull * i);
  }
  return m;
}

// calibd's streams of `topic` agree with the peer's reading of the same file.
void ExpectAgreement(const SensorLog& log, const json& peer, const std::string& topic) {
  ASSERT_TRUE(peer.is_object() && peer.contains(topic)) << peer.dump();
  const json& p = peer[topic];
  for (StreamKind kind : {StreamKind::kAccel, StreamKind::kGyro}) {
    const SensorStream* s = nullptr;
    for (const SensorStream& x : log.streams)
      if (x.topic == topic && x.kind == kind) s = &x;
    ASSERT_NE(s, nullptr) << topic << " " << StreamKindName(kind);
    SCOPED_TRACE(topic + " " + StreamKindName(kind));
    ASSERT_EQ(s->samples(), p["count"].get<int64_t>());
    EXPECT_EQ(s->time_source, "header.stamp");
    EXPECT_EQ(std::to_string(s->t_ns.front()), p["first_stamp_ns"].get<std::string>());
    EXPECT_EQ(std::to_string(s->t_ns.back()), p["last_stamp_ns"].get<std::string>());
    const json& mean = p[kind == StreamKind::kAccel ? "accel_mean" : "gyro_mean"];
    for (int k = 0; k < 3; ++k) {
      double sum = 0;
      for (int64_t i = 0; i < s->samples(); ++i) sum += s->values[3 * i + k];
      const double ours = sum / static_cast<double>(s->samples()), theirs = mean[k].get<double>();
      EXPECT_NEAR(ours, theirs, 1e-12 * std::max(1.0, std::abs(theirs))) << "axis " << k;
    }
  }
}

std::string WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

TEST(BagPeer, McapAgreesWithFoxglovesReaderUncompressedAndLz4) {
  if (const std::string why = PeerMissing(); !why.empty()) GTEST_SKIP() << why;
  const Messages m = ImuMessages(3000);
  for (const char* compression : {"", "lz4"}) {
    SCOPED_TRACE(std::string("chunks: ") + (*compression ? compression : "none"));
    std::string file = testing::McapBegin();
    std::string records =
        testing::Schema(1, "sensor_msgs/msg/Imu") + testing::Channel(1, 1, "/imu");
    for (size_t i = 0; i < m.cdr.size(); ++i) {
      records += testing::Message(1, m.record_ns[i], m.cdr[i]);
      if (i % 700 == 699 || i + 1 == m.cdr.size()) {
        file += testing::Chunk(records, compression);
        records.clear();
      }
    }
    file += testing::McapEnd();
    SensorLog log;
    const Status s = ReadMcap(file, "peer.mcap", SensorLogLimits(), &log);
    ASSERT_TRUE(s.ok()) << s.ToString();
    const std::string path =
        WriteFile(::testing::TempDir() + "peer-" + std::to_string(::getpid()) + ".mcap", file);
    const json peer = PeerReading(path);
    std::remove(path.c_str());
    ExpectAgreement(log, peer, "/imu");
    EXPECT_EQ(peer["/imu"]["first_record_ns"], std::to_string(m.record_ns.front()));
  }
}

TEST(BagPeer, Db3AgreesWithSqlJsAndFoxglovesCdrReader) {
  if (const std::string why = PeerMissing(); !why.empty()) GTEST_SKIP() << why;
  const Messages m = ImuMessages(2500);
  testing::Db3Writer db(::testing::TempDir() + "peer.db3");
  db.Topic(1, "/imu", "sensor_msgs/msg/Imu");
  db.Topic(2, "/imu2", "sensor_msgs/msg/Imu");
  for (size_t i = 0; i < m.cdr.size(); ++i) {
    db.Add(1, static_cast<int64_t>(m.record_ns[i]), m.cdr[i]);
    if (i % 2 == 0) db.Add(2, static_cast<int64_t>(m.record_ns[i]) + 1, m.cdr[i]);
  }
  db.Close();
  SensorLog log;
  const Status s = ReadRosBag2Sqlite(db.path(), "peer.db3", SensorLogLimits(), &log);
  ASSERT_TRUE(s.ok()) << s.ToString();
  const json peer = PeerReading(db.path());
  std::remove(db.path().c_str());
  ExpectAgreement(log, peer, "/imu");
  ExpectAgreement(log, peer, "/imu2");
}

}  // namespace
}  // namespace calibd::server
