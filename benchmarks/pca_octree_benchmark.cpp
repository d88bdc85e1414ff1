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

// ---- Image error against eye distance (Fig. 7) and what quantisation costs in it ----------

/// A model with its full-detail mesh: the reference every render is compared with.
struct scene_input {
  std::string name;
  point_cloud points;
  triangle_mesh mesh;
};
const scene_input& scene(const std::string& name) {
  static std::map<std::string, scene_input> cache;
  auto it = cache.find(name);
  if (it != cache.end()) return it->second;
  scene_input s{name, {}, {}};
  if (name == "demo") {  // the generated scene, sampled with its normals
    s.mesh = make_demo_scene(64);
    s.points = sample_surface(s.mesh, 200000, 5);
    s.points.colours.clear();
  } else {
    s.mesh = read_mesh(test::data_file(name));
    s.points = read_points(test::data_file(name));
  }
  return cache.emplace(name, std::move(s)).first->second;
}

struct rotation_error {
  double psnr = 0;    ///< mean over the views of the PSNR against the mesh (dB)
  double holes = 0;   ///< mean hole fraction
  double points = 0;  ///< mean points generated per frame
};

/// Renders `t` from `views` azimuths (a full turn, elevation 20°, 512², shading) at `distance`
/// radii with points of `point_px` pixels, against the mesh rendered at full detail from the
/// same camera (the paper's Fig. 7(c) measure), averaged over the views.
/// The render of t from cam with points of point_px pixels, and the points generated.
template <class T>
std::pair<image, std::size_t> render_view(const T& t, const camera& cam, float point_px) {
  constexpr effects fx{.shading = true, .colour = false};
  render_options ro;
  ro.fx = fx;
  pca_octree_policy policy;
  policy.render.point_px = point_px;
  const view v(cam, t.origin());
  rasterizer<T::attrs, fx> r(v, ro);
  const std::size_t points = traverse(t, v, traverse_options{}, r, policy).points;
  return {r.finish(), points};
}

/// View k of a turn of `views` about the model (elevation 20°, 512²) at `distance` radii.
camera turn_view(const scene_input& in, int k, int views, double distance) {
  const sphere s = bounding_sphere_about_box_centre(in.points.positions);
  return camera::orbit(in.points.origin + s.centre.cast<double>(), s.radius, 30 + 360.0 * k / views,
                       20, distance, 1, viewport{512, 512});
}

/// Renders `t` from `views` azimuths (a full turn) at `distance` radii with points of
/// `point_px` pixels, against the mesh rendered at full detail from the same camera (the
/// paper's Fig. 7(c) measure), averaged over the views. With `other`, also the PSNR of t's
/// render against other's (same seed).
template <class T>
rotation_error over_rotation(const T& t, const scene_input& in, double distance, float point_px,
                             int views = 4, const T* other = nullptr,
                             double* psnr_other = nullptr) {
  render_options ro;
  ro.fx = effects{.shading = true, .colour = false};
  rotation_error e;
  for (int k = 0; k < views; ++k) {
    const camera cam = turn_view(in, k, views, distance);
    const auto [img, points] = render_view(t, cam, point_px);
    e.points += static_cast<double>(points);
    const image_error err = compare_images(render_reference(in.mesh, cam, ro), img);
    e.psnr += err.psnr;
    e.holes += err.hole_fraction;
    if (other)
      *psnr_other += compare_images(render_view(*other, cam, point_px).first, img).psnr / views;
  }
  e.psnr /= views;
  e.holes /= views;
  e.points /= views;
  return e;
}

template <attributes A>
std::pair<pca_octree<pca_octree_attributes(A)>, pca_octree<pca_octree_attributes(A)>> both_trees(
    const point_cloud& c) {
  const auto pts = point_set<A>::from(c);
  return {build_pca_octree(pts, {.quantise = true}), build_pca_octree(pts, {.quantise = false})};
}

// What quantisation (§3.1) costs in image error: the quantised and the float hierarchy of the
// same input, rendered alike at 3 radii, each against the mesh; point sizes 1, 2 and 4 px (the
// tool's --tolerance). Printed as a markdown table.
void bm_quantised_image(benchmark::State& state, const std::string& name) {
  const scene_input& in = scene(name);
  for (auto _ : state) {
    const auto run = [&](const auto& trees) {
      std::printf(
          "\n%s, 3 radii, 4 views: | point px | points | PSNR float | PSNR quantised | "
          "PSNR quantised vs float |\n",
          name.c_str());
      for (const float px : {1.0f, 2.0f, 4.0f}) {
        double qf = 0;
        const rotation_error q = over_rotation(trees.first, in, 3, px, 4, &trees.second, &qf);
        const rotation_error f = over_rotation(trees.second, in, 3, px);
        std::printf("| %.0f | %.0f | %.2f dB | %.2f dB | %.2f dB |\n", static_cast<double>(px),
                    q.points, f.psnr, q.psnr, qf);
      }
    };
    if (in.points.normals.empty())
      run(both_trees<positions_only>(in.points));
    else
      run(both_trees<with_normals>(in.points));
  }
}
BENCHMARK_CAPTURE(bm_quantised_image, bunny, std::string("bun_zipper.ply"))
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(bm_quantised_image, demo, std::string("demo"))
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);

// Fig. 7: points generated and image error against the mesh per eye distance, averaged over a
// turn of 8 views, one-pixel points. Printed as a markdown table.
void bm_fig7(benchmark::State& state, const std::string& name) {
  const scene_input& in = scene(name);
  for (auto _ : state) {
    const auto run = [&](const auto& t) {
      std::printf("\n%s, 8 views: | distance (radii) | points | PSNR | holes %% |\n", name.c_str());
      for (const double dist : {2.0, 3.0, 4.0, 6.0, 8.0, 12.0}) {
        const rotation_error e = over_rotation(t, in, dist, 1.0f, 8);
        std::printf("| %.1f | %.0f | %.2f dB | %.3f |\n", dist, e.points, e.psnr, 100 * e.holes);
      }
    };
    if (in.points.normals.empty())
      run(build_pca_octree(point_set<positions_only>::from(in.points)));
    else
      run(build_pca_octree(point_set<with_normals>::from(in.points)));
  }
}
BENCHMARK_CAPTURE(bm_fig7, bunny, std::string("bun_zipper.ply"))
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(bm_fig7, demo, std::string("demo"))->Iterations(1)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
