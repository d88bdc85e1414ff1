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

namespace pbr_lod::detail {

/// madvise(MADV_HUGEPAGE) on the 2 MB-aligned part of [data, data + bytes); a no-op where that
/// is unavailable or the range holds no whole huge page. Never throws, never fails visibly.
void advise_huge_pages(const void* data, std::size_t bytes) noexcept;

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

}  // namespace pbr_lod::detail
