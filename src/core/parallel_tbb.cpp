// pbr_lod — the task runner behind core/parallel.hpp, on oneTBB's thread pool (every build but
// ThreadSanitizer's, which uses parallel_threads.cpp: src/core/sources.cmake).
#include "pbr_lod/core/parallel.hpp"

#include <tbb/blocked_range.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <mutex>

namespace pbr_lod::detail {
namespace {

/// One arena per thread budget, created on first use and kept: an arena caps how many threads
/// work on a call at once (max_concurrency) and numbers them from 0, which is what
/// parallel_tasks hands out as worker ids. A budget above the machine's concurrency gets an
/// arena of the machine's size: more threads than cores gain nothing, and TBB would warn on
/// stderr that it cannot supply them.
constexpr std::size_t max_budget = 64;
tbb::task_arena& arena_for(unsigned threads) {
  static const auto cores = static_cast<unsigned>(std::max(1, tbb::info::default_concurrency()));
  threads = std::min(threads, cores);
  // Never destroyed: a call from another static object's destructor still finds its arena.
  static auto* const arenas = new std::array<tbb::task_arena*, max_budget + 1>{};
  static std::mutex mutex;
  const std::size_t b = std::min<std::size_t>(threads, max_budget);
  const std::lock_guard lock(mutex);
  auto*& a = (*arenas)[b];
  if (a == nullptr) a = new tbb::task_arena(static_cast<int>(b));
  return *a;
}

}  // namespace

void run_tasks(std::size_t n, unsigned threads, void (*fn)(void*, std::size_t, unsigned),
               void* ctx) {
  if (n == 0) return;
  if (threads <= 1 || n == 1) {
    for (std::size_t t = 0; t < n; ++t) fn(ctx, t, 0u);
    return;
  }
  tbb::task_arena& arena = arena_for(threads);
  const auto budget = static_cast<unsigned>(std::max(1, arena.max_concurrency()));  // ≤ threads
  arena.execute([&] {
    // Isolated: a thread waiting here for this call's tasks runs none of an outer call's, so a
    // task's worker id is never reused by another of its own call's tasks while it waits.
    tbb::this_task_arena::isolate([&] {
      tbb::parallel_for(
          tbb::blocked_range<std::size_t>(0, n, 1),
          [&](const tbb::blocked_range<std::size_t>& r) {
            const int slot = tbb::this_task_arena::current_thread_index();
            const unsigned w =
                slot >= 0 ? static_cast<unsigned>(slot) % budget : 0u;  // slot < budget
            for (std::size_t t = r.begin(); t < r.end(); ++t) fn(ctx, t, w);
          },
          tbb::simple_partitioner());
    });
  });
}

}  // namespace pbr_lod::detail
