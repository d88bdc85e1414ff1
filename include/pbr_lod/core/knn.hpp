// pbr_lod — exact k-nearest-neighbour queries on 3D points.
//
// A small pimpl class in the geometry-central style (utilities/knn.h): FLANN's exact single
// k-d tree (flann::KDTreeSingleIndex, Muja & Lowe) lives in src/core/knn.cpp only, so users of
// this header never see FLANN. Used by the metrics (Hausdorff distance), the reference point
// renderer (splat radius from the spacing of the samples) and the normal / splat-ellipse
// estimation (core/estimation.hpp), which asks for the neighbours of every point at once
// (nearest_neighbour_graph: one batch on the thread pool, queries in Morton order).
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
  /// number found (0 when k ≤ 0 or the index is empty). Equal distances are ordered by the
  /// points' positions (x, then y, then z), exact duplicates by index: the same answer for the
  /// same data, and for any subset of it that holds the neighbours.
  void query(const vec3f& q, int k, std::vector<std::uint32_t>& idx,
             std::vector<float>& dist2) const;

  /// As above, into caller-owned arrays of at least `want` entries, without allocating: the
  /// number found, min(want, size()), is returned.
  std::size_t query(const vec3f& q, std::size_t want, std::uint32_t* idx, float* dist2) const;

  /// Distance from q to the nearest point; +inf when the index is empty.
  [[nodiscard]] float nearest_distance(const vec3f& q) const;

  [[nodiscard]] std::size_t size() const;

 private:
  struct impl;
  std::unique_ptr<impl> impl_;
};

/// The k nearest neighbours of every point of a set, among the set: row i of `index` / `dist2`
/// (k entries from i·k) lists the neighbours of point i nearest first; the first entry is i
/// itself or a duplicate of it (distance 0). Equidistant neighbours come ordered by position as
/// in knn_index::query (exact duplicates by their rank on the Morton curve below).
/// k = min(requested, #P).
struct knn_graph {
  std::size_t k = 0;
  std::vector<std::uint32_t> index;  ///< #P × k point indices
  std::vector<float> dist2;          ///< #P × k squared distances

  [[nodiscard]] std::size_t size() const { return k == 0 ? 0 : index.size() / k; }
  [[nodiscard]] std::span<const std::uint32_t> neighbours(std::size_t i) const {
    return std::span(index).subspan(i * k, k);
  }
};

/// All k-nearest-neighbour rows of `pts` in one batch (exact, as knn_index::query): the points
/// are sorted along a Morton (Z-order) curve over their bounding box, indexed in that order and
/// queried in that order on up to `threads` threads (0: all cores), so that consecutive queries
/// walk the same branches of the k-d tree; each writes straight into its row (no allocation per
/// query). The result does not depend on `threads`. Throws InvalidArgument when a point is not
/// finite or k < 1.
[[nodiscard]] knn_graph nearest_neighbour_graph(std::span<const vec3f> pts, int k,
                                                unsigned threads = 0);

/// The permutation that sorts `pts` along a Morton (Z-order) curve of 2^10 cells per axis over
/// their bounding box, ties by index: order[r] = the index of the point of rank r. Stable and
/// deterministic; linear time (radix sort). Non-finite points go last.
[[nodiscard]] std::vector<std::uint32_t> morton_order(std::span<const vec3f> pts);

/// Per point, the distance to its k-th nearest neighbour other than itself (a duplicate counts
/// as a neighbour at distance 0). When k ≥ #P the farthest other point is used instead; a single
/// point (or k ≤ 0) gets 0.
/// Queried in one Morton-ordered batch on up to `threads` threads (0: all cores), keeping only
/// the distance (no k-NN table in memory).
[[nodiscard]] std::vector<float> knn_spacing(std::span<const vec3f> pts, int k,
                                             unsigned threads = 0);

}  // namespace pbr_lod
