// pbr_lod — the primitives a hierarchy sends to a Sink (the host-renderer boundary).
//
// Coordinates are relative to the hierarchy's origin (the same frame as the `view` the traversal
// was given). Fields for attributes outside A do not exist: a sink instantiated for positions only
// receives 16-byte points.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

#include <Eigen/Eigenvalues>

#include "pbr_lod/core/attributes.hpp"
#include "pbr_lod/core/gaussians.hpp"
#include "pbr_lod/core/math.hpp"
#include "pbr_lod/core/texture_image.hpp"

namespace pbr_lod {

/// A screen-aligned square of `size_px` pixels (1 = a one-pixel point) centred on `position`.
template <attributes A>
struct point_prim {
  vec3f position;
  float size_px = 1;
  [[no_unique_address]] detail::maybe<A.normal, vec3f, 0> normal{};
  [[no_unique_address]] detail::maybe<A.colour, rgb8, 1> colour{};
};

/// A screen-aligned rectangle given in pixels: the screen-space form of a point_prim, for an
/// emitter that computes screen positions itself (the ρ-grid's displacement tables, Duguet &
/// Drettakis 2004 §5.1, and its per-corner rectangles, §4.1). Sent only to sinks that take it
/// (ScreenRectSink in sink.hpp); the others get as_point_prim() of it or, from the emitter,
/// the point_prim it would have sent anyway.
///
/// Coverage: x0, y0, x1, y1 are pixels × 2^fraction_bits from the image's top-left corner
/// (y down). Pixel (i, j) is covered when its centre (i + ½, j + ½) lies in [x0, x1) × [y0, y1)
/// — so a pixel index is a shift, (x0 + 2^(F−1) − 1) >> F the first column — and along an axis
/// where no centre does (a rectangle thinner than a pixel), the pixel containing the midpoint:
/// x0 = x1 is the pixel containing x0, a one-pixel point as point_prim's size ≤ 1.
/// depth is the eye-space depth (along the view direction) the z-buffer stores, what the
/// rasteriser's point() computes from a point_prim's position, so the two z-test against each
/// other in one frame. position is the sample in 3-D (origin-relative, as point_prim's): for what
/// needs world space — two-sided shading's view direction, back-face culling, shadow maps,
/// blending — and for sinks without the hook; coverage and depth do not use it.
template <attributes A>
struct screen_rect_prim {
  static constexpr int fraction_bits = 8;
  static constexpr std::int32_t one_px = std::int32_t(1) << fraction_bits;
  std::int32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  float depth = 0;
  vec3f position;
  [[no_unique_address]] detail::maybe<A.normal, vec3f, 0> normal{};
  [[no_unique_address]] detail::maybe<A.colour, rgb8, 1> colour{};
};

/// The point_prim a sink without screen_rect() gets for r: its 3-D position, as a square of the
/// rectangle's larger side (≤ 1 pixel: a one-pixel point).
template <attributes A>
[[nodiscard]] point_prim<A> as_point_prim(const screen_rect_prim<A>& r) {
  point_prim<A> p{r.position,
                  float(std::max(std::int64_t(r.x1) - r.x0, std::int64_t(r.y1) - r.y0)) /
                      float(screen_rect_prim<A>::one_px)};
  if constexpr (A.normal) p.normal = r.normal;
  if constexpr (A.colour) p.colour = r.colour;
  return p;
}

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

/// A texture-mapped triangle: `triangle` (positions, normals, per-vertex colours) with per-corner
/// texture coordinates into `texture` — POP's leaf triangles drawn by backward mapping (Chen &
/// Nguyen 2001, Figure 5). Sent only to sinks that take it (TexturedTriangleSink in sink.hpp);
/// the others get `triangle` alone, the flat-coloured triangle_prim they would get anyway.
///
/// Texture coordinates follow OBJ: u to the right, v up, one texture repeat per unit; texel
/// space is x = u·width, y = (1 − v)·height (rows top to bottom), texel (i, j) centred on
/// (i + ½, j + ½). The texture is not owned: it must outlive the frame (the emitter's hierarchy
/// holds it).
template <attributes A>
struct textured_triangle_prim {
  triangle_prim<A> triangle;
  std::array<vec2f, 3> uv{};
  const texture_image* texture = nullptr;
};

/// A 3-D Gaussian (3-D Gaussian Splatting, Kerbl et al. 2023): mean, covariance, opacity and
/// view-dependent colour, drawn by projecting the covariance to the screen (EWA, Zwicker et al.
/// 2001) and compositing front to back (raster/gaussians.hpp). Sent only to sinks that take it
/// (GaussianSink in sink.hpp); the others get as_splat_prim() of it.
///
/// `covariance` is Σ's upper triangle (xx, xy, xz, yy, yz, zz) in the origin-relative frame;
/// `sh` points at sh_coefficients(sh_degree) × 3 floats, coefficient-major with RGB interleaved
/// (gaussian_cloud's layout, core/gaussians.hpp; sh_colour() evaluates it). The coefficients are
/// not owned: they must outlive the frame (the emitter's hierarchy holds them).
struct gaussian_prim {
  vec3f position;
  std::array<float, 6> covariance{};
  float opacity = 1;
  int sh_degree = 0;
  const float* sh = nullptr;
};

/// The splat_prim a sink without gaussian() gets for g: the ellipse of Σ's two largest axes at
/// two standard deviations (86 % of a planar Gaussian's weight inside), its normal along the
/// smallest axis, its colour the view-independent one (the DC term, clamped to [0, 1]).
template <attributes A>
[[nodiscard]] splat_prim<A> as_splat_prim(const gaussian_prim& g) {
  const auto& c = g.covariance;
  Eigen::Matrix3f m;
  m << c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5];
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3f> eig(m);  // ascending eigenvalues
  const auto axis = [&](int i) {
    return vec3f(eig.eigenvectors().col(i) * 2.0f *
                 std::sqrt(std::max(eig.eigenvalues()[i], 0.0f)));
  };
  splat_prim<A> out{g.position, axis(2), axis(1)};
  if constexpr (A.normal) out.normal = eig.eigenvectors().col(0);
  if constexpr (A.colour) {
    const auto q = [&](int ch) {
      const float v = 0.5f + static_cast<float>(sh_c0) * (g.sh ? g.sh[ch] : 0.0f);
      return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f));
    };
    out.colour = rgb8{q(0), q(1), q(2)};
  }
  return out;
}

}  // namespace pbr_lod
