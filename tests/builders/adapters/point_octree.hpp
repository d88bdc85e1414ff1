// pbr_lod tests — the point-octree (Pajarola 2003) on the ladder and in the file-damage suite
// (adapter_support.hpp says what an adapter holds).
#pragma once

#include "adapter_support.hpp"
#include "pbr_lod/builders/point_octree.hpp"

namespace pbr_lod::test {

struct point_octree_ladder
    : ladder_adapter_base<point_octree<point_octree_attributes(attributes{.colour = true})>> {
  static constexpr const char* name = "point_octree";
  static built build(const triangle_mesh& m, unsigned threads) {
    return with_point_set(m.vertices, [&](const auto& ps) {
      return build_point_octree(ps, {.leaf_size = 8, .threads = threads});
    });
  }
  template <class F>
  static void visit(const built& b, F&& f) {
    f(b, [](const view&) { return point_octree_policy{}; });
  }
  static std::optional<std::size_t> normals_filled(const built& b) {
    return b.stats().normals_filled;
  }
};

struct point_octree_tests {
  using ladder = std::tuple<point_octree_ladder>;
  static std::vector<format_case> formats() {
    using octree = point_octree<point_octree_attributes(with_normals_colours)>;
    return {{"point_octree",
             [](const std::string& p) {
               return saved_bytes(
                   build_point_octree(point_set<with_normals_colours>::from(tiny_cloud())), p);
             },
             &load_and_save<octree>}};
  }
};

}  // namespace pbr_lod::test
