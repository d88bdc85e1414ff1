#include <gtest/gtest.h>

#include <atomic>
#include <thread>
#include <vector>

#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod::detail {
namespace {

// Every task runs exactly once, on a worker id below the thread budget, whatever the budget
// (more threads than tasks, none, one) and however uneven the tasks are.
TEST(ParallelTasks, EachTaskOnceOnAValidWorker) {
  for (const std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{7}, std::size_t{1000}})
    for (const unsigned threads : {0u, 1u, 2u, 3u, 16u}) {
      std::vector<std::atomic<int>> runs(n);
      std::atomic<unsigned> bad_worker{0};
      const unsigned budget = std::max(1u, threads);
      parallel_tasks(n, threads, [&](std::size_t t, unsigned w) {
        if (w >= budget) ++bad_worker;
        if (t % 97 == 0) std::this_thread::yield();  // uneven tasks
        ++runs[t];
      });
      for (std::size_t t = 0; t < n; ++t) EXPECT_EQ(runs[t].load(), 1) << n << " " << threads;
      EXPECT_EQ(bad_worker.load(), 0u);
    }
}

// Per-worker accumulators combined afterwards give the same total for any budget.
TEST(ParallelTasks, PerWorkerSumsCombine) {
  for (const unsigned threads : {1u, 2u, 5u}) {
    std::vector<std::size_t> sum(threads, 0);
    parallel_tasks(10000, threads, [&](std::size_t t, unsigned w) { sum[w] += t; });
    std::size_t total = 0;
    for (auto s : sum) total += s;
    EXPECT_EQ(total, std::size_t{10000} * 9999 / 2);
  }
}

}  // namespace
}  // namespace pbr_lod::detail
