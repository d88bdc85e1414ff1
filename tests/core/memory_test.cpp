#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <cstring>
#include <mutex>
#include <set>
#include <vector>

#include "pbr_lod/core/memory.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod::detail {
namespace {

constexpr std::size_t MB = std::size_t{1} << 20;

// A block given back is kept, still holding its contents' pages, and handed out again for a
// request of its size or up to a third smaller; not for a much smaller one.
TEST(RecycledPages, BlocksAreKeptAndReused) {
  release_recycled_pages();
  void* a = recycled_pages(MB);
  std::memset(a, 7, MB);
  EXPECT_EQ(recycled_bytes_kept(), 0u);
  recycle_pages(a, MB);
  EXPECT_EQ(recycled_bytes_kept(), MB);
  void* b = recycled_pages(MB - 1000);  // same whole pages
  EXPECT_EQ(b, a);
  EXPECT_EQ(static_cast<unsigned char*>(b)[MB - 1], 7);  // the pages were not returned
  EXPECT_EQ(recycled_bytes_kept(), 0u);
  // While it is lent the block is nobody else's: the same request maps another one (the count
  // of bytes kept above says nothing about a block still listed as free).
  void* other = recycled_pages(MB - 1000);
  EXPECT_NE(other, b);
  recycle_pages(other, MB - 1000);
  release_recycled_pages();
  // Given back with the smaller size it was lent at: kept at the size it was mapped with.
  recycle_pages(b, MB - 1000);
  EXPECT_EQ(recycled_bytes_kept(), MB);
  void* c = recycled_pages(MB / 2);  // a block twice the request is not used
  EXPECT_NE(c, a);
  EXPECT_EQ(recycled_bytes_kept(), MB);
  void* d = recycled_pages(MB * 3 / 4 + 4096);  // within a third: used
  EXPECT_EQ(d, a);
  recycle_pages(c, MB / 2);
  recycle_pages(d, MB * 3 / 4 + 4096);
  EXPECT_EQ(recycled_bytes_kept(), MB + MB / 2);
  release_recycled_pages();
  EXPECT_EQ(recycled_bytes_kept(), 0u);
}

// Small requests are ordinary heap allocations; they are never kept.
TEST(RecycledPages, SmallRequestsAreNotKept) {
  release_recycled_pages();
  void* p = recycled_pages(recycled_min_bytes - 1);
  ASSERT_NE(p, nullptr);
  recycle_pages(p, recycled_min_bytes - 1);
  EXPECT_EQ(recycled_bytes_kept(), 0u);
  recycle_pages(nullptr, MB);  // a no-op
  EXPECT_EQ(recycled_bytes_kept(), 0u);
}

// What is kept never exceeds the cap: older (smaller) blocks make room, and a block larger than
// the cap is unmapped at once.
TEST(RecycledPages, KeptBytesStayUnderTheCap) {
  release_recycled_pages();
  std::vector<void*> blocks;
  const std::size_t each = recycled_bytes_cap / 4 + 4096;  // four of them do not fit
  for (int i = 0; i < 5; ++i) blocks.push_back(recycled_pages(each));
  for (void* p : blocks) recycle_pages(p, each);
  EXPECT_LE(recycled_bytes_kept(), recycled_bytes_cap);
  EXPECT_EQ(recycled_bytes_kept(), 3 * each);
  void* huge = recycled_pages(recycled_bytes_cap + MB);
  recycle_pages(huge, recycled_bytes_cap + MB);
  EXPECT_EQ(recycled_bytes_kept(), 3 * each);
  release_recycled_pages();
}

// Lent and given back from many threads at once (run under ASan in CI): every block handed out
// is distinct while it is lent, and the bookkeeping stays consistent. Distinctness is checked in
// a registry of the blocks lent (a block handed to two threads at once is found there whatever
// the timing; the bytes written at both ends only show it when the two writes interleave).
TEST(RecycledPages, ConcurrentUse) {
  release_recycled_pages();
  std::mutex m;
  std::set<const void*> lent;
  std::atomic<int> shared{0};
  parallel_tasks(64, 4, [&](std::size_t t, unsigned) {
    const std::size_t bytes = recycled_min_bytes * (1 + t % 5);
    for (int i = 0; i < 50; ++i) {
      auto* p = static_cast<unsigned char*>(recycled_pages(bytes));
      {
        const std::lock_guard lock(m);
        if (!lent.insert(p).second) ++shared;
      }
      p[0] = static_cast<unsigned char>(t);
      p[bytes - 1] = static_cast<unsigned char>(t);
      EXPECT_EQ(p[0], p[bytes - 1]);
      {
        const std::lock_guard lock(m);
        lent.erase(p);
      }
      recycle_pages(p, bytes);
    }
  });
  EXPECT_EQ(shared.load(), 0) << "a block was lent to two users at once";
  EXPECT_GT(recycled_bytes_kept(), 0u) << "blocks given back are kept for reuse";
  EXPECT_LE(recycled_bytes_kept(), recycled_bytes_cap);
  release_recycled_pages();
  EXPECT_EQ(recycled_bytes_kept(), 0u);
}

// scratch_vector works with the builders' helpers and gives its storage back when destroyed.
TEST(RecycledPages, ScratchVector) {
  release_recycled_pages();
  {
    scratch_vector<std::uint32_t> v;
    resize_fresh(v, 1 << 20, 2);
    for (std::size_t i = 0; i < v.size(); ++i) v[i] = static_cast<std::uint32_t>(i);
    EXPECT_EQ(v[12345], 12345u);
  }
  EXPECT_GE(recycled_bytes_kept(), std::size_t{4} << 20);
  release_recycled_pages();
}

}  // namespace
}  // namespace pbr_lod::detail
