// pbr_lod — the primitives a hierarchy sends to a Sink (the host-renderer boundary).
//
// Coordinates are relative to the hierarchy's origin (the same frame as the `view` the traversal
// was given). Fields for attributes outside A do not exist: a sink instantiated for positions only
// receives 16-byte points.
#pragma once

#include <array>

#include "pbr_lod/core/attributes.hpp"
#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// A screen-aligned square of `size_px` pixels (1 = a one-pixel point) centred on `position`.
template <attributes A>
struct point_prim {
  vec3f position;
  float size_px = 1;
  [[no_unique_address]] detail::maybe<A.normal, vec3f, 0> normal{};
  [[no_unique_address]] detail::maybe<A.colour, rgb8, 1> colour{};
};

/// An object-space elliptical splat: centre, the two semi-axis vectors (tangent to the surface,
/// orthogonal), and — when A has normals — the shading normal (for a flat splat, ±u×v).
template <attributes A>
struct splat_prim {
  vec3f centre;
  vec3f u;
  vec3f v;
  [[no_unique_address]] detail::maybe<A.normal, vec3f, 0> normal{};
  [[no_unique_address]] detail::maybe<A.colour, rgb8, 1> colour{};
};

/// An occluder: a square of size_px pixels about the projection of `position` that hides what
/// lies behind it but is no surface itself — POP's first pass of visibility splatting (Chen &
/// Nguyen 2001 §3.4: each point drawn at full splat size in the background colour, then as one
/// pixel in its own colour). The rasteriser writes its depth and the background colour; where an
/// occluder stays front-most the pixel is a hole (background, no depth) for the hole filling.
/// Sent only to sinks that take it (OccluderSink in sink.hpp); it carries no attributes.
struct occluder_prim {
  vec3f position;
  float size_px = 1;
};

/// A triangle, counter-clockwise seen from its front, with per-vertex normal and colour.
template <attributes A>
struct triangle_prim {
  std::array<vec3f, 3> p;
  [[no_unique_address]] detail::maybe<A.normal, std::array<vec3f, 3>, 0> normal{};
  [[no_unique_address]] detail::maybe<A.colour, std::array<rgb8, 3>, 1> colour{};
};

}  // namespace pbr_lod
