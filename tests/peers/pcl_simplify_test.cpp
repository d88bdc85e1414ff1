// The PCL peers against brute force: VoxelGrid centroids per occupied cell, and the octree's
// voxel centroids when every voxel holds one point.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <tuple>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/peers/pcl_simplify.hpp"

namespace pbr_lod::peers {
namespace {

point_cloud jittered_lattice(int nx, int ny, int nz, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> jitter(-0.2f, 0.2f);
  std::uniform_int_distribution<int> colour(0, 255);
  point_cloud c;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        c.positions.emplace_back(x + 0.5f + jitter(rng), y + 0.5f + jitter(rng),
                                 z + 0.5f + jitter(rng));
        c.normals.push_back(vec3f::UnitZ());
        // All three channels random: PCL packs RGB into one float field, and a channel swapped or
        // lost on the way back shows only when it varies.
        c.colours.push_back({static_cast<std::uint8_t>(colour(rng)),
                             static_cast<std::uint8_t>(colour(rng)),
                             static_cast<std::uint8_t>(colour(rng))});
      }
  return c;
}

// Leaves of side 2 aligned at multiples of 2 (as VoxelGrid aligns them): one output point per
// occupied 2×2×2 block, at the centroid of its points, with their mean colour.
TEST(PclPeers, VoxelGridGivesCellCentroids) {
  const point_cloud in = jittered_lattice(10, 8, 3, 1);
  struct acc {
    vec3d sum = vec3d::Zero();
    double r = 0, g = 0, b = 0;
    int n = 0;
  };
  std::map<std::tuple<int, int, int>, acc> cells;
  for (std::size_t i = 0; i < in.size(); ++i) {
    const vec3f& p = in.positions[i];
    acc& a =
        cells[{int(std::floor(p.x() / 2)), int(std::floor(p.y() / 2)), int(std::floor(p.z() / 2))}];
    a.sum += p.cast<double>();
    a.r += in.colours[i].r;
    a.g += in.colours[i].g;
    a.b += in.colours[i].b;
    ++a.n;
  }
  const point_cloud out = pcl_voxel_grid(in, 2.0);
  ASSERT_EQ(out.size(), cells.size());
  for (std::size_t k = 0; k < out.size(); ++k) {
    const vec3f& p = out.positions[k];
    const auto it = cells.find(
        {int(std::floor(p.x() / 2)), int(std::floor(p.y() / 2)), int(std::floor(p.z() / 2))});
    ASSERT_NE(it, cells.end());
    const acc& a = it->second;
    EXPECT_NEAR((p.cast<double>() - a.sum / a.n).norm(), 0.0, 1e-4);
    EXPECT_NEAR(out.colours[k].r, a.r / a.n, 1.0);
    EXPECT_NEAR(out.colours[k].g, a.g / a.n, 1.0);
    EXPECT_NEAR(out.colours[k].b, a.b / a.n, 1.0);
    EXPECT_NEAR((out.normals[k] - vec3f::UnitZ()).norm(), 0.0f, 1e-5f);
  }
}

// Voxels of side 0.25 on points at least 0.6 apart: every voxel holds one point, so the
// centroids are the input points themselves.
TEST(PclPeers, OctreeCentroidsOfSingletonVoxelsAreThePoints) {
  const point_cloud in = jittered_lattice(6, 5, 4, 2);
  const point_cloud out = pcl_octree_centroids(in, 0.25);
  ASSERT_EQ(out.size(), in.size());
  const auto key = [](const vec3f& p) { return std::tuple{p.x(), p.y(), p.z()}; };
  std::vector<std::tuple<float, float, float>> a, b;
  for (const auto& p : in.positions) a.push_back(key(p));
  for (const auto& p : out.positions) b.push_back(key(p));
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_NEAR(std::get<0>(a[i]), std::get<0>(b[i]), 1e-5f);
    EXPECT_NEAR(std::get<1>(a[i]), std::get<1>(b[i]), 1e-5f);
    EXPECT_NEAR(std::get<2>(a[i]), std::get<2>(b[i]), 1e-5f);
  }
  // Each singleton voxel keeps its point's colour.
  for (std::size_t k = 0; k < out.size(); ++k) {
    std::size_t nearest = 0;
    for (std::size_t i = 1; i < in.size(); ++i)
      if ((in.positions[i] - out.positions[k]).squaredNorm() <
          (in.positions[nearest] - out.positions[k]).squaredNorm())
        nearest = i;
    EXPECT_EQ(out.colours[k], in.colours[nearest]) << k;
  }
  // Coarser voxels merge points.
  EXPECT_LT(pcl_octree_centroids(in, 2.0).size(), in.size());
}

TEST(PclPeers, BadArgumentsAreRejected) {
  const point_cloud in = jittered_lattice(3, 3, 1, 3);
  EXPECT_THROW((void)pcl_voxel_grid(in, 0), InvalidArgument);
  EXPECT_THROW((void)pcl_voxel_grid(in, 1e-12), InvalidArgument);  // past the 32-bit index
  EXPECT_THROW((void)pcl_octree_centroids(in, -1), InvalidArgument);
}

}  // namespace
}  // namespace pbr_lod::peers
