#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "pbr_lod/core/bounds.hpp"

namespace pbr_lod {
namespace {

TEST(Bounds, SphereAboutBoxCentreContainsAllPoints) {
  std::mt19937 rng(42);  // any cloud will do: the property holds for every input
  std::uniform_real_distribution<float> u(-3, 7);
  std::vector<vec3f> pts(1000);
  for (auto& p : pts) p = vec3f(u(rng), u(rng), u(rng));
  const sphere s = bounding_sphere_about_box_centre(pts);
  for (const auto& p : pts) EXPECT_TRUE(s.contains(p));
  // Containment alone holds for any sphere that is too large: the centre is the box's (from a
  // plain min/max) and the radius the farthest point's distance from it, so it touches a point.
  vec3f lo = pts[0], hi = pts[0];
  for (const auto& p : pts) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  EXPECT_LT((s.centre - 0.5f * (lo + hi)).norm(), 1e-6f);
  float far = 0;
  for (const auto& p : pts) far = std::max(far, (p - s.centre).norm());
  EXPECT_NEAR(s.radius, far, 1e-5f * far);
}

// A cone of normals around +z with 10° semi-angle, a small sphere straight ahead: seen from
// +z (normals towards the eye) it is front-facing; seen from -z it faces away.
TEST(Bounds, BackFacingCone) {
  const sphere s{vec3f::Zero(), 0.1f};
  const normal_cone c{vec3f::UnitZ(), 10.0f * std::numbers::pi_v<float> / 180};
  EXPECT_FALSE(back_facing(s, c, vec3f(0, 0, 5)));
  EXPECT_TRUE(back_facing(s, c, vec3f(0, 0, -5)));
  // Grazing: eye in the tangent plane, never culled.
  EXPECT_FALSE(back_facing(s, c, vec3f(5, 0, 0)));
  // Eye inside the bounds: never culled.
  EXPECT_FALSE(back_facing(s, c, vec3f(0, 0, -0.05f)));
  // A full cone is never culled.
  EXPECT_FALSE(back_facing(s, normal_cone{}, vec3f(0, 0, -5)));
}

TEST(Bounds, EllipseCovers) {
  const elliptical_disk e{vec3f::Zero(), vec3f::UnitZ(), vec3f(2, 0, 0), vec3f(0, 1, 0)};
  EXPECT_TRUE(e.covers(vec3f(1.99f, 0, 0)));
  EXPECT_TRUE(e.covers(vec3f(0, 0.99f, 0)));
  EXPECT_FALSE(e.covers(vec3f(1.5f, 0.8f, 0)));  // (0.75)² + 0.8² > 1
}

}  // namespace
}  // namespace pbr_lod
