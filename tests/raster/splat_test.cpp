// Splats and points: the exact perspective footprint of elliptical splats (against the area of
// the projected conic, a polygon of the projected rim, and a per-pixel ray cast), near-plane
// clipping, square points and the z-buffer.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "pbr_lod/raster/rasterizer.hpp"
#include "support/cameras.hpp"

namespace pbr_lod {
namespace {

using test::origin_camera;

struct ellipse3 {
  vec3f c, u, v;
};

image draw_splats(const view& v, const std::vector<ellipse3>& es) {
  return render<positions_only>(v, render_options{}, [&](auto& sink) {
    for (const auto& e : es) sink.splat(splat_prim<positions_only>{e.c, e.u, e.v});
  });
}

/// Homogeneous screen image (x·w, y·w, w) of an eye-space point or direction (the perspective
/// map is linear in eye coordinates).
vec3d hom(const view& v, const vec3f& e) {
  const double f = v.focal_px, cx = 0.5 * v.width, cy = 0.5 * v.height;
  return {f * e.x() + cx * e.z(), -f * e.y() + cy * e.z(), double(e.z())};
}

/// Area of the projected ellipse from its conic: with P = [u' v' c'] the homogeneous images,
/// the screen conic is C = P⁻ᵀ diag(1, 1, −1) P⁻¹ and the area of {xᵀCx ≤ 0} is
/// π·|det C| / det(C₂)^{3/2} (C₂ its upper-left 2×2 block).
double conic_area(const view& v, const ellipse3& e) {
  Eigen::Matrix3d P;
  P.col(0) = hom(v, v.to_eye(e.c + e.u) - v.to_eye(e.c));
  P.col(1) = hom(v, v.to_eye(e.c + e.v) - v.to_eye(e.c));
  P.col(2) = hom(v, v.to_eye(e.c));
  const Eigen::Matrix3d Pi = P.inverse();
  const Eigen::Matrix3d C = Pi.transpose() * Eigen::Vector3d(1, 1, -1).asDiagonal() * Pi;
  return std::numbers::pi * std::abs(C.determinant()) /
         std::pow(C.topLeftCorner<2, 2>().determinant(), 1.5);
}

/// Area of the polygon through 4096 projected points of the splat's rim (shoelace): the rim of a
/// planar ellipse projects onto the rim of its image, independent of any conic algebra.
double rim_polygon_area(const view& v, const ellipse3& e) {
  const int n = 4096;
  double a = 0;
  vec2f prev = v.eye_to_screen(v.to_eye(e.c + e.u));
  for (int i = 1; i <= n; ++i) {
    const double th = 2 * std::numbers::pi * i / n;
    const vec3f p = e.c + float(std::cos(th)) * e.u + float(std::sin(th)) * e.v;
    const vec2f s = v.eye_to_screen(v.to_eye(p));
    a += double(prev.x()) * s.y() - double(s.x()) * prev.y();
    prev = s;
  }
  return std::abs(a) / 2;
}

/// Per-pixel ray cast: +1 when the ray through the pixel centre hits the splat's plane inside the
/// ellipse at depth ≥ z_near, 0 when not, −1 within 1e-4 of the rim or the near plane.
int ray_cast(const view& v, const ellipse3& e, double px, double py) {
  const vec3d c = v.to_eye(e.c).cast<double>();
  const vec3d u = (v.to_eye(e.c + e.u) - v.to_eye(e.c)).cast<double>();
  const vec3d w = (v.to_eye(e.c + e.v) - v.to_eye(e.c)).cast<double>();
  const vec3d d((px - 0.5 * v.width) / v.focal_px, -(py - 0.5 * v.height) / v.focal_px, 1);
  const vec3d n = u.cross(w);
  const double t = n.dot(c) / n.dot(d);  // depth of the hit (d.z = 1)
  const vec3d q = t * d - c;
  const double s = q.dot(u) / u.squaredNorm(), r = q.dot(w) / w.squaredNorm();
  const double rho = s * s + r * r;
  if (std::abs(rho - 1) < 1e-4 || std::abs(t - v.z_near) < 1e-4 * v.z_near) return -1;
  return (rho <= 1 && t >= v.z_near) ? 1 : 0;
}

/// An ellipse with semi-axes a, b, its plane tilted by `tilt` about the x axis, then turned by
/// `spin` about the view axis, centred at c.
ellipse3 make_ellipse(vec3f c, float a, float b, float tilt, float spin) {
  const Eigen::AngleAxisf r(spin, vec3f::UnitZ()), t(tilt, vec3f::UnitX());
  const Eigen::Matrix3f m = (r * t).toRotationMatrix();
  return {c, m * vec3f(a, 0, 0), m * vec3f(0, b, 0)};
}

// Oblique splats at several positions: the number of covered pixel centres matches the area of
// the projected ellipse within 2 % (a region of ≥ 2000 px has a boundary of a few hundred px, so
// the centre-count error is well under 1 %), and the conic formula agrees with the rim polygon.
TEST(Splat, FootprintMatchesProjectedEllipseArea) {
  const view v(origin_camera(320, 240), vec3d::Zero());
  const std::vector<ellipse3> cases = {
      make_ellipse({0, 0, -3}, 0.6f, 0.3f, 0.0f, 0.0f),
      make_ellipse({0.4f, 0.2f, -2.5f}, 0.6f, 0.35f, 1.0f, 0.3f),
      make_ellipse({-0.6f, -0.3f, -2.0f}, 0.4f, 0.35f, 1.2f, 2.0f),
      make_ellipse({0.8f, -0.5f, -3.5f}, 0.9f, 0.45f, -0.9f, -0.7f),
      make_ellipse({-0.3f, 0.4f, -1.5f}, 0.4f, 0.4f, 1.35f, 0.9f),  // steep: strongly perspective
  };
  for (std::size_t k = 0; k < cases.size(); ++k) {
    const ellipse3& e = cases[k];
    const double area = conic_area(v, e);
    ASSERT_GE(area, 2000) << "case " << k;
    EXPECT_NEAR(area, rim_polygon_area(v, e), 1e-3 * area) << "case " << k;
    const image img = draw_splats(v, {e});
    EXPECT_NEAR(double(img.covered_count()), area, 0.02 * area) << "case " << k;
    // And pixel by pixel, against a ray cast.
    for (int y = 0; y < v.height; ++y)
      for (int x = 0; x < v.width; ++x) {
        const int want = ray_cast(v, e, x + 0.5, y + 0.5);
        if (want >= 0) {
          ASSERT_EQ(img.covered(x, y), want == 1) << k << ": " << x << "," << y;
        }
      }
  }
}

// The depth stored is the ray–plane intersection depth, not the centre's depth.
TEST(Splat, DepthIsRayPlaneIntersection) {
  const view v(origin_camera(160, 120), vec3d::Zero());
  const ellipse3 e = make_ellipse({0.1f, 0, -2}, 0.6f, 0.5f, 1.0f, 0.4f);
  const image img = draw_splats(v, {e});
  const vec3d c = v.to_eye(e.c).cast<double>();
  const vec3d n = (v.to_eye(e.c + e.u) - v.to_eye(e.c))
                      .cast<double>()
                      .cross((v.to_eye(e.c + e.v) - v.to_eye(e.c)).cast<double>());
  int n_checked = 0;
  for (int y = 0; y < v.height; ++y)
    for (int x = 0; x < v.width; ++x) {
      if (!img.covered(x, y)) continue;
      const vec3d d((x + 0.5 - 80) / v.focal_px, -(y + 0.5 - 60) / v.focal_px, 1);
      const double z = n.dot(c) / n.dot(d);
      ASSERT_NEAR(img.depth[img.index(x, y)], z, 1e-5 * z);
      ++n_checked;
    }
  EXPECT_GT(n_checked, 1000);
}

// A splat that reaches behind the eye: only the part at depth ≥ z_near is drawn, pixel for
// pixel as the ray cast says, and nothing is nearer than z_near.
TEST(Splat, StraddlingTheNearPlaneIsClipped) {
  const view v(origin_camera(160, 120, 0.5), vec3d::Zero());
  // A disk of radius 2 in the plane y = −0.3, centred at depth 1: it extends to depth −1.
  const ellipse3 e{vec3f(0, -0.3f, -1), vec3f(2, 0, 0), vec3f(0, 0, 2)};
  const image img = draw_splats(v, {e});
  EXPECT_GT(img.covered_count(), 1000u);
  for (int y = 0; y < v.height; ++y)
    for (int x = 0; x < v.width; ++x) {
      if (img.covered(x, y)) {
        ASSERT_GE(img.depth[img.index(x, y)], 0.5f * (1 - 1e-5f));
      }
      const int want = ray_cast(v, e, x + 0.5, y + 0.5);
      if (want >= 0) {
        ASSERT_EQ(img.covered(x, y), want == 1) << x << "," << y;
      }
    }
}

// Small splats, as a traversal emits them (radius ~1–4 px), still match the ray cast.
TEST(Splat, SmallSplatsMatchRayCast) {
  const view v(origin_camera(128, 128), vec3d::Zero());
  std::mt19937 rng(3);  // seeded: random orientations and sub-pixel positions
  std::uniform_real_distribution<float> pos(-0.5f, 0.5f), ang(-1.4f, 1.4f), r(0.01f, 0.04f);
  for (int k = 0; k < 200; ++k) {
    const ellipse3 e =
        make_ellipse({pos(rng), pos(rng), -2}, r(rng), r(rng), ang(rng), 3 * ang(rng));
    const image img = draw_splats(v, {e});
    for (int y = 0; y < v.height; ++y)
      for (int x = 0; x < v.width; ++x) {
        const int want = ray_cast(v, e, x + 0.5, y + 0.5);
        if (want >= 0) {
          ASSERT_EQ(img.covered(x, y), want == 1) << k << ": " << x << "," << y;
        }
      }
  }
}

// One-pixel points land in the pixel that contains their projection; a square of integer side s
// covers exactly s² pixels wherever its centre is (a half-open interval of length s contains s
// pixel centres). Which pixels: those whose centres lie in [sx − s/2, sx + s/2) ×
// [sy − s/2, sy + s/2), pixel for pixel (the count alone holds for a square one pixel off), also
// for sides that are not whole numbers.
TEST(Point, OnePixelAndSquares) {
  const view v(origin_camera(100, 80), vec3d::Zero());
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> xy(-0.5f, 0.5f);
  int checked = 0;
  for (int k = 0; k < 50; ++k) {
    const vec3f p(xy(rng), xy(rng), -2);
    const vec2f s = v.eye_to_screen(v.to_eye(p));
    for (float size : {1.0f, 0.3f, 2.0f, 3.0f, 5.0f, 2.5f, 4.2f}) {
      const image img = render<positions_only>(v, render_options{}, [&](auto& sink) {
        sink.point(point_prim<positions_only>{p, size});
      });
      if (size == std::floor(size) || size <= 1) {
        const int side = size <= 1 ? 1 : int(size);
        ASSERT_EQ(img.covered_count(), std::size_t(side * side)) << k << " size " << size;
      }
      if (size <= 1) {
        EXPECT_TRUE(img.covered(int(s.x()), int(s.y())));
        continue;
      }
      // +1 inside, 0 outside, −1 within 1e-3 px of an edge (the test's projection may round
      // differently from the rasteriser's there).
      const auto in = [&](double c, double centre) {
        const double lo = centre - 0.5 * size, hi = centre + 0.5 * size;
        if (std::abs(c - lo) < 1e-3 || std::abs(c - hi) < 1e-3) return -1;
        return (c >= lo && c < hi) ? 1 : 0;
      };
      for (int y = 0; y < v.height; ++y)
        for (int x = 0; x < v.width; ++x) {
          const int ix = in(x + 0.5, s.x()), iy = in(y + 0.5, s.y());
          if (ix < 0 || iy < 0) continue;
          ASSERT_EQ(img.covered(x, y), ix == 1 && iy == 1)
              << k << " size " << size << ": " << x << "," << y;
          ++checked;
        }
    }
  }
  EXPECT_GT(checked, 50 * 5 * 7000);
}

// Near over far for points and splats, whatever the order.
TEST(Point, DepthOrderIndependentOfDrawOrder) {
  constexpr attributes A{.colour = true};
  const view v(origin_camera(64, 64), vec3d::Zero());
  const auto scene = [&](bool near_first) {
    return render<A>(v, render_options{}, [&](auto& sink) {
      point_prim<A> pn{vec3f(0, 0, -1), 9}, pf{vec3f(0, 0, -2), 15};
      pn.colour = {255, 0, 0};
      pf.colour = {0, 255, 0};
      splat_prim<A> sn{vec3f(0.5f, 0, -2), vec3f(0.2f, 0, 0), vec3f(0, 0.2f, 0)};
      splat_prim<A> sf{vec3f(0.5f, 0, -3), vec3f(0.4f, 0, 0), vec3f(0, 0.4f, 0)};
      sn.colour = {255, 0, 0};
      sf.colour = {0, 255, 0};
      if (near_first) {
        sink.point(pn);
        sink.splat(sn);
        sink.point(pf);
        sink.splat(sf);
      } else {
        sink.splat(sf);
        sink.point(pf);
        sink.splat(sn);
        sink.point(pn);
      }
    });
  };
  const image a = scene(true), b = scene(false);
  EXPECT_EQ(a, b);
  EXPECT_EQ(a.at(32, 32), (rgb8{255, 0, 0}));  // the near point's centre
  const vec2f s = v.eye_to_screen(v.to_eye(vec3f(0.5f, 0, -2)));
  EXPECT_EQ(a.at(int(s.x()), int(s.y())), (rgb8{255, 0, 0}));  // the near splat's centre
}

}  // namespace
}  // namespace pbr_lod
