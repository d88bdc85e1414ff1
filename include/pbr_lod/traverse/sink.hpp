// pbr_lod — the Sink concept and the sinks every user gets: counting and buffering.
//
// A Sink receives the primitives of the nodes a traversal emits. The CPU reference rasteriser
// (raster/rasterizer.hpp) is one; a host renderer wraps its vertex buffers in another.
#pragma once

#include <concepts>
#include <cstddef>
#include <vector>

#include "pbr_lod/traverse/primitives.hpp"

namespace pbr_lod {

/// S accepts the primitives of attribute set A.
///   s.point(point_prim<A>)      — square splat / one-pixel point
///   s.splat(splat_prim<A>)      — object-space elliptical splat
///   s.triangle(triangle_prim<A>)
template <class S, attributes A>
concept Sink = requires(S& s, const point_prim<A>& p, const splat_prim<A>& q,
                        const triangle_prim<A>& t) {
  s.point(p);
  s.splat(q);
  s.triangle(t);
};

/// Counts primitives by kind; the cheapest sink (for traversal benchmarks and cut statistics).
template <attributes A>
struct counting_sink {
  std::size_t points = 0, splats = 0, triangles = 0;
  void point(const point_prim<A>&) { ++points; }
  void splat(const splat_prim<A>&) { ++splats; }
  void triangle(const triangle_prim<A>&) { ++triangles; }
  [[nodiscard]] std::size_t total() const { return points + splats + triangles; }
};

/// Collects primitives in arrays a host renderer copies into its vertex buffers.
template <attributes A>
struct buffer_sink {
  std::vector<point_prim<A>> points;
  std::vector<splat_prim<A>> splats;
  std::vector<triangle_prim<A>> triangles;
  void point(const point_prim<A>& p) { points.push_back(p); }
  void splat(const splat_prim<A>& s) { splats.push_back(s); }
  void triangle(const triangle_prim<A>& t) { triangles.push_back(t); }
  void clear() {
    points.clear();
    splats.clear();
    triangles.clear();
  }
  /// Replays the buffered primitives into another sink (e.g. the rasteriser).
  template <Sink<A> S>
  void replay(S& s) const {
    for (const auto& p : points) s.point(p);
    for (const auto& q : splats) s.splat(q);
    for (const auto& t : triangles) s.triangle(t);
  }
};

static_assert(Sink<counting_sink<positions_only>, positions_only>);
static_assert(Sink<buffer_sink<all_attributes>, all_attributes>);

}  // namespace pbr_lod
