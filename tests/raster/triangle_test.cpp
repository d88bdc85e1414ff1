// Triangles: coverage against a brute-force evaluation of the top-left rule at pixel centres,
// watertightness of shared edges (also after near-plane clipping), perspective-correct
// interpolation and the z-buffer.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "pbr_lod/raster/rasterizer.hpp"
#include "support/cameras.hpp"

namespace pbr_lod {
namespace {

using tri = std::array<vec3f, 3>;

using test::origin_camera;

image draw(const view& v, const std::vector<tri>& tris, effects fx = no_effects) {
  render_options opt;
  opt.fx = fx;
  return render<positions_only>(v, opt, [&](auto& sink) {
    for (const tri& t : tris) {
      triangle_prim<positions_only> p;
      p.p = t;
      sink.triangle(p);
    }
  });
}

vec2d screen(const view& v, const vec3f& p) {
  const vec3f e = v.to_eye(p);
  return {0.5 * v.width + double(v.focal_px) * e.x() / e.z(),
          0.5 * v.height - double(v.focal_px) * e.y() / e.z()};
}

/// The coverage rule, evaluated independently: +1 covered, 0 not, −1 when a pixel centre lies
/// within 1e-6 px of an edge (where rounding of the projection may legitimately decide).
int brute_force(const std::array<vec2d, 3>& s, double px, double py) {
  // Orientation: counter-clockwise on the (y-down) screen is the front; make inside positive.
  const double area =
      (s[0].x() - s[1].x()) * (s[2].y() - s[1].y()) - (s[0].y() - s[1].y()) * (s[2].x() - s[1].x());
  if (area == 0) return 0;
  const double o = area > 0 ? 1 : -1;
  bool inside = true;
  for (int i = 0; i < 3; ++i) {
    const vec2d a = s[static_cast<std::size_t>((i + 1) % 3)],
                b = s[static_cast<std::size_t>((i + 2) % 3)];
    const double e = o * ((px - a.x()) * (b.y() - a.y()) - (py - a.y()) * (b.x() - a.x()));
    if (std::abs(e) < 1e-6 * (b - a).norm()) return -1;
    // Top-left: a left edge has its inside towards +x, a top edge is horizontal, inside below.
    const double ga = o * (b.y() - a.y()), gb = -o * (b.x() - a.x());
    const bool tl = ga > 0 || (ga == 0 && gb > 0);
    inside = inside && (e > 0 || (e == 0 && tl));
  }
  return inside ? 1 : 0;
}

// Random triangles of every size and both windings: every pixel whose centre is not within
// 1e-6 px of an edge is covered iff the rule says so.
TEST(Triangle, CoverageMatchesBruteForce) {
  const view v(origin_camera(97, 83), vec3d::Zero());
  std::mt19937 rng(42);  // seeded: random triangles exercise every edge slope; fixed for CI
  std::uniform_real_distribution<float> xy(-0.8f, 0.8f), z(-3.0f, -1.0f);
  int ambiguous = 0, checked = 0;
  for (int n = 0; n < 60; ++n) {
    const tri t = {vec3f(xy(rng), xy(rng), z(rng)), vec3f(xy(rng), xy(rng), z(rng)),
                   vec3f(xy(rng), xy(rng), z(rng))};
    const image img = draw(v, {t});
    const std::array<vec2d, 3> s = {screen(v, t[0]), screen(v, t[1]), screen(v, t[2])};
    for (int y = 0; y < v.height; ++y)
      for (int x = 0; x < v.width; ++x) {
        const int want = brute_force(s, x + 0.5, y + 0.5);
        if (want < 0) {
          ++ambiguous;
          continue;
        }
        ++checked;
        ASSERT_EQ(img.covered(x, y), want == 1) << "triangle " << n << " pixel " << x << "," << y;
      }
  }
  EXPECT_GT(checked, 100000);
  EXPECT_LT(ambiguous, 10);
}

// A shared vertical edge at eye x = 0 projects to the screen column x = width/2 = 50.5 exactly
// (for any depth), i.e. through the centres of column 50. Every centre on it belongs to exactly
// one triangle — the one to its right, for which it is a left edge.
TEST(Triangle, SharedVerticalEdgeThroughPixelCentres) {
  const view v(origin_camera(101, 101), vec3d::Zero());
  const vec3f a(0, -0.4f, -1), b(0, 0.3f, -1.3f);
  const vec3f left(-0.3f, 0.1f, -1.2f), right(0.35f, -0.1f, -0.8f);
  const image l = draw(v, {{a, b, left}}), r = draw(v, {{b, a, right}});
  const double ya = screen(v, a).y(), yb = screen(v, b).y();
  int on_edge = 0;
  for (int y = 0; y < v.height; ++y) {
    for (int x = 0; x < v.width; ++x) ASSERT_FALSE(l.covered(x, y) && r.covered(x, y));
    const double cy = y + 0.5;
    if (cy > std::min(ya, yb) + 1e-3 && cy < std::max(ya, yb) - 1e-3) {
      ++on_edge;
      EXPECT_TRUE(r.covered(50, y)) << y;
      EXPECT_FALSE(l.covered(50, y)) << y;
    }
  }
  EXPECT_GT(on_edge, 20);
}

// A shared horizontal edge at eye y = 0 lies on the row of centres y = 50.5: those centres belong
// to the triangle below it, for which it is a top edge.
TEST(Triangle, SharedHorizontalEdgeThroughPixelCentres) {
  const view v(origin_camera(101, 101), vec3d::Zero());
  const vec3f a(-0.4f, 0, -1), b(0.3f, 0, -1.2f);
  const vec3f above(0.1f, 0.3f, -1.1f), below(-0.1f, -0.35f, -0.9f);
  const image up = draw(v, {{b, a, above}}), down = draw(v, {{a, b, below}});
  const double xa = screen(v, a).x(), xb = screen(v, b).x();
  int on_edge = 0;
  for (int x = 0; x < v.width; ++x) {
    for (int y = 0; y < v.height; ++y) ASSERT_FALSE(up.covered(x, y) && down.covered(x, y));
    const double cx = x + 0.5;
    if (cx > std::min(xa, xb) + 1e-3 && cx < std::max(xa, xb) - 1e-3) {
      ++on_edge;
      EXPECT_TRUE(down.covered(x, 50)) << x;
      EXPECT_FALSE(up.covered(x, 50)) << x;
    }
  }
  EXPECT_GT(on_edge, 20);
}

/// A jittered grid of 2·n² triangles on the plane z = −depth − 0.4x − 0.3y over [−s, s]².
/// Interior vertices move within the plane, the outer boundary stays a square.
std::vector<tri> jittered_grid(int n, float s, float depth, std::mt19937& rng) {
  std::uniform_real_distribution<float> jitter(-0.3f, 0.3f);
  std::vector<vec3f> p;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      float x = -s + 2 * s * float(i) / float(n), y = -s + 2 * s * float(j) / float(n);
      if (i > 0 && i < n && j > 0 && j < n) {
        x += jitter(rng) * 2 * s / float(n);
        y += jitter(rng) * 2 * s / float(n);
      }
      p.emplace_back(x, y, -depth - 0.4f * x - 0.3f * y);
    }
  std::vector<tri> t;
  const auto at = [&](int i, int j) { return p[static_cast<std::size_t>(j * (n + 1) + i)]; };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      t.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      t.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  return t;
}

/// How many of the triangles cover each pixel, drawing each one alone.
std::vector<int> coverage_counts(const view& v, const std::vector<tri>& tris) {
  std::vector<int> count(static_cast<std::size_t>(v.width * v.height), 0);
  for (const tri& t : tris) {
    const image img = draw(v, {t});
    for (std::size_t i = 0; i < count.size(); ++i) count[i] += img.covered(i) ? 1 : 0;
  }
  return count;
}

/// True when the ray through pixel centre (px, py) hits the grid's plane inside [−s, s]² at a
/// depth ≥ z_near, with a margin of `eps` (world units) from the boundary and the near plane.
int inside_grid(const view& v, double px, double py, double s, double depth, double eps) {
  // Ray (eye at the origin): direction ((px − cx)/f, −(py − cy)/f, −1) in world = eye axes.
  const double dx = (px - 0.5 * v.width) / v.focal_px, dy = -(py - 0.5 * v.height) / v.focal_px;
  // Plane z = −depth − 0.4x − 0.3y with (x, y, z) = t(dx, dy, −1): −t = −depth − t(0.4dx + 0.3dy)
  const double t = depth / (1 - 0.4 * dx - 0.3 * dy);
  const double x = t * dx, y = t * dy;
  if (t < v.z_near + eps || std::abs(x) > s + eps || std::abs(y) > s + eps) return 0;
  if (t < v.z_near + 2 * eps || std::abs(x) > s - eps || std::abs(y) > s - eps) return -1;
  return 1;
}

/// Every pixel is covered at most once; pixels whose centre lies inside the grid's square
/// (inside_grid == 1) exactly once, those clearly outside (0) never; more than 1000 inside.
void expect_covered_exactly_once(const view& v, const std::vector<tri>& grid, double size,
                                 double depth, double eps) {
  const std::vector<int> count = coverage_counts(v, grid);
  int inside = 0;
  for (int y = 0; y < v.height; ++y)
    for (int x = 0; x < v.width; ++x) {
      const int c = count[static_cast<std::size_t>(y * v.width + x)];
      ASSERT_LE(c, 1) << x << "," << y;
      const int want = inside_grid(v, x + 0.5, y + 0.5, size, depth, eps);
      if (want == 1) {
        ++inside;
        ASSERT_EQ(c, 1) << x << "," << y;
      } else if (want == 0) {
        ASSERT_EQ(c, 0) << x << "," << y;
      }
    }
  EXPECT_GT(inside, 1000);
}

// A closed grid of 2·12² triangles in perspective: every pixel centre inside its outline is
// covered by exactly one triangle, none by two (edges shared in all directions, with jitter).
TEST(Triangle, MeshIsWatertight) {
  const view v(origin_camera(120, 90), vec3d::Zero());
  std::mt19937 rng(7);  // seeded jitter: arbitrary edge slopes
  const std::vector<tri> grid = jittered_grid(12, 0.6f, 2.0f, rng);
  expect_covered_exactly_once(v, grid, 0.6, 2.0, 1e-5);
}

// The same grid crossing the near plane: the clipped triangles still tile the visible part of
// the plane exactly once (intersections on a shared edge are computed the same way by both
// triangles), and nothing in front of the near plane is drawn.
TEST(Triangle, ClippedMeshIsWatertight) {
  const view v(origin_camera(120, 90, 0.9), vec3d::Zero());
  std::mt19937 rng(11);
  const std::vector<tri> grid = jittered_grid(10, 1.5f, 1.2f, rng);
  expect_covered_exactly_once(v, grid, 1.5, 1.2, 1e-4);
}

// Colour interpolated over 1/z: on a quad in the plane y = −0.5 receding from depth 1 to depth
// 9, with 0 at the near edge and 240 at the far edge, the colour at a pixel is 240·(z − 1)/8 for
// the depth z its centre's ray hits, z = 0.5·f/(py − cy). At the row where the quad's midpoint
// (depth 5) projects, screen-space interpolation would give ~216 instead of ~120.
TEST(Triangle, PerspectiveCorrectColour) {
  constexpr attributes A{.colour = true};
  const view v(origin_camera(64, 128), vec3d::Zero());
  render_options opt;
  opt.fx.colour = true;
  const vec3f n0(-0.3f, -0.5f, -1), n1(0.3f, -0.5f, -1), f0(-0.3f, -0.5f, -9), f1(0.3f, -0.5f, -9);
  const rgb8 near_c{0, 0, 0}, far_c{240, 240, 240};
  const image img = render<A>(v, opt, [&](auto& sink) {
    triangle_prim<A> t;
    t.p = {n0, n1, f1};
    t.colour = {near_c, near_c, far_c};
    sink.triangle(t);
    t.p = {n0, f1, f0};
    t.colour = {near_c, far_c, far_c};
    sink.triangle(t);
  });
  const int x = 32;
  int rows = 0;
  for (int y = 0; y < v.height; ++y) {
    if (!img.covered(x, y)) continue;
    ++rows;
    const double z = 0.5 * v.focal_px / (y + 0.5 - 0.5 * v.height);
    EXPECT_NEAR(img.at(x, y).r, 240 * (z - 1) / 8, 1.0) << y;  // rounding of the channel
    EXPECT_NEAR(img.depth[img.index(x, y)], z, 1e-4 * z) << y;
  }
  EXPECT_GT(rows, 40);
  const int mid_row = int(screen(v, vec3f(0, -0.5f, -5)).y());
  EXPECT_LT(img.at(x, mid_row).r, 150);  // far from the screen-space answer (~216)
}

// Near over far, whatever the order: a red triangle at depth 1 and a green one at depth 2 that
// overlap give the same image drawn either way, red where both are.
TEST(Triangle, DepthOrderIndependentOfDrawOrder) {
  constexpr attributes A{.colour = true};
  const view v(origin_camera(64, 64), vec3d::Zero());
  render_options opt;
  const auto scene = [&](bool near_first) {
    return render<A>(v, opt, [&](auto& sink) {
      triangle_prim<A> near_t, far_t;
      near_t.p = {vec3f(-0.5f, -0.4f, -1), vec3f(0.4f, -0.4f, -1), vec3f(0, 0.5f, -1)};
      near_t.colour = {rgb8{255, 0, 0}, rgb8{255, 0, 0}, rgb8{255, 0, 0}};
      far_t.p = {vec3f(-1, -1, -2), vec3f(1, -1, -2), vec3f(0, 1, -2)};
      far_t.colour = {rgb8{0, 255, 0}, rgb8{0, 255, 0}, rgb8{0, 255, 0}};
      if (near_first) {
        sink.triangle(near_t);
        sink.triangle(far_t);
      } else {
        sink.triangle(far_t);
        sink.triangle(near_t);
      }
    });
  };
  const image a = scene(true), b = scene(false);
  EXPECT_EQ(a, b);
  EXPECT_EQ(a.at(32, 32), (rgb8{255, 0, 0}));
  EXPECT_NEAR(a.depth[a.index(32, 32)], 1.0f, 1e-5f);
}

// Back-face culling drops a triangle seen from behind (clockwise on screen) and keeps the same
// triangle wound the other way.
TEST(Triangle, BackfaceCulling) {
  const view v(origin_camera(64, 64), vec3d::Zero());
  const vec3f a(-0.5f, -0.5f, -2), b(0.5f, -0.5f, -2), c(0, 0.5f, -2);  // CCW seen from +z
  EXPECT_GT(draw(v, {{a, b, c}}, effects{.backface_cull = true}).covered_count(), 100u);
  EXPECT_EQ(draw(v, {{a, c, b}}, effects{.backface_cull = true}).covered_count(), 0u);
  EXPECT_GT(draw(v, {{a, c, b}}, no_effects).covered_count(), 100u);
}

}  // namespace
}  // namespace pbr_lod
