// pbr_lod — the PCA octree's randomised rendering: how many points a node needs and the points.
//
// This work is based on:
//   A. Kalaiah, A. Varshney. Statistical Point Geometry. SGP 2003.
// What this file implements:
//   §4  pca_required_points(): a·ln a + c·a points for a node whose ellipsoid (semi-axes
//       γ·λ·σ_p along f_p) covers a pixels; a from the eigen-analysis of the projected
//       ellipsoid (its screen ellipse's semi-axes are the singular values of the projected
//       axes). pca_generate(): the trivariate Box–Muller generator for positions
//           τ = √(−2 ln r₀), (x, y, z) = σ ∘ (τ√(1−r₂²) cos 2πr₁, τ√(1−r₂²) sin 2πr₁, τ r₂)
//       and colours, the 2-D one for normals (α = σ_n¹τ cos 2πr₁, β = σ_n²τ sin 2πr₁,
//       θ = √(α² + β²), φ = atan(β/α)), with r₀ drawn from [e^{−γ²/2}, 1] so that τ ≤ γ (the
//       extent γ·σ of §3). Each point's uniforms come from a counter-based stream keyed by
//       (seed, node, point index).
// Deviations (docs/pca-octree.md): the minor semi-axis of the projected ellipse is at least half
// a point, so a patch seen edge-on still gets a line of points; the paper's generator is used as
// written, although its τ is the radius of a 2-D Gaussian: along each axis the points' variance
// is E[τ²]/3·σ² ≈ 0.66 σ² (truncated at γ = 3.5), not σ².

#include <Eigen/Eigenvalues>
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

}  // namespace

float pca_required_points(const pca_data& d, std::uint32_t n, const view& v, float point_px,
                          float c) {
  const pca_node& nd = d.nodes[n];
  const vec3f e = v.to_eye(nd.mean);
  const vec3f axes = d.gamma * nd.lambda * nd.sigma;
  const float c_ln = c;
  const auto count = [c_ln](float a) {
    return a > 1 ? std::max(1.0f, a * std::log(a) + c_ln * a) : 1.0f;
  };
  // A node reaching the eye plane has no bounded projection: it can cover at most the screen.
  if (!(e.z() > axes.x()))
    return count(static_cast<float>(v.width) * static_cast<float>(v.height) /
                 (point_px * point_px));
  // Weak perspective about the centre: the screen ellipse of the ellipsoid {μ + F·diag(a)·u,
  // |u| ≤ 1} has the singular values of J·F·diag(a) as its semi-axes, J the 2×3 projection.
  const float s = v.focal_px / e.z();
  Eigen::Matrix<float, 2, 3> j;
  j.row(0) = v.right.transpose() * s;
  j.row(1) = v.up.transpose() * s;
  const Eigen::Matrix<float, 2, 3> b = j * nd.frame * axes.asDiagonal();
  const Eigen::Matrix2f m = b * b.transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2f> es;
  es.computeDirect(m);
  const float major = std::sqrt(std::max(0.0f, es.eigenvalues()[1]));
  const float minor = std::sqrt(std::max(0.0f, es.eigenvalues()[0]));
  const float half = 0.5f * point_px;
  const float a = std::numbers::pi_v<float> * std::max(major, half) * std::max(minor, half) /
                  (point_px * point_px);
  return count(a);
}

void pca_generate(const pca_data& d, std::uint32_t n, std::uint64_t seed, std::uint32_t first,
                  std::uint32_t count, pca_sample* out) {
  pca_generate(d, n, n, seed, first, count, out);
}

void pca_generate(const pca_data& d, std::uint32_t n, std::uint64_t stream_id, std::uint64_t seed,
                  std::uint32_t first, std::uint32_t count, pca_sample* out) {
  const pca_node& nd = d.nodes[n];
  const bool colour = !d.colours.empty();
  const float tmin = std::exp(-0.5f * d.gamma * d.gamma);
  const vec3f sp = nd.lambda * nd.sigma;
  const float pi = std::numbers::pi_v<float>;
  const std::uint64_t key = mix(mix(seed) ^ (stream_id * 0xD1B54A32D192ED03ull));
  for (std::uint32_t k = 0; k < count; ++k) {
    stream s{mix(key ^ (static_cast<std::uint64_t>(first + k) * 0x9E3779B97F4A7C15ull))};
    pca_sample& o = out[k];
    // Position.
    o.position = nd.mean + nd.frame * sp.cwiseProduct(box_muller3(s, tmin));
    // Normal: a Gaussian point of the normal ellipse, wrapped back onto the sphere.
    const float r0 = 1.0f - (1.0f - tmin) * s.next();
    const float tau = std::sqrt(-2.0f * std::log(r0));
    const float phi = 2.0f * pi * s.next();
    const float alpha = nd.normal_sigma.x() * tau * std::cos(phi);
    const float beta = nd.normal_sigma.y() * tau * std::sin(phi);
    const float theta = std::min(pi, std::sqrt(alpha * alpha + beta * beta));
    vec3f local = vec3f::UnitZ();
    if (theta > 0) {
      const float f = std::sin(theta) / theta;
      local = vec3f(alpha * f, beta * f, std::cos(theta));
    }
    o.normal = (nd.normal_frame * local).normalized();
    if (colour) {
      const pca_colour& c = d.colours[n];
      const vec3f rgb = (c.mean + c.frame * c.sigma.cwiseProduct(box_muller3(s, tmin)))
                            .cwiseMax(0.0f)
                            .cwiseMin(1.0f);
      o.colour = {static_cast<std::uint8_t>(std::lround(rgb.x() * 255)),
                  static_cast<std::uint8_t>(std::lround(rgb.y() * 255)),
                  static_cast<std::uint8_t>(std::lround(rgb.z() * 255))};
    } else {
      o.colour = {};
    }
  }
}

}  // namespace pbr_lod::detail
