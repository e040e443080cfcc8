// TaskPool: every task exactly once, concurrent callers, no pool threads, and solver results
// through the pool identical to the solver's own threads.
#include "core/task_pool.h"

#include <gtest/gtest.h>

#include <atomic>
#include <thread>
#include <vector>

#include "core/array.h"
#include "core/array_simulation.h"

namespace calibd::core {
namespace {

TEST(TaskPool, RunsEveryTaskExactlyOnce) {
  for (int threads : {0, 1, 3}) {
    TaskPool pool(threads);
    for (int64_t tasks : {1, 2, 7, 1000}) {
      std::vector<std::atomic<int>> runs(static_cast<size_t>(tasks));
      pool.Run(tasks, [&](int64_t c) { runs[static_cast<size_t>(c)].fetch_add(1); });
      for (int64_t c = 0; c < tasks; ++c)
        ASSERT_EQ(runs[static_cast<size_t>(c)].load(), 1) << "threads " << threads << " task " << c;
    }
  }
}

TEST(TaskPool, ConcurrentCallersEachGetAllTheirTasksDone) {
  TaskPool pool(2);
  constexpr int kCallers = 6;
  constexpr int64_t kTasks = 500;
  std::vector<std::vector<int>> runs(kCallers, std::vector<int>(kTasks, 0));
  std::vector<std::thread> callers;
  for (int k = 0; k < kCallers; ++k) {
    callers.emplace_back([&, k] {
      for (int round = 0; round < 20; ++round) {
        // Each task writes only its own slot: a task run twice or not at all shows in the count.
        pool.Run(kTasks, [&](int64_t c) { ++runs[k][static_cast<size_t>(c)]; });
      }
    });
  }
  for (auto& t : callers) t.join();
  for (int k = 0; k < kCallers; ++k)
    for (int64_t c = 0; c < kTasks; ++c) ASSERT_EQ(runs[k][static_cast<size_t>(c)], 20);
}

TEST(TaskPool, NestedRunFromATaskCompletes) {
  // A task that itself runs a batch (a solver inside a parallel loop) must not deadlock: the
  // caller of the inner batch works on it itself.
  TaskPool pool(1);
  std::atomic<int> inner{0};
  pool.Run(4, [&](int64_t) { pool.Run(8, [&](int64_t) { inner.fetch_add(1); }); });
  EXPECT_EQ(inner.load(), 32);
}

TEST(TaskPool, ArraySolverThroughThePoolIsBitIdenticalToItsOwnThreads) {
  ArraySimulationOptions sim;
  sim.samples = 400;
  sim.seed = 11;
  ArraySimulation data;
  ASSERT_TRUE(SimulateArray(sim, &data).ok());
  ArrayOptions own;
  own.accel_noise = sim.accel_noise;
  own.gyro_noise = sim.gyro_noise;
  own.threads = 2;
  ArrayResult a, b;
  const Status s = CalibrateArray(data.problem, own, &a);
  ASSERT_TRUE(s.ok()) << s.ToString();
  TaskPool pool(1);
  ArrayOptions pooled = own;
  pooled.threads = 0;
  pooled.executor = pool.Executor();
  ASSERT_TRUE(CalibrateArray(data.problem, pooled, &b).ok());
  ASSERT_TRUE(a.usable) << a.reason;
  EXPECT_EQ(a.iterations, b.iterations);
  ASSERT_EQ(a.positions.rows(), b.positions.rows());
  for (int i = 0; i < a.positions.size(); ++i)
    EXPECT_EQ(a.positions.data()[i], b.positions.data()[i]) << i;
}

}  // namespace
}  // namespace calibd::core
