// pbr_lod — deterministic fork-join over index ranges with std::thread (no scheduler state, so
// a library call never depends on a pool its caller configured).
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <thread>
#include <vector>

namespace pbr_lod::detail {

/// f(lo, hi) over up to `threads` contiguous chunks of [0, n), each at least about min_chunk
/// long; the calling thread takes the first. Each index is visited once and the chunking depends
/// only on n, threads and min_chunk, so results that combine per-chunk values are reproducible.
template <class F>
void parallel_chunks(std::size_t n, unsigned threads, std::size_t min_chunk, F&& f) {
  threads = std::max(
      1u, std::min<unsigned>(threads,
                             static_cast<unsigned>(n / std::max<std::size_t>(1, min_chunk) + 1)));
  if (threads == 1) {
    f(std::size_t{0}, n);
    return;
  }
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t)
    pool.emplace_back([&, t] { f(n * t / threads, n * (t + 1) / threads); });
  f(std::size_t{0}, n / threads);
  for (auto& th : pool) th.join();
}

/// f(task, worker) for every task in [0, n) on up to `threads` workers (worker 0 is the calling
/// thread), tasks handed out one at a time from a shared counter: for tasks of uneven size, where
/// fixed chunks leave a worker idle. Each task runs once, in no fixed order and on no fixed
/// worker, so f must not depend on either beyond per-worker accumulators combined afterwards.
template <class F>
void parallel_tasks(std::size_t n, unsigned threads, F&& f) {
  threads = static_cast<unsigned>(std::max<std::size_t>(1, std::min<std::size_t>(threads, n)));
  std::atomic<std::size_t> next{0};
  const auto work = [&](unsigned worker) {
    for (std::size_t t; (t = next.fetch_add(1, std::memory_order_relaxed)) < n;) f(t, worker);
  };
  std::vector<std::thread> pool;
  for (unsigned w = 1; w < threads; ++w) pool.emplace_back(work, w);
  work(0);
  for (auto& th : pool) th.join();
}

}  // namespace pbr_lod::detail
