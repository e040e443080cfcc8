// A writer of ROS 2 SQLite bags (.db3, rosbag2's schema: topics, messages) for the tests of
// formats/rosbag2_sqlite.h and of uploads: topics of cdr messages, messages with their record
// time (ns), then the file at path() = `path` + "." + the process id (replaced; private to the
// process, so test programs that ctest runs in parallel never share one). Not thread-safe; one
// writer per file.
#ifndef CALIBD_TESTS_FORMATS_DB3_WRITER_H_
#define CALIBD_TESTS_FORMATS_DB3_WRITER_H_

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>
#include <utility>

namespace calibd::server::testing {

class Db3Writer {
 public:
  explicit Db3Writer(std::string path) : path_(std::move(path) + "." + std::to_string(::getpid())) {
    std::remove(path_.c_str());
    EXPECT_EQ(sqlite3_open(path_.c_str(), &db_), SQLITE_OK);
    Exec(
        "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, "
        "serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);"
        "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp "
        "INTEGER NOT NULL, data BLOB NOT NULL);");
    // One transaction, no fsync: a statement per message in autocommit mode would sync the file
    // once per message (seconds for a few thousand messages, minutes on a loaded machine).
    Exec("PRAGMA synchronous=OFF; BEGIN;");
    sqlite3_prepare_v2(db_, "INSERT INTO messages(topic_id, timestamp, data) VALUES(?, ?, ?)", -1,
                       &insert_, nullptr);
  }
  ~Db3Writer() { Close(); }
  Db3Writer(const Db3Writer&) = delete;
  Db3Writer& operator=(const Db3Writer&) = delete;

  // Topic `id` named `name` of ROS 2 type `type` (e.g. "sensor_msgs/msg/Imu"), cdr.
  void Topic(int id, const std::string& name, const std::string& type) {
    Exec("INSERT INTO topics VALUES(" + std::to_string(id) + ", '" + name + "', '" + type +
         "', 'cdr', '');");
  }
  // One message on topic `id`, recorded at `record_ns`.
  void Add(int topic, int64_t record_ns, const std::string& cdr) {
    sqlite3_bind_int(insert_, 1, topic);
    sqlite3_bind_int64(insert_, 2, record_ns);
    sqlite3_bind_blob(insert_, 3, cdr.data(), static_cast<int>(cdr.size()), SQLITE_TRANSIENT);
    EXPECT_EQ(sqlite3_step(insert_), SQLITE_DONE);
    sqlite3_reset(insert_);
  }
  // Closes the database; the file is complete at path().
  void Close() {
    if (db_ == nullptr) return;
    sqlite3_finalize(insert_);
    Exec("COMMIT;");
    sqlite3_close(db_);
    db_ = nullptr;
  }
  const std::string& path() const { return path_; }
  // Closes the database and returns the file's bytes.
  std::string Bytes() {
    Close();
    std::ifstream in(path_, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }

 private:
  void Exec(const std::string& sql) {
    EXPECT_EQ(sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, nullptr), SQLITE_OK) << sql;
  }
  std::string path_;
  sqlite3* db_ = nullptr;
  sqlite3_stmt* insert_ = nullptr;
};

}  // namespace calibd::server::testing

#endif  // CALIBD_TESTS_FORMATS_DB3_WRITER_H_
