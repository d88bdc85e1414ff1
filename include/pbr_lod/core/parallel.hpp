// pbr_lod — deterministic fork-join over index ranges with std::thread (no scheduler state, so
// a library call never depends on a pool its caller configured).
#pragma once

#include <algorithm>
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

}  // namespace pbr_lod::detail
