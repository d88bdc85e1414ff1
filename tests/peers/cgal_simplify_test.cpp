// The CGAL peers against brute force: which points a grid keeps, what a hierarchy keeps, and
// that the kept points carry their own attributes.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <set>
#include <tuple>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/peers/cgal_simplify.hpp"

namespace pbr_lod::peers {
namespace {

/// Jittered lattice points (spacing 1, jitter ±0.2 about i + 0.5), the colour encoding the index
/// so a kept point's attributes can be traced to the input.
point_cloud jittered_lattice(int nx, int ny, int nz, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> jitter(-0.2f, 0.2f);
  point_cloud c;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        const auto i = c.positions.size();
        c.positions.emplace_back(x + 0.5f + jitter(rng), y + 0.5f + jitter(rng),
                                 z + 0.5f + jitter(rng));
        c.normals.push_back(vec3f::UnitZ());
        c.colours.push_back(
            {static_cast<std::uint8_t>(i & 255), static_cast<std::uint8_t>((i >> 8) & 255), 7});
      }
  return c;
}

/// The input index of a kept point, from its colour, after checking that its position and
/// normal are that input point's own.
std::size_t traced_index(const point_cloud& in, const point_cloud& out, std::size_t k) {
  const std::size_t i = out.colours[k].r + 256u * out.colours[k].g;
  EXPECT_LT(i, in.size());
  EXPECT_EQ(out.positions[k], in.positions[i]);
  EXPECT_EQ(out.normals[k], in.normals[i]);
  return i;
}

// Cells of side 2 over a jittered unit lattice: every lattice site lies inside one cell
// (jitter 0.2 keeps it off the cell walls), so the grid keeps exactly one point per occupied
// 2×2×2 block — counted here by brute force — and never two from one block.
TEST(CgalPeers, GridKeepsOnePointPerOccupiedCell) {
  const point_cloud in = jittered_lattice(10, 8, 3, 1);
  const point_cloud out = grid_simplify(in, 2.0);
  std::set<std::tuple<int, int, int>> occupied, seen;
  for (const auto& p : in.positions)
    occupied.insert(
        {int(std::floor(p.x() / 2)), int(std::floor(p.y() / 2)), int(std::floor(p.z() / 2))});
  ASSERT_EQ(out.size(), occupied.size());  // 5 × 4 × 2 = 40
  EXPECT_EQ(out.size(), 40u);
  std::size_t last = 0;
  for (std::size_t k = 0; k < out.size(); ++k) {
    const std::size_t i = traced_index(in, out, k);
    if (k > 0) {
      EXPECT_GT(i, last) << "kept points are in input order";
    }
    last = i;
    const auto& p = out.positions[k];
    EXPECT_TRUE(seen.insert({int(std::floor(p.x() / 2)), int(std::floor(p.y() / 2)),
                             int(std::floor(p.z() / 2))})
                    .second);
  }
}

// A flat cloud (surface variation 0) is split by size alone: every cluster ends with at most
// `size` points, so at least n / size points are kept, and at most n; each is an input point
// with its own attributes.
TEST(CgalPeers, HierarchyKeepsInputPointsWithAttributes) {
  const point_cloud in = jittered_lattice(20, 20, 1, 2);
  for (const unsigned size : {4u, 16u, 64u}) {
    const point_cloud out = hierarchy_simplify(in, size);
    EXPECT_GE(out.size() * size, in.size()) << size;
    EXPECT_LT(out.size(), in.size()) << size;
    for (std::size_t k = 0; k < out.size(); ++k) (void)traced_index(in, out, k);
  }
  // Smaller clusters keep more points.
  EXPECT_GT(hierarchy_simplify(in, 4).size(), hierarchy_simplify(in, 64).size());
}

TEST(CgalPeers, BadArgumentsAreRejected) {
  const point_cloud in = jittered_lattice(3, 3, 1, 3);
  EXPECT_THROW((void)grid_simplify(in, 0), InvalidArgument);
  EXPECT_THROW((void)grid_simplify(in, std::nan("")), InvalidArgument);
  EXPECT_THROW((void)hierarchy_simplify(in, 0), InvalidArgument);
  EXPECT_THROW((void)hierarchy_simplify(in, 8, 0.5), InvalidArgument);
  EXPECT_THROW((void)subset(in, {0, 99}), InvalidArgument);
}

}  // namespace
}  // namespace pbr_lod::peers
