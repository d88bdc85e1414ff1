// pbr_lod — the k nearest neighbours of every point of a set, by a uniform grid.
//
// The estimation's neighbourhoods (core/estimation.cpp) are all-points k-NN queries on scans,
// whose density is near uniform over a surface. A grid whose cells hold a few points each
// answers a query from its own cell and the 26 around it almost always, with no tree to descend:
// docs/estimation.md measures it beside FLANN's k-d tree.
//
// Exact, and the same rows as knn_index::query (core/knn.hpp) bit for bit: distances are
// FLANN's (L2_Simple: the squared differences summed in float, in x, y, z order; the library is
// compiled with -ffp-contract=off), ties ordered as knn_index orders them (by position, then
// index), and a query stops only when no unvisited cell can hold a point as near as its k-th
// (with a margin for the rounding of cell boundaries).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// Row i (k entries): the k nearest of pts to pts[i] (itself included), nearest first, as
/// knn_index(pts).query(pts[i], k) gives them. Queries run on up to `threads` threads (0: all
/// cores); the result does not depend on it. Throws InvalidArgument when k < 1, k > pts.size()
/// or a point is not finite.
[[nodiscard]] std::vector<std::uint32_t> grid_knn_table(std::span<const vec3f> pts, int k,
                                                        unsigned threads = 0);

}  // namespace pbr_lod
