#include <gtest/gtest.h>

#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/synthetic.hpp"

namespace pbr_lod {
namespace {

// The demo scene is a valid mesh whose vertex normals agree with the winding (outward faces).
TEST(Synthetic, DemoSceneIsConsistent) {
  const auto m = make_demo_scene(16);
  EXPECT_NO_THROW(m.validate());
  EXPECT_GT(m.num_faces(), 2000u);
  const auto& P = m.vertices.positions;
  std::size_t agree = 0;
  for (const auto& f : m.faces) {
    const vec3f fn = (P[f[1]] - P[f[0]]).cross(P[f[2]] - P[f[0]]);
    if (fn.norm() == 0) continue;
    agree += fn.dot(m.vertices.normals[f[0]]) > 0;
  }
  EXPECT_EQ(agree, m.num_faces());
}

TEST(Synthetic, SamplesLieOnTheSurface) {
  const auto m = make_demo_scene(8);
  const auto c = sample_surface(m, 1000, 1);
  ASSERT_EQ(c.size(), 1000u);
  ASSERT_EQ(c.normals.size(), 1000u);
  ASSERT_EQ(c.colours.size(), 1000u);
  const box3 b = box3::of(m.vertices.positions);
  for (const auto& p : c.positions) {
    EXPECT_TRUE((p.array() >= b.min.array() - 1e-5f).all());
    EXPECT_TRUE((p.array() <= b.max.array() + 1e-5f).all());
  }
  // Deterministic for a seed.
  EXPECT_EQ(sample_surface(m, 10, 5).positions, sample_surface(m, 10, 5).positions);
}

TEST(Synthetic, WavySurfaceHasUnitNormals) {
  const auto c = make_wavy_surface(1000);
  for (const auto& n : c.normals) EXPECT_NEAR(n.norm(), 1.0f, 1e-4f);
}

}  // namespace
}  // namespace pbr_lod
