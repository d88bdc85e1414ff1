#include <gtest/gtest.h>

#include <random>

#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/traverse/culling.hpp"
#include "pbr_lod/traverse/screen_size.hpp"

namespace pbr_lod {
namespace {

camera test_camera() {
  camera c;
  c.eye = vec3d(0, 0, 10);
  c.target = vec3d::Zero();
  c.vp = {640, 480};
  c.z_near = 0.1;
  c.z_far = 100;
  return c;
}

TEST(Camera, ProjectsTargetToCentre) {
  const view v(test_camera(), vec3d::Zero());
  const vec2f s = v.eye_to_screen(v.to_eye(vec3f::Zero()));
  EXPECT_FLOAT_EQ(s.x(), 320);
  EXPECT_FLOAT_EQ(s.y(), 240);
  // A point one unit up appears above the centre (y down on screen).
  EXPECT_LT(v.eye_to_screen(v.to_eye(vec3f(0, 1, 0))).y(), 240);
}

// The view subtracts the origin in double: a camera 10⁷ units away from the world origin sees
// data the same way as at the origin.
TEST(Camera, OriginKeepsFarDataExact) {
  camera c = test_camera();
  const vec3d far(1e7, -3e6, 2e7);
  c.eye += far;
  c.target += far;
  const view v(c, far);
  const view v0(test_camera(), vec3d::Zero());
  EXPECT_EQ(v.eye, v0.eye);
}

TEST(Camera, RejectsBadViewport) {
  camera c = test_camera();
  c.vp = {0, 10};
  EXPECT_THROW(view(c, vec3d::Zero()), InvalidArgument);
  c = test_camera();
  c.target = c.eye;
  EXPECT_THROW(view(c, vec3d::Zero()), InvalidArgument);
}

/// Brute force: project many points of the sphere's silhouette... simpler and exact enough: sample
/// the sphere surface densely, project every sample, and take half the largest extent along the
/// radial screen direction (the major axis of the projected ellipse).
float brute_force_major_radius(const view& v, const sphere& s) {
  const vec2f c0 = v.eye_to_screen(v.to_eye(s.centre));
  vec2f radial = c0 - vec2f(0.5f * v.width, 0.5f * v.height);
  radial = radial.norm() > 1e-6f ? radial.normalized() : vec2f(1, 0);
  float lo = 1e30f, hi = -1e30f;
  const int n = 400;
  for (int i = 0; i <= n; ++i) {
    const double th = std::numbers::pi * i / n;
    for (int j = 0; j < 2 * n; ++j) {
      const double ph = std::numbers::pi * j / n;
      const vec3f p = s.centre + s.radius * vec3f(static_cast<float>(std::sin(th) * std::cos(ph)),
                                                  static_cast<float>(std::sin(th) * std::sin(ph)),
                                                  static_cast<float>(std::cos(th)));
      const float t = v.eye_to_screen(v.to_eye(p)).dot(radial);
      lo = std::min(lo, t);
      hi = std::max(hi, t);
    }
  }
  return 0.5f * (hi - lo);
}

// Exact projection equals the brute-force extent within sampling error; the approximations
// underestimate off-axis, by the amount the docs quote.
TEST(Camera, SphereProjectionExactMatchesBruteForce) {
  const view v(test_camera(), vec3d::Zero());
  for (const vec3f& c : {vec3f(0, 0, 0), vec3f(2, 1, 0), vec3f(3, -2, 2), vec3f(-1.5f, 1.5f, -4)}) {
    const sphere s{c, 0.5f};
    const float exact = projected_radius_exact(v, s);
    const float brute = brute_force_major_radius(v, s);
    EXPECT_NEAR(exact, brute, 1e-3f * exact) << "centre " << c.transpose();
    EXPECT_LE(projected_radius_eye_z(v, s), exact * 1.0001f);
    EXPECT_LE(projected_radius_distance(v, s), projected_radius_eye_z(v, s) * 1.0001f);
  }
  // On the axis the exact value is f·tan(asin(r/d)) = f·r/sqrt(d²−r²).
  const sphere s{vec3f::Zero(), 1};
  EXPECT_NEAR(projected_radius_exact(v, s), v.focal_px / std::sqrt(99.0f), 1e-3f);
  EXPECT_NEAR(projected_minor_radius_exact(v, s), projected_radius_exact(v, s), 1e-3f);
}

TEST(Camera, SphereReachingEyePlaneIsInfinite) {
  const view v(test_camera(), vec3d::Zero());
  EXPECT_TRUE(std::isinf(projected_radius_exact(v, sphere{vec3f(0, 0, 9.5f), 1})));
  EXPECT_TRUE(std::isinf(projected_radius_exact(v, sphere{vec3f(0, 0, 20), 1})));  // behind
}

// PMR's estimate: the world size of a pixel at distance d on the axis is d/f, so the radius in
// pixels of a small sphere is r·f/d at the nearest corner.
TEST(Camera, PmrPixelSizeOnAxis) {
  const view v(test_camera(), vec3d::Zero());
  EXPECT_NEAR(pixel_size_pmr(v, vec3f::Zero()), 10.0f / v.focal_px, 1e-3f * 10.0f / v.focal_px);
  const sphere s{vec3f::Zero(), 0.01f};
  EXPECT_NEAR(projected_radius_pmr(v, s), projected_radius_eye_z(v, s),
              0.01f * projected_radius_eye_z(v, s));
}

TEST(Camera, FrustumClassifiesSpheres) {
  const view v(test_camera(), vec3d::Zero());
  EXPECT_EQ(frustum_test(v, sphere{vec3f::Zero(), 0.1f}), 0);     // inside
  EXPECT_EQ(frustum_test(v, sphere{vec3f(0, 0, 20), 1}), -1);     // behind the eye
  EXPECT_EQ(frustum_test(v, sphere{vec3f(100, 0, 0), 1}), -1);    // far right
  EXPECT_GT(frustum_test(v, sphere{vec3f(0, 0, -89.5f), 1}), 0);  // straddles the far plane
}

}  // namespace
}  // namespace pbr_lod
