// pbrlod — the point-octree (Pajarola 2003): build, render and stats of its .lod files.
#include <iostream>
#include <limits>

#include "pbr_lod/builders/point_octree.hpp"
#include "pbr_lod/raster/png.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "tool.hpp"

namespace pbrlod_tool {
namespace {

point_octree_options octree_options(const std::vector<std::string>& items, bool on_terminal) {
  params m(items);
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
  m.finish("point-octree",
           "leaf_size, max_depth, normal_bits, knn, knn_ellipses, viewpoint, threads, covariance, "
           "axes");
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
  return j;
}

template <class F>
auto with_octree(const std::string& path, F&& f) {
  if (peek_lod(path).flags & 1u)
    return f(point_octree<point_octree_attributes(attributes{.colour = true})>::load(path));
  return f(point_octree<point_octree_attributes(positions_only)>::load(path));
}

int build(const build_request& r) {
  auto opt = octree_options(r.params, interactive(r.as_json));
  read_report report;
  const point_cloud cloud = read_points(r.input, &report);
  if (!opt.viewpoint) opt.viewpoint = cloud.sensor;  // a PCD's scanner, unless overridden
  for (const auto& w : report.warnings) std::cerr << "warning: " << w << "\n";
  return with_point_set(cloud, r.input, [&](const auto& pts) {
    const auto t = build_point_octree(pts, opt);
    t.save(r.output);
    const json j = octree_stats_json(t, r.output);
    if (r.as_json)
      std::cout << j.text() << "\n";
    else
      std::cout << "wrote " << r.output << ": " << j.text() << "\n";
    return 0;
  });
}

int render_lod(const render_request& r) {
  return with_octree(r.input, [&](const auto& t) {
    using tree = std::decay_t<decltype(t)>;
    // Camera around the root's bounding sphere, in world coordinates.
    point_cloud bounds;
    bounds.origin = t.origin();
    bounds.positions = t.samples().positions;
    const camera cam = make_camera(bounds, r.view);
    const view v(cam, t.origin());
    const render_options o = lod_render_options(r.view, tree::attrs.colour);
    const traverse_options topt{.tolerance_px = r.tolerance,
                                .backface_cull = o.fx.backface_cull,
                                .cull_volume = traverse_options::volume::view_cone};
    traverse_stats st;
    const auto t0 = clock_type::now();
    const image img = render<tree::attrs>(
        v, o, [&](auto& sink) { st = traverse(t, v, topt, sink, point_octree_policy{}); });
    const double frame_s = seconds_since(t0);  // LOD selection + rasterisation, one pass
    write_png(r.output, img);
    if (r.as_json) {
      json j;
      j.str("input", r.input).str("output", r.output).str("method", "point-octree");
      j.num("tolerance_px", r.tolerance).str("effects", o.fx.to_string());
      j.integer("width", img.width).integer("height", img.height);
      j.integer("nodes_visited", static_cast<long long>(st.visited));
      j.integer("culled_frustum", static_cast<long long>(st.culled_frustum));
      j.integer("culled_backface", static_cast<long long>(st.culled_backface));
      j.integer("splats", static_cast<long long>(st.splats));
      j.num("fraction_drawn",
            static_cast<double>(st.splats) / static_cast<double>(t.samples().size()));
      j.num("frame_seconds", frame_s);
      std::cout << j.text() << "\n";
    } else {
      std::cout << "wrote " << r.output << ": " << st.splats << " splats of " << t.samples().size()
                << " samples at tolerance " << r.tolerance << " px (" << frame_s << " s)\n";
    }
    return 0;
  });
}

int stats(const std::string& path, bool as_json) {
  return with_octree(path, [&](const auto& t) {
    if (as_json) {
      std::cout << octree_stats_json(t, path).text() << "\n";
    } else {
      const double n = static_cast<double>(t.samples().size());
      std::cout << path << ": point-octree, " << t.nodes().size() << " nodes (" << t.stats().leaves
                << " leaves) over " << t.samples().size() << " samples, "
                << static_cast<double>(t.file_bytes()) / n << " bytes/point in the file, "
                << static_cast<double>(t.memory_bytes()) / n << " in memory, built in "
                << t.stats().seconds << " s\n";
    }
    return 0;
  });
}

}  // namespace

method_entry point_octree_method() {
  return {"point-octree", "Pajarola 2003", "PBRLODPO", &build, &render_lod, &stats};
}

}  // namespace pbrlod_tool
