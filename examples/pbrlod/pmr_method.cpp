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
#include "pbr_lod/builders/chunked_pmr.hpp"
#include "pbr_lod/builders/pmr.hpp"
#include "pbr_lod/core/atomic_file.hpp"

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

void build_counts_json(const pmr_build_stats& st, json& j) {
  j.integer("duplicates", static_cast<long long>(st.duplicates));
  j.integer("triangulated_points", static_cast<long long>(st.triangulated_points));
  j.integer("removals", static_cast<long long>(st.removals));
  j.integer("hull_points", static_cast<long long>(st.hull_points));
  j.integer("flat_leaves", static_cast<long long>(st.flat_leaves));
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
  // A chunk of a chunked folder also holds other chunks' umbrella vertices (foreign samples).
  const std::size_t own = h.positions().size() - h.foreign();
  j.integer("points", static_cast<long long>(own));
  if (h.foreign() > 0) j.integer("foreign_points", static_cast<long long>(h.foreign()));
  j.integer("nodes", static_cast<long long>(h.nodes().size()));
  j.integer("leaves", static_cast<long long>(h.leaf_count()));
  j.integer("levels", h.levels());
  j.raw("points_per_level", list(points));
  j.raw("triangles_per_level", list(tris));
  j.integer("max_leaf_points", h.max_leaf_points());
  j.num("neighbour_margin", h.neighbour_margin());
  build_counts_json(st, j);
  j.integer("file_bytes", static_cast<long long>(h.file_bytes()));
  j.num("bytes_per_point", static_cast<double>(h.file_bytes()) / static_cast<double>(own));
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
    if (std::isfinite(build_seconds)) {  // whole or not at all, as the .lod file
      std::ostringstream t;
      t.precision(10);
      t << build_seconds << "\n";
      const std::string text = t.str();
      write_file_atomically(timing_path(path), text.data(), text.size());
    }
  }
  std::size_t samples(const pmr_hierarchy& h) const { return h.positions().size(); }
};

/// A chunked PMR folder (build_pmr_chunked): framed by the input sphere its top file records,
/// drawn as PMR, its chunks read as the views need them.
struct chunked_pmr_traits : chunked_folder {
  template <class H>
  std::pair<vec3d, double> input_bounds(const H& h) const {
    return {h.origin() + h.input_sphere().centre.template cast<double>(),
            static_cast<double>(h.input_sphere().radius)};
  }
  template <class H>
  frame draw(const H& h, const frame_request& r) const {
    const view v(r.cam, h.origin());
    const render_options o = lod_render_options(r.view, H::attrs.colour);
    traverse_options topt;
    topt.tolerance_px = r.tolerance;
    std::vector<std::uint32_t> used(h.leaf_count(), 0);
    pmr_policy policy;
    policy.levels_used = &used;
    frame f = draw_frame(h, v, o, topt, policy, r, h.origin());
    std::vector<std::size_t> hist(h.levels(), 0);
    for (const auto u : used) ++hist[u];
    f.extra.raw("leaves_per_level", list(hist));
    f.extra.integer("chunks_read", static_cast<long long>(h.chunks_loaded()));
    return f;
  }
  template <class H>
  json stats(const H& h, const std::string& path) const {
    const auto& st = h.stats();
    const double n = static_cast<double>(h.input_points());
    json j;
    j.str("file", path).str("method", "pmr").boolean("chunked", true);
    j.integer("chunks", static_cast<long long>(h.chunk_count()));
    j.integer("top_nodes", static_cast<long long>(h.top_node_count()));
    j.integer("points", static_cast<long long>(h.input_points()));
    j.integer("nodes", static_cast<long long>(h.node_count()));
    j.integer("leaves", static_cast<long long>(h.leaf_count()));
    j.integer("levels", h.levels());
    build_counts_json(st, j);
    j.integer("file_bytes", static_cast<long long>(h.file_bytes()));
    j.num("bytes_per_point", static_cast<double>(h.file_bytes()) / n);
    j.boolean("colours", H::attrs.colour);
    return j;
  }
};

std::unique_ptr<lod> open_chunked(const std::string& dir) {
  if (chunked_folder_has_colours(dir))
    return make_lod(chunked_pmr_traits{}, chunked_pmr<with_normals_colours>::open(dir));
  return make_lod(chunked_pmr_traits{}, chunked_pmr<with_normals>::open(dir));
}

/// The PMR options from the --param items; `memory`/`chunk_points` only for a chunked build.
pmr_options pmr_params(const std::vector<std::string>& items, bool on_terminal,
                       chunked_pmr_options* chunked = nullptr) {
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
  o.triangulation_points = static_cast<std::uint32_t>(
      m.integer("triangulation_points", o.triangulation_points, 8, 1 << 30));
  o.cocone_degrees = static_cast<float>(m.number("cocone", o.cocone_degrees, 0, 89.9));
  o.edge_spacing = static_cast<float>(m.number("edge_spacing", o.edge_spacing, 0, 1000));
  o.input_normals = m.integer("input_normals", 1, 0, 1) != 0;
  o.neighbour_leaves = m.integer("neighbour_leaves", 1, 0, 1) != 0;
  if (chunked) chunked_params(m, *chunked);
  m.finish("pmr",
           "leaf_points, margin, levels, rho_step, threads, triangulation_points, cocone, "
           "edge_spacing, input_normals, neighbour_leaves, memory, chunk_points");
  o.progress = progress_callback("pmr", on_terminal);
  return o;
}

std::unique_ptr<lod> build(const std::vector<std::string>& items, const build_input& in,
                           bool on_terminal) {
  const pmr_options o = pmr_params(items, on_terminal);
  pmr_hierarchy h = build_pmr(in.get().mesh.vertices, o);
  pmr_method_traits method;
  method.build_seconds = h.stats().build_seconds;
  return make_lod(method, std::move(h));
}

std::unique_ptr<lod> build_chunked(const std::vector<std::string>& items, const std::string& input,
                                   const std::string& output, bool on_terminal, json& report,
                                   const distributed_rank* part) {
  chunked_pmr_options o;
  o.builder = pmr_params(items, on_terminal, &o);
  if (part) o.distributed = {part->rank, part->ranks, part->barrier};
  chunked_report_json(build_pmr_chunked(*open_build_source(input), output, o), report);
  return open_chunked(output);
}

std::unique_ptr<lod> load(const std::string& path) {
  if (is_chunked_pmr(path)) return open_chunked(path);
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
          .dir_magic = "PBRLODMC",
          .build = &build,
          .load = &load,
          .build_chunked = &build_chunked,
          .demo_tolerances = {8, 3, 1},
          .tolerance_key = "factor",
          .tolerance_means =
              "a factor: each leaf's level has umbrellas closest to factor x the "
              "pixel size at its nearest corner (§3, ramped as §4)"};
}

}  // namespace pbrlod_tool
