// pbr_lod — widening_sink: primitives of one attribute set handed to a sink of a larger one.
#pragma once

#include <array>

#include "pbr_lod/traverse/sink.hpp"

namespace pbr_lod {

/// Forwards the primitives of attribute set From to a sink of a superset To, the fields From
/// lacks left at their defaults (zero normal, black colour). A host renderer that draws every
/// hierarchy through one vertex format (examples/gl_viewer: normals and colours) wraps its sink
/// in this; which fields are real is From, known to the caller.
template <attributes From, attributes To, Sink<To> Out>
requires((!From.normal || To.normal) && (!From.colour || To.colour)) struct widening_sink {
  Out& out;
  void point(const point_prim<From>& p) {
    point_prim<To> q;
    q.position = p.position;
    q.size_px = p.size_px;
    widen_attributes(p, q);
    out.point(q);
  }
  void splat(const splat_prim<From>& s) {
    splat_prim<To> q;
    q.centre = s.centre;
    q.u = s.u;
    q.v = s.v;
    widen_attributes(s, q);
    out.splat(q);
  }
  void triangle(const triangle_prim<From>& t) {
    triangle_prim<To> q;
    widen_into(t, q);
    out.triangle(q);
  }
  /// Textured triangles (only between attribute sets with colour: the texture stands in for it)
  /// to an output that takes them, the widened triangle_prim otherwise.
  void textured_triangle(const textured_triangle_prim<From>& t) requires(From.colour) {
    if constexpr (TexturedTriangleSink<Out, To>) {
      textured_triangle_prim<To> q;
      q.uv = t.uv;
      q.texture = t.texture;
      widen_into(t.triangle, q.triangle);
      out.textured_triangle(q);
    } else {
      triangle(t.triangle);
    }
  }

 private:
  static void widen_into(const triangle_prim<From>& t, triangle_prim<To>& q) {
    q.p = t.p;
    widen_attributes(t, q);
  }
  /// The normal(s) and colour(s) of a point, splat or triangle; zero normals where From has none.
  template <class P, class Q>
  static void widen_attributes(const P& p, Q& q) {
    if constexpr (From.normal)
      q.normal = p.normal;
    else if constexpr (To.normal)
      set_zero(q.normal);
    if constexpr (From.colour) q.colour = p.colour;
  }
  // Eigen leaves a default-constructed vector uninitialised.
  static void set_zero(vec3f& n) { n = vec3f::Zero(); }
  static void set_zero(std::array<vec3f, 3>& n) { n.fill(vec3f::Zero()); }
};

static_assert(
    Sink<widening_sink<positions_only, with_normals_colours, buffer_sink<with_normals_colours>>,
         positions_only>);

}  // namespace pbr_lod
