// Db / Stmt / Transaction: pragmas at open, prepared statements, and SQLite errors as Status.
#include "storage/db.h"

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <fstream>

#include "tests/storage/storage_test_util.h"

namespace calibd::storage {
namespace {

using testing::TempDir;

std::unique_ptr<Db> OpenOrDie(const std::string& path, Db::Options options = {}) {
  std::unique_ptr<Db> db;
  Status s = Db::Open(path, options, &db);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return db;
}

std::string QueryText(Db* db, const char* sql) {
  Stmt st;
  EXPECT_TRUE(db->PrepareUncached(sql, &st).ok());
  bool row = false;
  EXPECT_TRUE(st.Step(&row).ok());
  return row ? st.ColumnText(0) : "";
}

TEST(Db, OpensWithWalFullSyncForeignKeysAndBusyTimeout) {
  TempDir dir;
  Db::Options o;
  o.busy_timeout_ms = 1234;
  auto db = OpenOrDie(dir.File("a.db"), o);
  EXPECT_EQ(QueryText(db.get(), "PRAGMA journal_mode"), "wal");
  int64_t v = 0;
  ASSERT_TRUE(db->QueryInt("PRAGMA synchronous", &v).ok());
  EXPECT_EQ(v, 2);  // FULL
  ASSERT_TRUE(db->QueryInt("PRAGMA foreign_keys", &v).ok());
  EXPECT_EQ(v, 1);
  ASSERT_TRUE(db->QueryInt("PRAGMA busy_timeout", &v).ok());
  EXPECT_EQ(v, 1234);
}

TEST(Db, BindsAndReadsEveryTypeIncludingBinaryBlobs) {
  TempDir dir;
  auto db = OpenOrDie(dir.File("a.db"));
  ASSERT_TRUE(db->Exec("CREATE TABLE t (i INTEGER, d REAL, s TEXT, b BLOB, n TEXT)").ok());
  Stmt ins;
  ASSERT_TRUE(db->Prepare("INSERT INTO t VALUES (?1, ?2, ?3, ?4, ?5)", &ins).ok());
  const std::string blob("a\0b\xff", 4);
  ins.BindInt(1, int64_t{1} << 40)
      .BindDouble(2, 0.25)
      .BindText(3, "héllo")
      .BindBlob(4, blob)
      .BindTextOrNull(5, "");
  ASSERT_TRUE(ins.Run().ok());
  EXPECT_EQ(db->Changes(), 1);
  EXPECT_EQ(db->LastInsertRowid(), 1);
  Stmt sel;
  ASSERT_TRUE(db->Prepare("SELECT i, d, s, b, n FROM t", &sel).ok());
  bool row = false;
  ASSERT_TRUE(sel.Step(&row).ok());
  ASSERT_TRUE(row);
  EXPECT_EQ(sel.ColumnInt(0), int64_t{1} << 40);
  EXPECT_EQ(sel.ColumnDouble(1), 0.25);
  EXPECT_EQ(sel.ColumnText(2), "héllo");
  EXPECT_EQ(sel.ColumnBlob(3), blob);
  EXPECT_TRUE(sel.ColumnIsNull(4));
  ASSERT_TRUE(sel.Step(&row).ok());
  EXPECT_FALSE(row);
}

TEST(Db, CachedStatementComesBackResetWithoutBindings) {
  TempDir dir;
  auto db = OpenOrDie(dir.File("a.db"));
  ASSERT_TRUE(db->Exec("CREATE TABLE t (x); INSERT INTO t VALUES (1), (2)").ok());
  for (int i = 0; i < 3; ++i) {
    Stmt st;
    ASSERT_TRUE(db->Prepare("SELECT x FROM t WHERE ?1 IS NULL OR x = ?1 ORDER BY x", &st).ok());
    if (i == 1) st.BindInt(1, 2);
    bool row = false;
    ASSERT_TRUE(st.Step(&row).ok());  // abandoned mid-result: the destructor resets it
    ASSERT_TRUE(row);
    EXPECT_EQ(st.ColumnInt(0), i == 1 ? 2 : 1);
  }
}

TEST(Db, NestedUseOfTheSameSqlGetsItsOwnStatement) {
  TempDir dir;
  auto db = OpenOrDie(dir.File("a.db"));
  ASSERT_TRUE(db->Exec("CREATE TABLE t (x); INSERT INTO t VALUES (1), (2)").ok());
  const char* sql = "SELECT x FROM t ORDER BY x";
  Stmt outer;
  ASSERT_TRUE(db->Prepare(sql, &outer).ok());
  bool row = false;
  ASSERT_TRUE(outer.Step(&row).ok());
  EXPECT_EQ(outer.ColumnInt(0), 1);
  {
    Stmt inner;  // same text while `outer` is mid-result: must not reset it
    ASSERT_TRUE(db->Prepare(sql, &inner).ok());
    ASSERT_TRUE(inner.Step(&row).ok());
    EXPECT_EQ(inner.ColumnInt(0), 1);
  }
  ASSERT_TRUE(outer.Step(&row).ok());
  ASSERT_TRUE(row);
  EXPECT_EQ(outer.ColumnInt(0), 2);
}

TEST(Db, SyntaxErrorIsInternalWithSqliteMessage) {
  TempDir dir;
  auto db = OpenOrDie(dir.File("a.db"));
  Stmt st;
  Status s = db->Prepare("SELEC 1", &st);
  EXPECT_EQ(s.code(), StatusCode::kInternal);
  EXPECT_NE(s.message().find("syntax error"), std::string::npos) << s.message();
}

TEST(Db, BindingAMissingParameterIsReportedAtStep) {
  TempDir dir;
  auto db = OpenOrDie(dir.File("a.db"));
  Stmt st;
  ASSERT_TRUE(db->Prepare("SELECT ?1", &st).ok());
  st.BindInt(5, 1);
  bool row;
  Status s = st.Step(&row);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("parameter 5"), std::string::npos) << s.message();
}

TEST(Db, ConstraintViolationIsConflict) {
  TempDir dir;
  auto db = OpenOrDie(dir.File("a.db"));
  ASSERT_TRUE(db->Exec("CREATE TABLE t (x UNIQUE); INSERT INTO t VALUES (1)").ok());
  Status s = db->Exec("INSERT INTO t VALUES (1)");
  EXPECT_EQ(s.code(), StatusCode::kConflict);
  EXPECT_NE(s.message().find("UNIQUE constraint failed"), std::string::npos) << s.message();
}

TEST(Db, ForeignKeysAreEnforced) {
  TempDir dir;
  auto db = OpenOrDie(dir.File("a.db"));
  ASSERT_TRUE(db->Exec("CREATE TABLE p (id INTEGER PRIMARY KEY);"
                       "CREATE TABLE c (p INTEGER REFERENCES p(id))")
                  .ok());
  EXPECT_EQ(db->Exec("INSERT INTO c VALUES (7)").code(), StatusCode::kConflict);
}

TEST(Db, LockedDatabaseIsBusyAfterTheTimeout) {
  TempDir dir;
  auto a = OpenOrDie(dir.File("a.db"));
  Db::Options o;
  o.busy_timeout_ms = 50;
  auto b = OpenOrDie(dir.File("a.db"), o);
  ASSERT_TRUE(a->Exec("CREATE TABLE t (x)").ok());
  Transaction txn(a.get());
  ASSERT_TRUE(txn.Begin().ok());
  Transaction other(b.get());
  Status s = other.Begin();
  EXPECT_EQ(s.code(), StatusCode::kBusy);
  EXPECT_TRUE(s.IsTransient());
  EXPECT_NE(s.message().find("database is locked"), std::string::npos) << s.message();
  // Readers are not blocked by a writer in WAL mode.
  int64_t n = -1;
  EXPECT_TRUE(b->QueryInt("SELECT COUNT(*) FROM t", &n).ok());
}

TEST(Db, TransactionRollsBackUnlessCommitted) {
  TempDir dir;
  auto db = OpenOrDie(dir.File("a.db"));
  ASSERT_TRUE(db->Exec("CREATE TABLE t (x)").ok());
  {
    Transaction txn(db.get());
    ASSERT_TRUE(txn.Begin().ok());
    ASSERT_TRUE(db->Exec("INSERT INTO t VALUES (1)").ok());
  }
  EXPECT_FALSE(db->InTransaction());
  {
    Transaction txn(db.get());
    ASSERT_TRUE(txn.Begin().ok());
    ASSERT_TRUE(db->Exec("INSERT INTO t VALUES (2)").ok());
    ASSERT_TRUE(txn.Commit().ok());
  }
  int64_t n = 0;
  ASSERT_TRUE(db->QueryInt("SELECT SUM(x) FROM t", &n).ok());
  EXPECT_EQ(n, 2);
}

TEST(Db, GarbageFileIsCorruption) {
  TempDir dir;
  {
    std::ofstream f(dir.File("junk.db"), std::ios::binary);
    for (int i = 0; i < 512; ++i) f << "this is not an SQLite database. ";
  }
  std::unique_ptr<Db> db;
  Status s = Db::Open(dir.File("junk.db"), Db::Options(), &db);
  EXPECT_EQ(s.code(), StatusCode::kCorruption) << s.ToString();
  EXPECT_NE(s.message().find("not a database"), std::string::npos) << s.message();
  EXPECT_EQ(db, nullptr);
}

TEST(Db, MissingFolderIsAnIoError) {
  std::unique_ptr<Db> db;
  Status s = Db::Open("/nonexistent-calibd-dir/x/a.db", Db::Options(), &db);
  EXPECT_EQ(s.code(), StatusCode::kIoError) << s.ToString();
  EXPECT_NE(s.message().find("unable to open"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("/nonexistent-calibd-dir/x/a.db"), std::string::npos);
}

TEST(Db, ReadOnlyConnectionRejectsWritesClearly) {
  TempDir dir;
  {
    auto db = OpenOrDie(dir.File("a.db"));
    ASSERT_TRUE(db->Exec("CREATE TABLE t (x); INSERT INTO t VALUES (1)").ok());
  }
  Db::Options o;
  o.read_only = true;
  auto db = OpenOrDie(dir.File("a.db"), o);
  int64_t n = 0;
  EXPECT_TRUE(db->QueryInt("SELECT COUNT(*) FROM t", &n).ok());
  EXPECT_EQ(n, 1);
  Status s = db->Exec("INSERT INTO t VALUES (2)");
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_NE(s.message().find("readonly"), std::string::npos) << s.message();
}

TEST(Db, MapsResultCodesToStatusCodes) {
  EXPECT_TRUE(StatusFromSqlite(SQLITE_OK, nullptr, "x").ok());
  EXPECT_TRUE(StatusFromSqlite(SQLITE_DONE, nullptr, "x").ok());
  EXPECT_EQ(StatusFromSqlite(SQLITE_BUSY, nullptr, "x").code(), StatusCode::kBusy);
  EXPECT_EQ(StatusFromSqlite(SQLITE_BUSY_SNAPSHOT, nullptr, "x").code(), StatusCode::kBusy);
  EXPECT_EQ(StatusFromSqlite(SQLITE_FULL, nullptr, "x").code(), StatusCode::kIoError);
  EXPECT_EQ(StatusFromSqlite(SQLITE_IOERR_FSYNC, nullptr, "x").code(), StatusCode::kIoError);
  EXPECT_EQ(StatusFromSqlite(SQLITE_READONLY, nullptr, "x").code(), StatusCode::kIoError);
  EXPECT_EQ(StatusFromSqlite(SQLITE_CANTOPEN, nullptr, "x").code(), StatusCode::kIoError);
  EXPECT_EQ(StatusFromSqlite(SQLITE_CORRUPT, nullptr, "x").code(), StatusCode::kCorruption);
  EXPECT_EQ(StatusFromSqlite(SQLITE_NOTADB, nullptr, "x").code(), StatusCode::kCorruption);
  EXPECT_EQ(StatusFromSqlite(SQLITE_CONSTRAINT_UNIQUE, nullptr, "x").code(), StatusCode::kConflict);
  EXPECT_EQ(StatusFromSqlite(SQLITE_TOOBIG, nullptr, "x").code(), StatusCode::kTooLarge);
  EXPECT_EQ(StatusFromSqlite(SQLITE_MISUSE, nullptr, "x").code(), StatusCode::kInternal);
  Status s = StatusFromSqlite(SQLITE_FULL, nullptr, "store recording");
  EXPECT_NE(s.message().find("store recording"), std::string::npos);
  EXPECT_NE(s.message().find("database or disk is full"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace calibd::storage
