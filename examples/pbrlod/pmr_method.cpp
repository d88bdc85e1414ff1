// pbrlod — PMR, Voronoi-based point and umbrella hierarchy (Dey & Hudson, IEEE Vis 2002):
// build, render, stats.
//
// Build time: the .lod file holds no timings (the same input gives the same bytes), so `build`
// reports build_seconds in its output and writes it next to the file, in OUT.lod.build-seconds;
// `stats` reads it from there (null when that file is absent, e.g. for a copied .lod).
#include <cmath>
#include <fstream>
#include <sstream>

#include "lod.hpp"
#include "pbr_lod/builders/pmr.hpp"

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
  j.boolean("colours", h.has_colours());
  j.num("build_seconds", build_seconds);  // NaN → null: unknown
  return j;
}

/// What PMR contributes to a frame (§3): every leaf the frustum keeps, its level from the pixel
/// size at its nearest corner with factor = --tolerance, then points or umbrella triangles. It
/// keeps the build time, which the file does not hold: save() writes it beside the file.
struct pmr_method_traits {
  double build_seconds = std::nan("");

  std::pair<vec3d, double> input_bounds(const pmr_hierarchy& h) const {
    return bounds_of(h.origin(), h.positions());  // every input point is in the hierarchy
  }
  frame draw(const pmr_hierarchy& h, const frame_request& r) const {
    const view v(r.cam, h.origin());
    const render_options o = lod_render_options(r.view, h.has_colours());
    traverse_options topt;
    topt.tolerance_px = r.tolerance;
    std::vector<std::uint32_t> used(h.leaf_count(), 0);
    pmr_policy policy;
    policy.levels_used = &used;
    frame f = h.has_colours() ? draw_frame(pmr_colour_view(h), v, o, topt, policy, r, h.origin())
                              : draw_frame(h, v, o, topt, policy, r, h.origin());
    std::vector<std::size_t> hist(h.levels(), 0);
    for (const auto u : used) ++hist[u];
    f.extra.raw("leaves_per_level", list(hist));
    return f;
  }
  json stats(const pmr_hierarchy& h, const std::string& path) const {
    return pmr_stats_json(h, path, build_seconds);
  }
  void save(const pmr_hierarchy& h, const std::string& path) const {
    h.save(path);
    if (std::isfinite(build_seconds)) {
      std::ofstream t(timing_path(path));
      t.precision(10);
      t << build_seconds << "\n";
    }
  }
  std::size_t samples(const pmr_hierarchy& h) const { return h.positions().size(); }
};

std::unique_ptr<lod> build(const std::vector<std::string>& items, const build_input& in,
                           bool on_terminal) {
  params m(items);
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
  o.progress = progress_callback("pmr", on_terminal);
  pmr_hierarchy h = build_pmr(in.get().mesh.vertices, o);
  pmr_method_traits method;
  method.build_seconds = h.stats().build_seconds;
  return make_lod(method, std::move(h));
}

std::unique_ptr<lod> load(const std::string& path) {
  pmr_method_traits method;
  if (std::ifstream t(timing_path(path)); t) {
    double s = 0;
    if (t >> s) method.build_seconds = s;
  }
  return make_lod(method, pmr_hierarchy::load(path));
}

}  // namespace

method_entry pmr_method() {
  return {.name = "pmr",
          .paper = "Dey & Hudson 2002",
          .magic = "PBRLODPM",
          .dir_magic = {},
          .build = &build,
          .load = &load,
          .demo_tolerances = {8, 3, 1},
          .tolerance_key = "factor"};
}

}  // namespace pbrlod_tool
