// pbr_lod — the Sink concept and the sinks every user gets: counting and buffering.
//
// A Sink receives the primitives of the nodes a traversal emits. The CPU reference rasteriser
// (raster/rasterizer.hpp) is one; a host renderer wraps its vertex buffers in another.
#pragma once

#include <algorithm>
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

/// A sink that also takes occluders (occluder_prim: the first pass of POP's visibility
/// splatting). Optional: an emitter sends occluders only to sinks that model this; the others
/// draw the frame without them.
template <class S>
concept OccluderSink = requires(S& s, const occluder_prim& o) {
  s.occluder(o);
};

/// A sink that also takes screen-space rectangles (screen_rect_prim: a cell whose pixel
/// rectangle and depth the emitter computed itself, the ρ-grid's §4.1 and §5.1). Optional: an
/// emitter sends them only to sinks that model this and sends the others the point_prim it
/// would send without the hook, so a sink that does not take them sees no change.
template <class S, attributes A>
concept ScreenRectSink = requires(S& s, const screen_rect_prim<A>& r) {
  s.screen_rect(r);
};

/// A sink that also takes texture-mapped triangles (textured_triangle_prim). Optional: an emitter
/// sends them only to sinks that model this and sends the others the triangle_prim inside, so a
/// sink that does not take them sees no change.
template <class S, attributes A>
concept TexturedTriangleSink = requires(S& s, const textured_triangle_prim<A>& t) {
  s.textured_triangle(t);
};

/// A sink that also takes 3-D Gaussians (gaussian_prim). Optional: an emitter sends them only to
/// sinks that model this and sends the others as_splat_prim() of each.
template <class S>
concept GaussianSink = requires(S& s, const gaussian_prim& g) {
  s.gaussian(g);
};

/// Counts primitives by kind; the cheapest sink (for traversal benchmarks and cut statistics).
template <attributes A>
struct counting_sink {
  std::size_t points = 0, splats = 0, triangles = 0, gaussians = 0;
  std::size_t occluders = 0;  ///< not primitives of the surface: not in total()
  void point(const point_prim<A>&) { ++points; }
  /// A screen-space rectangle is a point drawn in screen space: counted as a point.
  void screen_rect(const screen_rect_prim<A>&) { ++points; }
  void splat(const splat_prim<A>&) { ++splats; }
  void triangle(const triangle_prim<A>&) { ++triangles; }
  /// A textured triangle is a triangle: counted as one.
  void textured_triangle(const textured_triangle_prim<A>&) { ++triangles; }
  void gaussian(const gaussian_prim&) { ++gaussians; }
  void occluder(const occluder_prim&) { ++occluders; }
  [[nodiscard]] std::size_t total() const { return points + splats + triangles + gaussians; }
};

/// Collects primitives in arrays a host renderer copies into its vertex buffers, and remembers
/// the order they came in, so replay() sends exactly the sequence the traversal emitted (a depth
/// test that keeps the first of two equal depths then gives the same image as drawing directly).
template <attributes A>
struct buffer_sink {
  std::vector<point_prim<A>> points;
  std::vector<splat_prim<A>> splats;
  std::vector<triangle_prim<A>> triangles;
  std::vector<occluder_prim> occluders;
  std::vector<screen_rect_prim<A>> screen_rects;
  std::vector<textured_triangle_prim<A>> textured_triangles;
  std::vector<gaussian_prim> gaussians;

  void point(const point_prim<A>& p) {
    points.push_back(p);
    note(kind::point);
  }
  void screen_rect(const screen_rect_prim<A>& r) {
    screen_rects.push_back(r);
    note(kind::screen_rect);
  }
  void splat(const splat_prim<A>& s) {
    splats.push_back(s);
    note(kind::splat);
  }
  void triangle(const triangle_prim<A>& t) {
    triangles.push_back(t);
    note(kind::triangle);
  }
  void textured_triangle(const textured_triangle_prim<A>& t) {
    textured_triangles.push_back(t);
    note(kind::textured_triangle);
  }
  void gaussian(const gaussian_prim& g) {
    gaussians.push_back(g);
    note(kind::gaussian);
  }
  void occluder(const occluder_prim& o) {
    occluders.push_back(o);
    note(kind::occluder);
  }
  void clear() {
    points.clear();
    splats.clear();
    triangles.clear();
    occluders.clear();
    screen_rects.clear();
    textured_triangles.clear();
    gaussians.clear();
    runs_.clear();
  }
  /// Replays the buffered primitives into another sink (e.g. the rasteriser), in the order they
  /// were received; occluders only to a sink that takes them (OccluderSink); screen rectangles
  /// to a sink that takes them (ScreenRectSink), to the others as as_point_prim(); textured
  /// triangles to a sink that takes them (TexturedTriangleSink), to the others as their
  /// triangle_prim; Gaussians to a sink that takes them (GaussianSink), to the others as
  /// as_splat_prim().
  template <Sink<A> S>
  void replay(S& s) const {
    std::size_t ip = 0, is = 0, it = 0, io = 0, ir = 0, itt = 0, ig = 0;
    for (const run& r : runs_) {
      switch (r.what) {
        case kind::occluder:
          for (const std::size_t e = std::min(io + r.count, occluders.size()); io < e; ++io)
            if constexpr (OccluderSink<S>) s.occluder(occluders[io]);
          break;
        case kind::point:
          for (const std::size_t e = std::min(ip + r.count, points.size()); ip < e; ++ip)
            s.point(points[ip]);
          break;
        case kind::splat:
          for (const std::size_t e = std::min(is + r.count, splats.size()); is < e; ++is)
            s.splat(splats[is]);
          break;
        case kind::triangle:
          for (const std::size_t e = std::min(it + r.count, triangles.size()); it < e; ++it)
            s.triangle(triangles[it]);
          break;
        case kind::screen_rect:
          for (const std::size_t e = std::min(ir + r.count, screen_rects.size()); ir < e; ++ir)
            replay_rect(s, screen_rects[ir]);
          break;
        case kind::textured_triangle:
          for (const std::size_t e = std::min(itt + r.count, textured_triangles.size()); itt < e;
               ++itt)
            replay_textured(s, textured_triangles[itt]);
          break;
        case kind::gaussian:
          for (const std::size_t e = std::min(ig + r.count, gaussians.size()); ig < e; ++ig)
            replay_gaussian(s, gaussians[ig]);
          break;
      }
    }
    // Primitives a caller put into the arrays directly have no recorded order: kind by kind.
    for (; ip < points.size(); ++ip) s.point(points[ip]);
    for (; is < splats.size(); ++is) s.splat(splats[is]);
    for (; it < triangles.size(); ++it) s.triangle(triangles[it]);
    for (; ir < screen_rects.size(); ++ir) replay_rect(s, screen_rects[ir]);
    for (; itt < textured_triangles.size(); ++itt) replay_textured(s, textured_triangles[itt]);
    for (; ig < gaussians.size(); ++ig) replay_gaussian(s, gaussians[ig]);
    if constexpr (OccluderSink<S>)
      for (; io < occluders.size(); ++io) s.occluder(occluders[io]);
  }

 private:
  // The order as runs of one kind: a traversal emits long runs (a node's splats, a leaf's
  // triangles), so this costs a few bytes a frame, not a byte a primitive.
  enum class kind : unsigned char {
    point,
    splat,
    triangle,
    occluder,
    screen_rect,
    textured_triangle,
    gaussian
  };
  template <class S>
  static void replay_rect(S& s, const screen_rect_prim<A>& r) {
    if constexpr (ScreenRectSink<S, A>)
      s.screen_rect(r);
    else
      s.point(as_point_prim(r));
  }
  template <class S>
  static void replay_textured(S& s, const textured_triangle_prim<A>& t) {
    if constexpr (TexturedTriangleSink<S, A>)
      s.textured_triangle(t);
    else
      s.triangle(t.triangle);
  }
  template <class S>
  static void replay_gaussian(S& s, const gaussian_prim& g) {
    if constexpr (GaussianSink<S>)
      s.gaussian(g);
    else
      s.splat(as_splat_prim<A>(g));
  }
  struct run {
    kind what;
    std::size_t count;
  };
  void note(kind k) {
    if (runs_.empty() || runs_.back().what != k)
      runs_.push_back({k, 1});
    else
      ++runs_.back().count;
  }
  std::vector<run> runs_;
};

static_assert(Sink<counting_sink<positions_only>, positions_only>);
static_assert(Sink<buffer_sink<all_attributes>, all_attributes>);
static_assert(ScreenRectSink<buffer_sink<all_attributes>, all_attributes>);
static_assert(TexturedTriangleSink<buffer_sink<all_attributes>, all_attributes>);
static_assert(GaussianSink<buffer_sink<all_attributes>>);

}  // namespace pbr_lod
