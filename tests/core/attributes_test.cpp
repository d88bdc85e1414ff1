#include <gtest/gtest.h>

#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"
#include "pbr_lod/traverse/primitives.hpp"

namespace pbr_lod {
namespace {

// A point set without colours or normals carries no storage for them: the absent members have
// zero size, so the container is exactly origin + one vector.
TEST(Attributes, AbsentAttributesTakeNoStorage) {
  constexpr std::size_t base = sizeof(vec3d) + sizeof(std::vector<vec3f>);
  EXPECT_EQ(sizeof(point_set<positions_only>), base);
  EXPECT_EQ(sizeof(point_set<with_normals>), base + sizeof(std::vector<vec3f>));
  EXPECT_EQ(sizeof(point_set<attributes{.colour = true}>), base + sizeof(std::vector<rgb8>));
  // Per point: 12 bytes of position, +12 normal, +3 colour, +1 material, +24 ellipse.
  EXPECT_EQ(point_set<positions_only>::bytes_per_point(), 12u);
  EXPECT_EQ(point_set<with_normals_colours>::bytes_per_point(), 27u);
  EXPECT_EQ(point_set<all_attributes>::bytes_per_point(), 52u);
}

// Primitives follow the same rule: a positions-only point is 16 bytes (position + size).
TEST(Attributes, PrimitivesCarryOnlyTheirAttributes) {
  EXPECT_EQ(sizeof(point_prim<positions_only>), 16u);
  EXPECT_EQ(sizeof(splat_prim<positions_only>), 36u);
  EXPECT_EQ(sizeof(triangle_prim<positions_only>), 36u);
  EXPECT_GT(sizeof(point_prim<with_normals>), sizeof(point_prim<positions_only>));
}

TEST(Attributes, FromCloudRequiresRequestedAttributes) {
  point_cloud c;
  c.positions = {vec3f(0, 0, 0), vec3f(1, 0, 0)};
  EXPECT_NO_THROW(point_set<positions_only>::from(c));
  EXPECT_THROW(point_set<with_normals>::from(c, "test.ply"), InvalidArgument);
  c.normals = {vec3f::UnitZ(), vec3f::UnitZ()};
  const auto s = point_set<with_normals>::from(c);
  EXPECT_EQ(s.normals.size(), 2u);
  c.colours = {rgb8{}};  // wrong length
  EXPECT_THROW(c.validate(), InvalidArgument);
  // An empty cloud has every attribute (each vector holds its 0 entries), so a builder gets it
  // and says what is wrong — no points — rather than a missing attribute.
  EXPECT_TRUE(point_set<all_attributes>::from(point_cloud{}).empty());
}

TEST(Attributes, RebaseKeepsWorldPositions) {
  point_cloud c;
  c.origin = vec3d(5e5, 4e6, 100);
  c.positions = {vec3f(0.25f, -0.5f, 1.0f)};
  const vec3d w = c.world(0);
  rebase(c, vec3d(5e5 + 1, 4e6 - 2, 99));
  EXPECT_NEAR((c.world(0) - w).norm(), 0.0, 1e-6);
}

TEST(Mesh, ValidateRejectsOutOfRangeIndex) {
  triangle_mesh m;
  m.vertices.positions = {vec3f(0, 0, 0), vec3f(1, 0, 0), vec3f(0, 1, 0)};
  m.faces = {{0, 1, 2}};
  EXPECT_NO_THROW(m.validate());
  m.faces.push_back({0, 1, 3});
  EXPECT_THROW(m.validate("m.ply"), InvalidArgument);
}

}  // namespace
}  // namespace pbr_lod
