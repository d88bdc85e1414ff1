// pbr_lod — the PCA octree's randomised rendering: how many points a node needs and the points.
//
// This work is based on:
//   A. Kalaiah, A. Varshney. Statistical Point Geometry. SGP 2003.
// What this file implements:
//   §4  pca_required_points(): the points a node needs for the area its span covers on screen
//       (a·ln a + c·a for the paper's random points). pca_generate(): the paper's generators —
//       the trivariate Box–Muller generator for positions
//           τ = √(−2 ln r₀), (x, y, z) = σ ∘ (τ√(1−r₂²) cos 2πr₁, τ√(1−r₂²) sin 2πr₁, τ r₂)
//       and colours, the 2-D one for normals (α = σ_n¹τ cos 2πr₁, β = σ_n²τ sin 2πr₁,
//       θ = √(α² + β²), φ = atan(β/α)), with r₀ drawn from [e^{−γ²/2}, 1] so that τ ≤ γ (the
//       extent γ·σ of §3). Each point's uniforms come from a counter-based stream keyed by
//       (seed, node, point index).
// Deviations (docs/pca-octree.md): every generated position, normal and colour stays inside
// what the node's own points span (pca_node::extent, normal_extent, pca_colour::extent): a
// draw outside is drawn again, and after four misses moved onto the boundary. The default
// generator (pca_generator::span) places the tangential coordinates on a low-discrepancy
// sequence, uniform over the span, so a node covers its pixels with ≈ density points a pixel
// instead of a·ln a; the paper's generator is pca_generator::paper. By default a point carries
// its node's mean normal and colour (pca_attribute_draw::mean, the least-squares estimate
// without its position to condition on); pca_attribute_draw::sampled draws them as §4 does.

#include <array>
#include <cmath>
#include <limits>
#include <numbers>

#include "pca_octree_internal.hpp"

namespace pbr_lod::detail {

namespace {

std::uint64_t mix(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

/// A small counter-based stream: 24-bit uniforms in [0, 1) from successive mixes.
struct stream {
  std::uint64_t state;
  float next() {
    state += 0x9E3779B97F4A7C15ull;
    return static_cast<float>(mix(state) >> 40) * 0x1p-24f;
  }
};

/// The paper's trivariate generator in the unit frame, radius truncated at γ (tmin = e^{−γ²/2}).
vec3f box_muller3(stream& s, float tmin) {
  const float r0 = 1.0f - (1.0f - tmin) * s.next();  // (tmin, 1]
  const float tau = std::sqrt(-2.0f * std::log(r0));
  const float r1 = s.next();
  const float r2 = 2.0f * s.next() - 1.0f;
  const float q = tau * std::sqrt(std::max(0.0f, 1.0f - r2 * r2));
  const float phi = 2.0f * std::numbers::pi_v<float> * r1;
  return {q * std::cos(phi), q * std::sin(phi), tau * r2};
}

/// A standard normal deviate (Box–Muller, one of the pair), radius truncated at γ.
float box_muller1(stream& s, float tmin) {
  const float r0 = 1.0f - (1.0f - tmin) * s.next();
  return std::sqrt(-2.0f * std::log(r0)) * std::cos(2.0f * std::numbers::pi_v<float> * s.next());
}

/// Tries before a draw outside the span is moved onto its boundary: a node's extent is at least
/// its σ along every axis (the largest |offset| is at least the root mean square), so a draw
/// lands inside with probability ≥ 0.68 per axis and four misses are rare.
constexpr int tries = 4;

/// Roberts' R2 sequence (the plastic constant g: steps 1/g, 1/g² modulo 1) in 32-bit fixed
/// point: x_k = frac(o + k·a) exactly for every k, so a node's first k points are evenly spread
/// for every k.
constexpr std::uint32_t r2_a1 = 3242174889u;   // 2³² / g
constexpr std::uint32_t r2_a2 = 2447445414u;   // 2³² / g²
constexpr std::uint32_t golden = 2654435769u;  // 2³² / φ

/// Tiles of a node's tangential box: the longer side is cut into round(ratio) squares among
/// which the points are spread, so they are even in both directions. Extents below a millionth
/// of the node's cell are rounding, not extent (a leaf of one point, a line of them): taken as
/// that floor, so that their ratio, which the last bits of the coordinates decide, does not
/// decide the tiles (the same cloud 10⁷ units away drew 1 tile or 64 at the same leaf).
int tiles_of(const pca_node& nd) {
  const float floor = std::max(1e-6f * static_cast<float>(nd.cell_size), 1e-30f);
  const float e1 = std::max(nd.extent.x(), floor), e2 = std::max(nd.extent.y(), floor);
  return static_cast<int>(std::clamp(std::lround(std::max(e1, e2) / std::min(e1, e2)), 1l, 64l));
}

/// Node n's span box projected in view v: the screen vectors (pixels) of its three full axes
/// 2·extent^k·f^k under the weak perspective of its centre; false when it reaches the eye plane.
bool projected_axes(const pca_node& nd, const view& v, std::array<vec2f, 3>& ax) {
  const vec3f e = v.to_eye(nd.mean);
  if (!(e.z() > nd.extent.norm())) return false;
  const float s = v.focal_px / e.z();
  for (int k = 0; k < 3; ++k) {
    const vec3f a = nd.frame.col(k) * (2 * nd.extent[k] * s);
    ax[static_cast<std::size_t>(k)] = vec2f(a.dot(v.right), a.dot(v.up));
  }
  return true;
}

/// A colour in [0, 1]³ (clamped) as 8-bit RGB.
rgb8 to_rgb8(const vec3f& c) {
  const vec3f rgb = c.cwiseMax(0.0f).cwiseMin(1.0f);
  return {static_cast<std::uint8_t>(std::lround(rgb.x() * 255)),
          static_cast<std::uint8_t>(std::lround(rgb.y() * 255)),
          static_cast<std::uint8_t>(std::lround(rgb.z() * 255))};
}

float cross2(const vec2f& a, const vec2f& b) {
  return std::abs(a.x() * b.y() - a.y() * b.x());
}

}  // namespace

float pca_required_points(const pca_data& d, std::uint32_t n, const view& v,
                          const pca_render_options& o) {
  const pca_node& nd = d.nodes[n];
  const float p = o.point_px;
  std::array<vec2f, 3> ax;
  if (!projected_axes(nd, v, ax)) {  // reaching the eye plane: at most the whole screen
    const float a = static_cast<float>(v.width) * static_cast<float>(v.height) / (p * p);
    return o.generator == pca_generator::span ? o.density * a : a * std::log(a) + o.c * a;
  }
  if (o.generator == pca_generator::paper) {
    // The projected box (a parallelepiped's projection: |v₁×v₂| + |v₁×v₃| + |v₂×v₃|) dilated by
    // half a point (its perimeter is 2(|v₁| + |v₂| + |v₃|)), in point areas.
    const float area = cross2(ax[0], ax[1]) + cross2(ax[0], ax[2]) + cross2(ax[1], ax[2]);
    const float rim = ax[0].norm() + ax[1].norm() + ax[2].norm();
    const float a = (area + rim * p + 0.25f * std::numbers::pi_v<float> * p * p) / (p * p);
    return a > 1 ? std::max(1.0f, a * std::log(a) + o.c * a) : 1.0f;
  }
  // The span generator: each of the node's tiles (object-space squares along its tangential
  // box) takes the same number q of points, evenly spread over it; on screen a tile spans the
  // projected lengths (ℓ₁/m, ℓ₂) and needs q ≥ (its longer side in points + 1)² for a point
  // every point size along both sides, whatever the view's slant.
  const int m = tiles_of(nd);
  const bool long1 = m == 1 || nd.extent.x() >= nd.extent.y();
  const float l1 = ax[0].norm() / p, l2 = ax[1].norm() / p;
  const float side = std::max(long1 ? l1 / float(m) : l1, long1 ? l2 : l2 / float(m)) + 1;
  return o.density * float(m) * side * side;
}

void pca_generate(const pca_data& d, std::uint32_t n, std::uint64_t seed, std::uint32_t first,
                  std::uint32_t count, pca_sample* out, pca_generator g, pca_attribute_draw draw) {
  pca_generate(d, n, n, seed, first, count, out, g, draw);
}

void pca_generate(const pca_data& d, std::uint32_t n, std::uint64_t stream_id, std::uint64_t seed,
                  std::uint32_t first, std::uint32_t count, pca_sample* out, pca_generator g,
                  pca_attribute_draw draw) {
  const pca_node& nd = d.nodes[n];
  const bool colour = !d.colours.empty();
  const float tmin = std::exp(-0.5f * d.gamma * d.gamma);
  const vec3f sp = nd.lambda * nd.sigma;
  const vec3f& e = nd.extent;
  const float pi = std::numbers::pi_v<float>;
  const std::uint64_t key = mix(mix(seed) ^ (stream_id * 0xD1B54A32D192ED03ull));
  const auto inside = [&](const vec3f& u) {
    return std::abs(u.x()) <= e.x() && std::abs(u.y()) <= e.y() && std::abs(u.z()) <= e.z();
  };
  // The span generator's sequence: a per-node offset, the tiles along the longer side.
  const std::uint64_t off = mix(key ^ 0x5851F42D4C957F2Dull);
  const auto o1 = static_cast<std::uint32_t>(off), o2 = static_cast<std::uint32_t>(off >> 32);
  const auto o3 = static_cast<std::uint32_t>(mix(off));
  const int m = tiles_of(nd);
  // One tile: no longer side (which of two equal sides is longer is a last-bit matter).
  const bool long1 = m == 1 || e.x() >= e.y();
  // pca_attribute_draw::mean: the node's expected normal and colour for every point.
  const vec3f mean_normal = nd.normal_frame.col(2).normalized();
  const rgb8 mean_colour = colour ? to_rgb8(d.colours[n].mean) : rgb8{};
  for (std::uint32_t k = 0; k < count; ++k) {
    const std::uint32_t idx = first + k;
    stream s{mix(key ^ (static_cast<std::uint64_t>(idx) * 0x9E3779B97F4A7C15ull))};
    pca_sample& o = out[k];
    // Position (in the node's frame, u inside the span box).
    vec3f u;
    if (g == pca_generator::span) {
      // The tile from the golden-ratio sequence (any first k points spread over the tiles
      // evenly, also when k < m), the place in it from R2.
      const auto tile = static_cast<std::uint32_t>(
          (static_cast<std::uint64_t>(o3 + idx * golden) * static_cast<std::uint64_t>(m)) >> 32);
      const float x = static_cast<float>(o1 + idx * r2_a1) * 0x1p-32f;
      const float y = static_cast<float>(o2 + idx * r2_a2) * 0x1p-32f;
      const float along = (static_cast<float>(tile) + x) / static_cast<float>(m);
      const float a = long1 ? along : y, b = long1 ? y : along;
      float z = sp.z() * box_muller1(s, tmin);
      for (int t = 1; t < tries && std::abs(z) > e.z(); ++t) z = sp.z() * box_muller1(s, tmin);
      u = vec3f(e.x() * (2 * a - 1), e.y() * (2 * b - 1), std::clamp(z, -e.z(), e.z()));
    } else {
      u = sp.cwiseProduct(box_muller3(s, tmin));
      for (int t = 1; t < tries && !inside(u); ++t) u = sp.cwiseProduct(box_muller3(s, tmin));
      u = u.cwiseMax(-e).cwiseMin(e);
    }
    o.position = nd.mean + nd.frame * u;
    if (draw == pca_attribute_draw::mean) {
      o.normal = mean_normal;
      o.colour = mean_colour;
      continue;
    }
    // Normal: a Gaussian point of the normal ellipse, inside the normals' cone, wrapped back
    // onto the sphere.
    const auto draw_normal = [&](float& alpha, float& beta) {
      const float r0 = 1.0f - (1.0f - tmin) * s.next();
      const float tau = std::sqrt(-2.0f * std::log(r0));
      const float phi = 2.0f * pi * s.next();
      alpha = nd.normal_sigma.x() * tau * std::cos(phi);
      beta = nd.normal_sigma.y() * tau * std::sin(phi);
      return std::sqrt(alpha * alpha + beta * beta);
    };
    float alpha = 0, beta = 0, theta = draw_normal(alpha, beta);
    for (int t = 1; t < tries && theta > nd.normal_extent; ++t) theta = draw_normal(alpha, beta);
    if (theta > nd.normal_extent) {
      const float f = nd.normal_extent / theta;
      alpha *= f;
      beta *= f;
      theta = nd.normal_extent;
    }
    theta = std::min(pi, theta);
    vec3f local = vec3f::UnitZ();
    if (theta > 0) {
      const float f = std::sin(theta) / theta;
      local = vec3f(alpha * f, beta * f, std::cos(theta));
    }
    o.normal = (nd.normal_frame * local).normalized();
    if (colour) {
      const pca_colour& c = d.colours[n];
      const auto draw_colour = [&]() -> vec3f {
        const vec3f g3 = box_muller3(s, tmin);
        return c.frame * vec3f(c.sigma.cwiseProduct(g3));
      };
      vec3f dc = draw_colour();
      for (int t = 1; t < tries && dc.norm() > c.extent; ++t) dc = draw_colour();
      if (dc.norm() > c.extent) dc *= c.extent / dc.norm();
      o.colour = to_rgb8(c.mean + dc);
    } else {
      o.colour = {};
    }
  }
}

}  // namespace pbr_lod::detail
