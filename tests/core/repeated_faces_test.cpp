// unique_faces: exact repeats of a triangle (same corner positions in the same cyclic order,
// shared or copied vertices) are dropped, everything else kept in input order.
#include <gtest/gtest.h>

#include "pbr_lod/core/repeated_faces.hpp"

namespace pbr_lod {
namespace {

// Faces: 0 the triangle; 1 a rotation of it; 2 its other winding (kept: a back face); 3 the
// same positions through copied vertices (dropped); 4 another triangle; 5 = 0 again; 6 a copy
// of 4 through copied vertices rotated (dropped). Expected: 0, 2, 4.
TEST(RepeatedFaces, RotationsAndCopiesDropWindingKept) {
  triangle_mesh m;
  m.vertices.positions = {vec3f(0, 0, 0), vec3f(1, 0, 0), vec3f(0, 1, 0), vec3f(0, 0, 0),
                          vec3f(1, 0, 0), vec3f(0, 1, 0), vec3f(5, 5, 5), vec3f(5, 5, 5)};
  m.faces = {{0, 1, 2}, {1, 2, 0}, {0, 2, 1}, {3, 4, 5}, {6, 1, 2}, {0, 1, 2}, {4, 5, 7}};
  EXPECT_EQ(unique_faces(m), (std::vector<std::uint32_t>{0, 2, 4}));
}

// One triangle repeated 50,000 times keeps one face; an empty mesh none; positions that differ
// only in the sign of zero are different as stored (kept).
TEST(RepeatedFaces, ManyRepeatsEmptyAndSignedZero) {
  triangle_mesh m;
  m.vertices.positions = {vec3f(0, 0, 0), vec3f(1, 0, 0), vec3f(0, 1, 0), vec3f(-0.0f, 0, 0)};
  m.faces.assign(50000, {0, 1, 2});
  EXPECT_EQ(unique_faces(m), (std::vector<std::uint32_t>{0}));
  m.faces.push_back({3, 1, 2});
  EXPECT_EQ(unique_faces(m).size(), 2u);
  EXPECT_TRUE(unique_faces(triangle_mesh{}).empty());
}

}  // namespace
}  // namespace pbr_lod
