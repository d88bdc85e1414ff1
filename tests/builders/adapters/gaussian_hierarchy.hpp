// pbr_lod tests — the Gaussian hierarchy (Kerbl et al. 2024) on the ladder and in the file-damage
// suite (adapter_support.hpp says what an adapter holds). The ladder's meshes and clouds become
// flat Gaussians as the tool makes them (gaussians_of_surface, core/gaussian_splats.hpp).
#pragma once

#include "adapter_support.hpp"
#include "pbr_lod/builders/gaussian_hierarchy.hpp"
#include "pbr_lod/core/gaussian_splats.hpp"

namespace pbr_lod::test {

inline gaussian_cloud ladder_gaussians(const triangle_mesh& m, unsigned threads) {
  return gaussians_of_surface(m, 1.0f, threads);
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
