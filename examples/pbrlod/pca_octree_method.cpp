// pbrlod — the hierarchical PCA octree (Kalaiah & Varshney 2003): build, render and stats.
//
// Build time: the file holds no timings (its bytes depend only on the input and the options),
// so build_seconds and kmeans_seconds are reported by `build --json`; `stats` of a file reports
// them as null with "timings":"absent (not stored in the file)".
#include <limits>

#include "lod.hpp"
#include "pbr_lod/builders/chunked_pca_octree.hpp"
#include "pbr_lod/builders/pca_octree.hpp"
#include "pbr_lod/core/mesh_splats.hpp"

namespace pbrlod_tool {
namespace {

/// The PCA octree options from the --param items; `memory`/`chunk_points` only for a chunked
/// build. `from_faces`: where the in-memory build asks, mesh=faces (the default: a mesh's
/// vertices with the patches of their faces, core/mesh_splats.hpp) or mesh=vertices.
pca_octree_options pca_options(const std::vector<std::string>& items, bool on_terminal,
                               chunked_pca_octree_options* chunked = nullptr,
                               bool* from_faces = nullptr) {
  params m(items);
  pca_octree_options o;
  o.leaf_size = static_cast<std::uint32_t>(m.integer("leaf_size", 8, 1, 1 << 20));
  o.max_depth = static_cast<std::uint32_t>(m.integer("max_depth", 21, 1, 30));
  o.gamma = static_cast<float>(m.number("gamma", 3.5, 0.5, 10));
  o.curvature_c = static_cast<float>(m.number("curvature_c", 1, 0, 100));
  o.lambda_max = static_cast<float>(m.number("lambda_max", 2, 1, 16));
  o.surface_angle = static_cast<float>(m.number("surface_angle", 20, 1, 180));
  o.colour_tolerance = static_cast<float>(m.number("colour_tolerance", 2, 0, 2));
  o.quantise = m.flag("quantise", true);
  o.position_codebook = static_cast<std::uint32_t>(m.integer("codebook_p", 1024, 1, 4096));
  o.normal_codebook = static_cast<std::uint32_t>(m.integer("codebook_n", 1024, 1, 4096));
  o.colour_codebook = static_cast<std::uint32_t>(m.integer("codebook_c", 64, 1, 64));
  o.kmeans_iterations = static_cast<std::uint32_t>(m.integer("kmeans_iterations", 8, 0, 1000));
  o.kmeans_sample = static_cast<std::uint32_t>(m.integer("kmeans_sample", 1 << 14, 1, 1 << 30));
  o.kmeans_seed = static_cast<std::uint64_t>(m.integer("kmeans_seed", 1, 0, 1L << 62));
  o.knn = static_cast<int>(m.integer("knn", 16, 3, 256));
  o.threads = static_cast<unsigned>(m.integer("threads", 0, 0, 256));
  if (chunked) chunked_params(m, *chunked);
  if (from_faces) *from_faces = m.choice("mesh", "faces", {"faces", "vertices"}) == "faces";
  m.finish("pca-octree",
           "leaf_size, max_depth, gamma, curvature_c, lambda_max, surface_angle, colour_tolerance, "
           "quantise, "
           "codebook_p, codebook_n, codebook_c, kmeans_iterations, kmeans_sample, kmeans_seed, "
           "knn, threads, mesh (in memory), memory, chunk_points");
  o.progress = progress_callback("pca-octree", on_terminal);
  return o;
}

template <class Tree>
json pca_stats_json(const Tree& t, const std::string& path) {
  const auto& st = t.stats();
  const double nodes = static_cast<double>(t.nodes().size());
  const double points = static_cast<double>(st.input_points);
  const double nan = std::numeric_limits<double>::quiet_NaN();  // written as null
  json j;
  j.str("file", path).str("method", "pca-octree");
  j.integer("nodes", static_cast<long long>(st.nodes));
  j.integer("leaves", static_cast<long long>(st.leaves));
  j.integer("max_depth", static_cast<long long>(st.max_depth));
  j.integer("input_points", static_cast<long long>(st.input_points));
  j.boolean("colour", Tree::attrs.colour).boolean("quantised", t.quantised());
  j.integer("codebook_p", static_cast<long long>(t.codebook_size_p()));
  j.integer("codebook_n", static_cast<long long>(t.codebook_size_n()));
  j.integer("codebook_c", static_cast<long long>(t.codebook_size_c()));
  j.integer("file_bytes", static_cast<long long>(t.file_bytes()));
  j.integer("record_bytes", static_cast<long long>(t.record_bytes()));
  j.num("bytes_per_node", static_cast<double>(t.file_bytes()) / nodes);
  j.num("bytes_per_point", static_cast<double>(t.file_bytes()) / points);
  j.str("timings", st.has_timings ? "measured by this build" : "absent (not stored in the file)");
  j.num("build_seconds", st.has_timings ? st.seconds : nan);
  j.num("kmeans_seconds", st.has_timings ? st.kmeans_seconds : nan);
  j.num("estimation_seconds", st.has_timings ? st.estimation_seconds : nan);
  j.num("tree_seconds", st.has_timings ? st.tree_seconds : nan);
  // Zero or non-finite input normals estimated from the positions (build only; a file: 0).
  j.integer("normals_filled", static_cast<long long>(st.normals_filled));
  if (st.has_timings && t.quantised()) {
    j.num("max_mean_error_cell", st.max_mean_error_cell);
    j.num("max_axis_error_deg", st.max_axis_error_deg);
    j.num("mean_sigma_p_error", st.mean_sigma_p_error);
    j.num("mean_sigma_n_error_deg", st.mean_sigma_n_error_deg);
  }
  return j;
}

/// What the PCA octree contributes to a frame: --tolerance is the generated points' size in
/// pixels (§4), --seed their random stream; shadows and hole filling are not compiled in.
struct pca_method {
  template <class Tree>
  std::pair<vec3d, double> input_bounds(const Tree& t) const {
    return {t.origin(), t.input_radius()};  // recorded at build: frames like the input
  }
  template <class Tree>
  frame draw(const Tree& t, const frame_request& r) const {
    const view v(r.cam, t.origin());
    const render_options o = lod_render_options(r.view, Tree::attrs.colour);
    const traverse_options topt{.tolerance_px = r.tolerance, .backface_cull = o.fx.backface_cull};
    pca_octree_policy policy;
    policy.render.seed = r.seed;
    policy.render.point_px = std::max(1.0f, r.tolerance);
    constexpr effects compiled{
        .shading = true, .colour = true, .backface_cull = true, .shadows = false, .blending = true};
    frame f = draw_frame<compiled>(t, v, o, topt, policy, r, t.origin());
    f.extra.integer("seed", static_cast<long long>(r.seed));
    return f;
  }
  template <class Tree>
  json stats(const Tree& t, const std::string& path) const {
    return pca_stats_json(t, path);
  }
  template <class Tree>
  std::size_t samples(const Tree& t) const {
    return t.stats().input_points;
  }
};

/// A chunked PCA octree folder (build_pca_octree_chunked): drawn as the PCA octree, its chunks
/// read as the views need them.
struct chunked_pca_method : pca_method, chunked_folder {
  using chunked_folder::samples;
  template <class H>
  frame draw(const H& h, const frame_request& r) const {
    frame f = pca_method::draw(h, r);
    f.extra.integer("chunks_read", static_cast<long long>(h.chunks_loaded()));
    return f;
  }
  template <class H>
  json stats(const H& h, const std::string& path) const {
    const auto& top = h.top_data();
    json j;
    j.str("file", path).str("method", "pca-octree").boolean("chunked", true);
    j.integer("chunks", static_cast<long long>(h.chunk_count()));
    j.integer("top_nodes", static_cast<long long>(h.top_node_count()));
    j.integer("nodes", static_cast<long long>(h.node_count()));
    j.integer("input_points", static_cast<long long>(h.input_points()));
    j.boolean("colour", H::attrs.colour).boolean("quantised", h.quantised());
    j.integer("codebook_p", static_cast<long long>(top.codebook_p.size()));
    j.integer("codebook_n", static_cast<long long>(top.codebook_n.size()));
    j.integer("codebook_c", static_cast<long long>(top.codebook_c.size()));
    j.integer("file_bytes", static_cast<long long>(h.file_bytes()));
    j.num("bytes_per_point",
          static_cast<double>(h.file_bytes()) / static_cast<double>(h.input_points()));
    return j;
  }
};

std::unique_ptr<lod> open_chunked(const std::string& dir) {
  if (chunked_folder_has_colours(dir))
    return make_lod(chunked_pca_method{}, chunked_pca_octree<with_normals_colours>::open(dir));
  return make_lod(chunked_pca_method{}, chunked_pca_octree<with_normals>::open(dir));
}

std::unique_ptr<lod> build_chunked(const std::vector<std::string>& items, const std::string& input,
                                   const std::string& output, bool on_terminal, json& report,
                                   const distributed_rank* part) {
  chunked_pca_octree_options o;
  o.builder = pca_options(items, on_terminal, &o);
  if (part) o.distributed = {part->rank, part->ranks, part->barrier};
  chunked_report_json(build_pca_octree_chunked(*open_build_source(input), output, o), report);
  return open_chunked(output);
}

std::unique_ptr<lod> build(const std::vector<std::string>& items, const build_input& in,
                           bool on_terminal) {
  bool from_faces = true;
  const auto opt = pca_options(items, on_terminal, nullptr, &from_faces);
  // A mesh's vertices carry the patches of their faces (their splats bound their dual cells),
  // which the leaves span; a cloud's points as they are.
  const loaded_input& data = in.get();
  const bool splat_mesh = from_faces && data.is_mesh();
  const point_cloud splats = splat_mesh ? mesh_splats(data.mesh) : point_cloud{};
  const point_cloud& cloud = splat_mesh ? splats : data.mesh.vertices;
  // Only normals, colours and splat ellipses matter to this builder: eight instantiations of
  // the thin wrapper.
  const attributes have = cloud.present();
  const auto go = [&]<attributes A>() {
    return make_lod(pca_method{}, build_pca_octree(point_set<A>::from(cloud, in.name()), opt));
  };
  const auto by_attributes = [&]<bool E>() {
    if (have.colour && have.normal)
      return go.template operator()<attributes{.normal = true, .colour = true, .ellipse = E}>();
    if (have.colour) return go.template operator()<attributes{.colour = true, .ellipse = E}>();
    if (have.normal) return go.template operator()<attributes{.normal = true, .ellipse = E}>();
    return go.template operator()<attributes{.ellipse = E}>();
  };
  return have.ellipse ? by_attributes.template operator()<true>()
                      : by_attributes.template operator()<false>();
}

std::unique_ptr<lod> load(const std::string& path) {
  if (is_chunked_pca_octree(path)) return open_chunked(path);
  if (peek_lod(path).flags & 1u)
    return make_lod(pca_method{}, pca_octree<with_normals_colours>::load(path));
  return make_lod(pca_method{}, pca_octree<with_normals>::load(path));
}

}  // namespace

method_entry pca_octree_method() {
  return {.name = "pca-octree",
          .paper = "Kalaiah & Varshney 2003",
          .magic = "PBRLODSG",
          .dir_magic = "PBRLODSC",
          .build = &build,
          .load = &load,
          .build_chunked = &build_chunked,
          .demo_tolerances = {4, 2, 1},
          .tolerance_means =
              "pixels: a node is drawn once it projects to at most this, its "
              "generated points this size (§4)",
          .splats_from_mesh = true};
}

}  // namespace pbrlod_tool
