// k-NN normals, orientation and splat ellipses for positions-only input (core/estimation.hpp,
// docs/estimation.md), on the bunny, the Buddha and generated 1 M / 10 M-point surfaces, beside
// the peers a user would pick in the same binary: CGAL's pca_estimate_normals +
// mst_orient_normals (estimation_cgal_benchmark.cpp), and for the k-NN alone FLANN queried in
// input order (what a per-point loop does), nanoflann and CGAL's Orthogonal_k_neighbor_search.
//
// Counters: points/s; for inputs with true normals (the generated surfaces: analytic; the scans:
// area-weighted normals of their meshes) the mean and 95th-percentile angle to them and the
// share of flipped normals; peak_RSS_MB of the process (run one input per process with
// --benchmark_filter for a per-input peak).
#include <benchmark/benchmark.h>

#include <nanoflann.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

#include <cmath>
#include "estimation_inputs.hpp"
#include "pbr_lod/builders/point_octree.hpp"
#include "pbr_lod/core/estimation.hpp"
#include "pbr_lod/core/grid_knn.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/png.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/raster/reference.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod::bench {
namespace {

// Normals (PCA + orientation) and splat ellipses in one pass, as the point-octree build runs
// it. range(0): threads; range(1): 0 MST orientation, 1 towards a viewpoint above the model
// (the cost of that mode; no scan here has a sensor position, so no accuracy is scored).
void bm_estimate(benchmark::State& state, const std::string& name) {
  const estimation_input& in = estimation_inputs::get(name);
  estimation_options opt;
  opt.threads = static_cast<unsigned>(state.range(0));
  opt.orientation = state.range(1) == 0   ? normal_orientation::mst
                    : state.range(1) == 1 ? normal_orientation::viewpoint
                                          : normal_orientation::none;
  opt.viewpoint = vec3f(0, 10, 0);
  estimated_splats out;
  for (auto _ : state) {
    out = estimate_normals_and_ellipses(in.positions, opt);
    benchmark::DoNotOptimize(out.axes.u.data());
  }
  rate(state, in.positions.size());
  if (state.range(1) == 0) accuracy(state, in, out.normals);
}

void estimate_args(benchmark::internal::Benchmark* b, bool viewpoint) {
  b->ArgNames({"threads", "orient"})
      ->Unit(benchmark::kMillisecond)
      ->UseRealTime()
      ->MeasureProcessCPUTime();
  for (int t : {1, 2}) {
    b->Args({t, 0});
    if (viewpoint) b->Args({t, 1});
  }
}

BENCHMARK_CAPTURE(bm_estimate, bunny, std::string("bunny"))->Apply([](auto* b) {
  estimate_args(b, false);
});
BENCHMARK_CAPTURE(bm_estimate, buddha, std::string("buddha"))->Apply([](auto* b) {
  estimate_args(b, false);
});
BENCHMARK_CAPTURE(bm_estimate, wavy_1M, std::string("wavy1000000"))->Apply([](auto* b) {
  estimate_args(b, true);
});
BENCHMARK_CAPTURE(bm_estimate, lidar_500k, std::string("lidar500000"))->Apply([](auto* b) {
  estimate_args(b, true);
});
BENCHMARK_CAPTURE(bm_estimate, wavy_10M, std::string("wavy10000000"))
    ->Apply([](auto* b) { estimate_args(b, true); }) -> Iterations(1);

/// A 640×480 orbit view of the input's bounding sphere (up_axis 2 for the LiDAR tile).
camera view_of(const std::vector<vec3f>& pts, double azimuth, int up_axis) {
  vec3f lo = pts.front(), hi = lo;
  for (const auto& p : pts) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return camera::orbit((0.5f * (lo + hi)).cast<double>(), 0.5 * double((hi - lo).norm()), azimuth,
                       up_axis == 2 ? 45 : 20, 2.6, up_axis, {640, 480});
}

// Image error of the estimated normals: the scan rendered (shaded, full detail) with its
// estimated normals and ellipses against the same scan with its true normals and ellipses fitted
// to those, PSNR averaged over three views. range(0): 0 MST orientation, 2 none (the lines
// alone: what the sign costs on top).
void bm_normals_image_error(benchmark::State& state, const std::string& name) {
  const estimation_input& in = estimation_inputs::get(name);
  point_cloud truth, est;
  truth.positions = est.positions = in.positions;
  truth.normals = in.true_normals;
  for (auto& n : truth.normals)
    if (n.squaredNorm() == 0) n = vec3f::UnitZ();  // vertices no face uses
  const auto axes = estimate_splat_ellipses(truth.positions, truth.normals, 12);
  truth.axis_u = axes.u;
  truth.axis_v = axes.v;
  estimation_options opt{.k_ellipses = 12};
  if (state.range(0) == 2) opt.orientation = normal_orientation::none;
  for (auto _ : state) {
    auto e = estimate_normals_and_ellipses(est.positions, opt);
    est.normals = std::move(e.normals);
    est.axis_u = std::move(e.axes.u);
    est.axis_v = std::move(e.axes.v);
  }
  double psnr = 0;
  for (const double az : {30.0, 150.0, 270.0}) {
    const camera cam = view_of(in.positions, az, 1);
    psnr += compare_images(render_reference(truth, cam, {}), render_reference(est, cam, {})).psnr;
  }
  state.counters["psnr_dB"] = psnr / 3;
  rate(state, in.positions.size());
}
BENCHMARK_CAPTURE(bm_normals_image_error, bunny, std::string("bunny"))
    ->Arg(0)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);
BENCHMARK_CAPTURE(bm_normals_image_error, buddha, std::string("buddha"))
    ->Arg(0)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);

// Coverage of the estimated splats on the LiDAR tile without its isolated returns (they would
// dominate the reference: its squares grow with the k-NN spacing), three views: the share of
// the full-detail reference's pixels left uncovered (holes_%) and of pixels covered outside it
// (spill_%), for range(0) = 0 ellipse_rule::neighbours, 1 local_spacing. Also the largest major
// semi-axis over the distance to the 8th neighbour, and the spikes (major > 5 × minor and
// > 2 × that distance).
void bm_lidar_coverage(benchmark::State& state, const std::string& name) {
  const estimation_input& in = estimation_inputs::get(name);
  point_cloud ref, est;
  ref.positions = est.positions = in.positions;
  estimation_options opt{.k_ellipses = 12};
  opt.ellipses = state.range(0) == 0 ? ellipse_rule::neighbours : ellipse_rule::local_spacing;
  for (auto _ : state) {
    auto e = estimate_normals_and_ellipses(est.positions, opt);
    est.normals = std::move(e.normals);
    est.axis_u = std::move(e.axes.u);
    est.axis_v = std::move(e.axes.v);
  }
  double holes = 0, spill = 0;
  for (const double az : {30.0, 120.0, 200.0}) {
    const camera cam = view_of(in.positions, az, 2);
    const image a = render_reference(ref, cam, {}), b = render_reference(est, cam, {});
    std::size_t covered = 0, h = 0, s = 0;
    for (std::size_t i = 0; i < a.size(); ++i) {
      const bool x = std::isfinite(a.depth[i]), y = std::isfinite(b.depth[i]);
      covered += x;
      h += x && !y;
      s += y && !x;
    }
    holes += 100.0 * double(h) / double(covered) / 3;
    spill += 100.0 * double(s) / double(covered) / 3;
  }
  const std::vector<float> d8 = knn_spacing(in.positions, 8);
  double worst = 0;
  std::size_t spikes = 0;
  for (std::size_t i = 0; i < d8.size(); ++i) {
    const double a = est.axis_u[i].norm(), b = est.axis_v[i].norm();
    worst = std::max(worst, a / d8[i]);
    spikes += a > 5 * b && a > 2 * d8[i];
  }
  state.counters["holes_%"] = holes;
  state.counters["spill_%"] = spill;
  state.counters["max_major_per_d8"] = worst;
  state.counters["spikes"] = static_cast<double>(spikes);
  rate(state, in.positions.size());
}
BENCHMARK_CAPTURE(bm_lidar_coverage, lidar_500k, std::string("lidar500000clean"))
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);

// What the user sees on scans without normals: the estimated splats (range(1) = 0) or the
// point-octree's finest cut (1: tolerance 1 px, default options) against the cloud's own render
// (render_reference of the positions alone: every point a screen-aligned square of 1.6 × its
// 8th-neighbour distance), from 1.2 and 3 radii, three directions each (z up for the LiDAR
// tiles), 640 × 480. Counters, worst over the six views: holes_% (the reference's pixels left
// empty, in % of them), covered_x (pixels covered / the reference's), and the mean interior PSNR
// of compare_to_input; the largest splat of a non-surface neighbourhood (surface variation
// above local_spacing_max_thickness) over the sample's 8th-neighbour distance; estimation_s.
// range(0): 0 ellipse_rule::neighbours, 1 local_spacing. PBR_LOD_BENCH_PNG=DIR writes the images.
void bm_scan_coverage(benchmark::State& state, const std::string& name) {
  const estimation_input& in = estimation_inputs::get(name);
  const int up = name.starts_with("lidar") || name == "las" ? 2 : 1;
  point_cloud ref, est;
  ref.positions = est.positions = in.positions;
  ref.origin = est.origin = vec3d::Zero();
  estimation_options opt{.k_ellipses = 12};
  opt.ellipses = state.range(0) == 0 ? ellipse_rule::neighbours : ellipse_rule::local_spacing;
  double seconds = 0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    auto e = estimate_normals_and_ellipses(est.positions, opt);
    seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    est.normals = std::move(e.normals);
    est.axis_u = std::move(e.axes.u);
    est.axis_v = std::move(e.axes.v);
  }
  using octree = point_octree<point_octree_attributes(positions_only)>;
  std::optional<octree> tree;
  if (state.range(1) == 1) tree.emplace(build_point_octree(point_set<positions_only>::from(ref)));
  vec3f lo = in.positions.front(), hi = lo;
  for (const auto& p : in.positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const vec3d centre = (0.5f * (lo + hi)).cast<double>();
  const double radius = 0.5 * double((hi - lo).norm());
  double holes = 0, covered_x = 0, psnr = 0, interior_holes = 0;
  int views = 0;
  const char* png = std::getenv("PBR_LOD_BENCH_PNG");
  for (const double dist : {1.2, 3.0})
    for (const auto& [az, el] : {std::pair(30.0, 25.0), {160.0, 35.0}, {-70.0, 10.0}}) {
      const camera cam = camera::orbit(centre, radius, az, el, dist, up, {640, 480});
      const image a = render_reference(ref, cam, {});
      image b;
      if (tree) {
        const view v(cam, tree->origin());
        b = render<octree::attrs>(v, render_options{}, [&](auto& sink) {
          traverse(*tree, v, {.tolerance_px = 1}, sink, point_octree_policy{});
        });
      } else {
        b = render_reference(est, cam, {});
      }
      std::size_t ca = 0, cb = 0, h = 0;
      for (std::size_t i = 0; i < a.size(); ++i) {
        ca += a.covered(i);
        cb += b.covered(i);
        h += a.covered(i) && !b.covered(i);
      }
      holes = std::max(holes, 100.0 * double(h) / double(std::max<std::size_t>(ca, 1)));
      covered_x = std::max(covered_x, double(cb) / double(std::max<std::size_t>(ca, 1)));
      const input_likeness like = compare_to_input(a, b);
      psnr += std::min(like.psnr_interior, 100.0);
      const double inner = 100.0 * double(like.interior_holes) /
                           double(std::max<std::size_t>(like.interior_pixels, 1));
      interior_holes = std::max(interior_holes, inner);
      if (png) {
        const std::string stem = std::string(png) + "/" + name + "_r" +
                                 std::to_string(state.range(0)) + std::to_string(state.range(1)) +
                                 "_d" + std::to_string(int(dist * 10)) + "_az" +
                                 std::to_string(int(az));
        // Grey: covered by both; red: a hole (the reference only); blue: spill (ours only).
        image d(a.width, a.height, rgb8{255, 255, 255});
        std::fill(d.depth.begin(), d.depth.end(), 1.0f);
        for (std::size_t i = 0; i < a.size(); ++i)
          d.colour[i] = a.covered(i) && b.covered(i) ? rgb8{150, 150, 150}
                        : a.covered(i)               ? rgb8{230, 0, 0}
                        : b.covered(i)               ? rgb8{0, 0, 230}
                                                     : rgb8{255, 255, 255};
        write_png(stem + "_diff.png", d);
        if (!tree) {
          render_options shaded;
          shaded.fx.shading = true;
          write_png(stem + ".png", render_reference(est, cam, shaded));
        }
        std::printf("%s d%.1f az%.0f: holes %.2f %% (interior %.2f %%) covered %.3f\n",
                    name.c_str(), dist, az,
                    100.0 * double(h) / double(std::max<std::size_t>(ca, 1)), inner,
                    double(cb) / double(std::max<std::size_t>(ca, 1)));
      }
      ++views;
    }
  // The largest splat of a non-surface neighbourhood, over the sample's 8th-neighbour distance.
  const std::vector<float> d8 = knn_spacing(in.positions, 8);
  const knn_graph g = nearest_neighbour_graph(in.positions, 12);
  double worst = 0;
  std::size_t non_surface = 0;
  for (std::size_t i = 0; i < in.positions.size(); ++i) {
    vec3d mean = vec3d::Zero();
    for (int j = 0; j < 12; ++j) mean += in.positions[g.index[i * 12 + j]].cast<double>();
    mean /= 12;
    mat3d cov = mat3d::Zero();
    for (int j = 0; j < 12; ++j) {
      const vec3d d = in.positions[g.index[i * 12 + j]].cast<double>() - mean;
      cov += d * d.transpose();
    }
    const vec3d l = Eigen::SelfAdjointEigenSolver<mat3d>(cov, Eigen::EigenvaluesOnly).eigenvalues();
    if (!(l.sum() > 0) || l[0] <= local_spacing_max_thickness * l.sum()) continue;
    ++non_surface;
    if (d8[i] > 0) worst = std::max(worst, double(est.axis_u[i].norm()) / d8[i]);
  }
  state.counters["holes_%"] = holes;
  state.counters["covered_x"] = covered_x;
  state.counters["interior_holes_%"] = interior_holes;
  state.counters["psnr_interior"] = psnr / views;
  state.counters["non_surface_%"] = 100.0 * double(non_surface) / double(in.positions.size());
  state.counters["non_surface_major_per_d8"] = worst;
  state.counters["estimation_s"] = seconds;
}
void scan_coverage_args(benchmark::internal::Benchmark* b) {
  b->ArgNames({"rule", "octree"})->Unit(benchmark::kMillisecond)->Iterations(1);
  for (int r : {0, 1}) b->Args({r, 0});
  b->Args({1, 1});
}
BENCHMARK_CAPTURE(bm_scan_coverage, lidar_500k, std::string("lidar500000"))
    ->Apply(scan_coverage_args);
BENCHMARK_CAPTURE(bm_scan_coverage, lidar_500k_clean, std::string("lidar500000clean"))
    ->Apply(scan_coverage_args);
BENCHMARK_CAPTURE(bm_scan_coverage, las, std::string("las"))->Apply(scan_coverage_args);
BENCHMARK_CAPTURE(bm_scan_coverage, milk, std::string("milk"))->Apply(scan_coverage_args);
BENCHMARK_CAPTURE(bm_scan_coverage, bunny, std::string("bunny"))->Apply(scan_coverage_args);

// The k-NN graph alone (k = 16): our batch (Morton order, range(0) threads) ...
void bm_knn_graph(benchmark::State& state, const std::string& name) {
  const estimation_input& in = estimation_inputs::get(name);
  for (auto _ : state) {
    auto g = nearest_neighbour_graph(in.positions, 16, static_cast<unsigned>(state.range(0)));
    benchmark::DoNotOptimize(g.index.data());
  }
  rate(state, in.positions.size());
}
BENCHMARK_CAPTURE(bm_knn_graph, wavy_1M, std::string("wavy1000000"))
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

// ... the uniform grid's table (core/grid_knn.hpp: the same rows as the k-d tree's) ...
void bm_knn_grid(benchmark::State& state, const std::string& name) {
  const estimation_input& in = estimation_inputs::get(name);
  // In Morton order, as the estimation queries (and as nearest_neighbour_graph sorts them).
  std::vector<vec3f> sorted;
  for (const auto i : morton_order(in.positions)) sorted.push_back(in.positions[i]);
  for (auto _ : state) {
    auto t = grid_knn_table(sorted, 16, static_cast<unsigned>(state.range(0)));
    benchmark::DoNotOptimize(t.data());
  }
  rate(state, in.positions.size());
}
BENCHMARK_CAPTURE(bm_knn_grid, wavy_1M, std::string("wavy1000000"))
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();
BENCHMARK_CAPTURE(bm_knn_grid, lidar_500k, std::string("lidar500000"))
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();
BENCHMARK_CAPTURE(bm_knn_graph, lidar_500k, std::string("lidar500000"))
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

// ... the same FLANN index queried point by point in input order, one thread (the loop a user
// writes first) ...
void bm_knn_input_order(benchmark::State& state, const std::string& name) {
  const estimation_input& in = estimation_inputs::get(name);
  std::vector<std::uint32_t> idx(16);
  std::vector<float> d2(16);
  for (auto _ : state) {
    const knn_index index(in.positions);
    for (const auto& p : in.positions) index.query(p, 16, idx.data(), d2.data());
    benchmark::DoNotOptimize(idx.data());
  }
  rate(state, in.positions.size());
}
BENCHMARK_CAPTURE(bm_knn_input_order, wavy_1M, std::string("wavy1000000"))
    ->Unit(benchmark::kMillisecond);

// ... and nanoflann (Debian's libnanoflann-dev), leaf size 16, queried in the same Morton order
// on one thread: the alternative the issue names, measured rather than assumed.
struct cloud_adaptor {
  const std::vector<vec3f>* pts;
  [[nodiscard]] std::size_t kdtree_get_point_count() const { return pts->size(); }
  [[nodiscard]] float kdtree_get_pt(std::size_t i, std::size_t d) const {
    return (*pts)[i][static_cast<int>(d)];
  }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};

void bm_knn_nanoflann(benchmark::State& state, const std::string& name) {
  const estimation_input& in = estimation_inputs::get(name);
  const std::vector<std::uint32_t> order = morton_order(in.positions);
  using tree =
      nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, cloud_adaptor>,
                                          cloud_adaptor, 3, std::uint32_t>;
  std::vector<std::uint32_t> idx(16);
  std::vector<float> d2(16);
  const cloud_adaptor data{&in.positions};
  for (auto _ : state) {
    tree index(3, data, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    index.buildIndex();
    for (const auto i : order) {
      nanoflann::KNNResultSet<float, std::uint32_t> rs(16);
      rs.init(idx.data(), d2.data());
      index.findNeighbors(rs, in.positions[i].data(), nanoflann::SearchParams(32, 0.0f, true));
    }
    benchmark::DoNotOptimize(idx.data());
  }
  rate(state, in.positions.size());
}
BENCHMARK_CAPTURE(bm_knn_nanoflann, wavy_1M, std::string("wavy1000000"))
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace pbr_lod::bench

BENCHMARK_MAIN();
