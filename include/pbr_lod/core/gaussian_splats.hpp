// pbr_lod — flat 3-D Gaussians from elliptical splats: how a mesh or a scan becomes a Gaussian
// scene (the Gaussian hierarchy's input when the tool is given a mesh or a point cloud, and the
// large generated scenes of its tests and benchmarks).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/estimation.hpp"
#include "pbr_lod/core/gaussians.hpp"
#include "pbr_lod/core/mesh_splats.hpp"
#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"

namespace pbr_lod {

/// One Gaussian per splat of `c` (which needs normals and ellipse axes: mesh_splats(), or the
/// estimation front-end's ellipses): centred on the sample, standard deviations |u|/2 and |v|/2
/// along the ellipse's axes — a splat's ellipse bounds its share of the surface with overlap, and
/// at 2σ an opaque Gaussian still has α = e⁻² ≈ 0.14, so neighbours blend across the seam
/// instead of leaving it — and `thickness` × the minor one along the normal (flat, as trained
/// splats on surfaces are), opacity `opacity`, SH degree 0 with the sample's colour (204 grey
/// without colours). Samples with a zero axis or normal are kept as isotropic Gaussians of the
/// other axis's size (or 0): the hierarchy handles zero sizes.
[[nodiscard]] inline gaussian_cloud gaussians_from_splats(const point_cloud& c,
                                                          float opacity = 1.0f,
                                                          float thickness = 0.1f) {
  if (c.axis_u.size() != c.size() || c.axis_v.size() != c.size() || c.normals.size() != c.size())
    throw InvalidArgument("gaussians_from_splats: the cloud needs normals and splat ellipses");
  if (!(opacity >= 0 && opacity <= 1) || !(thickness >= 0))
    throw InvalidArgument("gaussians_from_splats: opacity must lie in [0, 1], thickness ≥ 0");
  gaussian_cloud g;
  g.origin = c.origin;
  g.sh_degree = 0;
  const std::size_t n = c.size();
  g.positions = c.positions;
  g.scales.resize(n);
  g.rotations.resize(n);
  g.opacities.assign(n, opacity);
  g.sh.resize(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const float su = 0.5f * c.axis_u[i].norm(), sv = 0.5f * c.axis_v[i].norm();
    Eigen::Matrix3f r = Eigen::Matrix3f::Zero();
    r.col(0) = c.axis_u[i];
    r.col(2) = c.normals[i];
    const bool frame = su > 0 && sv > 0 && r.col(2).squaredNorm() > 0 && all_finite(r);
    if (frame) {
      r.col(0).normalize();
      r.col(2) = (r.col(2) - r.col(2).dot(r.col(0)) * r.col(0)).normalized();
      r.col(1) = r.col(2).cross(r.col(0));
    }
    if (frame && all_finite(r)) {
      Eigen::Quaternionf q(r);
      q.normalize();
      g.rotations[i] = vec4f(q.w(), q.x(), q.y(), q.z());
      g.scales[i] = vec3f(su, sv, thickness * std::min(su, sv));
    } else {
      g.rotations[i] = vec4f(1, 0, 0, 0);
      g.scales[i] = vec3f::Constant(std::isfinite(su) ? std::max(su, sv) : 0.0f);
    }
    const rgb8 rgb = c.colours.empty() ? rgb8{204, 204, 204} : c.colours[i];
    const std::uint8_t channel[3] = {rgb.r, rgb.g, rgb.b};
    for (int ch = 0; ch < 3; ++ch)
      g.sh[3 * i + ch] = static_cast<float>((channel[ch] / 255.0 - 0.5) / sh_c0);
  }
  return g;
}

/// The Gaussians of a mesh or a scan, as the Gaussian hierarchy's tool entry and tests make them:
/// a mesh's vertex splats (mesh_splats), or — without faces of non-zero area — its vertices'
/// splats, with normals and ellipses estimated (core/estimation.hpp) where any normal is zero or
/// not finite (`estimated` gets how many normals were) and ellipses where the cloud has none.
[[nodiscard]] inline gaussian_cloud gaussians_of_surface(const triangle_mesh& m,
                                                         float opacity = 1.0f, unsigned threads = 0,
                                                         std::size_t* estimated = nullptr) {
  if (estimated) *estimated = 0;
  if (!m.faces.empty()) {
    const point_cloud s = mesh_splats(m);
    if (!s.empty()) return gaussians_from_splats(s, opacity);
  }
  point_cloud c = m.vertices;
  const bool usable = c.normals.size() == c.size() &&
                      std::all_of(c.normals.begin(), c.normals.end(), [](const vec3f& n) {
                        return all_finite(n) && n.squaredNorm() > 0;
                      });
  if (!usable) {
    estimated_splats e = estimate_normals_and_ellipses(c.positions, 16, 16, true, threads);
    if (estimated) *estimated = c.size();
    c.normals = std::move(e.normals);
    c.axis_u = std::move(e.axes.u);
    c.axis_v = std::move(e.axes.v);
  } else if (c.axis_u.size() != c.size()) {
    splat_axes a = estimate_splat_ellipses(c.positions, c.normals, 16, threads);
    c.axis_u = std::move(a.u);
    c.axis_v = std::move(a.v);
  }
  return gaussians_from_splats(c, opacity);
}

/// Gaussians [first, first + count) of make_gaussian_scene(n, sh_degree, seed) into `out`
/// (replacing its contents): each is made from its index alone, so a scene of 10⁸ is generated
/// block by block (generated_gaussian_source) and equals the whole one.
inline void make_gaussian_scene_range(std::size_t n, int sh_degree, std::uint32_t seed,
                                      std::size_t first, std::size_t count, gaussian_cloud& out) {
  if (sh_degree < 0 || sh_degree > max_sh_degree)
    throw InvalidArgument("make_gaussian_scene: sh_degree must be 0–3");
  if (first > n || count > n - first)
    throw InvalidArgument("make_gaussian_scene_range: Gaussians beyond the scene's " +
                          std::to_string(n));
  gaussian_cloud& g = out;
  g.origin = vec3d::Zero();
  g.sh_degree = sh_degree;
  g.positions.resize(count);
  g.scales.resize(count);
  g.rotations.resize(count);
  g.opacities.resize(count);
  g.sh.resize(count * g.sh_stride());
  const double spacing = std::sqrt(4 * std::numbers::pi / std::max<double>(1, double(n)));
  const double golden = std::numbers::pi * (3 - std::sqrt(5.0));
  constexpr std::uint64_t step = 0x9e3779b97f4a7c15ull;
  // splitmix64's state advances by `step` per draw and each Gaussian draws sh_stride() + 1
  // numbers: Gaussian i starts from the state the sequential stream has there.
  const std::uint64_t draws = g.sh_stride() + 1;
  std::uint64_t state = seed * step + 1 + std::uint64_t(first) * draws * step;
  const auto uniform = [&state] {  // splitmix64 → [0, 1)
    std::uint64_t z = (state += step);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return double((z ^ (z >> 31)) >> 11) * 0x1.0p-53;
  };
  for (std::size_t j = 0; j < count; ++j) {
    const std::size_t i = first + j;
    const double y = 1 - 2 * (double(i) + 0.5) / double(n), r = std::sqrt(1 - y * y);
    const double phi = golden * double(i);
    const Eigen::Vector3d d(r * std::cos(phi), y, r * std::sin(phi));
    const double bump = 1 + 0.08 * std::sin(9 * d.x()) * std::sin(7 * d.y()) * std::sin(8 * d.z());
    g.positions[j] = (bump * d).cast<float>();
    // A frame with the sphere's normal as its third axis, turned about it at random.
    const Eigen::Vector3d t = d.unitOrthogonal();
    const double a = 2 * std::numbers::pi * uniform();
    const Eigen::Vector3d u = std::cos(a) * t + std::sin(a) * d.cross(t);
    Eigen::Matrix3d m;
    m.col(0) = u;
    m.col(1) = d.cross(u);
    m.col(2) = d;
    Eigen::Quaterniond q(m);
    q.normalize();
    g.rotations[j] = vec4f(float(q.w()), float(q.x()), float(q.y()), float(q.z()));
    const double s = 0.6 * spacing * (0.7 + 0.6 * uniform());
    g.scales[j] = vec3f(float(s), float(s * (0.5 + 0.5 * uniform())), float(0.1 * s));
    g.opacities[j] = float(0.3 + 0.7 * uniform());
    const double colour[3] = {0.5 + 0.4 * std::sin(5 * d.x()), 0.5 + 0.4 * std::sin(4 * d.y() + 1),
                              0.5 + 0.4 * std::cos(6 * d.z())};
    float* sh = g.sh.data() + j * g.sh_stride();
    for (int c = 0; c < 3; ++c) sh[c] = float((colour[c] - 0.5) / sh_c0);
    for (std::size_t k = 3; k < g.sh_stride(); ++k) sh[k] = float(0.1 * (2 * uniform() - 1));
  }
}

/// A generated Gaussian scene in the form trained scenes take: n flat Gaussians covering a bumpy
/// unit sphere (a Fibonacci lattice; standard deviations 0.6 × the lattice spacing in the
/// tangent plane, a tenth of that across, rotated at random about the normal), opacities in
/// [0.3, 1], a smooth colour field in the DC term and small random higher-degree coefficients up
/// to `sh_degree`. Deterministic for a seed (tests and benchmarks; 10⁷ take about a second).
[[nodiscard]] inline gaussian_cloud make_gaussian_scene(std::size_t n, int sh_degree = 3,
                                                        std::uint32_t seed = 1) {
  gaussian_cloud g;
  make_gaussian_scene_range(n, sh_degree, seed, 0, n, g);
  return g;
}

}  // namespace pbr_lod
