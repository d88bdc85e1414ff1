// pbr_lod — the one rule for a `threads` option (core/parallel.hpp); the task runner itself is
// parallel_tbb.cpp, or parallel_threads.cpp under ThreadSanitizer.
#include "pbr_lod/core/parallel.hpp"

#include <algorithm>
#include <thread>

namespace pbr_lod {

unsigned resolve_threads(unsigned threads) {
  return threads != 0 ? threads : std::max(1u, std::thread::hardware_concurrency());
}

}  // namespace pbr_lod
