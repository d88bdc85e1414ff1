// pbr_lod — the task runner behind core/parallel.hpp on plain std::threads, for the
// ThreadSanitizer build only (PBR_LOD_TSAN; src/core/sources.cmake).
//
// Why not oneTBB there: Debian's libtbb is not built with -fsanitize=thread, so TSan sees
// neither the pool's hand-over of a task to a worker nor its join, and reports the writes of
// TBB's own templates inlined into our code (blocked_range, start_for::finalize) as races with
// the tasks they hand out. Threads created and joined here are synchronisation TSan sees, so
// what it reports is ours. Every call creates its threads: slow, and irrelevant to what TSan
// checks. The contract (core/parallel.hpp) is the same: worker ids in [0, threads), no two
// running tasks with the same id, the first exception rethrown after the running tasks end.
#include "pbr_lod/core/parallel.hpp"

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace pbr_lod::detail {

void run_tasks(std::size_t n, unsigned threads, void (*fn)(void*, std::size_t, unsigned),
               void* ctx) {
  if (n == 0) return;
  if (threads <= 1 || n == 1) {
    for (std::size_t t = 0; t < n; ++t) fn(ctx, t, 0u);
    return;
  }
  constexpr unsigned max_workers = 64;  // as the TBB runner's largest arena
  const auto workers =
      static_cast<unsigned>(std::min<std::size_t>({n, std::size_t{threads}, max_workers}));
  std::atomic<std::size_t> next{0};
  std::atomic<bool> failed{false};
  std::exception_ptr first;
  std::mutex first_mutex;
  const auto work = [&](unsigned w) {
    while (!failed.load(std::memory_order_relaxed)) {
      const std::size_t t = next.fetch_add(1, std::memory_order_relaxed);
      if (t >= n) return;
      try {
        fn(ctx, t, w);
      } catch (...) {
        const std::lock_guard lock(first_mutex);
        if (!first) first = std::current_exception();
        failed.store(true, std::memory_order_relaxed);
      }
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(workers - 1);
  for (unsigned w = 1; w < workers; ++w) pool.emplace_back(work, w);
  work(0);
  for (std::thread& t : pool) t.join();
  if (first) std::rethrow_exception(first);
}

}  // namespace pbr_lod::detail
