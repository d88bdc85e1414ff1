// pbrlod — the point-octree (Pajarola 2003): build, render and stats of its .lod files.
#include <limits>

#include "lod.hpp"
#include "pbr_lod/builders/chunked_point_octree.hpp"
#include "pbr_lod/builders/point_octree.hpp"
#include "pbr_lod/core/mesh_splats.hpp"
#include "pbr_lod/core/point_source.hpp"

namespace pbrlod_tool {
namespace {

/// `from_faces`: where the in-memory build asks, mesh=faces (the default: a mesh's vertices as
/// splats bounding their dual cells) or mesh=vertices (its vertices as a bare cloud, normals
/// and ellipses estimated, as a chunked build streams them).
point_octree_options octree_options(const std::vector<std::string>& items, bool on_terminal,
                                    chunked_point_octree_options* chunked = nullptr,
                                    bool* from_faces = nullptr) {
  params m(items);
  if (chunked) chunked_params(m, *chunked);
  point_octree_options o;
  o.leaf_size = static_cast<std::uint32_t>(m.integer("leaf_size", 8, 1, 1 << 20));
  o.max_depth = static_cast<std::uint32_t>(m.integer("max_depth", 48, 1, 250));
  o.normal_bits = static_cast<int>(m.integer("normal_bits", 16, 0, 24));
  o.knn = static_cast<int>(m.integer("knn", 16, 3, 256));
  o.knn_ellipses = static_cast<int>(m.integer("knn_ellipses", 12, 3, 256));
  o.threads = static_cast<unsigned>(m.integer("threads", 0, 0, 256));
  if (const auto vp = m.point("viewpoint")) o.viewpoint = vec3d((*vp)[0], (*vp)[1], (*vp)[2]);
  const auto cov = m.choice("covariance", "stable", {"stable", "generic_double", "generic_float"});
  o.covariance = cov == "stable"           ? covariance_method::stable
                 : cov == "generic_double" ? covariance_method::generic_double
                                           : covariance_method::generic_float;
  o.axis_rule = m.choice("axes", "sqrt", {"sqrt", "eigenvalue"}) == "sqrt"
                    ? ellipse_axis_rule::sqrt_eigenvalue
                    : ellipse_axis_rule::eigenvalue;
  o.circle_guard = m.flag("circle_guard", true);
  if (from_faces) *from_faces = m.choice("mesh", "faces", {"faces", "vertices"}) == "faces";
  m.finish("point-octree",
           "leaf_size, max_depth, normal_bits, knn, knn_ellipses, viewpoint, threads, covariance, "
           "axes, circle_guard, mesh, memory, chunk_points");
  o.progress = progress_callback("point-octree", on_terminal);
  return o;
}

template <class Tree>
json octree_stats_json(const Tree& t, const std::string& path) {
  const auto& st = t.stats();
  const double n = static_cast<double>(t.samples().size());
  json j;
  j.str("file", path).str("method", "point-octree");
  j.integer("nodes", static_cast<long long>(t.nodes().size()));
  j.integer("leaves", static_cast<long long>(st.leaves));
  j.integer("samples", static_cast<long long>(t.samples().size()));
  j.integer("max_depth", static_cast<long long>(st.max_depth));
  j.num("nodes_per_point", static_cast<double>(t.nodes().size()) / n);
  j.integer("normal_bits", t.normal_bits());
  j.boolean("colour", Tree::attrs.colour);
  j.integer("file_bytes", static_cast<long long>(t.file_bytes()));
  j.num("bytes_per_point", static_cast<double>(t.file_bytes()) / n);
  j.num("bytes_per_point_file", static_cast<double>(t.file_bytes()) / n);
  j.num("bytes_per_point_memory", static_cast<double>(t.memory_bytes()) / n);
  j.num("bits_per_sample", 8.0 * static_cast<double>(t.file_bytes()) / n);
  // The file holds no timings (its bytes depend only on the input and the options): `build
  // --json` reports them, `stats` of a file reports null.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  j.str("timings", st.has_timings ? "measured by this build" : "absent (not stored in the file)");
  j.num("build_seconds", st.has_timings ? st.seconds : nan);
  j.num("estimation_seconds", st.has_timings ? st.estimation_seconds : nan);
  j.num("tree_seconds", st.has_timings ? st.tree_seconds : nan);
  // Nodes whose EQ 5–6 ellipse was replaced by the corners' bounding circle: counted on the
  // stored nodes (point_octree::is_circle), so a loaded file gives the build's number.
  j.integer("circle_fallbacks", static_cast<long long>(st.circle_fallbacks));
  // Zero or non-finite input normals estimated from the positions (build only; a file: 0).
  j.integer("normals_filled", static_cast<long long>(st.normals_filled));
  return j;
}

/// What the point-octree contributes to a frame: the view-cone culling of §6 and back-face
/// culling by normal cones when the effects ask for it. `samples`: the input's points.
template <class Tree>
frame draw_octree(const Tree& t, const frame_request& r, std::uint64_t samples) {
  const view v(r.cam, t.origin());
  const render_options o = lod_render_options(r.view, Tree::attrs.colour);
  const traverse_options topt{.tolerance_px = r.tolerance,
                              .backface_cull = o.fx.backface_cull,
                              .cull_volume = traverse_options::volume::view_cone};
  frame f = draw_frame(t, v, o, topt, point_octree_policy{}, r, t.origin());
  f.extra.num("fraction_drawn", static_cast<double>(f.st.splats) / static_cast<double>(samples));
  return f;
}

struct octree_method {
  template <class Tree>
  std::pair<vec3d, double> input_bounds(const Tree& t) const {
    return bounds_of(t.origin(), t.samples().positions);  // the samples are the input points
  }
  template <class Tree>
  frame draw(const Tree& t, const frame_request& r) const {
    return draw_octree(t, r, t.samples().size());
  }
  template <class Tree>
  json stats(const Tree& t, const std::string& path) const {
    return octree_stats_json(t, path);
  }
  template <class Tree>
  std::size_t samples(const Tree& t) const {
    return t.samples().size();
  }
};

/// A chunked point-octree folder (build_point_octree_chunked): framed by the input sphere its top
/// file records, drawn like a point-octree, its chunks read as the views need them.
struct chunked_method : chunked_folder {
  template <class Tree>
  std::pair<vec3d, double> input_bounds(const Tree& t) const {
    return {t.origin() + t.input_sphere().centre.template cast<double>(),
            static_cast<double>(t.input_sphere().radius)};
  }
  template <class Tree>
  frame draw(const Tree& t, const frame_request& r) const {
    frame f = draw_octree(t, r, t.input_points());
    f.extra.integer("chunks_read", static_cast<long long>(t.chunks_loaded()));
    return f;
  }
  template <class Tree>
  json stats(const Tree& t, const std::string& path) const {
    const double n = static_cast<double>(t.input_points());
    const double bytes = static_cast<double>(t.file_bytes());
    json j;
    j.str("file", path).str("method", "point-octree").boolean("chunked", true);
    j.integer("chunks", static_cast<long long>(t.chunk_count()));
    j.integer("top_nodes", static_cast<long long>(t.top_node_count()));
    j.integer("nodes", static_cast<long long>(t.node_count()));
    j.integer("samples", static_cast<long long>(t.input_points()));
    j.num("nodes_per_point", static_cast<double>(t.node_count()) / n);
    j.integer("normal_bits", t.normal_bits());
    j.boolean("colour", Tree::attrs.colour);
    j.integer("file_bytes", static_cast<long long>(t.file_bytes()));
    j.num("bytes_per_point", bytes / n);
    j.num("bytes_per_point_file", bytes / n);
    j.num("bits_per_sample", 8.0 * bytes / n);
    return j;
  }
};

std::unique_ptr<lod> open_chunked(const std::string& dir) {
  if (chunked_folder_has_colours(dir))
    return make_lod(
        chunked_method{},
        chunked_point_octree<point_octree_attributes(attributes{.colour = true})>::open(dir));
  return make_lod(chunked_method{},
                  chunked_point_octree<point_octree_attributes(positions_only)>::open(dir));
}

std::unique_ptr<lod> build(const std::vector<std::string>& items, const build_input& in,
                           bool on_terminal) {
  bool from_faces = true;
  auto opt = octree_options(items, on_terminal, nullptr, &from_faces);
  // A mesh's vertices as splats bounding their dual cells, with the mesh's normals
  // (core/mesh_splats.hpp); a cloud's points as they are (normals, ellipses estimated if absent).
  const loaded_input& data = in.get();
  const bool splat_mesh = from_faces && data.is_mesh();
  const point_cloud splats = splat_mesh ? mesh_splats(data.mesh) : point_cloud{};
  const point_cloud& cloud = splat_mesh ? splats : data.mesh.vertices;
  if (!opt.viewpoint) opt.viewpoint = cloud.sensor;  // a PCD's scanner, unless overridden
  return with_point_set(cloud, in.name(), [&](const auto& pts) {
    return make_lod(octree_method{}, build_point_octree(pts, opt));
  });
}

std::unique_ptr<lod> load(const std::string& path) {
  if (is_chunked_point_octree(path)) return open_chunked(path);
  if (peek_lod(path).flags & 1u)
    return make_lod(octree_method{},
                    point_octree<point_octree_attributes(attributes{.colour = true})>::load(path));
  return make_lod(octree_method{},
                  point_octree<point_octree_attributes(positions_only)>::load(path));
}

std::unique_ptr<lod> build_chunked(const std::vector<std::string>& items, const std::string& input,
                                   const std::string& output, bool on_terminal, json& report,
                                   const distributed_rank* part) {
  chunked_point_octree_options o;
  o.builder = octree_options(items, on_terminal, &o);
  if (part) o.distributed = {part->rank, part->ranks, part->barrier};
  const std::unique_ptr<point_source> src = open_build_source(input);
  if (!o.builder.viewpoint) o.builder.viewpoint = src->sensor();
  chunked_report_json(build_point_octree_chunked(*src, output, o), report);
  return open_chunked(output);
}

}  // namespace

bool wants_chunked_build(const std::vector<std::string>& items) {
  for (const auto& p : items)
    if (p.rfind("memory=", 0) == 0 || p.rfind("chunk_points=", 0) == 0) return true;
  return false;
}

void chunked_report_json(const chunked_build_report& r, json& report) {
  report.integer("chunk_points_limit", static_cast<long long>(r.chunk_points))
      .integer("largest_chunk", static_cast<long long>(r.largest_chunk))
      .integer("halo_points", static_cast<long long>(r.halo_points))
      .integer("normals_filled", static_cast<long long>(r.normals_filled))
      .integer("passes", r.passes)
      .num("build_seconds", r.seconds)
      .num("pass_seconds", r.pass_seconds)
      .num("estimation_seconds", r.estimation_seconds)
      .num("chunk_build_seconds", r.chunk_build_seconds);
}

method_entry point_octree_method() {
  return {.name = "point-octree",
          .paper = "Pajarola 2003",
          .magic = "PBRLODPO",
          .dir_magic = "PBRLODPC",
          .build = &build,
          .load = &load,
          .build_chunked = &build_chunked,
          .demo_tolerances = {16, 4, 1},
          .tolerance_means =
              "pixels: a node's splat is drawn once the diameter of its projected "
              "disk's area is at most this (§6, Fig. 11)",
          .splats_from_mesh = true};
}

}  // namespace pbrlod_tool
