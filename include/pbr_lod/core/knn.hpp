// pbr_lod — exact k-nearest-neighbour queries on 3D points.
//
// A small pimpl class in the geometry-central style (utilities/knn.h): FLANN's exact single
// k-d tree (flann::KDTreeSingleIndex, Muja & Lowe) lives in src/core/knn.cpp only, so users of
// this header never see FLANN. Used by the metrics (Hausdorff distance) and the reference point
// renderer (splat radius from the spacing of the samples).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// Exact k-NN index over a copy of the points (P #P positions; duplicates allowed).
/// Const queries are safe for concurrent readers.
class knn_index {
 public:
  /// Copies the points (FLANN keeps a pointer, so the index owns them). Throws InvalidArgument
  /// when a point is not finite. An empty span gives an index that finds nothing.
  explicit knn_index(std::span<const vec3f> pts);
  ~knn_index();
  knn_index(knn_index&&) noexcept;
  knn_index& operator=(knn_index&&) noexcept;
  knn_index(const knn_index&) = delete;
  knn_index& operator=(const knn_index&) = delete;

  /// The min(k, size()) points nearest to q, nearest first: idx their indices into the points
  /// given to the constructor, dist2 their squared distances. Both vectors are resized to the
  /// number found (0 when k ≤ 0 or the index is empty). Ties between equal distances are
  /// resolved deterministically (same data → same answer).
  void query(const vec3f& q, int k, std::vector<std::uint32_t>& idx,
             std::vector<float>& dist2) const;

  /// Distance from q to the nearest point; +inf when the index is empty.
  [[nodiscard]] float nearest_distance(const vec3f& q) const;

  [[nodiscard]] std::size_t size() const;

 private:
  struct impl;
  std::unique_ptr<impl> impl_;
};

/// Per point, the distance to its k-th nearest neighbour other than itself (a duplicate counts
/// as a neighbour at distance 0). When k ≥ #P the farthest other point is used instead; a single
/// point (or k ≤ 0) gets 0.
[[nodiscard]] std::vector<float> knn_spacing(std::span<const vec3f> pts, int k);

}  // namespace pbr_lod
