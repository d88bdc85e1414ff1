// The grid k-NN (core/grid_knn.hpp) against FLANN's k-d tree (knn_index): the same rows, bit for
// bit, on clouds that stress the grid — a real scan, a surface with a far outlier (one cell size
// for both), clusters with empty space between, duplicates and ties on a lattice, collinear and
// coplanar points, a scan 10^7 units from the origin — and brute force on a small cloud.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/grid_knn.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/io/read.hpp"
#include "support/data.hpp"

namespace pbr_lod {
namespace {

std::vector<std::uint32_t> flann_table(const std::vector<vec3f>& pts, int k) {
  const knn_index index(pts);
  std::vector<std::uint32_t> table(pts.size() * std::size_t(k));
  std::vector<float> d2(static_cast<std::size_t>(k));
  for (std::size_t i = 0; i < pts.size(); ++i)
    index.query(pts[i], std::size_t(k), &table[i * std::size_t(k)], d2.data());
  return table;
}

void expect_same_rows(const std::vector<vec3f>& pts, int k, const char* what) {
  const auto want = flann_table(pts, k);
  for (const unsigned threads : {1u, 2u}) {
    const auto got = grid_knn_table(pts, k, threads);
    ASSERT_EQ(got.size(), want.size()) << what;
    std::size_t differ = 0, first = got.size();
    for (std::size_t i = 0; i < got.size(); ++i)
      if (got[i] != want[i]) {
        ++differ;
        first = std::min(first, i);
      }
    EXPECT_EQ(differ, 0u) << what << ", k = " << k << ": first at row " << first / std::size_t(k);
  }
}

std::vector<vec3f> wavy_surface(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1, 1);
  std::vector<vec3f> p;
  for (std::size_t i = 0; i < n; ++i) {
    const float x = u(rng), y = u(rng);
    p.emplace_back(x, y, 0.1f * std::sin(5 * x) * std::cos(4 * y));
  }
  return p;
}

TEST(GridKnn, SameRowsAsTheKdTreeOnAScan) {
  const auto cloud = read_points(test::data_file("bun_zipper_res2.ply"));
  for (const int k : {1, 8, 16, 24}) expect_same_rows(cloud.positions, k, "bunny res2");
}

TEST(GridKnn, SameRowsOnHardClouds) {
  auto surface = wavy_surface(20000, 3);
  expect_same_rows(surface, 16, "wavy surface");
  surface.emplace_back(1000, -500, 200);  // one cell size for a cloud with a far outlier
  expect_same_rows(surface, 16, "wavy surface and an outlier");
  // Clusters with empty space between them.
  std::vector<vec3f> clusters;
  std::mt19937 rng(5);
  std::normal_distribution<float> g(0, 0.01f);
  for (int c = 0; c < 8; ++c)
    for (int i = 0; i < 500; ++i)
      clusters.emplace_back(float(c % 2) * 5 + g(rng), float(c / 2 % 2) * 5 + g(rng),
                            float(c / 4) * 5 + g(rng));
  expect_same_rows(clusters, 16, "clusters");
  // A lattice: every distance tied many ways; each point twice (exact duplicates).
  std::vector<vec3f> lattice;
  for (int x = 0; x < 12; ++x)
    for (int y = 0; y < 12; ++y)
      for (int z = 0; z < 3; ++z)
        for (int copy = 0; copy < 2; ++copy) lattice.emplace_back(0.1f * x, 0.1f * y, 0.1f * z);
  expect_same_rows(lattice, 16, "lattice with duplicates");
  // Collinear, coplanar, all coincident.
  std::vector<vec3f> line, plane, one(50, vec3f(1, 2, 3));
  for (int i = 0; i < 3000; ++i) line.emplace_back(0.001f * float(i), 2 * 0.001f * float(i), 0);
  for (int i = 0; i < 3000; ++i) plane.emplace_back(float(i % 60), float(i / 60), 7);
  expect_same_rows(line, 16, "collinear");
  expect_same_rows(plane, 16, "coplanar");
  expect_same_rows(one, 16, "coincident");
  // A scan far from the origin (float positions of 10^7 with ~1 unit of resolution).
  std::vector<vec3f> far = wavy_surface(5000, 9);
  for (vec3f& p : far) p = p * 300.0f + vec3f(1e7f, -1e7f, 5e6f);
  expect_same_rows(far, 16, "10^7 from the origin");
}

TEST(GridKnn, MatchesBruteForce) {
  const auto pts = wavy_surface(700, 11);
  const int k = 12;
  const auto got = grid_knn_table(pts, k, 1);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    std::vector<std::pair<float, std::uint32_t>> all;
    for (std::size_t j = 0; j < pts.size(); ++j)
      all.push_back({(pts[i] - pts[j]).squaredNorm(), std::uint32_t(j)});
    std::sort(all.begin(), all.end());
    // Distances (float rounding may order exact near-ties differently: compare the distances).
    for (int r = 0; r < k; ++r)
      EXPECT_NEAR((pts[i] - pts[got[i * k + std::size_t(r)]]).squaredNorm(),
                  all[std::size_t(r)].first, 1e-6f)
          << "row " << i << " rank " << r;
  }
}

TEST(GridKnn, RefusesBadInput) {
  const std::vector<vec3f> pts{{0, 0, 0}, {1, 0, 0}};
  EXPECT_THROW((void)grid_knn_table(pts, 0), InvalidArgument);
  EXPECT_THROW((void)grid_knn_table(pts, 3), InvalidArgument);
  const std::vector<vec3f> bad{{0, 0, 0}, {NAN, 0, 0}};
  EXPECT_THROW((void)grid_knn_table(bad, 1), InvalidArgument);
  EXPECT_EQ(grid_knn_table(pts, 2), (std::vector<std::uint32_t>{0, 1, 1, 0}));
}

}  // namespace
}  // namespace pbr_lod
