// pbr_lod tests — the ρ-grid (Duguet & Drettakis 2004) on the ladder, from a mesh and from
// points, and its three file layouts in the file-damage suite (adapter_support.hpp).
#pragma once

#include "adapter_support.hpp"
#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/builders/rho_grid_policy.hpp"

namespace pbr_lod::test {

struct rho_grid_ladder : ladder_adapter_base<rho_grid<3>> {
  static constexpr const char* name = "rho_grid";
  static built build(const triangle_mesh& m, unsigned threads) {
    return build_rho_grid<3>(m, {.level = 4, .threads = threads});
  }
  template <class F>
  static void visit(const built& g, F&& f) {
    const auto policy = [&g](const view& v) { return rho_grid_policy<3>(g, v); };
    if (g.has_normals())
      f(rho_grid_hierarchy<3, with_normals>(g), policy);
    else
      f(rho_grid_hierarchy<3, positions_only>(g), policy);
  }
  /// No count: a mesh's missing vertex normal takes its faces' normal where it is used.
  static std::optional<std::size_t> normals_filled(const built&) { return std::nullopt; }
};

/// The ρ-grid's other entry point: the mesh's vertices as a point cloud (cells hold the input
/// point nearest their centre; normals only when the vertices have them).
struct rho_grid_points_ladder : rho_grid_ladder {
  static constexpr const char* name = "rho_grid_points";
  static built build(const triangle_mesh& m, unsigned threads) {
    return build_rho_grid<3>(m.vertices, {.level = 4, .threads = threads});
  }
  static std::optional<std::size_t> normals_filled(const built& b) {
    return b.stats().normals_filled;
  }
};

template <int Rho>
format_case rho_grid_format(rho_grid_layout layout, const std::string& name) {
  return {name,
          [layout](const std::string& p) {
            return saved_bytes(build_rho_grid<Rho>(tiny_mesh(), {.level = 1}), p, layout);
          },
          &load_and_save<rho_grid<Rho>>};
}

struct rho_grid_tests {
  using ladder = std::tuple<rho_grid_ladder, rho_grid_points_ladder>;
  static std::vector<format_case> formats() {
    return {rho_grid_format<3>(rho_grid_layout::nis, "rho_grid_nis"),
            rho_grid_format<3>(rho_grid_layout::is, "rho_grid_is"),
            rho_grid_format<2>(rho_grid_layout::compressed, "rho_grid_compressed")};
  }
};

}  // namespace pbr_lod::test
