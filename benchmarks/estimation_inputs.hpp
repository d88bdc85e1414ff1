// Inputs of the estimation benchmarks (estimation_benchmark.cpp and its CGAL peer), loaded once
// per process: positions only, with the true normals kept aside to score the estimate.
#pragma once

#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include <map>
#include <string>
#include <vector>

#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/raster/reference.hpp"
#include "support/data.hpp"

namespace pbr_lod::bench {

struct estimation_input {
  std::vector<vec3f> positions;
  std::vector<vec3f> true_normals;  ///< zero where unknown (a vertex no face uses)
};

struct estimation_inputs {
  /// "bunny", "buddha" (the scans' vertices, true normals from their meshes), "wavyN" (N
  /// samples of make_wavy_surface: analytic normals, inward), "lidarN" / "lidarNclean" (about N
  /// returns of make_lidar_tile, with / without its isolated returns; no true normals), "las" /
  /// "milk" (1.2-with-color.las, milk_cartoon_all_small_clorox.pcd: positions only).
  static const estimation_input& get(const std::string& name) {
    static std::map<std::string, estimation_input> cache;
    auto it = cache.find(name);
    if (it != cache.end()) return it->second;
    estimation_input in;
    if (name.starts_with("lidar")) {  // "lidarN": make_lidar_tile, no true normals
      in.positions =
          make_lidar_tile(std::stoul(name.substr(5)), 1, name.ends_with("clean") ? false : true)
              .positions;
    } else if (name == "las" || name == "milk") {  // real scans without normals: positions
      const point_cloud c = read_points(test::data_file(
          name == "las" ? "1.2-with-color.las" : "milk_cartoon_all_small_clorox.pcd"));
      in.positions = c.positions;
    } else if (name.starts_with("wavy")) {
      point_cloud c = make_wavy_surface(std::stoul(name.substr(4)), 1);
      in.positions = std::move(c.positions);
      in.true_normals = std::move(c.normals);
    } else {
      const triangle_mesh m =
          read_mesh(test::data_file(name == "bunny" ? "bun_zipper.ply" : "happy_vrip_res3.ply"));
      in.positions = m.vertices.positions;
      in.true_normals = area_weighted_normals(m);
    }
    return cache.emplace(name, std::move(in)).first->second;
  }
};

inline double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_maxrss) / 1024.0;
}

inline void rate(benchmark::State& state, std::size_t n) {
  state.counters["points/s"] =
      benchmark::Counter(static_cast<double>(n) * static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate);
  state.counters["peak_RSS_MB"] = peak_rss_mb();
}

/// Angle statistics of `normals` against the input's true normals: the mean and 95th percentile
/// of the angle between the lines, and the share of normals whose sign disagrees with the truth,
/// up to one global sign (an orientation method fixes each component's sign by a convention,
/// which on make_wavy_surface is the opposite of the generator's inward normals).
inline void accuracy(benchmark::State& state, const estimation_input& in,
                     const std::vector<vec3f>& n) {
  if (in.true_normals.empty()) return;
  std::vector<double> angle;
  std::size_t flipped = 0;
  for (std::size_t i = 0; i < n.size(); ++i) {
    if (in.true_normals[i].squaredNorm() == 0) continue;  // a vertex no face uses
    const double c = std::clamp(double(n[i].dot(in.true_normals[i])), -1.0, 1.0);
    flipped += c < 0;
    angle.push_back(std::acos(std::abs(c)) * 180 / std::numbers::pi);  // the line's error
  }
  if (angle.empty()) return;
  double sum = 0;
  for (double a : angle) sum += a;
  const auto p95 = angle.begin() + static_cast<std::ptrdiff_t>(0.95 * double(angle.size()));
  std::nth_element(angle.begin(), p95, angle.end());
  state.counters["mean_deg"] = sum / double(angle.size());
  state.counters["p95_deg"] = *p95;
  const double f = 100.0 * double(flipped) / double(angle.size());
  state.counters["flipped_%"] = std::min(f, 100.0 - f);
}

}  // namespace pbr_lod::bench
