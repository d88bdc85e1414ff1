#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <stdexcept>
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

// A task's exception reaches the caller (it used to end the process from a spawned thread), the
// tasks already running finish first, and the runner stays usable afterwards.
TEST(ParallelTasks, ExceptionReachesTheCaller) {
  std::atomic<int> ran{0};
  EXPECT_THROW(parallel_tasks(64, 2,
                              [&](std::size_t t, unsigned) {
                                ++ran;
                                if (t == 5) throw std::runtime_error("task 5");
                              }),
               std::runtime_error);
  EXPECT_GE(ran.load(), 1);
  std::atomic<int> after{0};
  parallel_tasks(64, 2, [&](std::size_t, unsigned) { ++after; });
  EXPECT_EQ(after.load(), 64);
}

// Nested calls (a builder's pass inside another's task) run every inner task once, and within
// one call no worker id is held by two running tasks at once, even while a task waits for its
// nested call (the runner isolates each call's wait). On 2 cores the steal that would break the
// second property cannot happen (the thief's own queue is empty when it steals, so no outer task
// is left to take); with more cores it can.
TEST(ParallelTasks, NestedCallsKeepWorkerIdsExclusive) {
  for (const unsigned threads : {2u, 3u}) {
    std::vector<std::atomic<int>> busy(threads);
    std::atomic<int> clash{0}, inner{0};
    parallel_tasks(16, threads, [&](std::size_t, unsigned w) {
      if (busy[w].fetch_add(1) != 0) ++clash;
      // Few, slow inner tasks: the waiting thread runs out of its own and would otherwise take
      // one of the outer call's tasks, under the worker id it already holds.
      parallel_tasks(4, threads, [&](std::size_t, unsigned) {
        std::this_thread::sleep_for(std::chrono::microseconds(300));
        ++inner;
      });
      busy[w].fetch_sub(1);
    });
    EXPECT_EQ(clash.load(), 0) << threads;
    EXPECT_EQ(inner.load(), 16 * 4) << threads;
  }
}

// parallel_chunks: the chunks tile [0, n) in order, as many as the budget allows (n / min_chunk).
TEST(ParallelChunks, ChunksTileTheRange) {
  for (const std::size_t n :
       {std::size_t{0}, std::size_t{5}, std::size_t{4096}, std::size_t{100001}})
    for (const unsigned threads : {1u, 2u, 7u}) {
      std::vector<std::atomic<int>> hits(n);
      std::atomic<int> calls{0};
      parallel_chunks(n, threads, 1000, [&](std::size_t lo, std::size_t hi) {
        ++calls;
        for (std::size_t i = lo; i < hi; ++i) ++hits[i];
      });
      for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(hits[i].load(), 1) << n << " " << threads;
      EXPECT_EQ(static_cast<std::size_t>(calls.load()),
                std::max<std::size_t>(1, std::min<std::size_t>(threads, n / 1000 + 1)));
    }
}

// parallel_pieces: `pieces` ranges when each holds min_piece, fewer otherwise, every index once.
TEST(ParallelPieces, PiecesTileTheRange) {
  for (const std::size_t n : {std::size_t{0}, std::size_t{100}, std::size_t{50000}})
    for (const unsigned threads : {1u, 2u}) {
      std::vector<std::atomic<int>> hits(n);
      std::atomic<int> calls{0};
      parallel_pieces(n, threads, 16, 2048, [&](std::size_t lo, std::size_t hi) {
        ++calls;
        for (std::size_t i = lo; i < hi; ++i) ++hits[i];
      });
      for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(hits[i].load(), 1) << n << " " << threads;
      const std::size_t want =
          threads == 1 ? 1 : std::max<std::size_t>(1, std::min<std::size_t>(16, n / 2048));
      EXPECT_EQ(static_cast<std::size_t>(calls.load()), want) << n << " " << threads;
    }
}

}  // namespace
}  // namespace pbr_lod::detail
