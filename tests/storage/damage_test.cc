// Damaged copies of a database file (bytes changed under SQLite, as a bad copy or a bad sector
// does): a recording's bytes are checked against their SHA-256 when read and repaired by a
// re-upload of the same bytes; the structure check finds broken pages; a full disk is said
// without SQL.
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <string>

#include "storage/db.h"
#include "storage/store.h"
#include "tests/storage/storage_test_util.h"

namespace calibd::storage {
namespace {

using testing::RandomBytes;
using testing::TempDir;

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Changes the byte at `offset` of `marker`'s only occurrence in the file (xor 0x01): one bit.
void FlipBitOf(const std::string& path, const std::string& marker, size_t offset = 0) {
  const std::string file = ReadFile(path);
  const size_t at = file.find(marker);
  ASSERT_NE(at, std::string::npos) << marker << " not in " << path;
  ASSERT_EQ(file.find(marker, at + 1), std::string::npos) << marker << " twice in " << path;
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  f.seekp(static_cast<std::streamoff>(at + offset));
  const char flipped = static_cast<char>(file[at + offset] ^ 0x01);
  f.write(&flipped, 1);
}

// A recording of 64 KiB (overflow pages) with `marker` in its middle.
std::string RecordingBytes(const std::string& marker) {
  std::string bytes = RandomBytes(64 << 10, 7);
  bytes.replace(30000, marker.size(), marker);
  return bytes;
}

class Damage : public ::testing::Test {
 protected:
  // Stores `bytes` (no job), writes everything into the main file and closes the store.
  int64_t StoreAndClose(const std::string& bytes) {
    std::unique_ptr<Store> store;
    Status s = Store::Open(path_, StoreOptions(), &store);
    EXPECT_TRUE(s.ok()) << s.ToString();
    NewRecording r;
    r.data = bytes;
    r.device = "SN1";
    RecordingInfo info;
    s = store->PutRecording(r, &info, nullptr);
    EXPECT_TRUE(s.ok()) << s.ToString();
    EXPECT_TRUE(store->Checkpoint().ok());
    return info.id;
  }
  std::unique_ptr<Store> Reopen() {
    std::unique_ptr<Store> store;
    Status s = Store::Open(path_, StoreOptions(), &store);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return store;
  }
  TempDir dir_;
  std::string path_ = dir_.File("damaged.db");
};

TEST_F(Damage, AFlippedBitInARecordingIsFoundWhenItIsReadAndNamed) {
  const std::string bytes = RecordingBytes("<<recording-marker-0001>>");
  const int64_t id = StoreAndClose(bytes);
  FlipBitOf(path_, "<<recording-marker-0001>>", 5);
  std::unique_ptr<Store> store = Reopen();
  // SQLite's own check sees nothing: the page structure is intact, only content changed.
  std::string check;
  ASSERT_TRUE(store->IntegrityCheck(&check).ok());
  EXPECT_EQ(check, "ok");
  std::string read;
  Status s = store->ReadRecordingBytes(id, &read);
  EXPECT_EQ(s.code(), StatusCode::kCorruption) << s.ToString();
  EXPECT_EQ(s.reason(), Reason::kStorageDamaged);
  EXPECT_NE(s.message().find("recording " + std::to_string(id) + " is damaged"), std::string::npos)
      << s.message();
  EXPECT_NE(s.message().find("upload the original file again"), std::string::npos) << s.message();
  // A reader that stops early has not read the whole: no verdict, no error.
  size_t chunks = 0;
  EXPECT_TRUE(store->ReadRecordingData(id, [&](std::string_view) { return ++chunks < 1; }).ok());
}

TEST_F(Damage, AReuploadOfTheSameBytesRepairsADamagedCopy) {
  const std::string bytes = RecordingBytes("<<recording-marker-0002>>");
  const int64_t id = StoreAndClose(bytes);
  FlipBitOf(path_, "<<recording-marker-0002>>", 3);
  std::unique_ptr<Store> store = Reopen();
  std::string read;
  ASSERT_EQ(store->ReadRecordingBytes(id, &read).code(), StatusCode::kCorruption);

  NewRecording again;
  again.data = bytes;
  again.device = "SN1";
  RecordingInfo info;
  bool existed = false;
  Status s = store->PutRecording(again, &info, &existed);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(existed);
  EXPECT_EQ(info.id, id);
  s = store->ReadRecordingBytes(id, &read);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(read == bytes);
}

TEST_F(Damage, AStagedReuploadRepairsADamagedCopyWithOrWithoutItsAnnouncedHash) {
  const std::string bytes = RecordingBytes("<<recording-marker-0003>>");
  const std::string staged = dir_.File("staged.bin");
  {
    std::ofstream out(staged, std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }
  const int64_t id = StoreAndClose(bytes);
  for (bool announce : {false, true}) {
    FlipBitOf(path_, "<<recording-marker-0003>>", announce ? 7 : 9);
    std::unique_ptr<Store> store = Reopen();
    std::string read;
    ASSERT_EQ(store->ReadRecordingBytes(id, &read).code(), StatusCode::kCorruption) << announce;
    NewRecording again;
    again.path = staged;
    if (announce) {
      RecordingInfo stored;
      ASSERT_TRUE(store->GetRecording(id, &stored).ok());
      again.sha256 = stored.sha256;
    }
    RecordingInfo info;
    bool existed = false;
    Status s = store->PutRecording(again, &info, &existed);
    ASSERT_TRUE(s.ok()) << s.ToString();
    EXPECT_TRUE(existed);
    s = store->ReadRecordingBytes(id, &read);
    ASSERT_TRUE(s.ok()) << announce << ": " << s.ToString();
    EXPECT_TRUE(read == bytes) << announce;
    ASSERT_TRUE(store->Checkpoint().ok());
  }
}

TEST_F(Damage, TheQuickCheckFindsABrokenPageChainThatQueriesOfTheQueueDoNotTouch) {
  const std::string marker = "<<recording-marker-0005>>";
  const int64_t id = StoreAndClose(RecordingBytes(marker));
  {
    std::unique_ptr<Store> store = Reopen();
    std::string report;
    ASSERT_TRUE(store->QuickCheck(&report).ok());
    EXPECT_EQ(report, "ok");
  }
  // The first 4 bytes of an overflow page hold the next page's number: point it nowhere.
  const std::string file = ReadFile(path_);
  const size_t at = file.find(marker);
  ASSERT_NE(at, std::string::npos);
  {
    std::fstream f(path_, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(at / 4096 * 4096));
    f.write("\x7f\xff\xff\xff", 4);
  }
  std::unique_ptr<Store> store = Reopen();
  QueueCounts counts;
  EXPECT_TRUE(store->QueueDepth(&counts).ok());  // what /healthz asked before: still fine
  std::string report;
  Status s = store->QuickCheck(&report);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_NE(report, "ok");
  EXPECT_FALSE(report.empty());
  std::string read;
  EXPECT_FALSE(store->ReadRecordingBytes(id, &read).ok());
}

TEST_F(Damage, AFileTooDamagedToCheckGivesTheErrorAsItsReport) {
  StoreAndClose(RecordingBytes("<<recording-marker-0006>>"));
  std::unique_ptr<Store> store = Reopen();
  {
    // Page 2 onwards (the tables' roots) overwritten while the store is open.
    std::fstream f(path_, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(4096);
    const std::string garbage(8 * 4096, '\xab');
    f.write(garbage.data(), static_cast<std::streamsize>(garbage.size()));
  }
  store.reset();
  store = Reopen();
  if (!store) return;  // refused at open: also a clear outcome (fault_test covers it)
  std::string report;
  Status s = store->QuickCheck(&report);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_NE(report, "ok");
}

TEST(DiskFull, AFullDatabaseSaysSoWithItsReasonAndWithoutSql) {
  TempDir dir;
  std::unique_ptr<Store> store;
  StoreOptions o;
  o.max_page_count = 60;
  ASSERT_TRUE(Store::Open(dir.File("full.db"), o, &store).ok());
  Status failure;
  for (uint32_t i = 0; i < 100 && failure.ok(); ++i) {
    const std::string bytes = RandomBytes(20000, i);
    NewRecording r;
    r.data = bytes;
    r.job = NewJob{"pca", "SN1", "{}"};
    failure = store->PutRecording(r, nullptr, nullptr);
  }
  ASSERT_FALSE(failure.ok());
  EXPECT_EQ(failure.code(), StatusCode::kIoError) << failure.ToString();
  EXPECT_EQ(failure.reason(), Reason::kDiskFull) << failure.ToString();
  for (const char* sql : {"INSERT", "SELECT", "UPDATE", "VALUES", "`", "?1"}) {
    EXPECT_EQ(failure.message().find(sql), std::string::npos) << sql << " in " << failure.message();
  }
  EXPECT_NE(failure.message().find("full"), std::string::npos) << failure.message();
}

TEST(DescribeStatement, NamesWhatAStatementDoesWithoutItsText) {
  EXPECT_EQ(DescribeStatement("INSERT INTO recordings (sha256, bytes) VALUES (?1, ?2)"),
            "writing recordings");
  EXPECT_EQ(DescribeStatement("  update jobs SET status = 'x' WHERE id = ?1"), "writing jobs");
  EXPECT_EQ(DescribeStatement("SELECT id FROM recordings WHERE sha256 = ?1"), "reading recordings");
  EXPECT_EQ(DescribeStatement("DELETE FROM recording_data WHERE recording_id = ?1"),
            "deleting from recording_data");
  EXPECT_EQ(DescribeStatement("BEGIN IMMEDIATE"), "a transaction");
  EXPECT_EQ(DescribeStatement("PRAGMA journal_mode=WAL"), "a database setting");
  EXPECT_EQ(DescribeStatement(""), "a statement");
  EXPECT_EQ(DescribeStatement("SELECT 1"), "reading");
}

}  // namespace
}  // namespace calibd::storage
