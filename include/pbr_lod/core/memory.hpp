// pbr_lod — large working buffers backed by transparent huge pages.
//
// First touch of fresh memory is the hidden cost of a build on a virtual machine: on the 2-core
// VM the project is measured on, filling 160 MB of new 4 kB pages takes ≈450 ms, the same with
// 2 MB transparent huge pages ≈30–45 ms (docs/point-octree.md, "Build throughput"). Builders
// reserve their large arrays through reserve_huge() before writing them; with THP "always" or
// off, or on other systems, this is an ordinary reserve().
#pragma once

#include <cstddef>
#include <vector>

#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod::detail {

/// Storage in its own anonymous mapping (mmap, whole pages), outside the malloc heap; throws
/// std::bad_alloc when the system refuses. operator new where mmap is unavailable.
void* map_pages(std::size_t bytes);
/// Releases map_pages(bytes) storage. Never throws.
void unmap_pages(void* p, std::size_t bytes) noexcept;

/// Allocator for tables that live as long as the program (normal_quantizer::shared()): their
/// storage does not come from the malloc heap, so they cannot land in the free space that
/// repeated builds reuse there. (On the 2-core VM a 512 kB table allocated from the heap moved
/// glibc into trimming ≈ 4 MB at the end of every 67 k-triangle POP build, and each build then
/// paid ≈ 1 000 page faults, +40 % time; docs/normal-quantization.md.)
template <class T>
struct mapped_allocator {
  using value_type = T;
  mapped_allocator() noexcept = default;
  template <class U>
  mapped_allocator(const mapped_allocator<U>&) noexcept {}  // NOLINT: rebinding is implicit
  T* allocate(std::size_t n) { return static_cast<T*>(map_pages(n * sizeof(T))); }
  void deallocate(T* p, std::size_t n) noexcept { unmap_pages(p, n * sizeof(T)); }
  template <class U>
  bool operator==(const mapped_allocator<U>&) const noexcept {
    return true;
  }
};

/// Storage for a build's large temporary buffers, kept for the next build instead of returned:
/// whole pages outside the malloc heap (map_pages()). A block freed through recycle_pages() is
/// kept while the blocks kept total at most recycled_bytes_cap and handed out again by
/// recycled_pages() for a request of its size up to a quarter less, with its pages still
/// faulted in. Why: a build's temporaries freed to the malloc heap leave a free top that glibc
/// trims when it passes its threshold, and the next build faults the same pages in again (a
/// 67 k-triangle POP build: ≈ 1 300 faults, +12 %, after an unrelated 0.9 MB buffer was added;
/// docs/pop.md, session 9). Thread-safe. Requests below recycled_min_bytes go to operator new.
void* recycled_pages(std::size_t bytes);
/// Gives back recycled_pages(bytes) storage (the same `bytes`). Never throws.
void recycle_pages(void* p, std::size_t bytes) noexcept;
inline constexpr std::size_t recycled_min_bytes = std::size_t{64} << 10;
inline constexpr std::size_t recycled_bytes_cap = std::size_t{64} << 20;
/// Bytes held in kept blocks now (for tests and the docs' measurements).
std::size_t recycled_bytes_kept() noexcept;
/// Unmaps every kept block (blocks lent out are kept when given back, as before).
void release_recycled_pages() noexcept;

/// Allocator over recycled_pages(): for the temporaries of a build that is repeated (a scene's
/// meshes, a benchmark), never for what a builder returns.
template <class T>
struct recycling_allocator {
  using value_type = T;
  recycling_allocator() noexcept = default;
  template <class U>
  recycling_allocator(const recycling_allocator<U>&) noexcept {}  // NOLINT: rebinding is implicit
  T* allocate(std::size_t n) { return static_cast<T*>(recycled_pages(n * sizeof(T))); }
  void deallocate(T* p, std::size_t n) noexcept { recycle_pages(p, n * sizeof(T)); }
  template <class U>
  bool operator==(const recycling_allocator<U>&) const noexcept {
    return true;
  }
};
template <class T>
using scratch_vector = std::vector<T, recycling_allocator<T>>;

/// madvise(MADV_HUGEPAGE) on the 2 MB-aligned part of [data, data + bytes); a no-op where that
/// is unavailable or the range holds no whole huge page. Never throws, never fails visibly.
void advise_huge_pages(const void* data, std::size_t bytes) noexcept;

/// Faults in the pages of [data, data + bytes) for writing without touching their contents
/// (MADV_POPULATE_WRITE, Linux ≥ 5.14): lets several threads take the first-touch cost of one
/// fresh buffer instead of the one that later writes it. A no-op elsewhere; never throws.
void populate_pages(const void* data, std::size_t bytes) noexcept;

/// v.reserve(n), advising huge pages for the new storage when it is large (≥ 4 MB) and not yet
/// touched. Call before filling v.
template <class T, class Alloc>
void reserve_huge(std::vector<T, Alloc>& v, std::size_t n) {
  if (n <= v.capacity()) return;
  if (v.empty()) {
    std::vector<T, Alloc> fresh;
    fresh.reserve(n);
    v.swap(fresh);
  } else {
    v.reserve(n);
  }
  if (n * sizeof(T) >= (std::size_t{4} << 20)) advise_huge_pages(v.data(), n * sizeof(T));
}

/// reserve_huge(v, n), then the pages [v.size(), n) will occupy faulted in by up to `threads`
/// threads (populate_pages). On the 2-core VM the first touch of a fresh 2 MB page costs
/// ≈ 1–2 ms; a sequential resize of a 30 MB array paid all of it on one core.
template <class T, class Alloc>
void populate_fresh(std::vector<T, Alloc>& v, std::size_t n, unsigned threads) {
  const std::size_t old = v.size();
  if (n <= old) return;
  reserve_huge(v, n);
  const auto* from = reinterpret_cast<const unsigned char*>(v.data() + old);
  parallel_chunks((n - old) * sizeof(T), threads, std::size_t{1} << 21,
                  [&](std::size_t lo, std::size_t hi) { populate_pages(from + lo, hi - lo); });
}

/// v.resize(n) for a buffer about to be overwritten: populate_fresh(), then the resize, which
/// only streams the default values through mapped memory (nothing for types whose default
/// constructor leaves them uninitialised, such as Eigen vectors).
template <class T, class Alloc>
void resize_fresh(std::vector<T, Alloc>& v, std::size_t n, unsigned threads) {
  populate_fresh(v, n, threads);
  v.resize(n);
}

/// v.resize(n, value) on pages faulted in by up to `threads` threads (populate_fresh()).
template <class T, class Alloc>
void resize_fresh(std::vector<T, Alloc>& v, std::size_t n, unsigned threads, const T& value) {
  populate_fresh(v, n, threads);
  v.resize(n, value);
}

}  // namespace pbr_lod::detail
