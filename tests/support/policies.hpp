// Test/benchmark support: shared helpers for traversal policies and point-octree comparisons.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod::test {

/// Forwards to Base and records every node the traversal emits, so tests can check the cut.
template <class Base>
struct recording_policy : Base {
  std::vector<std::uint32_t>* out = nullptr;
  template <class H, class S>
  void emit(const H& h, const typename H::node_id& n, const view& v, float size,
            const traverse_options& o, S& sink) const {
    out->push_back(n);
    Base::emit(h, n, v, size, o, sink);
  }
};

/// Gives every sample a circular splat of radius 1.5·√(area per sample / π) in its tangent plane
/// (about 1.5× the mean spacing, so splats overlap), and grey colours if it has none: input with
/// ellipses, so builders can be measured without k-NN estimation.
inline void add_circular_splats(point_cloud& c, double total_area) {
  const auto r = static_cast<float>(
      1.5 * std::sqrt(total_area / (std::numbers::pi * static_cast<double>(c.size()))));
  c.axis_u.resize(c.size());
  c.axis_v.resize(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) {
    const vec3f t = any_orthogonal(c.normals[i]);
    c.axis_u[i] = t * r;
    c.axis_v[i] = c.normals[i].cross(t) * r;
  }
  if (c.colours.empty()) c.colours.assign(c.size(), rgb8{200, 200, 200});
}

/// Per node, the relative difference of two same-shaped trees' ellipses, ‖E_a − E_b‖ / |u_a|²
/// with E = u·uᵀ + v·vᵀ (Frobenius norm).
template <class T>
std::vector<double> ellipse_drifts(const T& a, const T& b) {
  // Compared as shapes, E = u·uᵀ + v·vᵀ (the ellipse's second-moment tensor in the tangent
  // plane): independent of the axes' signs, and of their directions where the ellipse is nearly
  // a circle and any rotation of the axes describes the same disk.
  const auto shape = [](const auto& n) {
    const vec3d u = n.axis_u.template cast<double>(), v = n.axis_v.template cast<double>();
    return mat3d(u * u.transpose() + v * v.transpose());
  };
  std::vector<double> rel;
  rel.reserve(a.nodes().size());
  for (std::size_t i = 0; i < a.nodes().size(); ++i) {
    const auto &x = a.nodes()[i], &y = b.nodes()[i];
    const double s = std::max<double>(x.axis_u.squaredNorm(), 1e-30);
    rel.push_back((shape(x) - shape(y)).norm() / s);
  }
  return rel;
}

}  // namespace pbr_lod::test
