#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <vector>

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

// The view works in double until it is relative to the origin: a camera 10⁷ units away from the
// world origin sees data the same way as at the origin — the same eye and frame, so the same
// pixels. (A view that took the eye or the viewing direction in float at 10⁷, where floats are
// a unit apart, fails: the eye moves by units, the direction by degrees.)
TEST(Camera, OriginKeepsFarDataExact) {
  camera base = test_camera();  // off the integer grid, where floats at 10⁷ would round
  base.eye = vec3d(0.37, -0.21, 9.6);
  base.target = vec3d(0.05, 0.11, -0.3);
  camera c = base;
  const vec3d far(1e7, -3e6, 2e7);
  c.eye += far;
  c.target += far;
  const view v(c, far);
  const view v0(base, vec3d::Zero());
  EXPECT_EQ(v.eye, v0.eye);
  EXPECT_NEAR((v.forward - v0.forward).norm(), 0.0f, 1e-6f);
  EXPECT_NEAR((v.right - v0.right).norm(), 0.0f, 1e-6f);
  EXPECT_NEAR((v.up - v0.up).norm(), 0.0f, 1e-6f);
  for (const vec3f& p : {vec3f(0, 0, 0), vec3f(0.3f, -0.2f, 0.1f), vec3f(-1, 0.5f, 0.25f)}) {
    const vec2f a = v.eye_to_screen(v.to_eye(p)), b = v0.eye_to_screen(v0.to_eye(p));
    EXPECT_NEAR(a.x(), b.x(), 1e-3f) << p.transpose();
    EXPECT_NEAR(a.y(), b.y(), 1e-3f) << p.transpose();
  }
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
    // The estimates' own values (the orderings above hold for 0 too): the camera sits at
    // (0, 0, 10) looking down −z, so the eye-space depth is 10 − c.z and the distance |c − eye|.
    const float f = v.focal_px, depth = 10 - c.z(), dist = (c - vec3f(0, 0, 10)).norm();
    EXPECT_NEAR(projected_radius_eye_z(v, s), f * 0.5f / depth, 1e-5f * exact);
    EXPECT_NEAR(projected_radius_distance(v, s), f * 0.5f / dist, 1e-5f * exact);
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

// Against sampled spheres (random centres in and around the view volume, radii 0.05–6): a
// sphere the test calls outside (−1) has no sampled point inside the view volume (on screen,
// depth within [z_near, z_far]); one it calls inside (0) has every sampled point inside. The
// four spheres of FrustumClassifiesSpheres lie on the x and z axes, where top and bottom planes
// built with the horizontal half-angle still classify them right.
TEST(Camera, FrustumAgreesWithSampledSpheres) {
  const view v(test_camera(), vec3d::Zero());
  std::vector<vec3f> dirs;  // a Fibonacci sphere of directions, and the centre itself
  const float golden = std::numbers::pi_v<float> * (3 - std::sqrt(5.0f));
  for (int i = 0; i < 300; ++i) {
    const float y = 1 - 2 * (float(i) + 0.5f) / 300, r = std::sqrt(1 - y * y);
    dirs.emplace_back(r * std::cos(golden * float(i)), y, r * std::sin(golden * float(i)));
  }
  dirs.emplace_back(vec3f::Zero());
  // Inside / outside by a margin, so that rounding at a plane decides nothing.
  const auto where = [&](const vec3f& p) {
    const vec3f e = v.to_eye(p);
    const float m = 1e-3f;
    if (e.z() < v.z_near * (1 - m) || e.z() > v.z_far * (1 + m)) return -1;
    if (e.z() < v.z_near * (1 + m) || e.z() > v.z_far * (1 - m)) return 0;
    const vec2f q = v.eye_to_screen(e);
    const float mx = m * float(v.width), my = m * float(v.height);
    if (q.x() < -mx || q.x() > float(v.width) + mx || q.y() < -my || q.y() > float(v.height) + my)
      return -1;
    if (q.x() < mx || q.x() > float(v.width) - mx || q.y() < my || q.y() > float(v.height) - my)
      return 0;
    return 1;
  };
  std::mt19937 rng(8);  // seeded: any spheres will do, the property holds for each
  std::uniform_real_distribution<float> xy(-45, 45), z(-100, 12), radius(0.05f, 6);
  int outside = 0, inside = 0, straddling = 0;
  for (int k = 0; k < 4000; ++k) {
    const sphere s{vec3f(xy(rng), 0.75f * xy(rng), z(rng)), radius(rng)};
    const int r = frustum_test(v, s);
    int in = 0, out = 0;
    for (const vec3f& d : dirs) {
      const int w = where(s.centre + s.radius * d);
      in += w > 0;
      out += w < 0;
    }
    if (r < 0) {
      ++outside;
      ASSERT_EQ(in, 0) << k << ": culled, but " << in << " sampled points are in view";
    } else if (r == 0) {
      ++inside;
      ASSERT_EQ(out, 0) << k << ": inside, but " << out << " sampled points are out of view";
    } else {
      ++straddling;
    }
  }
  EXPECT_GT(outside, 400);
  EXPECT_GT(inside, 400);
  EXPECT_GT(straddling, 400);
}

}  // namespace
}  // namespace pbr_lod
