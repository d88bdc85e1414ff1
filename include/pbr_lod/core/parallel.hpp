// pbr_lod — deterministic fork-join over index ranges. The work runs on a persistent pool of
// threads (oneTBB's, reached through src/core/parallel_tbb.cpp, so TBB stays out of this header):
// no thread is created per call, and what a call computes depends only on its arguments, never
// on the pool, how many of its threads take part or in which order they pick up the work.
#pragma once

#include <algorithm>
#include <cstddef>
#include <memory>
#include <type_traits>
#include <utility>

namespace pbr_lod {

/// What a `threads` option means, in every builder, estimation, metric and the tool: 0 is every
/// core the machine reports (at least 1), any other value is itself.
[[nodiscard]] unsigned resolve_threads(unsigned threads);

}  // namespace pbr_lod

namespace pbr_lod::detail {

/// fn(ctx, task, worker) for every task in [0, n), each exactly once, on at most `threads`
/// threads at a time (the calling thread is one of them); worker ∈ [0, max(threads, 1)), and no
/// two tasks run concurrently under the same worker id. Tasks are handed out one at a time, so
/// a slow core or a long task leaves the others busy. An exception thrown by a task is rethrown
/// here (the first one, after the tasks already running have finished; tasks not yet started
/// may be skipped). A call from inside a task waits only for its own tasks (it never picks up
/// its caller's), so nesting is safe.
void run_tasks(std::size_t n, unsigned threads, void (*fn)(void*, std::size_t, unsigned),
               void* ctx);

/// f(task, worker) for every task in [0, n) on up to `threads` workers (worker 0 is the calling
/// thread when it runs alone), tasks handed out one at a time: for tasks of uneven size, where
/// fixed chunks leave a worker idle. Each task runs once, in no fixed order and on no fixed
/// worker, so f must not depend on either beyond per-worker accumulators combined afterwards.
template <class F>
void parallel_tasks(std::size_t n, unsigned threads, F&& f) {
  if (threads <= 1 || n <= 1) {
    for (std::size_t t = 0; t < n; ++t) f(t, 0u);
    return;
  }
  using G = std::remove_reference_t<F>;
  run_tasks(
      n, threads, [](void* ctx, std::size_t t, unsigned w) { (*static_cast<G*>(ctx))(t, w); },
      const_cast<void*>(static_cast<const void*>(std::addressof(f))));
}

/// f(lo, hi) over up to `threads` contiguous chunks of [0, n), each at least about min_chunk
/// long. Each index is visited once and the chunking depends only on n, threads and min_chunk,
/// so results that combine per-chunk values are reproducible.
template <class F>
void parallel_chunks(std::size_t n, unsigned threads, std::size_t min_chunk, F&& f) {
  threads = std::max(
      1u, std::min<unsigned>(threads,
                             static_cast<unsigned>(n / std::max<std::size_t>(1, min_chunk) + 1)));
  if (threads == 1) {
    f(std::size_t{0}, n);
    return;
  }
  parallel_tasks(threads, threads,
                 [&](std::size_t t, unsigned) { f(n * t / threads, n * (t + 1) / threads); });
}

/// How many ranges parallel_pieces() cuts [0, n) into: `pieces`, fewer when n is small so that
/// each holds at least min_piece, and one when threads ≤ 1. For callers that hand out the same
/// pieces themselves (piece_range()).
inline std::size_t piece_count(std::size_t n, unsigned threads, std::size_t pieces,
                               std::size_t min_piece) {
  if (threads <= 1) return 1;
  return std::max<std::size_t>(1, std::min(pieces, n / std::max<std::size_t>(1, min_piece)));
}

/// Range i of [0, n) cut into `count` contiguous, nearly equal ranges.
inline std::pair<std::size_t, std::size_t> piece_range(std::size_t n, std::size_t count,
                                                       std::size_t i) {
  return {n * i / count, n * (i + 1) / count};
}

/// f(lo, hi) over piece_count() contiguous, nearly equal ranges of [0, n), handed out one at a
/// time to up to `threads` workers: for element-wise passes, where more pieces than threads keep
/// every core busy when one is slower (a busy neighbour on a VM) or a piece costs more than
/// another.
template <class F>
void parallel_pieces(std::size_t n, unsigned threads, std::size_t pieces, std::size_t min_piece,
                     F&& f) {
  const std::size_t count = piece_count(n, threads, pieces, min_piece);
  if (count == 1) {
    f(std::size_t{0}, n);
    return;
  }
  parallel_tasks(count, threads, [&](std::size_t t, unsigned) {
    const auto [lo, hi] = piece_range(n, count, t);
    f(lo, hi);
  });
}

}  // namespace pbr_lod::detail
