// Storage throughput with synchronous=FULL (every acknowledged write is on disk), beside the
// disk's raw fdatasync rate, which bounds one writer's commits per second.
//
//   storage_bench [--benchmark_...]     files go to $CALIBD_BENCH_DIR (default: $TMPDIR or /tmp)
//
// Figures and the exact command: bench/README.md.
#include <benchmark/benchmark.h>
#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "storage/db.h"
#include "storage/store.h"

namespace calibd::storage {
namespace {

std::string BenchDir() {
  static const std::string dir = [] {
    const char* base = std::getenv("CALIBD_BENCH_DIR");
    if (base == nullptr) base = std::getenv("TMPDIR");
    std::string templ = std::string(base != nullptr ? base : "/tmp") + "/calibd-bench-XXXXXX";
    char* made = mkdtemp(templ.data());
    if (made == nullptr) std::abort();
    return std::string(made);
  }();
  return dir;
}

void Check(const Status& s) {
  if (!s.ok()) {
    std::fprintf(stderr, "storage_bench: %s\n", s.ToString().c_str());
    std::abort();
  }
}

// One store per configuration, shared by the benchmark's threads.
Store* SharedStore(const std::string& name, int max_write_batch) {
  static std::mutex mu;
  static std::map<std::string, std::unique_ptr<Store>> stores;
  std::lock_guard<std::mutex> lock(mu);
  auto& slot = stores[name];
  if (!slot) {
    StoreOptions o;
    o.max_write_batch = max_write_batch;
    Check(Store::Open(BenchDir() + "/" + name + ".db", o, &slot));
  }
  return slot.get();
}

std::atomic<uint64_t> g_unique{0};

// Raw disk: append 512 bytes and fdatasync, the cost floor of one durable commit.
void BM_RawFdatasync(benchmark::State& state) {
  const std::string path = BenchDir() + "/fsync.tmp";
  int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd < 0) std::abort();
  char block[512] = {1};
  for (auto _ : state) {
    if (::write(fd, block, sizeof block) != static_cast<ssize_t>(sizeof block)) std::abort();
    if (::fdatasync(fd) != 0) std::abort();
  }
  ::close(fd);
  ::unlink(path.c_str());
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_RawFdatasync)->UseRealTime()->MinTime(2.0);

// A durable upload of range(0) bytes with its job (PutRecording + NewJob), distinct bytes each.
void Upload(benchmark::State& state, Store* store) {
  std::string bytes(static_cast<size_t>(state.range(0)), 'x');
  for (auto _ : state) {
    uint64_t n = g_unique.fetch_add(1);
    std::memcpy(bytes.data(), &n, sizeof n);  // unique content: no dedupe
    NewRecording r;
    r.data = bytes;
    r.device = "SN-bench";
    r.job = NewJob{"pca", "", "{}"};
    Check(store->PutRecording(r, nullptr, nullptr));
  }
  state.SetItemsProcessed(state.iterations());
  state.SetBytesProcessed(state.iterations() * state.range(0));
}

void BM_DurableUpload(benchmark::State& state) { Upload(state, SharedStore("upload", 64)); }
BENCHMARK(BM_DurableUpload)
    ->Arg(1 << 10)
    ->Arg(1 << 20)
    ->Threads(1)
    ->Threads(8)
    ->UseRealTime()
    ->MinTime(3.0);

void BM_DurableUploadNoGroupCommit(benchmark::State& state) {
  Upload(state, SharedStore("upload_nobatch", 1));
}
BENCHMARK(BM_DurableUploadNoGroupCommit)->Arg(1 << 10)->Threads(8)->UseRealTime()->MinTime(3.0);

// A durable enqueue of a job for a stored recording (POST /jobs).
void BM_DurableEnqueue(benchmark::State& state) {
  Store* store = SharedStore("enqueue", 64);
  static std::once_flag once;
  static int64_t recording = 0;
  std::call_once(once, [&] {
    NewRecording r;
    r.data = "position,s1\np1,1\n";
    RecordingInfo info;
    Check(store->PutRecording(r, &info, nullptr));
    recording = info.id;
  });
  for (auto _ : state) {
    JobInfo job;
    Check(store->EnqueueJob(recording, "pca", "SN-bench", "{\"dimension\":3}", &job));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_DurableEnqueue)->Threads(1)->Threads(8)->UseRealTime()->MinTime(3.0);

// Claim + complete (two durable commits per job), from a queue seeded with enough jobs.
void BM_ClaimComplete(benchmark::State& state) {
  Store* store = SharedStore("claim", 64);
  static std::once_flag once;
  std::call_once(once, [&] {
    NewRecording r;
    r.data = "position,s1\np1,2\n";
    RecordingInfo info;
    Check(store->PutRecording(r, &info, nullptr));
    std::unique_ptr<Db> db;  // seed 100k jobs in one transaction (not what is measured)
    Check(Db::Open(store->path(), Db::Options(), &db));
    Check(
        db->Exec("WITH RECURSIVE n(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM n WHERE i < 100000) "
                 "INSERT INTO jobs (recording_id, method, device, config_json, status, created_at) "
                 "SELECT " +
                 std::to_string(info.id) + ", 'pca', 'SN-bench', '{}', 'queued', 0 FROM n"));
  });
  const std::string worker = "bench-" + std::to_string(state.thread_index());
  const std::string result = R"({"method":"pca","parameters":{"sensors":[]}})";
  for (auto _ : state) {
    JobInfo job;
    bool claimed = false;
    Check(store->ClaimJob(worker, 60000, &job, &claimed));
    if (!claimed) {
      state.SkipWithError("queue ran dry");
      break;
    }
    Check(store->CompleteJob(job.id, worker, result));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_ClaimComplete)->Threads(1)->Threads(4)->UseRealTime()->MinTime(3.0);

}  // namespace
}  // namespace calibd::storage

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  std::error_code ec;
  std::filesystem::remove_all(calibd::storage::BenchDir(), ec);
  return 0;
}
