// pbr_lod — huge-page advice for large working buffers (include/pbr_lod/core/memory.hpp).
#include "pbr_lod/core/memory.hpp"

#include <cstdint>
#include <map>
#include <mutex>
#include <new>
#include <unordered_map>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace pbr_lod::detail {

void* map_pages(std::size_t bytes) {
  if (bytes == 0) return nullptr;
#if defined(__linux__)
  void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) throw std::bad_alloc();
  return p;
#else
  return ::operator new(bytes);
#endif
}

void unmap_pages(void* p, std::size_t bytes) noexcept {
  if (p == nullptr) return;
#if defined(__linux__)
  (void)munmap(p, bytes);
#else
  (void)bytes;
  ::operator delete(p);
#endif
}

namespace {
// Kept blocks by mapped size (total ≤ recycled_bytes_cap), and the mapped size of each block
// handed out: a kept block may serve a smaller request, so the size a caller gives back is not
// always the size to keep or unmap.
struct recycled_store {
  std::mutex m;
  std::multimap<std::size_t, void*> kept_blocks;
  std::unordered_map<void*, std::size_t> lent;
  std::size_t kept = 0;
  void unmap_kept() noexcept {  // with m held, or at exit
    for (const auto& [bytes, p] : kept_blocks) unmap_pages(p, bytes);
    kept_blocks.clear();
    kept = 0;
  }
  ~recycled_store() { unmap_kept(); }
};
recycled_store& store() {
  static recycled_store s;
  return s;
}
std::size_t whole_pages(std::size_t bytes) {
  constexpr std::size_t page = 4096;
  return (bytes + page - 1) / page * page;
}
}  // namespace

void* recycled_pages(std::size_t bytes) {
  if (bytes < recycled_min_bytes) return ::operator new(bytes);
  const std::size_t want = whole_pages(bytes);
  auto& s = store();
  const std::lock_guard lock(s.m);
  // The smallest kept block that holds the request and is at most a third larger.
  const auto it = s.kept_blocks.lower_bound(want);
  if (it != s.kept_blocks.end() && it->first - want <= want / 3) {
    const auto [size, p] = *it;
    s.lent.emplace(p, size);  // may throw: nothing is taken yet
    s.kept -= size;
    s.kept_blocks.erase(it);
    return p;
  }
  void* p = map_pages(want);
  try {
    s.lent.emplace(p, want);
  } catch (...) {
    unmap_pages(p, want);
    throw;
  }
  return p;
}

void recycle_pages(void* p, std::size_t bytes) noexcept {
  if (p == nullptr) return;
  if (bytes < recycled_min_bytes) {
    ::operator delete(p);
    return;
  }
  auto& s = store();
  std::size_t size = whole_pages(bytes);
  {
    const std::lock_guard lock(s.m);
    if (const auto it = s.lent.find(p); it != s.lent.end()) {
      size = it->second;
      s.lent.erase(it);
    }
    // Room for it: the smallest kept blocks go first (a block larger than the cap is not kept).
    while (size <= recycled_bytes_cap && s.kept + size > recycled_bytes_cap) {
      const auto first = s.kept_blocks.begin();
      unmap_pages(first->second, first->first);
      s.kept -= first->first;
      s.kept_blocks.erase(first);
    }
    if (size <= recycled_bytes_cap) {
      try {
        s.kept_blocks.emplace(size, p);
        s.kept += size;
        return;
      } catch (...) {  // no memory for the map node: unmap it instead
      }
    }
  }
  unmap_pages(p, size);
}

std::size_t recycled_bytes_kept() noexcept {
  auto& s = store();
  const std::lock_guard lock(s.m);
  return s.kept;
}

void release_recycled_pages() noexcept {
  auto& s = store();
  const std::lock_guard lock(s.m);
  s.unmap_kept();
}

void advise_huge_pages(const void* data, std::size_t bytes) noexcept {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  constexpr std::uintptr_t huge = std::uintptr_t{2} << 20;
  const auto begin = reinterpret_cast<std::uintptr_t>(data);
  const std::uintptr_t lo = (begin + huge - 1) & ~(huge - 1);
  const std::uintptr_t hi = (begin + bytes) & ~(huge - 1);
  // Advice only: an EINVAL (THP compiled out) or ENOMEM leaves ordinary pages, which is correct.
  if (hi > lo) (void)madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_HUGEPAGE);
#else
  (void)data;
  (void)bytes;
#endif
}

void populate_pages(const void* data, std::size_t bytes) noexcept {
#if defined(__linux__)
#ifndef MADV_POPULATE_WRITE
  constexpr int MADV_POPULATE_WRITE = 23;  // Linux 5.14; older kernels answer EINVAL
#endif
  if (bytes == 0) return;
  constexpr std::uintptr_t page = 4096;
  const auto begin = reinterpret_cast<std::uintptr_t>(data);
  const std::uintptr_t lo = begin & ~(page - 1);
  const std::uintptr_t hi = (begin + bytes + page - 1) & ~(page - 1);
  // Advice only: EINVAL (old kernel) leaves the pages to be faulted in on first write.
  (void)madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_POPULATE_WRITE);
#else
  (void)data;
  (void)bytes;
#endif
}

}  // namespace pbr_lod::detail
