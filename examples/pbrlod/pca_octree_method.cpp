// pbrlod — the hierarchical PCA octree (Kalaiah & Varshney 2003): build, render and stats.
//
// Build time: the file holds no timings (its bytes depend only on the input and the options),
// so build_seconds and kmeans_seconds are reported by `build --json`; `stats` of a file reports
// them as null with "timings":"absent (not stored in the file)".
#include <iostream>

#include "pbr_lod/builders/pca_octree.hpp"
#include "pbr_lod/raster/png.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "tool.hpp"

namespace pbrlod_tool {
namespace {

pca_octree_options pca_options(const std::vector<std::string>& items, bool on_terminal) {
  params m(items);
  pca_octree_options o;
  o.leaf_size = static_cast<std::uint32_t>(m.integer("leaf_size", 8, 1, 1 << 20));
  o.max_depth = static_cast<std::uint32_t>(m.integer("max_depth", 21, 1, 30));
  o.gamma = static_cast<float>(m.number("gamma", 3.5, 0.5, 10));
  o.curvature_c = static_cast<float>(m.number("curvature_c", 1, 0, 100));
  o.lambda_max = static_cast<float>(m.number("lambda_max", 2, 1, 16));
  o.quantise = m.flag("quantise", true);
  o.position_codebook = static_cast<std::uint32_t>(m.integer("codebook_p", 1024, 1, 4096));
  o.normal_codebook = static_cast<std::uint32_t>(m.integer("codebook_n", 1024, 1, 4096));
  o.colour_codebook = static_cast<std::uint32_t>(m.integer("codebook_c", 64, 1, 64));
  o.kmeans_iterations = static_cast<std::uint32_t>(m.integer("kmeans_iterations", 8, 0, 1000));
  o.kmeans_sample = static_cast<std::uint32_t>(m.integer("kmeans_sample", 1 << 14, 1, 1 << 30));
  o.kmeans_seed = static_cast<std::uint64_t>(m.integer("kmeans_seed", 1, 0, 1L << 62));
  o.knn = static_cast<int>(m.integer("knn", 16, 3, 256));
  o.threads = static_cast<unsigned>(m.integer("threads", 0, 0, 256));
  m.finish("pca-octree",
           "leaf_size, max_depth, gamma, curvature_c, lambda_max, quantise, codebook_p, "
           "codebook_n, codebook_c, kmeans_iterations, kmeans_sample, kmeans_seed, knn, threads");
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
  if (st.has_timings && t.quantised()) {
    j.num("max_mean_error_cell", st.max_mean_error_cell);
    j.num("max_axis_error_deg", st.max_axis_error_deg);
    j.num("mean_sigma_p_error", st.mean_sigma_p_error);
    j.num("mean_sigma_n_error_deg", st.mean_sigma_n_error_deg);
  }
  return j;
}

template <class F>
auto with_pca(const std::string& path, F&& f) {
  if (peek_lod(path).flags & 1u) return f(pca_octree<with_normals_colours>::load(path));
  return f(pca_octree<with_normals>::load(path));
}

int build(const build_request& r) {
  const auto opt = pca_options(r.params, interactive(r.as_json));
  read_report report;
  const point_cloud cloud = read_points(r.input, &report);
  for (const auto& w : report.warnings) std::cerr << "warning: " << w << "\n";
  const auto go = [&](const auto& t) {
    t.save(r.output);
    std::cout << (r.as_json ? "" : "wrote " + r.output + ": ") << pca_stats_json(t, r.output).text()
              << "\n";
    return 0;
  };
  // Only normals and colours matter to this builder: four instantiations of the thin wrapper.
  const attributes have = cloud.present();
  if (have.colour && have.normal)
    return go(build_pca_octree(point_set<with_normals_colours>::from(cloud, r.input), opt));
  if (have.colour)
    return go(build_pca_octree(point_set<attributes{.colour = true}>::from(cloud, r.input), opt));
  if (have.normal) return go(build_pca_octree(point_set<with_normals>::from(cloud, r.input), opt));
  return go(build_pca_octree(point_set<positions_only>::from(cloud, r.input), opt));
}

int render_lod(const render_request& r) {
  return with_pca(r.input, [&](const auto& t) {
    using tree = std::decay_t<decltype(t)>;
    // Frame the input's bounds, as `render INPUT` does.
    point_cloud bounds;
    bounds.origin = t.origin();
    const float rad = static_cast<float>(t.input_radius());
    bounds.positions = {vec3f(-rad, 0, 0), vec3f(rad, 0, 0)};
    const camera cam = make_camera(bounds, r.view);
    const view v(cam, t.origin());
    const render_options o = lod_render_options(r.view, tree::attrs.colour);
    const traverse_options topt{.tolerance_px = r.tolerance, .backface_cull = o.fx.backface_cull};
    pca_octree_policy policy;
    policy.render.seed = r.seed;
    policy.render.point_px = std::max(1.0f, r.tolerance);  // --tolerance = point size (§4)
    traverse_stats st;
    const auto t0 = clock_type::now();
    // Effects a generated-point cloud uses; shadows and hole filling are not compiled in here.
    constexpr effects compiled{.shading = true, .colour = true, .backface_cull = true};
    const image img = render<tree::attrs, compiled>(
        v, o, [&](auto& sink) { st = traverse(t, v, topt, sink, policy); });
    const double frame_s = seconds_since(t0);
    write_png(r.output, img);
    if (r.as_json) {
      json j;
      j.str("input", r.input).str("output", r.output).str("method", "pca-octree");
      j.num("tolerance_px", r.tolerance).str("effects", o.fx.to_string());
      j.integer("seed", static_cast<long long>(r.seed));
      j.integer("width", img.width).integer("height", img.height);
      j.integer("nodes_visited", static_cast<long long>(st.visited));
      j.integer("nodes_drawn", static_cast<long long>(st.emitted_nodes + st.emitted_leaves));
      j.integer("culled_frustum", static_cast<long long>(st.culled_frustum));
      j.integer("culled_backface", static_cast<long long>(st.culled_backface));
      j.integer("points", static_cast<long long>(st.points));
      j.integer("covered_pixels", static_cast<long long>(img.covered_count()));
      j.num("frame_seconds", frame_s);
      std::cout << j.text() << "\n";
    } else {
      std::cout << "wrote " << r.output << ": " << st.points << " generated points from "
                << st.emitted_nodes + st.emitted_leaves << " nodes, seed " << r.seed << " ("
                << frame_s << " s)\n";
    }
    return 0;
  });
}

int stats(const std::string& path, bool as_json) {
  return with_pca(path, [&](const auto& t) {
    std::cout << (as_json ? "" : path + ": ") << pca_stats_json(t, path).text() << "\n";
    return 0;
  });
}

}  // namespace

method_entry pca_octree_method() {
  return {"pca-octree", "Kalaiah & Varshney 2003", "PBRLODSG", &build, &render_lod, &stats};
}

}  // namespace pbrlod_tool
