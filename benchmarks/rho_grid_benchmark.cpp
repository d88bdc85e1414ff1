// ρ-grid (Duguet & Drettakis 2004) benchmarks: the storage study of Table 2 (bits per leaf
// sample of the NIS and IS streams and of the in-core structure) on the Stanford bunny and
// Buddha at oct/7, tri/4, oct/10, tri/6 (the paper's levels, σ = 16); build time and peak memory
// (tri/6 on the bunny);
// flexible rendering in float and fixed point (§4.1, §5.1), cells drawn from the traversal's
// tables as screen rectangles (§5.1, §4.1); one-pass shadows against the
// rasteriser's two-pass shadow map (§4.2); beyond the paper, the entropy-coded layout (bits per
// sample of the coded geometry and attributes, encode and decode time, the context choices).
// docs/rho-grid.md quotes these numbers.
//
// Run with --benchmark_repetitions=3 --benchmark_report_aggregates_only=true for medians.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <map>
#include <string>
#include <tuple>

#include "pbr_lod/builders/detail/rho_grid_coder.hpp"
#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/builders/rho_grid_policy.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/one_pass_shadows.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/raster/reference.hpp"
#include "support/data.hpp"

namespace {
using namespace pbr_lod;

const triangle_mesh& model(const std::string& name) {
  static std::map<std::string, triangle_mesh> cache;
  auto it = cache.find(name);
  if (it == cache.end()) it = cache.emplace(name, read_mesh(test::data_file(name))).first;
  return it->second;
}

const char* model_name(int i) {
  return i == 0 ? "bun_zipper.ply" : "happy_vrip_res3.ply";
}

double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / 1024.0;  // kB on Linux
}

template <int Rho>
void report(benchmark::State& state, const rho_grid<Rho>& g) {
  const auto& s = g.stats();
  state.counters["samples"] = double(s.samples);
  state.counters["inner"] = double(s.inner_cells);
  state.counters["inner/leaf"] = double(s.inner_cells) / double(s.samples);
  state.counters["eq1_inner/leaf"] = 1.0 / (Rho * Rho - 1);
  state.counters["bps_nis"] = s.bits_per_sample_nis;
  state.counters["bps_is"] = s.bits_per_sample_is;
  state.counters["bps_incore"] = s.bits_per_sample_incore;
  state.counters["kB_nis"] = double(g.serialise(rho_grid_layout::nis).size()) / 1e3;
  state.counters["kB_is"] = double(g.serialise(rho_grid_layout::is).size()) / 1e3;
  state.counters["kB_mem"] = double(g.memory_bytes()) / 1e3;
  state.counters["build_s"] = s.build_seconds;
  state.counters["working_MB"] = double(s.peak_working_bytes) / 1e6;
  state.counters["peak_rss_MB"] = peak_rss_mb();
}

// Table 2 as the paper measures it: σ = 16 (13-bit normal + 3-bit material index) at the
// paper's levels — oct/7 and tri/4 are 256³ and 243³ grids, oct/10 and tri/6 2048³ and 2187³.
// Our scans have no materials, so every vertex gets material 0: the 3 bits are stored (bits per
// sample depend on σ, not on the values). The Buddha rows carry the paper's Buddha row
// (paper_*); every row carries Eq. 4's prediction (eq4_*: NIS ρ³/(ρ²−1) + σ, IS (ρ³+σ)/(ρ²−1) + σ).
struct paper_row {
  int rho, level;
  double samples, nis, is, mem;
};
constexpr paper_row paper_buddha[] = {{2, 7, 125283, 18.6, 23.9, 37.00},
                                      {3, 4, 112924, 19.2, 21.1, 27.40},
                                      {2, 10, 7286757, 18.8, 24.5, 38.76},
                                      {3, 6, 8242567, 19.7, 21.8, 29.04}};

const triangle_mesh& model_sigma16(int i) {
  static std::map<int, triangle_mesh> cache;
  auto it = cache.find(i);
  if (it == cache.end()) {
    triangle_mesh m = model(model_name(i));
    m.vertices.materials.assign(m.vertices.size(), 0);
    it = cache.emplace(i, std::move(m)).first;
  }
  return it->second;
}

template <int Rho>
void bm_table2(benchmark::State& state) {
  const int model_index = int(state.range(0)), level = int(state.range(1));
  const auto& m = model_sigma16(model_index);
  rho_grid<Rho> g;
  for (auto _ : state) {
    g = build_rho_grid<Rho>(m,
                            {.level = level, .normal_bits = 13, .material_bits = 3, .threads = 2});
    benchmark::DoNotOptimize(g.cell_count());
  }
  report(state, g);
  const double r3 = Rho * Rho * Rho, r2m1 = Rho * Rho - 1, sigma = g.sigma();
  state.counters["sigma"] = sigma;
  state.counters["eq4_nis"] = r3 / r2m1 + sigma;
  state.counters["eq4_is"] = (r3 + sigma) / r2m1 + sigma;
  for (const auto& p : paper_buddha)
    if (model_index == 1 && p.rho == Rho && p.level == level) {
      state.counters["paper_samples"] = p.samples;
      state.counters["paper_nis"] = p.nis;
      state.counters["paper_is"] = p.is;
      state.counters["paper_mem"] = p.mem;
    }
}
BENCHMARK(bm_table2<2>)
    ->ArgNames({"model", "level"})
    ->Args({0, 7})
    ->Args({1, 7})
    ->Args({0, 10})
    ->Args({1, 10})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);
BENCHMARK(bm_table2<3>)
    ->ArgNames({"model", "level"})
    ->Args({0, 4})
    ->Args({1, 4})
    ->Args({0, 6})
    ->Args({1, 6})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);
// ρ = 4 and 5 (Table 1's cheaper grids): level 4 of ρ = 4 is a 1024³ grid, level 3 of ρ = 5 a
// 625³ grid.
BENCHMARK(bm_table2<4>)
    ->ArgNames({"model", "level"})
    ->Args({0, 4})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);
BENCHMARK(bm_table2<5>)
    ->ArgNames({"model", "level"})
    ->Args({0, 3})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);

// The memory question: the tri-grid at level 6 (2187³) on the bunny (run alone for a clean
// peak RSS:
// --benchmark_filter=bm_tri6_bunny_rss).
void bm_tri6_bunny_rss(benchmark::State& state) {
  const auto& m = model("bun_zipper.ply");
  const double before = peak_rss_mb();
  rho_grid<3> g;
  for (auto _ : state) g = build_rho_grid<3>(m, {.level = 6, .threads = 2});
  report(state, g);
  state.counters["rss_before_MB"] = before;
}
BENCHMARK(bm_tri6_bunny_rss)->Unit(benchmark::kMillisecond)->Iterations(1);

// Built grids shared by the coding benchmarks (the build is not what they time).
template <int Rho>
const rho_grid<Rho>& cached_grid(int model_index, int level) {
  static std::map<std::tuple<int, int>, rho_grid<Rho>> cache;
  const auto key = std::make_tuple(model_index, level);
  auto it = cache.find(key);
  if (it == cache.end())
    it = cache
             .emplace(key, build_rho_grid<Rho>(model(model_name(model_index)),
                                               {.level = level, .threads = 2}))
             .first;
  return it->second;
}

// Beyond the paper: the compressed layout, one level below the Table 2 levels (σ = 13: the
// scans' normals only). The loop times the encode
// (serialise(compressed): both streams, header, checksum); decode_ms is the median of 3 parses
// (decode + validation + the in-core structure). Sizes are the real stream byte counts.
template <int Rho>
void bm_coded(benchmark::State& state) {
  const auto& g = cached_grid<Rho>(int(state.range(0)), int(state.range(1)));
  std::vector<unsigned char> bytes;
  for (auto _ : state) {
    bytes = g.serialise(rho_grid_layout::compressed);
    benchmark::DoNotOptimize(bytes.data());
  }
  std::vector<double> dec;
  for (int i = 0; i < 3; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    const auto back = rho_grid<Rho>::parse(bytes);
    dec.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    if (!(back == g)) state.SkipWithError("compressed round trip differs");
  }
  std::sort(dec.begin(), dec.end());
  const auto cs = g.coded_size();
  const double n = double(g.leaf_count());
  state.counters["samples"] = n;
  state.counters["bps_geo"] = cs.bits_per_sample_geometry;
  state.counters["bps_attr"] = cs.bits_per_sample_attributes;
  state.counters["bps_file"] = double(cs.file_bytes) * 8 / n;
  state.counters["bps_nis"] = g.stats().bits_per_sample_nis;
  state.counters["bps_is"] = g.stats().bits_per_sample_is;
  state.counters["kB_coded"] = double(cs.file_bytes) / 1e3;
  state.counters["decode_ms"] = dec[1];
  state.counters["enc_samples/s"] =
      benchmark::Counter(n * double(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["dec_samples/s"] = n / (dec[1] / 1e3);
}
BENCHMARK(bm_coded<2>)
    ->ArgNames({"model", "level"})
    ->Args({0, 6})
    ->Args({1, 6})
    ->Args({0, 9})
    ->Args({1, 9})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(bm_coded<3>)
    ->ArgNames({"model", "level"})
    ->Args({0, 3})
    ->Args({1, 3})
    ->Args({0, 5})
    ->Args({1, 5})
    ->Unit(benchmark::kMillisecond);

// Colours as a sample attribute (§3.1: "we need more bits if we have more materials or
// colors"): bits per leaf sample of the NIS, IS, in-core and compressed forms with colour_bits
// = 0 (no colour), 8 (3:3:2), 12 (4:4:4) and 16 (5:6:5), on the coloured generated scenes
// (0: the demo scene, detail 64; 1: the hard-cases scene, detail 48) at tri/4 and tri/5. The
// raw forms grow by exactly colour_bits per cell (IS, in core: 16 bits per cell whatever
// colour_bits), the coded one by what the parent prediction leaves.
void bm_colour_storage(benchmark::State& state) {
  static const triangle_mesh scenes[2] = {make_demo_scene(64), make_hard_cases_scene(48)};
  const triangle_mesh& m = scenes[state.range(0)];
  const int level = int(state.range(1)), bits = int(state.range(2));
  rho_grid<3> g;
  for (auto _ : state) {
    g = build_rho_grid<3>(m, {.level = level, .colour_bits = bits, .threads = 2});
    benchmark::DoNotOptimize(g.cell_count());
  }
  const auto cs = g.coded_size();
  const double n = double(g.leaf_count());
  state.counters["samples"] = n;
  state.counters["sigma"] = g.sigma();
  state.counters["bps_nis"] = g.stats().bits_per_sample_nis;
  state.counters["bps_is"] = g.stats().bits_per_sample_is;
  state.counters["bps_incore"] = g.stats().bits_per_sample_incore;
  state.counters["bps_coded_attr"] = cs.bits_per_sample_attributes;
  state.counters["bps_coded_file"] = double(cs.file_bytes) * 8 / n;
}
BENCHMARK(bm_colour_storage)
    ->ArgNames({"scene", "level", "colour_bits"})
    ->ArgsProduct({{0, 1}, {4, 5}, {0, 8, 12, 16}})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);

// The context choices of the coder: geometry context model (0 level+child, 1 + parent's face
// neighbours, 2 + child-level neighbours) × attribute predictor (0 parent, 1 previous sibling).
template <int Rho>
void bm_coder_contexts(benchmark::State& state) {
  const auto& g = cached_grid<Rho>(int(state.range(0)), int(state.range(1)));
  const detail::rho_coder_options o{
      .geometry = detail::rho_geometry_context(std::uint32_t(state.range(2))),
      .attributes = detail::rho_attribute_predictor(std::uint32_t(state.range(3)))};
  detail::rho_coded_streams s;
  for (auto _ : state) {
    s = detail::rho_grid_encode(g, o);
    benchmark::DoNotOptimize(s.geometry.data());
  }
  const double n = double(g.leaf_count());
  state.counters["bps_geo"] = double(s.geometry.size()) * 8 / n;
  state.counters["bps_attr"] = double(s.attributes.size()) * 8 / n;
}
BENCHMARK(bm_coder_contexts<2>)
    ->ArgNames({"model", "level", "geo", "attr"})
    ->ArgsProduct({{0, 1}, {6}, {0, 1, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(bm_coder_contexts<3>)
    ->ArgNames({"model", "level", "geo", "attr"})
    ->ArgsProduct({{0, 1}, {3}, {0, 1, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// Point cloud input: the bunny's vertices.
void bm_points(benchmark::State& state) {
  const point_cloud pc = read_points(test::data_file("bun_zipper.ply"));
  rho_grid<3> g;
  for (auto _ : state) g = build_rho_grid<3>(pc, {.level = int(state.range(0))});
  report(state, g);
  state.counters["points/s"] = benchmark::Counter(double(pc.size()) * double(state.iterations()),
                                                  benchmark::Counter::kIsRate);
}
BENCHMARK(bm_points)->Arg(3)->Arg(5)->Unit(benchmark::kMillisecond);

const rho_grid<3>& bunny_tri5() {
  static const rho_grid<3> g = build_rho_grid<3>(model("bun_zipper.ply"), {.level = 5});
  return g;
}

camera bench_camera(const rho_grid<3>& g, double dist, int size = 512) {
  const vec3d c = g.origin() + vec3d::Constant(0.5 * g.cube_side());
  return camera::orbit(c, 0.5 * g.cube_side(), 30, 20, dist, 1, {size, size});
}

// §4.1 / §5.1: the flexible traversal (the common traverse with rho_grid_policy) in float (0),
// int64 fixed point (1) and the paper's 32-bit fixed point with the reciprocal table (2), splat
// size s. prims = 0: the traversal's decisions alone (the policy's emit only counts
// the cells, what Render() costs without drawing); prims = 1: the cells' points (centre,
// positions only) sent to a counting sink, what a renderer gets.
template <rho_grid_arithmetic Ar>
struct counting_rho_policy : rho_grid_policy<3, Ar> {
  std::size_t* cells = nullptr;
  template <class H, class S>
  void emit(const H&, const rho_grid_cell&, const view&, float, const traverse_options&, S&) const {
    ++*cells;
  }
};
template <rho_grid_arithmetic Ar>
traverse_stats traverse_once(const rho_grid<3>& g, const view& v, float s, bool prims) {
  const rho_grid_hierarchy<3, positions_only> h(g);
  counting_sink<positions_only> sink;
  const traverse_options o{.tolerance_px = s};
  if (prims) {
    const auto st = traverse(h, v, o, sink, rho_grid_policy<3, Ar>(g, v));
    benchmark::DoNotOptimize(sink.points);
    return st;
  }
  std::size_t cells = 0;
  const auto st =
      traverse(h, v, o, sink, counting_rho_policy<Ar>{rho_grid_policy<3, Ar>(g, v), &cells});
  benchmark::DoNotOptimize(cells);
  return st;
}
void bm_traverse(benchmark::State& state) {
  const auto& g = bunny_tri5();
  const view v(bench_camera(g, double(state.range(2)) / 10), g.origin());
  const auto s = float(state.range(1));
  const bool prims = state.range(3) != 0;
  traverse_stats st;
  for (auto _ : state)
    st = state.range(0) == 2   ? traverse_once<rho_grid_arithmetic::fixed32>(g, v, s, prims)
         : state.range(0) == 1 ? traverse_once<rho_grid_arithmetic::fixed>(g, v, s, prims)
                               : traverse_once<rho_grid_arithmetic::floating>(g, v, s, prims);
  state.counters["visited"] = double(st.visited);
  state.counters["splats"] = double(st.emitted_nodes);
  state.counters["points"] = double(st.emitted_leaves);
  state.counters["cells/s"] = benchmark::Counter(double(st.visited) * double(state.iterations()),
                                                 benchmark::Counter::kIsRate);
}
BENCHMARK(bm_traverse)
    ->ArgNames({"arith", "s", "dist10", "prims"})
    ->ArgsProduct({{0, 1, 2}, {1}, {25, 80}, {0}})
    ->ArgsProduct({{0, 1, 2}, {4}, {25}, {0}})
    ->ArgsProduct({{0, 1, 2}, {1}, {25}, {1}})
    ->Unit(benchmark::kMillisecond);

/// One frame of g through the shared rasteriser: with the one-pass shadows of §4.2 when `order`
/// (the light's child order) is given and g has normals — light-map positions from §4.2's light
/// displacement table when `light_table`, else projected per drawn cell — else the traversal
/// with policy p.
template <class H, rho_grid_arithmetic Ar>
image rho_frame(const H& h, const rho_grid<3>& g, const view& v, const render_options& o,
                const traverse_options& t, const std::array<int, 27>* order,
                const rho_grid_policy<3, Ar>& p, traverse_stats& st, bool light_table = false) {
  constexpr attributes A = H::attrs;
  if constexpr (A.normal) {
    if (order && light_table)
      return render_one_pass_shadows(
          h, v, o, t, rho_grid_light_policy<3, Ar>(g, v, one_pass_light_frame(h, o), order), &st);
    if (order) return render_one_pass_shadows(h, v, o, t, rho_grid_policy<3, Ar>(g, v, order), &st);
  }
  return render<A>(v, o, [&](auto& sink) { st = traverse(h, v, t, sink, p); });
}

// Whole frames (512², shading) into the shared rasteriser: no shadows, one-pass shadows (§4.2)
// with each drawn cell projected into the light map, the rasteriser's two-pass shadow map,
// one-pass shadows with the light displacement table (§4.2).
void bm_frame(benchmark::State& state) {
  const auto& g = bunny_tri5();
  const view v(bench_camera(g, 2.5), g.origin());
  render_options o;
  const int mode = int(state.range(0));
  o.fx = effects{.shading = true, .shadows = mode == 2};
  o.sun.direction = vec3f(-0.6f, 0.7f, 0.3f);
  const traverse_options t{.tolerance_px = 1};
  const auto order = rho_grid_light_order<3>(o.sun.direction.normalized());
  traverse_stats st;
  with_rho_grid_hierarchy(g, [&](const auto& h) {
    for (auto _ : state) {
      const image img = rho_frame(h, g, v, o, t, mode == 1 || mode == 3 ? &order : nullptr,
                                  rho_grid_policy<3>(g, v), st, mode == 3);
      benchmark::DoNotOptimize(img.colour.data());
    }
  });
  state.counters["drawn"] = double(st.emitted_nodes + st.emitted_leaves);
  state.counters["fps"] =
      benchmark::Counter(double(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(bm_frame)
    ->ArgName("mode_0none_1onepass_2twopass_3onepasstable")
    ->DenseRange(0, 3)
    ->Unit(benchmark::kMillisecond);

// §4.2 with frustum culling, a close view (1.2 half sides: the bunny overflows the frame) and a
// light from the side: one-pass shadows with the cells outside the frame culled (0: occluders
// off the frame cast nothing), kept as casters (1: rho_grid_policy::cast_shadows), or without
// culling (2: every cell in front of the eye traversed, the reference). `drawn`: cells emitted
// (off-frame casters included); `psnr_vs_nocull`: the frame against mode 2's.
void bm_off_frame_casters(benchmark::State& state) {
  const auto& g = bunny_tri5();
  const view v(bench_camera(g, 1.2), g.origin());
  render_options o;
  o.fx = effects{.shading = true, .shadows = true};
  o.sun.direction = vec3f(-0.9f, 0.4f, 0.2f);
  const int mode = int(state.range(0));
  const traverse_options t{.tolerance_px = 1, .frustum_cull = mode != 2};
  const auto order = rho_grid_light_order<3>(o.sun.direction.normalized());
  rho_grid_policy<3> p(g, v, &order);
  if (mode == 1)
    p.cast_shadows(g, v, o.sun.direction.normalized(), rho_grid_caster_side(g, o.shadow_map_size));
  traverse_stats st;
  image img, reference;
  with_rho_grid_hierarchy(g, [&](const auto& h) {
    if constexpr (std::decay_t<decltype(h)>::attrs.normal) {
      reference = render_one_pass_shadows(h, v, o, {.tolerance_px = 1, .frustum_cull = false},
                                          rho_grid_policy<3>(g, v, &order));
      for (auto _ : state) {
        img = render_one_pass_shadows(h, v, o, t, p, &st);
        benchmark::DoNotOptimize(img.colour.data());
      }
    }
  });
  state.counters["drawn"] = double(st.emitted_nodes + st.emitted_leaves);
  // PSNR against the frame without culling (60: identical).
  state.counters["psnr_vs_nocull"] = std::min(60.0, compare_images(reference, img).psnr);
}
BENCHMARK(bm_off_frame_casters)
    ->ArgName("mode_0culled_1casters_2nocull")
    ->DenseRange(0, 2)
    ->Unit(benchmark::kMillisecond);

// Table 3's analogue: frames per second of "Points" (every leaf in view as a one-pixel point,
// no multi-level: rho_grid_policy::points_only), "Splats" (the flexible traversal, s = 1 px),
// "Shadows" (flexible + the one-pass shadows of §4.2, each drawn cell projected into the light
// map) and "Shadows + table" (the light positions from §4.2's displacement table), tri-grid levels
// 4 and 5 of the bunny and Buddha res3, at the iPAQ's 240×320, shading on, from a far view (8 half
// sides of the cube from its centre, the model ≈ 110 px tall: Fig. 5's top row) and a close one (3
// half sides, the model fills the screen and level 5's leaves are ≈ 0.4 px). `arith`: the policy's
// arithmetic as in bm_traverse (the paper's iPAQ ran 32-bit fixed point, 2).
const rho_grid<3>& tri_grid(int model_index, int level) {
  static std::map<std::pair<int, int>, rho_grid<3>> cache;
  const auto key = std::pair{model_index, level};
  auto it = cache.find(key);
  if (it == cache.end())
    it = cache.emplace(key, build_rho_grid<3>(model(model_name(model_index)), {.level = level}))
             .first;
  return it->second;
}

/// Frames of g until the benchmark stops, the policy in arithmetic Ar (as in bm_traverse).
template <rho_grid_arithmetic Ar>
void table3_frames(benchmark::State& state, const rho_grid<3>& g, const view& v,
                   const render_options& o, const traverse_options& t,
                   const std::array<int, 27>* order, bool points_only, bool light_table,
                   traverse_stats& st) {
  with_rho_grid_hierarchy(g, [&](const auto& h) {
    for (auto _ : state) {
      rho_grid_policy<3, Ar> p(g, v);
      p.points_only = points_only;
      const image img = rho_frame(h, g, v, o, t, order, p, st, light_table);
      benchmark::DoNotOptimize(img.colour.data());
    }
  });
}

void bm_table3(benchmark::State& state) {
  const int mode = int(state.range(2)), arith = int(state.range(4));
  const double dist = double(state.range(3));
  const auto& g = tri_grid(int(state.range(0)), int(state.range(1)));
  const vec3d c = g.origin() + vec3d::Constant(0.5 * g.cube_side());
  const view v(camera::orbit(c, 0.5 * g.cube_side(), 30, 20, dist, 1, {240, 320}), g.origin());
  render_options o;
  o.fx = effects{.shading = true};
  o.sun.direction = vec3f(-0.6f, 0.7f, 0.3f);
  const traverse_options t{.tolerance_px = 1};
  const auto order = rho_grid_light_order<3>(o.sun.direction.normalized());
  traverse_stats st;
  const auto* ord = mode >= 2 ? &order : nullptr;
  const bool table = mode == 3;
  if (arith == 2)
    table3_frames<rho_grid_arithmetic::fixed32>(state, g, v, o, t, ord, mode == 0, table, st);
  else if (arith == 1)
    table3_frames<rho_grid_arithmetic::fixed>(state, g, v, o, t, ord, mode == 0, table, st);
  else
    table3_frames<rho_grid_arithmetic::floating>(state, g, v, o, t, ord, mode == 0, table, st);
  state.SetLabel(std::string(model_name(int(state.range(0)))) + " tri/" +
                 std::to_string(state.range(1)) + " " +
                 (mode == 0   ? "points"
                  : mode == 1 ? "splats"
                  : mode == 2 ? "shadows"
                              : "shadows+table"));
  state.counters["samples"] = double(g.stats().samples);
  state.counters["drawn"] = double(st.emitted_nodes + st.emitted_leaves);
  state.counters["fps"] =
      benchmark::Counter(double(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(bm_table3)
    ->ArgsProduct({{0, 1}, {4, 5}, {0, 1, 2, 3}, {8, 3}, {0, 1, 2}})
    ->ArgNames({"model", "level", "mode_0points_1splats_2shadows_3table", "dist", "arith"})
    ->Unit(benchmark::kMillisecond);

// §4.1's close views: leaves as one-pixel points (0) or as squares of their projected cell
// (1, rho_grid_policy::leaf_splats), bunny tri/4, 512², s = 1, shading; the image against the
// mesh drawn by the same rasteriser (PSNR over covered pixels, holes).
void bm_leaf_splats(benchmark::State& state) {
  const bool splats = state.range(0) != 0;
  const double dist = double(state.range(1)) / 10;
  const auto& g = tri_grid(0, 4);
  const vec3d c = g.origin() + vec3d::Constant(0.5 * g.cube_side());
  const camera cam = camera::orbit(c, 0.5 * g.cube_side(), 30, 20, dist, 1, {512, 512});
  const view v(cam, g.origin());
  render_options o;
  o.fx = effects{.shading = true};
  const traverse_options t{.tolerance_px = 1};
  image img;
  with_rho_grid_hierarchy(g, [&](const auto& h) {
    constexpr attributes A = std::decay_t<decltype(h)>::attrs;
    rho_grid_policy<3> p(g, v);
    p.leaf_splats = splats;
    for (auto _ : state) {
      img = render<A>(v, o, [&](auto& sink) { traverse(h, v, t, sink, p); });
      benchmark::DoNotOptimize(img.colour.data());
    }
  });
  const image_error e = compare_images(render_reference(model(model_name(0)), cam, o), img);
  state.counters["psnr_vs_mesh"] = e.psnr;
  state.counters["holes"] = e.hole_fraction;
}
BENCHMARK(bm_leaf_splats)
    ->ArgsProduct({{0, 1}, {12, 25, 60}})
    ->ArgNames({"leaf_splats", "dist_x10"})
    ->Unit(benchmark::kMillisecond);

// §4.1's bounds: the symmetric bound (0) against the per-corner bounds table (1,
// rho_grid_bounds::per_corner), float, bunny tri/5, 512², splat size s: the time of the
// traversal alone (frame 0: cells to a counting sink) or of a whole frame with shading (frame 1);
// cells visited, splats and points drawn, and the shaded frame against the mesh drawn by the
// same rasteriser (PSNR, holes) in both.
template <rho_grid_bounds Bd>
void bounds_frames(benchmark::State& state, const rho_grid<3>& g, const camera& cam, float s,
                   bool frame) {
  const view v(cam, g.origin());
  render_options o;
  o.fx = effects{.shading = true};
  traverse_stats st;
  image img;
  const rho_grid_hierarchy<3, with_normals> h(g);
  const auto draw = [&](auto& sink) {
    st = traverse(h, v, {.tolerance_px = s}, sink,
                  rho_grid_policy<3, rho_grid_arithmetic::floating, Bd>(g, v));
  };
  for (auto _ : state) {
    if (frame) {
      img = render<with_normals>(v, o, draw);
      benchmark::DoNotOptimize(img.colour.data());
    } else {
      counting_sink<with_normals> sink;
      draw(sink);
      benchmark::DoNotOptimize(sink.points);
    }
  }
  if (!frame) img = render<with_normals>(v, o, draw);
  const image_error e = compare_images(render_reference(model(model_name(0)), cam, o), img);
  state.counters["visited"] = double(st.visited);
  state.counters["splats"] = double(st.emitted_nodes);
  state.counters["points"] = double(st.emitted_leaves);
  state.counters["psnr_vs_mesh"] = e.psnr;
  state.counters["holes"] = e.hole_fraction;
}
void bm_bounds(benchmark::State& state) {
  const auto& g = bunny_tri5();
  const camera cam = bench_camera(g, double(state.range(2)) / 10);
  const auto s = float(state.range(1));
  if (state.range(0) == 1)
    bounds_frames<rho_grid_bounds::per_corner>(state, g, cam, s, state.range(3) != 0);
  else
    bounds_frames<rho_grid_bounds::symmetric>(state, g, cam, s, state.range(3) != 0);
}
BENCHMARK(bm_bounds)
    ->ArgNames({"per_corner", "s", "dist10", "frame"})
    ->ArgsProduct({{0, 1}, {1, 4}, {25, 80}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// §5.1 and §4.1 drawing (rho_grid_policy::screen_draw): whole shaded frames, bunny tri/5, 512²,
// with the cells drawn as today (draw 0: point_prims re-projected by the rasteriser in float,
// inner cells as s × s squares at their samples) or from the traversal's tables (draw 1:
// screen rectangles placed from H/W in the policy's arithmetic; with per-corner bounds an inner
// cell is the rectangle of its sampled children). `arith` as in bm_traverse. psnr_vs_mesh: the
// frame against the mesh drawn by the same rasteriser (the full-detail reference).
template <rho_grid_arithmetic Ar, rho_grid_bounds Bd>
void draw_frames(benchmark::State& state, const rho_grid<3>& g, const camera& cam, float s,
                 bool screen_draw) {
  const view v(cam, g.origin());
  render_options o;
  o.fx = effects{.shading = true};
  const rho_grid_hierarchy<3, with_normals> h(g);
  rho_grid_policy<3, Ar, Bd> p(g, v);
  p.screen_draw = screen_draw;
  traverse_stats st;
  image img;
  for (auto _ : state) {
    img = render<with_normals>(
        v, o, [&](auto& sink) { st = traverse(h, v, {.tolerance_px = s}, sink, p); });
    benchmark::DoNotOptimize(img.colour.data());
  }
  static std::map<std::pair<double, int>, image> references;
  const auto key = std::pair{cam.eye.x(), cam.vp.width};
  auto it = references.find(key);
  if (it == references.end())
    it = references.emplace(key, render_reference(model(model_name(0)), cam, o)).first;
  const image_error e = compare_images(it->second, img);
  state.counters["drawn"] = double(st.emitted_nodes + st.emitted_leaves);
  state.counters["psnr_vs_mesh"] = e.psnr;
  state.counters["holes"] = e.hole_fraction;
}
template <rho_grid_arithmetic Ar>
void draw_frames_bounds(benchmark::State& state, const rho_grid<3>& g, const camera& cam, float s,
                        bool screen_draw, bool per_corner) {
  if (per_corner)
    return draw_frames<Ar, rho_grid_bounds::per_corner>(state, g, cam, s, screen_draw);
  draw_frames<Ar, rho_grid_bounds::symmetric>(state, g, cam, s, screen_draw);
}
void bm_draw(benchmark::State& state) {
  const auto& g = bunny_tri5();
  const camera cam = bench_camera(g, double(state.range(4)) / 10);
  const auto s = float(state.range(3));
  const bool screen_draw = state.range(1) != 0, per_corner = state.range(2) != 0;
  if (state.range(0) == 2)
    draw_frames_bounds<rho_grid_arithmetic::fixed32>(state, g, cam, s, screen_draw, per_corner);
  else if (state.range(0) == 1)
    draw_frames_bounds<rho_grid_arithmetic::fixed>(state, g, cam, s, screen_draw, per_corner);
  else
    draw_frames_bounds<rho_grid_arithmetic::floating>(state, g, cam, s, screen_draw, per_corner);
}
BENCHMARK(bm_draw)
    ->ArgNames({"arith", "draw", "per_corner", "s", "dist10"})
    ->ArgsProduct({{0, 1, 2}, {0, 1}, {0}, {1, 4}, {25, 80}})
    ->ArgsProduct({{0, 1, 2}, {0, 1}, {1}, {1, 4}, {25, 80}})
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
