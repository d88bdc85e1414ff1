// pbrlod — POP, triangle-leaf bounding-sphere trees (Chen & Nguyen 2001): build, render, stats.
#include <cmath>
#include <iostream>
#include <limits>

#include "pbr_lod/builders/pop.hpp"
#include "pbr_lod/raster/png.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "tool.hpp"

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
  return j;
}

template <class F>
auto with_pop(const std::string& path, F&& f) {
  if (peek_lod(path).flags & 1u) return f(pop_tree<with_normals_colours>::load(path));
  return f(pop_tree<with_normals>::load(path));
}

int build(const build_request& r) {
  params m(r.params);
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
  const loaded_input in = load(r.input);
  if (!in.is_mesh())
    throw InvalidArgument(r.input + ": POP builds from a triangle mesh (its leaves are triangles)");
  const auto go = [&](const auto& t) {
    t.save(r.output);
    std::cout << (r.as_json ? "" : "wrote " + r.output + ": ") << pop_stats_json(t, r.output).text()
              << "\n";
    return 0;
  };
  if (pop_mesh_has_colour(in.mesh)) return go(build_pop<with_normals_colours>(in.mesh, o));
  return go(build_pop<with_normals>(in.mesh, o));
}

int render_lod(const render_request& r) {
  return with_pop(r.input, [&](const auto& t) {
    using tree = std::decay_t<decltype(t)>;
    point_cloud bounds;
    bounds.origin = t.origin();
    bounds.positions = t.positions();
    const camera cam = make_camera(bounds, r.view);
    const view v(cam, t.origin());
    render_options o = lod_render_options(r.view, tree::attrs.colour);
    // The paper's splat size from eye-space z (§3.3), its back-face culling by normal cones.
    const traverse_options topt{
        .tolerance_px = r.tolerance, .metric = projection_metric::eye_z, .backface_cull = true};
    pop_policy policy;
    if (o.fx.hole_filling) {
      // §3.4: visibility splatting (one-pixel points) + screen-space reconstruction.
      policy.points = pop_point_mode::visibility;
      o.hole_filling_radius = std::max(1, static_cast<int>(std::ceil(r.tolerance)));
    }
    traverse_stats st;
    const auto t0 = clock_type::now();
    const image img =
        render<tree::attrs>(v, o, [&](auto& sink) { st = traverse(t, v, topt, sink, policy); });
    const double frame_s = seconds_since(t0);
    write_png(r.output, img);
    if (r.as_json) {
      json j;
      j.str("input", r.input).str("output", r.output).str("method", "pop");
      j.num("tolerance_px", r.tolerance).str("effects", o.fx.to_string());
      j.integer("width", img.width).integer("height", img.height);
      j.integer("nodes_visited", static_cast<long long>(st.visited));
      j.integer("culled_frustum", static_cast<long long>(st.culled_frustum));
      j.integer("culled_backface", static_cast<long long>(st.culled_backface));
      j.integer("points", static_cast<long long>(st.points));
      j.integer("triangles", static_cast<long long>(st.triangles));
      j.num("frame_seconds", frame_s);
      std::cout << j.text() << "\n";
    } else {
      std::cout << "wrote " << r.output << ": " << st.points << " points and " << st.triangles
                << " triangles at threshold " << r.tolerance << " px (" << frame_s << " s)\n";
    }
    return 0;
  });
}

int stats(const std::string& path, bool as_json) {
  return with_pop(path, [&](const auto& t) {
    std::cout << (as_json ? "" : path + ": ") << pop_stats_json(t, path).text() << "\n";
    return 0;
  });
}

}  // namespace

method_entry pop_method() {
  return {"pop", "Chen & Nguyen 2001", "PBRLODPP", &build, &render_lod, &stats};
}

}  // namespace pbrlod_tool
