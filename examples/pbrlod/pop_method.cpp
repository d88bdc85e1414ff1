// pbrlod — POP, triangle-leaf bounding-sphere trees (Chen & Nguyen 2001): build, render, stats.
#include <cmath>
#include <limits>

#include "lod.hpp"
#include "pbr_lod/builders/pop.hpp"

namespace pbrlod_tool {
namespace {

template <class Tree>
json pop_stats_json(const Tree& t, const std::string& path) {
  const auto& st = t.stats();
  json j;
  j.str("file", path).str("method", "pop");
  j.str("spheres", t.sphere_rule() == pop_sphere_rule::exact ? "exact" : "paper");
  j.integer("nodes", static_cast<long long>(st.nodes));
  j.integer("leaves", static_cast<long long>(st.leaves));
  j.integer("triangles", static_cast<long long>(st.triangles));
  j.integer("vertices", static_cast<long long>(st.vertices));
  j.integer("max_depth", static_cast<long long>(st.max_depth));
  j.str("adjacency", t.adjacency() == pop_adjacency::openmesh ? "openmesh" : "edge_sort");
  j.boolean("quantised_nodes", t.quantised_nodes());
  j.integer("isolated_faces", static_cast<long long>(st.isolated_faces));
  j.integer("nonmanifold_edges", static_cast<long long>(st.nonmanifold_edges));
  j.integer("degenerate_faces", static_cast<long long>(st.degenerate_faces));
  j.boolean("colour", Tree::attrs.colour);
  j.integer("file_bytes", static_cast<long long>(t.file_bytes()));
  j.num("bytes_per_vertex", st.bytes_per_vertex);
  j.num("bytes_per_triangle", st.bytes_per_triangle);
  j.integer("vertex_file_bytes", static_cast<long long>(st.vertex_file_bytes));
  j.integer("face_file_bytes", static_cast<long long>(st.face_file_bytes));
  j.integer("node_file_bytes", static_cast<long long>(st.node_file_bytes));
  // The file holds no timings: `build --json` reports them, `stats` of a file reports null.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  j.str("timings", st.has_timings ? "measured by this build" : "absent (not stored in the file)");
  j.num("build_seconds", st.has_timings ? st.build_seconds : nan);
  j.num("prepare_seconds", st.has_timings ? st.prepare_seconds : nan);
  j.num("adjacency_seconds", st.has_timings ? st.adjacency_seconds : nan);
  j.num("tree_seconds", st.has_timings ? st.tree_seconds : nan);
  // Zero or non-finite vertex normals given their faces' normal (build only; a file: 0).
  j.integer("normals_filled", static_cast<long long>(st.normals_filled));
  return j;
}

/// What POP contributes to a frame: the paper's splat size from eye-space z (§3.3), back-face
/// culling by normal cones when the effects ask for it (§3.2 culls always; a mesh that is not
/// closed — a wall, an open scan — then loses the side seen from behind, which the mesh's own
/// render draws: the hard-cases scene's wall from azimuth 210°, IoU 0.86), and with hole
/// filling §3.4's visibility splatting (a full-size occluder then a one-pixel point per point
/// node + screen-space reconstruction).
struct pop_method_traits {
  template <class Tree>
  std::pair<vec3d, double> input_bounds(const Tree& t) const {
    return bounds_of(t.origin(), t.positions());  // the mesh's vertices
  }
  template <class Tree>
  frame draw(const Tree& t, const frame_request& r) const {
    const view v(r.cam, t.origin());
    render_options o = lod_render_options(r.view, Tree::attrs.colour);
    const traverse_options topt{.tolerance_px = r.tolerance,
                                .metric = projection_metric::eye_z,
                                .backface_cull = o.fx.backface_cull};
    pop_policy policy;
    if (o.fx.hole_filling) {
      policy.points = pop_point_mode::visibility_two_pass;
      o.hole_filling_radius = std::max(1, static_cast<int>(std::ceil(r.tolerance)));
    }
    return draw_frame(t, v, o, topt, policy, r, t.origin());
  }
  template <class Tree>
  json stats(const Tree& t, const std::string& path) const {
    return pop_stats_json(t, path);
  }
  template <class Tree>
  std::size_t samples(const Tree& t) const {
    return t.positions().size();
  }
};

std::unique_ptr<lod> build(const std::vector<std::string>& items, const build_input& in,
                           bool /*on_terminal*/) {
  params m(items);
  pop_options o;
  o.max_leaf_triangles = static_cast<std::uint32_t>(m.integer("leaf_triangles", 4, 1, 4));
  o.spheres = m.choice("spheres", "paper", {"paper", "exact"}) == "exact" ? pop_sphere_rule::exact
                                                                          : pop_sphere_rule::paper;
  o.normal_bits = static_cast<int>(m.integer("normal_bits", 16, 6, 24));
  o.threads = static_cast<unsigned>(m.integer("threads", 0, 0, 256));
  o.adjacency = m.choice("adjacency", "edge_sort", {"edge_sort", "openmesh"}) == "openmesh"
                    ? pop_adjacency::openmesh
                    : pop_adjacency::edge_sort;
  o.quantise_nodes = m.choice("nodes", "quantised", {"quantised", "float"}) == "quantised";
  m.finish("pop", "leaf_triangles, spheres, normal_bits, threads, adjacency, nodes");
  const triangle_mesh& mesh = in.get().mesh;
  if (mesh.faces.empty())
    throw InvalidArgument(in.name() +
                          ": POP builds from a triangle mesh (its leaves are triangles)");
  if (pop_mesh_has_colour(mesh))
    return make_lod(pop_method_traits{}, build_pop<with_normals_colours>(mesh, o));
  return make_lod(pop_method_traits{}, build_pop<with_normals>(mesh, o));
}

std::unique_ptr<lod> load(const std::string& path) {
  if (peek_lod(path).flags & 1u)
    return make_lod(pop_method_traits{}, pop_tree<with_normals_colours>::load(path));
  return make_lod(pop_method_traits{}, pop_tree<with_normals>::load(path));
}

}  // namespace

method_entry pop_method() {
  return {.name = "pop",
          .paper = "Chen & Nguyen 2001",
          .magic = "PBRLODPP",
          .dir_magic = {},
          .builds_from_mesh = true,
          .build = &build,
          .load = &load,
          .demo_tolerances = {8, 3, 1},
          .tolerance_means =
              "pixels: a node is drawn once its sphere's eye-z size is at most this "
              "(§3.3); also the hole-filling radius (§3.4)"};
}

}  // namespace pbrlod_tool
