// pbr_lod tests — the Gaussian hierarchy (Kerbl et al. 2024) on the ladder and in the file-damage
// suite (adapter_support.hpp says what an adapter holds). The ladder's meshes and clouds become
// flat Gaussians as the tool makes them (core/gaussian_splats.hpp): a mesh's vertex splats, a
// cloud's splats with normals and ellipses estimated where a normal is missing.
#pragma once

#include <algorithm>

#include "adapter_support.hpp"
#include "pbr_lod/builders/gaussian_hierarchy.hpp"
#include "pbr_lod/core/estimation.hpp"
#include "pbr_lod/core/gaussian_splats.hpp"
#include "pbr_lod/core/mesh_splats.hpp"

namespace pbr_lod::test {

/// Flat Gaussians on the mesh's vertex splats, or on the cloud's splats (estimated where any
/// normal is zero or not finite, and without ellipses).
inline gaussian_cloud ladder_gaussians(const triangle_mesh& m, unsigned threads) {
  if (!m.faces.empty()) {
    const point_cloud s = mesh_splats(m);
    if (!s.empty()) return gaussians_from_splats(s);
  }
  point_cloud c = m.vertices;
  const bool usable = c.normals.size() == c.size() &&
                      std::all_of(c.normals.begin(), c.normals.end(), [](const vec3f& n) {
                        return all_finite(n) && n.squaredNorm() > 0;
                      });
  if (!usable) {
    estimated_splats e = estimate_normals_and_ellipses(c.positions, 16, 16, true, threads);
    c.normals = std::move(e.normals);
    c.axis_u = std::move(e.axes.u);
    c.axis_v = std::move(e.axes.v);
  } else {
    splat_axes a = estimate_splat_ellipses(c.positions, c.normals, 16, threads);
    c.axis_u = std::move(a.u);
    c.axis_v = std::move(a.v);
  }
  return gaussians_from_splats(c);
}

struct gaussian_hierarchy_ladder : ladder_adapter_base<gaussian_hierarchy> {
  static constexpr const char* name = "gaussian_hierarchy";
  static built build(const triangle_mesh& m, unsigned threads) {
    return build_gaussian_hierarchy(ladder_gaussians(m, threads), {.threads = threads});
  }
  template <class F>
  static void visit(const built& b, F&& f) {
    f(b, [](const view&) { return gaussian_policy{}; });
  }
  static std::optional<std::size_t> normals_filled(const built&) { return std::nullopt; }
};

struct gaussian_hierarchy_tests {
  using ladder = std::tuple<gaussian_hierarchy_ladder>;
  static std::vector<format_case> formats() {
    return {{"gaussian_hierarchy",
             [](const std::string& p) {
               return saved_bytes(
                   build_gaussian_hierarchy(ladder_gaussians(tiny_mesh(), 1), {.leaf_size = 2}), p);
             },
             &load_and_save<gaussian_hierarchy>}};
  }
};

}  // namespace pbr_lod::test
