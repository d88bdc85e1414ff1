// The trigonometry-free culling tests (Pajarola 2003 §6, Fig. 10) against the angles taken
// literally, in double: γ − α > ω for the view cone, a + θ + β < π/2 for back faces.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/traverse/culling.hpp"
#include "support/trig_culling.hpp"

namespace pbr_lod {
namespace {

constexpr double pi = std::numbers::pi;

// Angle between two vectors in double, the reference's way.
double angle(const vec3d& a, const vec3d& b) {
  return std::acos(std::clamp(a.dot(b) / (a.norm() * b.norm()), -1.0, 1.0));
}

// Random spheres about a random view. A case whose literal margin is within `eps` radians of
// the boundary is skipped: float rounding may fall either way there.
TEST(Culling, ViewConeWithoutTrigonometryMatchesTheAngles) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1), fov(10, 120), rad(0, 2);
  int outside = 0, inside = 0;
  for (int i = 0; i < 20000; ++i) {
    camera c;
    c.eye = vec3d(u(rng), u(rng), u(rng)) * 5;
    c.target = c.eye + vec3d(u(rng), u(rng), u(rng));
    if ((c.target - c.eye).norm() < 0.1) continue;
    c.fovy_degrees = fov(rng);
    c.vp = {i % 2 ? 640 : 300, 480};
    const view v(c, vec3d::Zero());
    const sphere s{vec3f(u(rng), u(rng), u(rng)) * 10, static_cast<float>(rad(rng))};
    const vec3d d = s.centre.cast<double>() - v.eye.cast<double>();
    if (d.norm() <= s.radius) continue;
    const double hx = 0.5 * v.width / v.focal_px, hy = v.tan_half_fovy;
    const double omega = std::atan(std::sqrt(hx * hx + hy * hy));
    const double margin =
        angle(d, v.forward.cast<double>()) - std::asin(s.radius / d.norm()) - omega;
    if (std::abs(margin) < 1e-3) continue;
    const bool expected = margin > 0;
    ASSERT_EQ(outside_view_cone(v, s), expected) << "case " << i << ", margin " << margin;
    ASSERT_EQ(test::outside_view_cone_trig(v, s), expected) << "case " << i;
    (expected ? outside : inside)++;
  }
  // Both answers occur often, so the comparison above tested both branches.
  EXPECT_GT(outside, 5000);
  EXPECT_GT(inside, 2000);
}

// A sphere straight ahead is inside; one whose nearest edge lies just beyond the cone's corner
// angle ω is outside, just inside it is kept (ω for a 90° square view is atan(√2)).
TEST(Culling, ViewConeBoundaryAtTheCorners) {
  camera c;
  c.eye = vec3d::Zero();
  c.target = vec3d(0, 0, -1);
  c.fovy_degrees = 90;
  c.vp = {400, 400};
  const view v(c, vec3d::Zero());
  const double omega = std::atan(std::sqrt(2.0));
  EXPECT_NEAR(v.cos_cone, std::cos(omega), 1e-6);
  EXPECT_NEAR(v.sin_cone, std::sin(omega), 1e-6);
  EXPECT_FALSE(outside_view_cone(v, {vec3f(0, 0, -10), 1}));
  const double alpha = std::asin(0.5 / 10.0);  // r = 0.5 at distance 10
  for (const double delta : {-0.01, 0.01}) {
    const double g = omega + alpha + delta;  // centre direction at angle g from the axis
    const vec3f centre = (10 * vec3d(std::sin(g), 0, -std::cos(g))).cast<float>();
    EXPECT_EQ(outside_view_cone(v, {centre, 0.5f}), delta > 0) << delta;
  }
  // Behind the eye: outside; the eye inside the sphere: kept.
  EXPECT_TRUE(outside_view_cone(v, {vec3f(0, 0, 10), 1}));
  EXPECT_FALSE(outside_view_cone(v, {vec3f(0, 0, 0.5f), 1}));
}

TEST(Culling, BackFacingWithoutTrigonometryMatchesTheAngles) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1, 1), theta(0, 1.7), rad(0, 1.5);
  int culled = 0, kept = 0;
  for (int i = 0; i < 40000; ++i) {
    const vec3d axis = vec3d(u(rng), u(rng), u(rng));
    if (axis.norm() < 0.1) continue;
    const double th = theta(rng);
    const sphere s{vec3f(u(rng), u(rng), u(rng)), static_cast<float>(rad(rng))};
    const vec3f eye = (vec3d(u(rng), u(rng), u(rng)) * 6).cast<float>();
    const vec3d d = s.centre.cast<double>() - eye.cast<double>();
    if (d.norm() <= s.radius || th >= pi / 2) continue;
    const double margin = pi / 2 - (angle(axis, d) + th + std::asin(s.radius / d.norm()));
    if (std::abs(margin) < 1e-3) continue;
    const bool expected = margin > 0;
    const vec3f a = axis.normalized().cast<float>();
    const normal_cone_cs cs{a, static_cast<float>(std::cos(th)), static_cast<float>(std::sin(th))};
    ASSERT_EQ(back_facing(s, cs, eye), expected) << "case " << i << ", margin " << margin;
    ASSERT_EQ(back_facing(s, normal_cone{a, static_cast<float>(th)}, eye), expected) << i;
    ASSERT_EQ(test::back_facing_trig(s, normal_cone{a, static_cast<float>(th)}, eye), expected);
    (expected ? culled : kept)++;
  }
  EXPECT_GT(culled, 1000);
  EXPECT_GT(kept, 1000);
}

// θ + β just below and above 90° with the axis pointing straight away from the eye: the first
// condition (cos(θ + β) > 0) alone decides; and a cone of θ ≥ 90° never culls.
TEST(Culling, BackFacingBoundaryOfTheConeAngle) {
  const vec3f eye(0, 0, 0);
  const sphere s{vec3f(0, 0, -10), 5};  // β = 30°
  for (const double deg : {59.0, 61.0}) {
    const double th = deg * pi / 180;
    const normal_cone_cs cs{vec3f(0, 0, -1), static_cast<float>(std::cos(th)),
                            static_cast<float>(std::sin(th))};
    EXPECT_EQ(back_facing(s, cs, eye), deg < 60) << deg;
  }
  EXPECT_FALSE(back_facing(s, normal_cone_cs{vec3f(0, 0, -1), 0.0f, 1.0f}, eye));
  EXPECT_FALSE(back_facing(s, normal_cone_cs{}, eye));
}

}  // namespace
}  // namespace pbr_lod
