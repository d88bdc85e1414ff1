// pbr_lod tests — POP (Chen & Nguyen 2001) on the ladder and in the file-damage suite
// (adapter_support.hpp says what an adapter holds).
#pragma once

#include "adapter_support.hpp"
#include "pbr_lod/builders/pop.hpp"

namespace pbr_lod::test {

struct pop_ladder : ladder_adapter_base<pop_tree<with_normals_colours>> {
  static constexpr const char* name = "pop";
  /// Leaves draw their triangles: a mesh of zero-area triangles only draws nothing.
  static constexpr bool draws_faces_only = true;
  static built build(const triangle_mesh& m, unsigned threads) {
    return build_pop<with_normals_colours>(m, {.threads = threads});
  }
  template <class F>
  static void visit(const built& b, F&& f) {
    f(b, [](const view&) { return pop_policy{}; });
  }
  static std::optional<std::size_t> normals_filled(const built& b) {
    return b.stats().normals_filled;
  }
};

struct pop_tests {
  using ladder = std::tuple<pop_ladder>;
  static std::vector<format_case> formats() {
    return {{"pop",
             [](const std::string& p) {
               return saved_bytes(build_pop<with_normals_colours>(tiny_mesh()), p);
             },
             &load_and_save<pop_tree<with_normals_colours>>}};
  }
};

}  // namespace pbr_lod::test
