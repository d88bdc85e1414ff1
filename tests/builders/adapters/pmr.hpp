// pbr_lod tests — PMR (Dey & Hudson 2002) on the ladder and in the file-damage suite
// (adapter_support.hpp says what an adapter holds).
#pragma once

#include "adapter_support.hpp"
#include "pbr_lod/builders/pmr.hpp"

namespace pbr_lod::test {

struct pmr_ladder : ladder_adapter_base<pmr_hierarchy> {
  static constexpr const char* name = "pmr";
  static built build(const triangle_mesh& m, unsigned threads) {
    pmr_options o;
    o.threads = threads;
    return build_pmr(m.vertices, o);
  }
  template <class F>
  static void visit(const built& b, F&& f) {
    f(b, [](const view&) { return pmr_policy{}; });
  }
  /// No count: PMR estimates its own normals and ignores the input's.
  static std::optional<std::size_t> normals_filled(const built&) { return std::nullopt; }
};

struct pmr_tests {
  using ladder = std::tuple<pmr_ladder>;
  static std::vector<format_case> formats() {
    return {{"pmr",
             [](const std::string& p) {
               pmr_options o;
               o.max_leaf_points = 16;  // several leaves, so the node table is not trivial
               o.rho = {0.5f, 1.0f};    // two decimated levels: enough for the level table
               o.threads = 1;
               return saved_bytes(build_pmr(tiny_cloud(), o), p);
             },
             &load_and_save<pmr_hierarchy>}};
  }
};

}  // namespace pbr_lod::test
