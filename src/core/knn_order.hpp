// pbr_lod — the order of k-NN results, shared by the k-d tree (knn.cpp) and the grid
// (grid_knn.cpp) so that both give the same rows.
#pragma once

#include <cstddef>
#include <cstdint>

namespace pbr_lod::detail {

/// Distance first; equal distances by position (x, then y, then z) and then index — so ties come
/// out the same whatever order a search visits them in and, being decided by where the points
/// are, the same in any subset that holds them. `coords`: x, y, z of every point.
[[nodiscard]] inline bool knn_less(float d, std::uint32_t i, float d2, std::uint32_t i2,
                                   const float* coords) {
  if (d != d2) return d < d2;
  const float *a = coords + 3 * std::size_t{i}, *b = coords + 3 * std::size_t{i2};
  for (int c = 0; c < 3; ++c)
    if (a[c] != b[c]) return a[c] < b[c];
  return i < i2;  // duplicates: the same point to every use of a neighbourhood
}

/// Offers (d, id) to the `count` best of at most `capacity` kept in idx/dist, sorted by
/// knn_less; returns whether it was kept.
inline bool knn_insert(std::size_t& count, std::size_t capacity, std::uint32_t* idx, float* dist,
                       float d, std::uint32_t id, const float* coords) {
  if (count == capacity && !knn_less(d, id, dist[capacity - 1], idx[capacity - 1], coords))
    return false;
  std::size_t i = count < capacity ? count++ : capacity - 1;
  for (; i > 0 && knn_less(d, id, dist[i - 1], idx[i - 1], coords); --i) {
    dist[i] = dist[i - 1];
    idx[i] = idx[i - 1];
  }
  dist[i] = d;
  idx[i] = id;
  return true;
}

}  // namespace pbr_lod::detail
