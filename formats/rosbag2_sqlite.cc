// rosbag2 SQLite (.db3) reader (formats/rosbag2_sqlite.h).
#include "formats/rosbag2_sqlite.h"

#include <sqlite3.h>

#include <map>
#include <memory>
#include <string_view>
#include <utility>

#include "formats/cdr.h"
#include "formats/ros_topics.h"

namespace calibd::server {
namespace {

struct Topic {
  std::string name;
  RosMessageType type = RosMessageType::kOther;
};

using Statement = std::unique_ptr<sqlite3_stmt, decltype(&sqlite3_finalize)>;

std::string_view Text(sqlite3_stmt* stmt, int column) {
  const unsigned char* text = sqlite3_column_text(stmt, column);
  return text ? std::string_view(reinterpret_cast<const char*>(text),
                                 static_cast<size_t>(sqlite3_column_bytes(stmt, column)))
              : std::string_view();
}

class Db3Reader {
 public:
  Db3Reader(sqlite3* db, const std::string& file_name, const SensorLogLimits& limits)
      : db_(db), file_name_(file_name), samples_(limits) {}

  Status Read(SensorLog* log) {
    Status s = ReadTopics();
    if (s.ok()) s = ReadMessages();
    if (s.ok()) samples_.Finish(log);
    return s;
  }

 private:
  Status Unreadable() const {
    return Status::InvalidInput(file_name_ +
                                ": not a readable rosbag2 SQLite file: " + sqlite3_errmsg(db_))
        .WithFile(file_name_);
  }
  Status Prepare(const char* sql, Statement* stmt) const {
    sqlite3_stmt* raw = nullptr;
    if (sqlite3_prepare_v2(db_, sql, -1, &raw, nullptr) != SQLITE_OK) return Unreadable();
    stmt->reset(raw);
    return Status::Ok();
  }

  Status ReadTopics() {
    Statement stmt(nullptr, &sqlite3_finalize);
    Status s = Prepare("SELECT id, name, type, serialization_format FROM topics", &stmt);
    if (!s.ok()) return s;
    int rc;
    while ((rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
      Topic t;
      t.name = std::string(Text(stmt.get(), 1));
      if (Text(stmt.get(), 3) == "cdr") t.type = Ros2MessageType(Text(stmt.get(), 2));
      topics_[sqlite3_column_int64(stmt.get(), 0)] = std::move(t);
    }
    return rc == SQLITE_DONE ? Status::Ok() : Unreadable();
  }

  Status ReadMessages() {
    Statement stmt(nullptr, &sqlite3_finalize);
    Status s = Prepare("SELECT rowid, topic_id, timestamp, data FROM messages", &stmt);
    if (!s.ok()) return s;
    int rc;
    while ((rc = sqlite3_step(stmt.get())) == SQLITE_ROW) {
      auto topic = topics_.find(sqlite3_column_int64(stmt.get(), 1));
      if (topic == topics_.end() || topic->second.type == RosMessageType::kOther) continue;
      RosSample sample;
      sample.record_ns = sqlite3_column_int64(stmt.get(), 2);
      const void* blob = sqlite3_column_blob(stmt.get(), 3);
      std::string_view data(static_cast<const char*>(blob),
                            blob ? static_cast<size_t>(sqlite3_column_bytes(stmt.get(), 3)) : 0);
      if (!DecodeCdrMessage(data, topic->second.type, &sample)) {
        return Status::InvalidInput(file_name_ + ": damaged rosbag2 file: the message in row " +
                                    std::to_string(sqlite3_column_int64(stmt.get(), 0)) +
                                    " of table messages is not CDR or too short for its type")
            .WithFile(file_name_);
      }
      s = samples_.Add(topic->second.name, topic->second.type, sample);
      if (!s.ok()) return s.WithFile(file_name_);
    }
    return rc == SQLITE_DONE ? Status::Ok() : Unreadable();
  }

  sqlite3* db_;
  const std::string& file_name_;
  RosTopicSamples samples_;
  std::map<int64_t, Topic> topics_;
};

}  // namespace

Status ReadRosBag2Sqlite(const std::string& path, const std::string& file_name,
                         const SensorLogLimits& limits, SensorLog* log) {
  *log = SensorLog();
  log->format = "rosbag2";
  sqlite3* raw = nullptr;
  int rc = sqlite3_open_v2(path.c_str(), &raw, SQLITE_OPEN_READONLY, nullptr);
  std::unique_ptr<sqlite3, decltype(&sqlite3_close)> db(raw, &sqlite3_close);
  if (rc != SQLITE_OK) {
    return Status::InvalidInput(file_name + ": cannot open as SQLite: " +
                                (raw ? sqlite3_errmsg(raw) : "out of memory"))
        .WithFile(file_name);
  }
  Status s = Db3Reader(db.get(), file_name, limits).Read(log);
  if (!s.ok()) {
    *log = SensorLog();
    log->format = "rosbag2";
  }
  return s;
}

}  // namespace calibd::server
