// pbrlod — ρ-grid packed point trees (Duguet & Drettakis 2004): build, render and stats.
#include <filesystem>
#include <limits>

#include "lod.hpp"
#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/builders/rho_grid_policy.hpp"
#include "pbr_lod/raster/one_pass_shadows.hpp"

namespace pbrlod_tool {
namespace {

template <int R>
json grid_stats_json(const rho_grid<R>& g, const std::string& path) {
  const auto& st = g.stats();
  json j;
  j.str("file", path).str("method", "rho-grid");
  j.integer("rho", R).integer("level", g.level()).integer("sigma", g.sigma());
  j.integer("normal_bits", g.normal_bits()).integer("material_bits", g.material_bits());
  j.integer("colour_bits", g.colour_bits());
  j.integer("samples", static_cast<long long>(st.samples));
  j.integer("inner_cells", static_cast<long long>(st.inner_cells));
  j.num("bits_per_sample_nis", st.bits_per_sample_nis);
  j.num("bits_per_sample_is", st.bits_per_sample_is);
  j.num("bits_per_sample_incore", st.bits_per_sample_incore);
  j.integer("memory_bytes", static_cast<long long>(g.memory_bytes()));
  // Beyond the paper: the compressed layout's real stream sizes (one encode).
  const rho_grid_coded_size cs = g.coded_size();
  j.num("bits_per_sample_coded_geometry", cs.bits_per_sample_geometry);
  j.num("bits_per_sample_coded_attributes", cs.bits_per_sample_attributes);
  j.integer("coded_file_bytes", static_cast<long long>(cs.file_bytes));
  // The file holds no timings: `build --json` reports them, `stats` of a file reports null.
  j.str("timings", st.has_timings ? "measured by this build" : "absent (not stored in the file)");
  j.num("build_seconds",
        st.has_timings ? st.build_seconds : std::numeric_limits<double>::quiet_NaN());
  if (st.has_timings) {
    j.boolean("estimated_normals", st.estimated_normals);
    j.num("estimation_seconds", st.estimation_seconds);
    j.integer("normals_filled", static_cast<long long>(st.normals_filled));
  }
  return j;
}

/// What the ρ-grid contributes to a frame: the §4.1 traversal policy (s = the tolerance) and,
/// with shadows and normals, the paper's one-pass shadows (§4.2): children front to back from
/// the light, shaded through raster/one_pass_shadows.hpp. It keeps the layout its file is
/// written in.
struct rho_method {
  rho_grid_layout layout = rho_grid_layout::is;
  std::string layout_name;       ///< empty for a loaded file (the stats then omit it)
  std::size_t loaded_bytes = 0;  ///< a loaded file's size

  template <int R>
  std::pair<vec3d, double> input_bounds(const rho_grid<R>& g) const {
    return {g.input_centre(), g.input_radius()};  // recorded at build: frames like the input
  }
  /// The cells of every level (their points; the grid's Hierarchy view by attributes).
  template <int R>
  levelled_points points_by_level(const rho_grid<R>& g, const std::string& name, bool snap) const {
    return with_rho_grid_hierarchy(
        g, [&](const auto& h) { return collect_levelled_points(h, input_bounds(g), name, snap); });
  }
  template <int R>
  frame draw(const rho_grid<R>& g, const frame_request& r) const {
    const view v(r.cam, g.origin());
    render_options o = lod_render_options(r.view, g.has_colours() || g.has_materials());
    o.fx.shading = o.fx.shading && g.has_normals();
    const bool one_pass = o.fx.shadows && g.has_normals();
    const traverse_options t{.tolerance_px = r.tolerance};
    frame f = with_rho_grid_hierarchy(g, [&](const auto& h) {
      constexpr attributes A = std::decay_t<decltype(h)>::attrs;
      if constexpr (A.normal) {
        if (one_pass && !r.host) {
          const auto order = rho_grid_light_order<R>(o.sun.direction.normalized());
          // The policy's tables are for the view the frame is drawn in: supersampled, the k×
          // view, which render_one_pass_shadows traverses with k × the tolerance.
          const supersampled_cut cut(v, t, o.supersample);
          const view& dv = cut.drawn;
          const traverse_options& tk = cut.options;
          // Light-map positions from §4.2's displacement table; occluders outside the frame
          // still cast into it (§4.2 with culling).
          rho_grid_light_policy<R> p(g, dv, one_pass_light_frame(h, o), &order);
          p.cast_shadows(g, dv, o.sun.direction.normalized(),
                         rho_grid_caster_side(g, o.shadow_map_size));
          frame one;
          one.fx = o.fx;
          const auto t0 = clock_type::now();
          one.img = render_one_pass_shadows(h, v, o, t, p, &one.st);
          one.seconds = seconds_since(t0);
          if (r.time_traversal) one.traverse_seconds = traversal_seconds(h, dv, tk, p);
          collect_samples(one, h, dv, tk, p, r, g.origin());
          return one;
        }
      }
      const auto policy = [&](const view& pv) { return rho_grid_policy<R>(g, pv); };
      return draw_frame(h, v, o, t, policy, r, g.origin());
    });
    f.extra.boolean("one_pass_shadows", one_pass);
    return f;
  }
  template <int R>
  json stats(const rho_grid<R>& g, const std::string& path) const {
    json j = grid_stats_json(g, path);
    if (!layout_name.empty()) j.str("layout", layout_name);
    return j;
  }
  template <int R>
  void save(const rho_grid<R>& g, const std::string& path) const {
    g.save(path, layout);
  }
  template <int R>
  std::size_t file_bytes(const rho_grid<R>& g) const {
    return loaded_bytes ? loaded_bytes : g.serialise(layout).size();
  }
  template <int R>
  std::size_t samples(const rho_grid<R>& g) const {
    return g.stats().samples;
  }
};

std::unique_ptr<lod> build(const std::vector<std::string>& items, const build_input& in,
                           bool on_terminal) {
  for (const std::string& p : items)
    if (p.starts_with("depth="))
      throw InvalidArgument(
          "rho-grid: --param depth=N was renamed: use --param level=N-1 (the paper's level; "
          "oct/7 is rho=2 level=7, a 256^3 grid)");
  params m(items);
  const int rho = static_cast<int>(m.integer("rho", 3, 2, 5));
  rho_grid_options o;
  // No level given: rho_grid_options' default (rho_grid_auto_level: from ρ for a mesh, no finer
  // than the sampling for a point cloud).
  if (const long level = m.integer("level", -1, 0, 39); level >= 0) o.level = int(level);
  o.normal_bits = static_cast<int>(m.integer("normal_bits", 13, 0, 16));
  o.material_bits = static_cast<int>(m.integer("material_bits", 3, 0, 8));
  o.colour_bits = static_cast<int>(m.integer("colour_bits", 16, 0, 16));
  o.knn = static_cast<int>(m.integer("knn", 16, 0, 256));
  o.threads = static_cast<unsigned>(m.integer("threads", 0, 0, 256));
  rho_method method;
  method.layout_name = m.choice("layout", "is", {"is", "nis", "compressed"});
  method.layout = method.layout_name == "is"    ? rho_grid_layout::is
                  : method.layout_name == "nis" ? rho_grid_layout::nis
                                                : rho_grid_layout::compressed;
  m.finish("rho-grid", "rho, level, normal_bits, material_bits, colour_bits, knn, threads, layout");
  o.progress = progress_callback("rho-grid", on_terminal);
  const loaded_input& li = in.get();
  return visit_rho(rho, [&]<int R>() {
    return make_lod(method, li.is_mesh() ? build_rho_grid<R>(li.mesh, o)
                                         : build_rho_grid<R>(li.mesh.vertices, o));
  });
}

std::unique_ptr<lod> load(const std::string& path) {
  return visit_rho(rho_grid_file_rho(path), [&]<int R>() -> std::unique_ptr<lod> {
    rho_method method;
    method.loaded_bytes = std::filesystem::file_size(path);
    return make_lod(method, rho_grid<R>::load(path));
  });
}

}  // namespace

method_entry rho_grid_method() {
  return {.name = "rho-grid",
          .paper = "Duguet & Drettakis 2004",
          .magic = "PBRLODRG",
          .dir_magic = {},
          .builds_from_mesh = true,
          .build = &build,
          .load = &load,
          .demo_tolerances = {8, 3, 1},
          .tolerance_means =
              "s, the splat size in pixels: a cell whose projection fits in s is "
              "drawn as one s x s splat (§4.1)"};
}

}  // namespace pbrlod_tool
