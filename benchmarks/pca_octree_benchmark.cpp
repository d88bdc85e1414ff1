// PCA octree (Kalaiah & Varshney 2003) benchmarks: build throughput including k-means (§3,
// §3.1) on two scans and a generated surface, bytes per node, the randomised render (§4)
// against a plain one-pixel point render of the input, and — in pca_octree_cgal_benchmark.cpp,
// the same binary — CGAL's hierarchy_simplify_point_set on the same inputs. docs/pca-octree.md
// quotes these numbers.
#include <benchmark/benchmark.h>

#include <bit>

#include <cstdio>
#include <map>

#include "pbr_lod/builders/pca_octree.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/raster/reference.hpp"
#include "support/data.hpp"

namespace {
using namespace pbr_lod;

const point_cloud& input(const std::string& name) {
  static std::map<std::string, point_cloud> cache;
  auto it = cache.find(name);
  if (it == cache.end()) {
    point_cloud c = name.starts_with("wavy") ? make_wavy_surface(std::stoul(name.substr(4)), 1)
                                             : read_points(test::data_file(name));
    it = cache.emplace(name, std::move(c)).first;
  }
  return it->second;
}

template <class T>
void report(benchmark::State& state, const T& t) {
  const auto& st = t.stats();
  const std::size_t n = st.input_points;
  state.counters["nodes"] = static_cast<double>(t.nodes().size());
  state.counters["B/node_record"] = static_cast<double>(t.record_bytes());
  state.counters["B/node_file"] =
      static_cast<double>(t.file_bytes()) / static_cast<double>(t.nodes().size());
  state.counters["B/point_file"] = static_cast<double>(t.file_bytes()) / static_cast<double>(n);
  state.counters["estimation_s"] = st.estimation_seconds;
  state.counters["tree_s"] = st.tree_seconds;
  state.counters["kmeans_s"] = st.kmeans_seconds;
  state.counters["quantise_s"] = st.quantise_seconds;
}

// The whole build: k-NN normals when the input has none (both scans), octree, per-node PCA,
// k-means of σ_p, σ_n (σ_c) with the default codebooks (1024, 1024, 64), encoding.
void bm_build(benchmark::State& state, const std::string& name) {
  const point_cloud& c = input(name);
  const pca_octree_options o{.threads = static_cast<unsigned>(state.range(0))};
  const auto run = [&](const auto& pts) {
    for (auto _ : state) {
      auto t = build_pca_octree(pts, o);
      benchmark::DoNotOptimize(t);
      state.PauseTiming();
      report(state, t);
      state.ResumeTiming();
    }
    state.counters["points/s"] =
        benchmark::Counter(static_cast<double>(c.size()) * static_cast<double>(state.iterations()),
                           benchmark::Counter::kIsRate);
  };
  if (!c.normals.empty() && !c.colours.empty())
    run(point_set<with_normals_colours>::from(c));
  else if (!c.normals.empty())
    run(point_set<with_normals>::from(c));
  else
    run(point_set<positions_only>::from(c));
}
BENCHMARK_CAPTURE(bm_build, bunny, std::string("bun_zipper.ply"))
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(bm_build, happy_buddha, std::string("happy_vrip_res3.ply"))
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(bm_build, wavy_1M, std::string("wavy1000000"))
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(bm_build, wavy_5M, std::string("wavy5000000"))
    ->Arg(2)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// §4 randomised rendering of the bunny at the tool's default view (512², distance 3 radii and
// farther) against drawing its 35 947 input points as one-pixel points (the plain render).
// Counters: generated points, covered pixels, and — as the paper's Fig. 7(c) — the image error
// against the mesh rendered at full detail (PSNR over pixels covered in either, hole fraction).
void bm_render(benchmark::State& state, bool randomised) {
  const point_cloud& c = input("bun_zipper.ply");
  static const auto t = build_pca_octree(point_set<positions_only>::from(c));
  const sphere s = bounding_sphere_about_box_centre(c.positions);
  const camera cam = camera::orbit(c.origin + s.centre.cast<double>(), s.radius, 30, 20,
                                   static_cast<double>(state.range(0)) / 2, 1, viewport{512, 512});
  constexpr effects fx{.shading = true, .colour = false};
  render_options ro;
  ro.fx = fx;
  std::size_t points = 0;
  image img;
  for (auto _ : state) {
    if (randomised) {
      const view v(cam, t.origin());
      rasterizer<with_normals, fx> r(v, ro);
      points = traverse(t, v, traverse_options{}, r, pca_octree_policy{}).points;
      img = r.finish();
    } else {
      const view v(cam, c.origin);
      rasterizer<positions_only, fx> r(v, ro);
      for (const auto& p : c.positions) r.point(point_prim<positions_only>{p, 1});
      points = c.size();
      img = r.finish();
    }
  }
  static const triangle_mesh mesh = read_mesh(test::data_file("bun_zipper.ply"));
  const image_error e = compare_images(render_reference(mesh, cam, ro), img);
  state.counters["points"] = static_cast<double>(points);
  state.counters["covered_px"] = static_cast<double>(img.covered_count());
  state.counters["psnr_vs_mesh"] = e.psnr;
  state.counters["holes"] = e.hole_fraction;
}
BENCHMARK_CAPTURE(bm_render, randomised, true)
    ->Arg(6)
    ->Arg(12)
    ->Arg(24)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(bm_render, plain_points, false)
    ->Arg(6)
    ->Arg(12)
    ->Arg(24)
    ->Unit(benchmark::kMillisecond);

// §5.1, Table 1: per octree level L, for every node at depth L, the distance from the farthest of
// as many generated points as the node has input points to its nearest input point of the node
// ("the maximum distance between any generated point ... and its nearest point on the
// surface"), as % of the edge of the model's bounding cube (the root cell: the paper's "best
// fitting axis-aligned cube" — its percentages fall with the level as the model's would, and a
// node of one or two points has no cube of its own); the maximum and the mean
// over the level; and the compression of the cut at level L (the nodes at depth L and the
// leaves above it) against the paper's 8 bytes a point (16-bit x, y, z and normal), counting
// the 13-byte records only. Printed as a markdown table (once per input and quantisation).
template <class T>
void table1(const T& t, const point_cloud& c, const char* name) {
  const auto& nodes = t.nodes();
  // Each input point's path: descend by the cells (the builder's split rule).
  std::vector<std::vector<std::uint32_t>> members(nodes.size());
  for (std::size_t i = 0; i < c.size(); ++i) {
    const vec3d p = c.world(i) - t.origin();
    std::uint32_t n = 0;
    while (true) {
      members[n].push_back(static_cast<std::uint32_t>(i));
      const auto& nd = nodes[n];
      if (nd.count == 0) break;
      const vec3d mid = nd.cell_min + vec3d::Constant(0.5 * nd.cell_size);
      const unsigned o = (p.x() >= mid.x() ? 1u : 0u) | (p.y() >= mid.y() ? 2u : 0u) |
                         (p.z() >= mid.z() ? 4u : 0u);
      if (!(nd.mask & (1u << o))) break;  // (cannot happen for the input the tree was built on)
      n = nd.first + static_cast<std::uint32_t>(std::popcount(nd.mask & ((1u << o) - 1u)));
    }
  }
  std::size_t depth = 0;
  for (const auto& nd : nodes) depth = std::max<std::size_t>(depth, nd.depth);
  std::printf(
      "\n%s (%s): %zu points, %zu nodes\n| level | nodes | compression %% | max error %% "
      "| mean error %% |\n|---|---|---|---|---|\n",
      name, t.quantised() ? "quantised" : "float", c.size(), nodes.size());
  for (std::size_t level = 1; level <= depth; ++level) {
    double max_e = 0, sum_e = 0;
    std::size_t count = 0, cut = 0;
    for (std::uint32_t n = 0; n < nodes.size(); ++n) {
      if (nodes[n].depth == level || (nodes[n].depth < level && nodes[n].count == 0)) ++cut;
      if (nodes[n].depth != level || members[n].empty()) continue;
      std::vector<vec3f> orig, gen(members[n].size());
      for (const auto i : members[n])
        orig.push_back((c.world(i) - t.origin()).template cast<float>());
      std::vector<detail::pca_sample> s(members[n].size());
      detail::pca_generate(t.data(), n, 1, 0, static_cast<std::uint32_t>(s.size()), s.data());
      for (std::size_t k = 0; k < s.size(); ++k) gen[k] = s[k].position;
      const knn_index io(orig);
      double h = 0;
      for (const auto& q : gen) h = std::max(h, static_cast<double>(io.nearest_distance(q)));
      const double edge = t.cube_size();
      const double e = 100 * h / edge;
      max_e = std::max(max_e, e);
      sum_e += e;
      ++count;
    }
    std::printf("| %zu | %zu | %.0f | %.3f | %.3f |\n", level, count,
                100.0 * 8 * static_cast<double>(c.size()) / (13.0 * static_cast<double>(cut)),
                max_e, count ? sum_e / static_cast<double>(count) : 0.0);
  }
}
void bm_table1(benchmark::State& state, const std::string& name) {
  const point_cloud& c = input(name);
  for (auto _ : state) {
    for (const bool q : {true, false}) {
      const auto t = build_pca_octree(point_set<positions_only>::from(c), {.quantise = q});
      table1(t, c, name.c_str());
    }
    // λ = 1 (curvature_c = 0): what the curvature scale adds to the error.
    const auto t = build_pca_octree(point_set<positions_only>::from(c), {.curvature_c = 0});
    std::printf("\n(λ = 1)");
    table1(t, c, name.c_str());
  }
}
BENCHMARK_CAPTURE(bm_table1, bunny, std::string("bun_zipper.ply"))
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(bm_table1, happy_buddha, std::string("happy_vrip_res3.ply"))
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
