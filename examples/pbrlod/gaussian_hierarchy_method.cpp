// pbrlod — hierarchies of 3-D Gaussians (Kerbl et al. 2024): build, render and stats.
#include <chrono>

#include "lod.hpp"
#include "pbr_lod/builders/chunked_gaussian_hierarchy.hpp"
#include "pbr_lod/builders/gaussian_hierarchy.hpp"
#include "pbr_lod/core/gaussian_source.hpp"
#include "pbr_lod/core/gaussian_splats.hpp"
#include "pbr_lod/io/gaussians.hpp"
#include "pbr_lod/raster/gaussians.hpp"

namespace pbrlod_tool {
namespace {

json gaussian_stats_json(const gaussian_hierarchy& h, const std::string& path) {
  json j;
  j.str("file", path).str("method", "gaussian-hierarchy");
  j.integer("gaussians", static_cast<long long>(h.store().size()));
  j.integer("input_gaussians", static_cast<long long>(h.input_gaussians()));
  j.integer("inner_gaussians", static_cast<long long>(h.inner_gaussians()));
  j.integer("nodes", static_cast<long long>(h.nodes().size()));
  j.integer("depth", static_cast<long long>(h.depth()));
  j.integer("sh_degree", h.store().sh_degree);
  j.integer("file_bytes", static_cast<long long>(h.file_bytes()));
  j.num("bytes_per_gaussian",
        h.input_gaussians() == 0
            ? 0.0
            : static_cast<double>(h.file_bytes()) / static_cast<double>(h.input_gaussians()));
  return j;
}

/// The cut sent to a host renderer as Gaussians (gl_viewer draws them as sorted quads; a host
/// without gaussian() gets their splats). The hierarchy emits nothing else; its attributes are
/// the host's.
template <class H>
frame host_gaussians(const H& h, const view& v, const render_options& o, const traverse_options& t,
                     float lowpass, host_sink& host) {
  static_assert(gaussian_hierarchy::attrs == host_attributes);
  struct to_host {
    host_sink& out;
    void point(const point_prim<host_attributes>& p) { out.point(p); }
    void splat(const splat_prim<host_attributes>& s) { out.splat(s); }
    void triangle(const triangle_prim<host_attributes>& q) { out.triangle(q); }
    void gaussian(const gaussian_prim& g) { out.gaussian(g); }
  } sink{host};
  frame f;
  render_options ho = o;
  ho.fx = effects{.colour = true};
  f.fx = ho.fx;
  const auto t0 = clock_type::now();
  host.begin(v, ho, gaussian_hierarchy::attrs);
  f.st = traverse(h, v, t, sink, gaussian_policy{.merged_lowpass_px2 = lowpass});
  f.seconds = seconds_since(t0);
  f.extra.integer("gaussians", static_cast<long long>(f.st.gaussians));
  return f;
}

/// Draws the cut of Kerbl et al. 2024 §4.2 (gaussian_policy) with the Gaussian rasteriser
/// (raster/gaussians.hpp): EWA splatting, sorted, composited front to back. The effects list's
/// shading, shadows and hole filling do not apply to Gaussians (their colour is their own);
/// a host renderer gets the Gaussians (host_gaussians).
struct gaussian_method_traits {
  std::pair<vec3d, double> input_bounds(const gaussian_hierarchy& h) const {
    std::size_t n = h.input_gaussians();
    const auto& p = h.store().positions;
    return bounds_of(h.origin(), std::span<const vec3f>(p.data(), n));
  }
  template <class H>
  frame draw(const H& h, const frame_request& r) const {
    const view v(r.cam, h.origin());
    const render_options o = lod_render_options(r.view, true);
    const traverse_options t{.tolerance_px = r.tolerance};
    if (r.host) return host_gaussians(h, v, o, t, r.view.merged_lowpass, *r.host);
    frame f;
    f.fx = effects{.colour = true};
    const auto t0 = clock_type::now();
    gaussian_render_options go;
    go.background = o.background;
    gaussian_rasterizer raster(v, go);
    const gaussian_policy policy{.merged_lowpass_px2 = r.view.merged_lowpass};
    f.st = traverse(h, v, t, raster, policy);
    f.img = raster.finish();
    f.seconds = seconds_since(t0);
    if (r.time_traversal) f.traverse_seconds = traversal_seconds(h, v, t, policy);
    collect_samples(f, h, v, t, policy, r, h.origin());
    f.extra.integer("gaussians", static_cast<long long>(f.st.gaussians));
    return f;
  }
  json stats(const gaussian_hierarchy& h, const std::string& path) const {
    return gaussian_stats_json(h, path);
  }
  std::size_t samples(const gaussian_hierarchy& h) const { return h.input_gaussians(); }
};

/// A chunked Gaussian hierarchy folder (build_gaussian_hierarchy_chunked): framed by the input
/// sphere its top file records (the in-memory build's frame), drawn like a gaussian_hierarchy,
/// its chunks read as the views need them.
struct chunked_gaussian_traits : chunked_folder, gaussian_method_traits {
  using gaussian_method_traits::draw;
  std::pair<vec3d, double> input_bounds(const chunked_gaussian_hierarchy& h) const {
    return {h.origin() + h.input_sphere().centre.cast<double>(),
            static_cast<double>(h.input_sphere().radius)};
  }
  frame draw(const chunked_gaussian_hierarchy& h, const frame_request& r) const {
    frame f = gaussian_method_traits::draw(h, r);
    f.extra.integer("chunks_read", static_cast<long long>(h.chunks_loaded()));
    return f;
  }
  json stats(const chunked_gaussian_hierarchy& h, const std::string& path) const {
    json j;
    j.str("file", path).str("method", "gaussian-hierarchy").boolean("chunked", true);
    j.integer("gaussians", static_cast<long long>(h.stored_gaussians()));
    j.integer("input_gaussians", static_cast<long long>(h.input_gaussians()));
    j.integer("inner_gaussians",
              static_cast<long long>(h.stored_gaussians() - h.input_gaussians()));
    j.integer("nodes", static_cast<long long>(h.node_count()));
    j.integer("chunks", static_cast<long long>(h.chunk_count()));
    j.integer("top_nodes", static_cast<long long>(h.top_node_count()));
    j.integer("sh_degree", h.sh_degree());
    j.integer("file_bytes", static_cast<long long>(h.file_bytes()));
    j.num("bytes_per_gaussian",
          static_cast<double>(h.file_bytes()) / static_cast<double>(h.input_gaussians()));
    return j;
  }
  std::size_t samples(const chunked_gaussian_hierarchy& h) const {
    return static_cast<std::size_t>(h.input_gaussians());
  }
  using chunked_folder::file_bytes;
  using chunked_folder::save;
};

/// The in-memory build's parameters (a chunked build's too).
gaussian_hierarchy_options gaussian_options(params& m) {
  gaussian_hierarchy_options o;
  o.leaf_size = static_cast<int>(m.integer("leaf_size", o.leaf_size, 1, 64));
  o.threads = static_cast<unsigned>(m.integer("threads", 0, 0, 256));
  o.opacity = m.choice("merge", "grow", {"grow", "conserve"}) == "conserve"
                  ? merged_opacity::conserve
                  : merged_opacity::grow;
  return o;
}

std::unique_ptr<lod> build(const std::vector<std::string>& items, const build_input& in,
                           bool /*on_terminal*/) {
  params m(items);
  const gaussian_hierarchy_options o = gaussian_options(m);
  const auto opacity = static_cast<float>(m.number("opacity", 1.0, 0.0, 1.0));
  m.finish("gaussian-hierarchy", "leaf_size, threads, opacity, merge");
  // A Gaussian scene as it is; a mesh or a scan as flat Gaussians on its splats.
  const loaded_input& input = in.get();
  const gaussian_cloud g =
      input.is_gaussians() ? input.gaussians : gaussians_of_surface(input.mesh, opacity, o.threads);
  if (g.empty()) throw InvalidArgument(in.name() + ": no Gaussians to build from");
  gaussian_hierarchy_stats st;
  return make_lod(gaussian_method_traits{}, build_gaussian_hierarchy(g, o, &st));
}

std::unique_ptr<lod> load(const std::string& path) {
  if (is_chunked_gaussian_hierarchy(path))
    return make_lod(chunked_gaussian_traits{}, chunked_gaussian_hierarchy::open(path));
  return make_lod(gaussian_method_traits{}, gaussian_hierarchy::load(path));
}

/// `--param memory=SIZE` (or chunk_points=N): out of core from a 3DGS .ply / .splat read by rows
/// (io/gaussians.hpp; a .spz or an ASCII PLY is read whole) or generated-gaussians:N made block
/// by block; a mesh or a scan is made into Gaussians in memory, so it has no chunked build.
std::unique_ptr<lod> build_chunked(const std::vector<std::string>& items, const std::string& input,
                                   const std::string& output, bool /*on_terminal*/, json& report,
                                   const distributed_rank* part) {
  params m(items);
  chunked_gaussian_hierarchy_options o;
  o.builder = gaussian_options(m);
  chunked_params(m, o);
  m.finish("gaussian-hierarchy", "leaf_size, threads, merge, memory, chunk_points");
  if (part) o.distributed = {part->rank, part->ranks, part->barrier};
  std::unique_ptr<gaussian_source> src;
  const std::string gen = "generated-gaussians:";
  if (input.rfind(gen, 0) == 0)
    src = std::make_unique<generated_gaussian_source>(generated_count(input, gen));
  else if (is_gaussian_file(input))
    src = open_gaussian_source(input);
  else
    throw InvalidArgument(input +
                          ": a chunked gaussian-hierarchy build (memory=, chunk_points=) reads a "
                          "3DGS .ply, .splat or .spz, or generated-gaussians:N");
  chunked_report_json(build_gaussian_hierarchy_chunked(*src, output, o), report);
  return load(output);
}

}  // namespace

method_entry gaussian_hierarchy_method() {
  return {.name = "gaussian-hierarchy",
          .paper = "Kerbl et al. 2024",
          .magic = "PBRLODGH",
          .dir_magic = "PBRLODGC",
          .builds_from_mesh = true,
          .build = &build,
          .load = &load,
          .build_chunked = &build_chunked,
          .demo_tolerances = {8, 3, 1},
          .tolerance_means =
              "pixels: a node is drawn once twice the projected radius of its "
              "largest standard deviation is at most this (§4.2)"};
}

}  // namespace pbrlod_tool
