// CSV parsing throughput of the recording parser (issue #2 target: >= 500 MB/s per core) on a
// 100 MB recording fed in 1 MiB chunks, as an upload streams in.
#include <benchmark/benchmark.h>

#include <cstdio>
#include <random>
#include <string>

#include "formats/recording.h"

namespace {

// A ~100 MB pca raw log (12 sensors, 9 significant digits) or array recording (K=32 + 32 gyro
// triads), deterministic.
const std::string& Recording(bool array) {
  static std::string pca, arr;
  std::string& text = array ? arr : pca;
  if (!text.empty()) return text;
  std::mt19937_64 rng(1);
  std::normal_distribution<double> normal;
  char buf[64];
  if (array) {
    text = "t";
    for (int k = 0; k < 32; ++k)
      text +=
          ",a" + std::to_string(k) + "_x,a" + std::to_string(k) + "_y,a" + std::to_string(k) + "_z";
    for (int k = 0; k < 32; ++k)
      text +=
          ",g" + std::to_string(k) + "_x,g" + std::to_string(k) + "_y,g" + std::to_string(k) + "_z";
    text += "\n";
    for (int row = 0; text.size() < (100u << 20); ++row) {
      std::snprintf(buf, sizeof buf, "%.2f", row * 0.01);
      text += buf;
      for (int j = 0; j < 192; ++j) {
        std::snprintf(buf, sizeof buf, ",%.9g", normal(rng) * 10);
        text += buf;
      }
      text += "\n";
    }
  } else {
    text = "position,phase";
    for (int i = 0; i < 12; ++i) text += ",s" + std::to_string(i);
    text += "\n";
    for (int row = 0; text.size() < (100u << 20); ++row) {
      std::snprintf(buf, sizeof buf, "p%d,%s", row / 2000, (row / 1000) % 2 ? "moving" : "static");
      text += buf;
      for (int i = 0; i < 12; ++i) {
        std::snprintf(buf, sizeof buf, ",%.9g", normal(rng));
        text += buf;
      }
      text += "\n";
    }
  }
  return text;
}

void Parse(benchmark::State& state, bool array, bool collect) {
  const std::string& text = Recording(array);
  const size_t chunk = 1 << 20;
  for (auto _ : state) {
    calibd::server::RecordingParser parser("bench.csv", collect);
    for (size_t at = 0; at < text.size(); at += chunk) {
      auto s = parser.Feed(std::string_view(text).substr(at, chunk));
      if (!s.ok()) state.SkipWithError(s.ToString().c_str());
    }
    if (!parser.Finish().ok()) state.SkipWithError("finish failed");
    benchmark::DoNotOptimize(parser.summary().rows);
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * text.size()));
}

void BM_ValidatePcaRaw(benchmark::State& state) { Parse(state, false, false); }
void BM_CollectPcaRaw(benchmark::State& state) { Parse(state, false, true); }
void BM_ValidateArray(benchmark::State& state) { Parse(state, true, false); }
void BM_CollectArray(benchmark::State& state) { Parse(state, true, true); }

BENCHMARK(BM_ValidatePcaRaw)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CollectPcaRaw)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ValidateArray)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CollectArray)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
