// pbr_lod tests — the PCA octree (Kalaiah & Varshney 2003) on the ladder and in the file-damage
// suite (adapter_support.hpp says what an adapter holds).
#pragma once

#include "adapter_support.hpp"
#include "pbr_lod/builders/pca_octree.hpp"

namespace pbr_lod::test {

struct pca_octree_ladder : ladder_adapter_base<pca_octree<with_normals_colours>> {
  static constexpr const char* name = "pca_octree";
  static built build(const triangle_mesh& m, unsigned threads) {
    return with_point_set(
        m.vertices, [&](const auto& ps) { return build_pca_octree(ps, {.threads = threads}); });
  }
  template <class F>
  static void visit(const built& b, F&& f) {
    f(b, [](const view&) { return pca_octree_policy{}; });
  }
  static std::optional<std::size_t> normals_filled(const built& b) {
    return b.stats().normals_filled;
  }
};

struct pca_octree_tests {
  using ladder = std::tuple<pca_octree_ladder>;
  static std::vector<format_case> formats() {
    return {{"pca_octree",
             [](const std::string& p) {
               return saved_bytes(
                   build_pca_octree(point_set<with_normals_colours>::from(tiny_cloud())), p);
             },
             &load_and_save<pca_octree<with_normals_colours>>}};
  }
};

}  // namespace pbr_lod::test
