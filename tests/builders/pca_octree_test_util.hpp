// Test support for the PCA octree tests (pca_octree_test.cpp, pca_octree_render_test.cpp):
// seeded inputs, frame checks, temporary files.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <random>

#include "pbr_lod/builders/pca_octree.hpp"
#include "pbr_lod/core/synthetic.hpp"

namespace pbr_lod {
namespace pca_test {

using tree_n = pca_octree<with_normals>;
using tree_nc = pca_octree<with_normals_colours>;
inline constexpr double deg = 180 / std::numbers::pi;

inline double angle_deg(const vec3d& a, const vec3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * deg;
}
inline double axis_deg(const vec3d& a, const vec3d& b) {
  return std::min(angle_deg(a, b), angle_deg(a, -b));
}

inline mat3d random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> g;
  return Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized().toRotationMatrix();
}

inline point_set<with_normals_colours> demo_points(std::size_t n, std::uint64_t seed = 7) {
  return point_set<with_normals_colours>::from(sample_surface(make_demo_scene(16), n, seed));
}

inline void expect_orthonormal(const mat3d& f, const std::string& what, double tol = 1e-9) {
  ASSERT_TRUE(all_finite(f)) << what;
  EXPECT_LT((f.transpose() * f - mat3d::Identity()).cwiseAbs().maxCoeff(), tol) << what;
  EXPECT_NEAR(f.determinant(), 1.0, tol) << what << ": right-handed";
}

template <class T>
void expect_finite_tree(const T& t, const std::string& what) {
  ASSERT_FALSE(t.empty()) << what;
  for (std::uint32_t i = 0; i < t.nodes().size(); ++i) {
    const auto& nd = t.at(i);
    ASSERT_TRUE(all_finite(nd.mean) && all_finite(nd.frame) && all_finite(nd.sigma) &&
                all_finite(nd.normal_frame) && all_finite(nd.normal_sigma) &&
                std::isfinite(nd.radius) && std::isfinite(nd.cone_angle) &&
                std::isfinite(nd.lambda))
        << what << " node " << i;
    EXPECT_GE(nd.sigma.minCoeff(), 1e-15f) << what << " node " << i << ": the §3 floor";
    // Float frames: orthonormal to float precision.
    expect_orthonormal(nd.frame.template cast<double>(), what, 1e-5);
    expect_orthonormal(nd.normal_frame.template cast<double>(), what, 1e-5);
  }
}

/// One generated point set per node drawn; the traversal with the paper's policy.
template <class T>
inline buffer_sink<T::attrs> draw(const T& t, const camera& cam, std::uint64_t seed,
                                  traverse_stats* st = nullptr) {
  buffer_sink<T::attrs> sink;
  pca_octree_policy policy;
  policy.render.seed = seed;
  const view v(cam, t.origin());
  const auto s = traverse(t, v, traverse_options{}, sink, policy);
  if (st) *st = s;
  return sink;
}

inline camera camera_for(const vec3d& centre, double radius) {
  return camera::orbit(centre, radius, 30, 20, 3, 1, viewport{160, 120});
}

inline std::vector<char> read_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}
inline void write_bytes(const std::string& path, const std::vector<char>& b) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(b.data(), static_cast<std::streamsize>(b.size()));
}
inline std::string temp(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("pbr_lod_pca_" + name)).string();
}

}  // namespace pca_test
}  // namespace pbr_lod
