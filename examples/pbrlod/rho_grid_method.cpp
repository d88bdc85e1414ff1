// pbrlod — ρ-grid packed point trees (Duguet & Drettakis 2004): build, render and stats.
#include <iostream>
#include <limits>

#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/builders/rho_grid_hierarchy.hpp"
#include "pbr_lod/raster/one_pass_shadows.hpp"
#include "pbr_lod/raster/png.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "tool.hpp"

namespace pbrlod_tool {
namespace {

template <int R>
json grid_stats_json(const rho_grid<R>& g, const std::string& path) {
  const auto& st = g.stats();
  json j;
  j.str("file", path).str("method", "rho-grid");
  j.integer("rho", R).integer("level", g.level()).integer("sigma", g.sigma());
  j.integer("normal_bits", g.normal_bits()).integer("material_bits", g.material_bits());
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
  return j;
}

int build(const build_request& r) {
  for (const std::string& p : r.params)
    if (p.starts_with("depth="))
      throw InvalidArgument(
          "rho-grid: --param depth=N was renamed: use --param level=N-1 (the paper's level; "
          "oct/7 is rho=2 level=7, a 256^3 grid)");
  params m(r.params);
  const int rho = static_cast<int>(m.integer("rho", 3, 2, 5));
  rho_grid_options o;
  o.level = static_cast<int>(m.integer("level", 5, 0, 39));
  o.normal_bits = static_cast<int>(m.integer("normal_bits", 13, 0, 16));
  o.material_bits = static_cast<int>(m.integer("material_bits", 3, 0, 8));
  o.threads = static_cast<unsigned>(m.integer("threads", 0, 0, 256));
  const std::string layout_name = m.choice("layout", "is", {"is", "nis", "compressed"});
  const auto layout = layout_name == "is"    ? rho_grid_layout::is
                      : layout_name == "nis" ? rho_grid_layout::nis
                                             : rho_grid_layout::compressed;
  m.finish("rho-grid", "rho, level, normal_bits, material_bits, threads, layout");
  o.progress = progress_callback("rho-grid", interactive(r.as_json));
  const loaded_input in = load(r.input);
  return visit_rho(rho, [&]<int R>() {
    const auto g =
        in.is_mesh() ? build_rho_grid<R>(in.mesh, o) : build_rho_grid<R>(in.mesh.vertices, o);
    g.save(r.output, layout);
    json j = grid_stats_json(g, r.output);
    j.str("layout", layout_name);
    std::cout << (r.as_json ? "" : "wrote " + r.output + ": ") << j.text() << "\n";
    return 0;
  });
}

/// One frame of g through the common traversal with the §4.1 policy (s = the tolerance); with
/// shadows and normals, the paper's one-pass shadows (§4.2): children front to back from the
/// light, shaded through raster/one_pass_shadows.hpp.
template <int R>
image draw_grid(const rho_grid<R>& g, const view& v, const render_options& o, float tolerance,
                bool one_pass, traverse_stats& st) {
  const traverse_options t{.tolerance_px = tolerance};
  return with_rho_grid_hierarchy(g, [&](const auto& h) {
    constexpr attributes A = std::decay_t<decltype(h)>::attrs;
    if constexpr (A.normal) {
      if (one_pass) {
        const auto order = rho_grid_light_order<R>(o.sun.direction.normalized());
        return render_one_pass_shadows(h, v, o, t, rho_grid_policy<R>(g, v, &order), &st);
      }
    }
    return render<A>(v, o,
                     [&](auto& sink) { st = traverse(h, v, t, sink, rho_grid_policy<R>(g, v)); });
  });
}

int render_lod(const render_request& r) {
  return visit_rho(rho_grid_file_rho(r.input), [&]<int R>() {
    const auto g = rho_grid<R>::load(r.input);
    // Framed like the input: the grid records the input's bounding sphere.
    const camera cam = make_camera(g.input_centre(), g.input_radius(), r.view);
    const view v(cam, g.origin());
    render_options o = lod_render_options(r.view, g.has_materials());
    o.fx.shading = o.fx.shading && g.has_normals();
    const bool one_pass = o.fx.shadows && g.has_normals();
    traverse_stats st;
    const auto t0 = clock_type::now();
    const image img = draw_grid(g, v, o, r.tolerance, one_pass, st);
    const double frame_s = seconds_since(t0);
    write_png(r.output, img);
    // splats: inner cells drawn at s pixels (the splat condition of §4.1); points: leaves.
    if (r.as_json) {
      json j;
      j.str("input", r.input).str("output", r.output).str("method", "rho-grid");
      j.num("tolerance_px", r.tolerance).str("effects", o.fx.to_string());
      j.boolean("one_pass_shadows", one_pass);
      j.integer("width", img.width).integer("height", img.height);
      j.integer("cells_visited", static_cast<long long>(st.visited));
      j.integer("culled", static_cast<long long>(st.culled_frustum));
      j.integer("splats", static_cast<long long>(st.emitted_nodes));
      j.integer("points", static_cast<long long>(st.emitted_leaves));
      j.num("frame_seconds", frame_s);
      std::cout << j.text() << "\n";
    } else {
      std::cout << "wrote " << r.output << ": " << st.emitted_nodes << " splats and "
                << st.emitted_leaves << " points at s = " << r.tolerance << " px (" << frame_s
                << " s)\n";
    }
    return 0;
  });
}

int stats(const std::string& path, bool as_json) {
  return visit_rho(rho_grid_file_rho(path), [&]<int R>() {
    const auto g = rho_grid<R>::load(path);
    const json j = grid_stats_json(g, path);
    std::cout << (as_json ? "" : path + ": ") << j.text() << "\n";
    return 0;
  });
}

}  // namespace

method_entry rho_grid_method() {
  return {"rho-grid", "Duguet & Drettakis 2004", "PBRLODRG", &build, &render_lod, &stats};
}

}  // namespace pbrlod_tool
