// pbrlod — PMR, Voronoi-based point and umbrella hierarchy (Dey & Hudson, IEEE Vis 2002):
// build, render, stats.
//
// Build time: the .lod file holds no timings (the same input gives the same bytes), so `build`
// reports build_seconds in its output and writes it next to the file, in OUT.lod.build-seconds;
// `stats` reads it from there (null when that file is absent, e.g. for a copied .lod).
#include <cmath>
#include <fstream>
#include <iostream>
#include <sstream>

#include "pbr_lod/builders/pmr.hpp"
#include "pbr_lod/raster/png.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "tool.hpp"

namespace pbrlod_tool {
namespace {

std::string timing_path(const std::string& lod) {
  return lod + ".build-seconds";
}

std::string list(const std::vector<std::size_t>& v) {
  std::ostringstream s;
  s << '[';
  for (std::size_t i = 0; i < v.size(); ++i) s << (i ? "," : "") << v[i];
  s << ']';
  return s.str();
}

json pmr_stats_json(const pmr_hierarchy& h, const std::string& path, double build_seconds) {
  const auto& st = h.stats();
  std::vector<std::size_t> points, tris;
  for (std::uint32_t i = 0; i < h.levels(); ++i) {
    points.push_back(h.points_at_level(i));
    tris.push_back(h.triangles_at_level(i));
  }
  json j;
  j.str("file", path).str("method", "pmr");
  j.integer("points", static_cast<long long>(h.positions().size()));
  j.integer("nodes", static_cast<long long>(h.nodes().size()));
  j.integer("leaves", static_cast<long long>(h.leaf_count()));
  j.integer("levels", h.levels());
  j.raw("points_per_level", list(points));
  j.raw("triangles_per_level", list(tris));
  j.integer("max_leaf_points", h.max_leaf_points());
  j.num("neighbour_margin", h.neighbour_margin());
  j.integer("duplicates", static_cast<long long>(st.duplicates));
  j.integer("triangulated_points", static_cast<long long>(st.triangulated_points));
  j.integer("removals", static_cast<long long>(st.removals));
  j.integer("hull_points", static_cast<long long>(st.hull_points));
  j.integer("flat_leaves", static_cast<long long>(st.flat_leaves));
  j.integer("file_bytes", static_cast<long long>(h.file_bytes()));
  j.num("bytes_per_point",
        static_cast<double>(h.file_bytes()) / static_cast<double>(h.positions().size()));
  j.num("build_seconds", build_seconds);  // NaN → null: unknown
  return j;
}

int build(const build_request& r) {
  params m(r.params);
  pmr_options o;
  o.max_leaf_points = static_cast<std::uint32_t>(m.integer("leaf_points", 10000, 8, 1 << 24));
  o.neighbour_margin = static_cast<float>(m.number("margin", o.neighbour_margin, 0, 2));
  const long nrho = m.integer("levels", 10, 0, 31);
  const double step = m.number("rho_step", 0.1, 1e-3, 1);
  o.rho.clear();
  for (long i = 1; i <= nrho; ++i)
    o.rho.push_back(static_cast<float>(step * static_cast<double>(i)));
  o.threads = static_cast<unsigned>(m.integer("threads", 0, 0, 256));
  m.finish("pmr", "leaf_points, margin, levels, rho_step, threads");
  const loaded_input in = load(r.input);
  o.progress = progress_callback("pmr", interactive(r.as_json));
  const pmr_hierarchy h = build_pmr(in.mesh.vertices, o);
  h.save(r.output);
  const double seconds = h.stats().build_seconds;
  {
    std::ofstream t(timing_path(r.output));
    t.precision(10);
    t << seconds << "\n";
  }
  std::cout << (r.as_json ? "" : "wrote " + r.output + ": ")
            << pmr_stats_json(h, r.output, seconds).text() << "\n";
  return 0;
}

int render_lod(const render_request& r) {
  const pmr_hierarchy h = pmr_hierarchy::load(r.input);
  point_cloud bounds;
  bounds.origin = h.origin();
  bounds.positions = h.positions();
  const camera cam = make_camera(bounds, r.view);
  const view v(cam, h.origin());
  const render_options o = lod_render_options(r.view, false);
  // §3: every leaf the frustum keeps, its level from the pixel size at its nearest corner with
  // factor = --tolerance, then points or umbrella triangles.
  traverse_options topt;
  topt.tolerance_px = r.tolerance;
  std::vector<std::uint32_t> used(h.leaf_count(), 0);
  pmr_policy policy;
  policy.levels_used = &used;
  traverse_stats st;
  const auto t0 = clock_type::now();
  const image img = render<pmr_hierarchy::attrs>(
      v, o, [&](auto& sink) { st = traverse(h, v, topt, sink, policy); });
  const double frame_s = seconds_since(t0);
  write_png(r.output, img);
  std::vector<std::size_t> hist(h.levels(), 0);
  for (const auto u : used) ++hist[u];
  if (r.as_json) {
    json j;
    j.str("input", r.input).str("output", r.output).str("method", "pmr");
    j.num("factor", r.tolerance).str("effects", o.fx.to_string());
    j.integer("width", img.width).integer("height", img.height);
    j.integer("leaves_drawn", static_cast<long long>(st.emitted_leaves));
    j.integer("culled_frustum", static_cast<long long>(st.culled_frustum));
    j.raw("leaves_per_level", list(hist));
    j.integer("points", static_cast<long long>(st.points));
    j.integer("triangles", static_cast<long long>(st.triangles));
    j.num("frame_seconds", frame_s);
    std::cout << j.text() << "\n";
  } else {
    std::cout << "wrote " << r.output << ": " << st.points << " points and " << st.triangles
              << " triangles at factor " << r.tolerance << " (" << frame_s << " s)\n";
  }
  return 0;
}

int stats(const std::string& path, bool as_json) {
  const pmr_hierarchy h = pmr_hierarchy::load(path);
  double seconds = std::nan("");
  if (std::ifstream t(timing_path(path)); t) {
    double s = 0;
    if (t >> s) seconds = s;
  }
  std::cout << (as_json ? "" : path + ": ") << pmr_stats_json(h, path, seconds).text() << "\n";
  return 0;
}

}  // namespace

method_entry pmr_method() {
  return {"pmr", "Dey & Hudson 2002", "PBRLODPM", &build, &render_lod, &stats};
}

}  // namespace pbrlod_tool
