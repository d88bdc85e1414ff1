// core/knn.hpp (tested here because the rasteriser's metrics and reference renders own it):
// exact answers against brute force, deterministic ties, duplicates and tiny inputs.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/knn.hpp"

namespace pbr_lod {
namespace {

// Random points: the k nearest (indices and squared distances) equal a brute-force sort by
// (distance, index). Random input is fine here: ties have probability ~0 and the seed is fixed.
TEST(Knn, MatchesBruteForce) {
  std::mt19937 rng(42);
  std::uniform_real_distribution<float> u(-1, 1);
  std::vector<vec3f> pts(2000);
  for (auto& p : pts) p = vec3f(u(rng), u(rng), u(rng));
  const knn_index index(pts);
  EXPECT_EQ(index.size(), pts.size());
  std::vector<std::uint32_t> idx;
  std::vector<float> d2;
  for (int q = 0; q < 100; ++q) {
    const vec3f x(u(rng), u(rng), u(rng));
    std::vector<std::uint32_t> order(pts.size());
    std::iota(order.begin(), order.end(), 0u);
    std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
      const float da = (pts[a] - x).squaredNorm(), db = (pts[b] - x).squaredNorm();
      return da < db || (da == db && a < b);
    });
    index.query(x, 7, idx, d2);
    ASSERT_EQ(idx.size(), 7u);
    for (std::size_t i = 0; i < 7; ++i) {
      EXPECT_EQ(idx[i], order[i]);
      EXPECT_NEAR(d2[i], (pts[order[i]] - x).squaredNorm(), 1e-6f);
    }
    EXPECT_NEAR(index.nearest_distance(x), (pts[order[0]] - x).norm(), 1e-6f);
  }
}

// The batch over all points equals a brute-force k-NN of each point (distances; indices where
// there is no tie, which random points have with probability ~0), whatever the thread count.
TEST(Knn, GraphMatchesBruteForce) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1, 1);
  std::vector<vec3f> pts(3000);
  for (auto& p : pts) p = vec3f(u(rng), u(rng), u(rng) * 0.1f);
  const knn_graph g = nearest_neighbour_graph(pts, 9, 1);
  ASSERT_EQ(g.k, 9u);
  ASSERT_EQ(g.size(), pts.size());
  for (std::size_t i = 0; i < pts.size(); i += 7) {
    std::vector<std::uint32_t> order(pts.size());
    std::iota(order.begin(), order.end(), 0u);
    std::partial_sort(
        order.begin(), order.begin() + 9, order.end(), [&](std::uint32_t a, std::uint32_t b) {
          const float da = (pts[a] - pts[i]).squaredNorm(), db = (pts[b] - pts[i]).squaredNorm();
          return da < db || (da == db && a < b);
        });
    for (std::size_t j = 0; j < 9; ++j) {
      EXPECT_EQ(g.neighbours(i)[j], order[j]) << i << " " << j;
      EXPECT_FLOAT_EQ(g.dist2[i * 9 + j], (pts[order[j]] - pts[i]).squaredNorm());
    }
  }
  for (const unsigned t : {2u, 3u}) {
    const knn_graph h = nearest_neighbour_graph(pts, 9, t);
    EXPECT_EQ(h.index, g.index);
    EXPECT_EQ(h.dist2, g.dist2);
  }
  // knn_spacing(k) is the distance of each row's (k + 1)-th entry (the point itself first), for
  // every point in the caller's order.
  const std::vector<float> s8 = knn_spacing(pts, 8, 2);
  for (std::size_t i = 0; i < pts.size(); ++i) ASSERT_EQ(s8[i], std::sqrt(g.dist2[i * 9 + 8])) << i;
  // Fewer points than k: every row lists all of them.
  const knn_graph small = nearest_neighbour_graph(std::span(pts).first(4), 9);
  EXPECT_EQ(small.k, 4u);
  EXPECT_TRUE(nearest_neighbour_graph({}, 3).index.empty());
  EXPECT_THROW((void)nearest_neighbour_graph(pts, 0), InvalidArgument);
}

// The Morton order of the 8 corners of a cube is the Z-order x, then y, then z (bit 0 of the
// code is x): (0,0,0), (1,0,0), (0,1,0), (1,1,0), (0,0,1), ... whatever order they come in.
TEST(Knn, MortonOrderIsZOrder) {
  std::vector<vec3f> corners;
  for (int i = 7; i >= 0; --i)
    corners.emplace_back(float(i & 1), float((i >> 1) & 1), float(i >> 2));
  const auto order = morton_order(corners);
  ASSERT_EQ(order.size(), 8u);
  for (std::size_t r = 0; r < 8; ++r) {
    const vec3f& p = corners[order[r]];
    EXPECT_EQ(int(p.x()) | int(p.y()) << 1 | int(p.z()) << 2, int(r));
  }
  // Equal keys keep the input order (stable), and a non-finite point goes last.
  const std::vector<vec3f> dup = {vec3f(1, 1, 1), vec3f(std::nanf(""), 0, 0), vec3f(0, 0, 0),
                                  vec3f(1, 1, 1)};
  EXPECT_EQ(morton_order(dup), (std::vector<std::uint32_t>{2, 0, 3, 1}));
}

// On a unit grid the 4 nearest neighbours of an interior point are at distance 1 (ties): they
// come out ordered by position (x, then y), not by index, and the same on every query.
TEST(Knn, TiesAreOrderedByPosition) {
  std::vector<vec3f> pts;
  for (int j = 0; j < 9; ++j)
    for (int i = 0; i < 9; ++i) pts.emplace_back(float(i), float(j), 0);
  const knn_index index(pts);
  std::vector<std::uint32_t> idx;
  std::vector<float> d2;
  index.query(vec3f(4, 4, 0), 5, idx, d2);
  // Self, then (3,4), (4,3), (4,5), (5,4) — by index it would be 31, 39, 41, 49.
  const std::vector<std::uint32_t> want = {40, 39, 31, 49, 41};
  EXPECT_EQ(idx, want);
  EXPECT_EQ(d2, (std::vector<float>{0, 1, 1, 1, 1}));
}

// k-th neighbour spacing on a square grid of spacing h: 4 neighbours at h, 4 at √2·h, so the
// 8th is at √2·h for interior points; the 4th at h.
TEST(Knn, SpacingOnGrid) {
  std::vector<vec3f> pts;
  for (int j = 0; j < 10; ++j)
    for (int i = 0; i < 10; ++i) pts.emplace_back(0.5f * float(i), 0.5f * float(j), 2);
  const std::vector<float> s8 = knn_spacing(pts, 8), s4 = knn_spacing(pts, 4);
  EXPECT_NEAR(s8[55], 0.5f * std::sqrt(2.0f), 1e-6f);
  EXPECT_NEAR(s4[55], 0.5f, 1e-6f);
}

// Duplicates and tiny inputs: no crash, sensible answers.
TEST(Knn, DuplicatesAndTinyInputs) {
  std::vector<vec3f> dup(500, vec3f(1, 2, 3));
  dup.emplace_back(2, 2, 3);
  const std::vector<float> s = knn_spacing(dup, 8);
  EXPECT_EQ(s[0], 0.0f);      // 8 duplicates at distance 0
  EXPECT_EQ(s.back(), 1.0f);  // the lone point: all its neighbours at distance 1
  const knn_index index(dup);
  std::vector<std::uint32_t> idx;
  std::vector<float> d2;
  index.query(vec3f(0, 0, 0), 3, idx, d2);
  EXPECT_EQ(idx, (std::vector<std::uint32_t>{0, 1, 2}));

  const knn_index empty(std::span<const vec3f>{});
  EXPECT_EQ(empty.size(), 0u);
  empty.query(vec3f::Zero(), 4, idx, d2);
  EXPECT_TRUE(idx.empty() && d2.empty());
  EXPECT_TRUE(std::isinf(empty.nearest_distance(vec3f::Zero())));

  const std::vector<vec3f> two = {vec3f(0, 0, 0), vec3f(0, 3, 4)};
  const knn_index small(two);
  small.query(vec3f::Zero(), 10, idx, d2);  // k ≥ n: all of them
  EXPECT_EQ(idx.size(), 2u);
  EXPECT_EQ(knn_spacing(two, 8), (std::vector<float>{5, 5}));  // k ≥ n: farthest other point
  EXPECT_EQ(knn_spacing(std::vector<vec3f>{vec3f::Ones()}, 8), (std::vector<float>{0}));
  small.query(vec3f::Zero(), 0, idx, d2);
  EXPECT_TRUE(idx.empty());
}

TEST(Knn, RejectsNonFinitePoints) {
  const std::vector<vec3f> bad = {vec3f::Zero(),
                                  vec3f(std::numeric_limits<float>::quiet_NaN(), 0, 0)};
  EXPECT_THROW(knn_index{bad}, InvalidArgument);
}

}  // namespace
}  // namespace pbr_lod
