// pbr_lod — the point-set simplifications a user would pick today instead of a LOD hierarchy:
// CGAL's grid_simplify_point_set and hierarchy_simplify_point_set, run level by level to make a
// pyramid. `pbrlod sweep` measures them beside the builders (docs/accuracy.md). CGAL stays out
// of this header (STYLE.md); the implementation is src/peers/cgal_simplify.cpp.
#pragma once

#include <cstdint>
#include <vector>

#include "pbr_lod/core/point_set.hpp"

namespace pbr_lod::peers {

/// CGAL::grid_simplify_point_set: keeps one point per occupied cell of a grid of side `cell`
/// (in the cloud's units, relative to its origin). The kept points carry their own normals,
/// colours, materials and ellipse axes; the order is the input's. Throws InvalidArgument for
/// cell ≤ 0 or not finite, or an invalid cloud (point_cloud::validate).
[[nodiscard]] point_cloud grid_simplify(const point_cloud& in, double cell);

/// CGAL::hierarchy_simplify_point_set (Pauly, Gross & Kobbelt 2002): splits the cloud by PCA
/// until every cluster holds at most `size` points and its surface variation is at most
/// `max_variation` (≤ 1/3), and keeps the point nearest each cluster's centroid, with its
/// attributes; the order is the input's. Throws InvalidArgument for size 0, a variation outside
/// (0, 1/3], or an invalid cloud.
[[nodiscard]] point_cloud hierarchy_simplify(const point_cloud& in, unsigned size,
                                             double max_variation = 1.0 / 3.0);

/// The points of `in` at `keep` (indices in increasing order), with their attributes.
[[nodiscard]] point_cloud subset(const point_cloud& in, const std::vector<std::uint32_t>& keep);

}  // namespace pbr_lod::peers
