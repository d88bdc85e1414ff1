// k-NN normals (PCA + MST orientation) and splat ellipses (Pajarola 2003, end of §4): known
// surfaces, the degenerate ladder, translation invariance, coverage of a plane.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <random>
#include <utility>
#include <vector>

#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/estimation.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/reference.hpp"

namespace pbr_lod {
namespace {

constexpr double rad_to_deg = 180.0 / std::numbers::pi;

double angle_deg(const vec3f& a, const vec3f& b) {
  const vec3d x = a.cast<double>().normalized(), y = b.cast<double>().normalized();
  return std::atan2(x.cross(y).norm(), x.dot(y)) * rad_to_deg;
}

/// Angle between lines (sign ignored).
double line_angle_deg(const vec3f& a, const vec3f& b) {
  const double t = angle_deg(a, b);
  return std::min(t, 180.0 - t);
}

void expect_unit_finite(const std::vector<vec3f>& normals) {
  for (const auto& n : normals) {
    ASSERT_TRUE(all_finite(n)) << n.transpose();
    ASSERT_NEAR(n.norm(), 1.0f, 1e-5f) << n.transpose();
  }
}

/// Uniform samples on a sphere (double), seeded: PCA + MST must work for any sample of a smooth
/// closed surface, so a random one is the honest test.
std::vector<vec3d> sphere_sample(std::size_t n, double radius, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g;
  std::vector<vec3d> out(n);
  for (auto& p : out) p = vec3d(g(rng), g(rng), g(rng)).normalized() * radius;
  return out;
}

std::vector<vec3f> to_float(const std::vector<vec3d>& pts, const vec3d& origin) {
  std::vector<vec3f> out;
  out.reserve(pts.size());
  for (const auto& p : pts) out.push_back((p - origin).cast<float>());
  return out;
}

// 50 000 samples of a sphere of radius 2: a 16-neighbourhood spans ~2° of arc. The PCA normal
// is the normal at the neighbourhood's mean, which in a random (clumpy) sample can sit off the
// point, so the worst error grows with the neighbourhood: measured 1.19° here, 2.04° with
// 20 000 samples. After MST orientation all normals point the same way (outward: CGAL seeds
// the top sample with +z).
TEST(EstimateNormals, SphereIsRadialAndConsistentlyOriented) {
  const vec3d centre(1, -2, 3);
  auto world = sphere_sample(50000, 2.0, 1);
  for (auto& p : world) p += centre;
  const auto pts = to_float(world, vec3d::Zero());
  const auto normals = estimate_normals(pts, 16);
  ASSERT_EQ(normals.size(), pts.size());
  expect_unit_finite(normals);
  std::size_t outward = 0;
  double worst = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const vec3f radial = (world[i] - centre).normalized().cast<float>();
    outward += normals[i].dot(radial) > 0;
    worst = std::max(worst, line_angle_deg(normals[i], radial));
  }
  std::printf("sphere: worst %.3f°\n", worst);
  EXPECT_EQ(outward, pts.size()) << "all normals point the same way (outward)";
  EXPECT_LT(worst, 2.0);
}

// A tilted plane: the exact normal up to float rounding of the samples, one sign for all.
TEST(EstimateNormals, TiltedPlane) {
  const vec3d n = vec3d(0.3, -0.4, 0.866).normalized();
  const vec3d t1 = n.unitOrthogonal(), t2 = n.cross(t1);
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-5, 5);
  std::vector<vec3f> pts;
  for (int i = 0; i < 5000; ++i) pts.push_back((u(rng) * t1 + u(rng) * t2).cast<float>());
  const auto normals = estimate_normals(pts, 12);
  expect_unit_finite(normals);
  const float sign = normals[0].dot(n.cast<float>()) > 0 ? 1.0f : -1.0f;
  for (const auto& e : normals) {
    EXPECT_LT(angle_deg(sign * e, n.cast<float>()), 1e-3);
  }
}

// The CGAL-style ladder: 1 point, duplicates, 2 points, a line, a coplanar grid, and fewer
// points than k. Each gets a finite unit normal with the documented fallback.
TEST(EstimateNormals, DegenerateLadder) {
  for (const bool orient : {false, true}) {
    SCOPED_TRACE(orient ? "oriented" : "unoriented");
    EXPECT_TRUE(estimate_normals({}, 16, orient).empty());

    const std::vector<vec3f> one = {vec3f(1, 2, 3)};
    EXPECT_EQ(estimate_normals(one, 16, orient), std::vector<vec3f>{vec3f::UnitZ()});

    const std::vector<vec3f> dup(20, vec3f(-4, 5, 6));  // all at one position: +z (documented)
    for (const auto& e : estimate_normals(dup, 16, orient)) EXPECT_EQ(e, vec3f::UnitZ());

    const std::vector<vec3f> two = {vec3f(0, 0, 0), vec3f(1, 1, 0)};
    const auto n2 = estimate_normals(two, 16, orient);
    expect_unit_finite(n2);
    for (const auto& e : n2) EXPECT_NEAR(e.dot(vec3f(1, 1, 0).normalized()), 0.0f, 1e-6f);

    std::vector<vec3f> line;  // collinear: any direction orthogonal to the line
    for (int i = 0; i < 30; ++i) line.push_back(vec3f(1, 2, 3) * (0.1f * float(i)));
    const auto nl = estimate_normals(line, 8, orient);
    expect_unit_finite(nl);
    for (const auto& e : nl) EXPECT_NEAR(e.dot(vec3f(1, 2, 3).normalized()), 0.0f, 1e-5f);

    std::vector<vec3f> grid;  // a 6×6 grid in the plane x + y + z = 1
    for (int i = 0; i < 6; ++i)
      for (int j = 0; j < 6; ++j) grid.push_back(vec3f(float(i), float(j), 1.0f - float(i + j)));
    const auto ng = estimate_normals(grid, 16, orient);
    expect_unit_finite(ng);
    for (const auto& e : ng) EXPECT_LT(line_angle_deg(e, vec3f(1, 1, 1)), 1e-3);
    if (orient) {  // one connected plane: one sign
      for (const auto& e : ng) EXPECT_GT(e.dot(ng[0]), 0.99f);
    }

    // Fewer points than k (n = 4 < 16): every point sees all of them, the plane z = 0.
    const std::vector<vec3f> few = {vec3f(0, 0, 0), vec3f(1, 0, 0), vec3f(0, 1, 0), vec3f(1, 1, 0)};
    for (const auto& e : estimate_normals(few, 16, orient)) EXPECT_EQ(e.cwiseAbs(), vec3f::UnitZ());

    // Duplicates mixed into a plane: the duplicates do not disturb the plane normal.
    std::vector<vec3f> mixed = grid;
    for (int i = 0; i < 10; ++i) mixed.push_back(grid[7]);
    const auto nm = estimate_normals(mixed, 16, orient);
    expect_unit_finite(nm);
    for (const auto& e : nm) EXPECT_LT(line_angle_deg(e, vec3f(1, 1, 1)), 1e-3);
  }
}

// Unoriented normals have the documented canonical sign: largest-magnitude component positive.
TEST(EstimateNormals, UnorientedSignIsCanonical) {
  const auto world = sphere_sample(2000, 1.0, 5);
  const auto pts = to_float(world, vec3d::Zero());
  for (const auto& e : estimate_normals(pts, 12, false)) {
    int m = 0;
    for (int c = 1; c < 3; ++c)
      if (std::abs(e[c]) > std::abs(e[m])) m = c;
    EXPECT_GT(e[m], 0.0f);
  }
}

// Georeferenced data (a 10 m sphere 4000 km from the world origin) expressed relative to a
// local origin gives the same normals as the same sphere near the world origin: the method
// only sees relative coordinates and centres the covariance. The local origin is deliberately
// not the sphere's centre, so the float coordinates are rounded differently in the two runs.
// Cast to float directly, the absolute coordinates (ulp 0.25–0.5 m) no longer describe the
// sphere at all — why point_cloud keeps a double origin.
TEST(EstimateNormals, TranslationInvariantInRelativeCoordinates) {
  const vec3d offset(5e5, 4e6, 100);
  const vec3d local(0.37, -0.21, 0.55);
  const auto base = sphere_sample(5000, 10.0, 3);
  std::vector<vec3d> far = base;
  for (auto& p : far) p += offset;

  const auto n_near = estimate_normals(to_float(base, local), 16);
  point_cloud cloud;  // the far data as a reader would return it, then rebased
  cloud.origin = offset + local;
  cloud.positions = to_float(far, cloud.origin);
  const auto n_far = estimate_normals(cloud.positions, 16);
  double worst = 0;
  for (std::size_t i = 0; i < base.size(); ++i)
    worst = std::max(worst, angle_deg(n_near[i], n_far[i]));
  EXPECT_LT(worst, 0.01) << "same normals, same orientation";

  const auto n_absolute = estimate_normals(to_float(far, vec3d::Zero()), 16, false);
  expect_unit_finite(n_absolute);  // still defined, but meaningless:
  double worst_abs = 0;
  for (std::size_t i = 0; i < base.size(); ++i)
    worst_abs =
        std::max(worst_abs, line_angle_deg(n_absolute[i], base[i].normalized().cast<float>()));
  EXPECT_GT(worst_abs, 10.0);
}

// Same input, same output, bit for bit (parallel k-NN and edge sort, sequential forest walk).
TEST(EstimateNormals, Deterministic) {
  const auto cloud = make_wavy_surface(30000, 4);
  const auto a = estimate_normals(cloud.positions, 16);
  const auto b = estimate_normals(cloud.positions, 16);
  EXPECT_EQ(a, b);
  const auto ea = estimate_splat_ellipses(cloud.positions, a, 16);
  const auto eb = estimate_splat_ellipses(cloud.positions, a, 16);
  EXPECT_EQ(ea.u, eb.u);
  EXPECT_EQ(ea.v, eb.v);
}

// The thread count changes who computes what, never the result: 1, 2 and 3 threads give the
// same bytes for normals (MST and viewpoint orientation) and ellipses.
TEST(EstimateNormals, IndependentOfThreadCount) {
  const auto cloud = make_wavy_surface(40000, 9);
  for (const auto orient : {normal_orientation::mst, normal_orientation::viewpoint}) {
    estimation_options opt{.orientation = orient, .viewpoint = vec3f(0, 5, 0), .threads = 1};
    const auto one = estimate_normals_and_ellipses(cloud.positions, opt);
    for (const unsigned t : {2u, 3u}) {
      opt.threads = t;
      const auto more = estimate_normals_and_ellipses(cloud.positions, opt);
      EXPECT_EQ(one.normals, more.normals) << t;
      EXPECT_EQ(one.axes.u, more.axes.u) << t;
      EXPECT_EQ(one.axes.v, more.axes.v) << t;
    }
  }
}

// Towards a viewpoint: from the centre of a sphere every normal points inwards, from far above
// every normal of the upper half points up; the lines themselves are the PCA ones (the same as
// without orientation, up to sign).
TEST(EstimateNormals, OrientedTowardsTheViewpoint) {
  const vec3d centre(3, -1, 2);
  auto world = sphere_sample(20000, 1.5, 11);
  for (auto& p : world) p += centre;
  const auto pts = to_float(world, vec3d::Zero());
  const auto plain = estimate_normals(pts, 16, false);
  estimation_options opt{.orientation = normal_orientation::viewpoint};
  opt.viewpoint = centre.cast<float>();
  const auto inward = estimate_normals(pts, opt);
  opt.viewpoint = centre.cast<float>() + vec3f(0, 0, 1000);
  const auto up = estimate_normals(pts, opt);
  std::size_t in = 0, upper = 0, up_ok = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    ASSERT_TRUE(inward[i] == plain[i] || inward[i] == -plain[i]);
    in += inward[i].cast<double>().dot(centre - world[i]) > 0;
    if (world[i].z() > centre.z() + 0.1) {
      ++upper;
      up_ok += up[i].z() > 0;
    }
  }
  EXPECT_EQ(in, pts.size());
  EXPECT_EQ(up_ok, upper);
  opt.viewpoint = vec3f(std::numeric_limits<float>::quiet_NaN(), 0, 0);
  EXPECT_THROW((void)estimate_normals(pts, opt), InvalidArgument);
}

// Progress rises to 1 between the stages, on the calling thread; a false answer cancels with
// Cancelled (the k-NN stage is the longest: a cancel at its end must not run the rest).
TEST(EstimateNormals, ProgressAndCancel) {
  const auto cloud = make_wavy_surface(20000, 2);
  std::vector<double> seen;
  estimation_options opt{.threads = 2, .progress = [&](double f) {
                           seen.push_back(f);
                           return true;
                         }};
  (void)estimate_normals_and_ellipses(cloud.positions, opt);
  ASSERT_GE(seen.size(), 4u);
  EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
  EXPECT_GT(seen.front(), 0.0);
  EXPECT_EQ(seen.back(), 1.0);
  seen.clear();
  (void)estimate_normals(cloud.positions, opt);
  ASSERT_GE(seen.size(), 3u);
  EXPECT_EQ(seen.back(), 1.0);
  std::size_t calls = 0;
  opt.progress = [&](double f) {
    ++calls;
    return f < 0.5;
  };
  EXPECT_THROW((void)estimate_normals_and_ellipses(cloud.positions, opt), Cancelled);
  EXPECT_EQ(calls, 2u);
}

// Two spheres far apart: the k-NN graph has two components and each is oriented from its own
// top sample, so both come out outward (CGAL's mst_orient_normals oriented only the component
// of the global top sample and left the other with canonical, mixed signs).
TEST(EstimateNormals, EveryComponentIsOriented) {
  std::vector<vec3d> world = sphere_sample(8000, 1.0, 7);
  const std::size_t first = world.size();
  for (const auto& p : sphere_sample(8000, 1.0, 8)) world.push_back(p + vec3d(100, 0, -50));
  const auto pts = to_float(world, vec3d::Zero());
  const auto normals = estimate_normals(pts, 16);
  std::size_t outward = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const vec3d centre = i < first ? vec3d::Zero() : vec3d(100, 0, -50);
    outward += normals[i].cast<double>().dot(world[i] - centre) > 0;
  }
  EXPECT_EQ(outward, pts.size());
}

// The one-search path the builders use equals the two separate calls (no equidistant neighbours
// on a random surface), for k_normals above, equal to and below k_ellipses.
TEST(EstimateNormals, CombinedWithEllipsesEqualsSeparateCalls) {
  const auto cloud = make_wavy_surface(20000, 6);
  for (const auto& [kn, ke] : {std::pair{16, 12}, std::pair{12, 12}, std::pair{8, 20}}) {
    const auto both = estimate_normals_and_ellipses(cloud.positions, kn, ke);
    const auto normals = estimate_normals(cloud.positions, kn);
    const auto axes = estimate_splat_ellipses(cloud.positions, normals, ke);
    EXPECT_EQ(both.normals, normals) << kn << " " << ke;
    EXPECT_EQ(both.axes.u, axes.u) << kn << " " << ke;
    EXPECT_EQ(both.axes.v, axes.v) << kn << " " << ke;
  }
  EXPECT_THROW((void)estimate_normals_and_ellipses(cloud.positions, 2, 12), InvalidArgument);
  EXPECT_THROW((void)estimate_normals_and_ellipses(cloud.positions, 16, 1), InvalidArgument);
  EXPECT_TRUE(estimate_normals_and_ellipses({}, 16, 12).normals.empty());
}

// The wavy closed surface: orientation agrees with the generator's outward normals everywhere
// (or everywhere disagrees), and the PCA normals are close to the analytic ones.
TEST(EstimateNormals, WavySurfaceIsConsistent) {
  const auto cloud = make_wavy_surface(40000, 2);
  const auto normals = estimate_normals(cloud.positions, 16);
  expect_unit_finite(normals);
  std::size_t agree = 0;
  std::vector<double> err;
  for (std::size_t i = 0; i < normals.size(); ++i) {
    agree += normals[i].dot(cloud.normals[i]) > 0;
    err.push_back(line_angle_deg(normals[i], cloud.normals[i]));
  }
  EXPECT_TRUE(agree == normals.size() || agree == 0) << agree << " of " << normals.size();
  std::nth_element(err.begin(), err.begin() + err.size() / 2, err.end());
  EXPECT_LT(err[err.size() / 2], 1.0) << "median error, degrees";
}

TEST(EstimateNormals, InvalidArguments) {
  const std::vector<vec3f> pts = {vec3f(0, 0, 0), vec3f(1, 0, 0), vec3f(0, 1, 0)};
  EXPECT_THROW((void)estimate_normals(pts, 2), InvalidArgument);
  std::vector<vec3f> bad = pts;
  bad[1].y() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW((void)estimate_normals(bad, 16), InvalidArgument);
}

// ---------------------------------------------------------------------------------------------
// Splat ellipses

/// A plane sample: n random points in [0, sx] × [0, sy] of the plane through `o` spanned by
/// t1, t2 (random, so there is no lattice for the ellipses to be lucky on).
struct plane_sample {
  std::vector<vec3f> pts, normals;
  vec3f o, t1, t2, n;
};

plane_sample make_plane(std::size_t n, float sx, float sy, std::uint64_t seed) {
  plane_sample s;
  s.n = vec3f(0.2f, 0.3f, 0.9f).normalized();
  s.t1 = any_orthogonal(s.n);
  s.t2 = s.n.cross(s.t1);
  s.o = vec3f(3, -1, 2);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> ux(0, sx), uy(0, sy);
  for (std::size_t i = 0; i < n; ++i) {
    s.pts.push_back(s.o + ux(rng) * s.t1 + uy(rng) * s.t2);
    s.normals.push_back(s.n);
  }
  return s;
}

void expect_axes_valid(const splat_axes& e, const std::vector<vec3f>& normals) {
  ASSERT_EQ(e.u.size(), normals.size());
  ASSERT_EQ(e.v.size(), normals.size());
  for (std::size_t i = 0; i < normals.size(); ++i) {
    const vec3f n = normals[i].normalized();
    const float a = e.u[i].norm(), b = e.v[i].norm();
    ASSERT_TRUE(all_finite(e.u[i]) && all_finite(e.v[i]));
    ASSERT_GT(b, 0.0f);
    EXPECT_GE(a, b * (1 - 1e-5f));
    EXPECT_GE(b, float(splat_min_axis_ratio) * a * (1 - 1e-5f));
    EXPECT_LT(std::abs(e.u[i].dot(n)), 1e-5f * a);
    EXPECT_LT(std::abs(e.v[i].dot(n)), 1e-5f * b);
    EXPECT_LT(std::abs(e.u[i].dot(e.v[i])), 1e-5f * a * b);
  }
}

/// Grid points of [0.02, 0.98]² (in the t1, t2 frame at o) that no splat covers; a splat
/// centred farther than the 64 nearest samples cannot matter at this density.
std::size_t count_uncovered(const std::vector<vec3f>& pts, const splat_axes& e, const vec3f& o,
                            const vec3f& t1, const vec3f& t2, const vec3f& n, int steps) {
  const knn_index index(pts);
  std::vector<std::uint32_t> idx;
  std::vector<float> d2;
  std::size_t uncovered = 0;
  for (int gx = 0; gx <= steps; ++gx)
    for (int gy = 0; gy <= steps; ++gy) {
      const float x = 0.02f + 0.96f * float(gx) / float(steps);
      const float y = 0.02f + 0.96f * float(gy) / float(steps);
      const vec3f q = o + x * t1 + y * t2;
      index.query(q, 64, idx, d2);
      bool covered = false;
      for (const auto j : idx)
        if (elliptical_disk{pts[j], n, e.u[j], e.v[j]}.covers(q, 0)) {
          covered = true;
          break;
        }
      uncovered += !covered;
    }
  return uncovered;
}

// Every splat contains its k nearest neighbours (the Fig. 6a bounding rule), and every point of
// a fine grid inside the sampled region is covered by some splat: no gaps. Random samples, so
// there is no lattice for the ellipses to be lucky on.
TEST(SplatEllipses, CoverAPlane) {
  for (const int k : {6, 8, 10, 12, 16}) {
    SCOPED_TRACE(k);
    const auto s = make_plane(4000, 1.0f, 1.0f, 11);
    const auto e = estimate_splat_ellipses(s.pts, s.normals, k, 0, ellipse_rule::neighbours);
    expect_axes_valid(e, s.normals);
    const knn_index index(s.pts);
    std::vector<std::uint32_t> idx;
    std::vector<float> d2;
    for (std::size_t i = 0; i < s.pts.size(); ++i) {
      const elliptical_disk disk{s.pts[i], s.n, e.u[i], e.v[i]};
      index.query(s.pts[i], k, idx, d2);
      for (const auto j : idx) ASSERT_TRUE(disk.covers(s.pts[j], 0)) << i << " misses " << j;
    }
    // Grid spacing 1/300: ~5 × finer than the samples (mean spacing 1/63). Covering the k
    // nearest covers the Delaunay triangles around a sample only when its Delaunay neighbours
    // are among them; from k = 12 on they always were here, below that a few gaps remain
    // (measured: k = 6 → 1.4 % of the grid, 8 → 0.15 %, 10 → 0.007 %; docs/normal-quantization.md).
    const std::size_t uncovered = count_uncovered(s.pts, e, s.o, s.t1, s.t2, s.n, 300);
    if (k >= 12) {
      EXPECT_EQ(uncovered, 0u);
    } else {
      std::printf("k = %2d: %zu of %d grid points uncovered\n", k, uncovered, 301 * 301);
      EXPECT_LT(double(uncovered), 0.02 * 301 * 301);
    }
    // The default rule clips splats at the square's edges (they no longer hold every
    // neighbour there) and leaves the grid covered but for a few points.
    const auto bounded = estimate_splat_ellipses(s.pts, s.normals, k);
    expect_axes_valid(bounded, s.normals);
    const std::size_t bounded_uncovered =
        count_uncovered(s.pts, bounded, s.o, s.t1, s.t2, s.n, 300);
    std::printf("k = %2d: local_spacing leaves %zu grid points uncovered\n", k, bounded_uncovered);
    // Measured: k = 12 → 13 of 90,601 (0.014 %, where the clip trims splats), k = 16 → 0.
    if (k >= 12) {
      EXPECT_LE(bounded_uncovered, k >= 16 ? 0u : 30u);
    }
  }
}

// A jittered grid 4 × denser along t2 than along t1 (spacings 0.02 × 0.005): the splats are
// elongated (mean minor/major well below 1) and still leave no gap between the columns.
TEST(SplatEllipses, CoverAnAnisotropicGrid) {
  const auto t = make_plane(0, 1.0f, 1.0f, 13);  // just the frame
  std::mt19937 rng(14);
  std::uniform_real_distribution<float> jitter(-0.001f, 0.001f);
  std::vector<vec3f> pts;
  for (int i = 0; i <= 50; ++i)
    for (int j = 0; j <= 200; ++j)
      pts.push_back(t.o + (0.02f * float(i) + jitter(rng)) * t.t1 +
                    (0.005f * float(j) + jitter(rng)) * t.t2);
  const std::vector<vec3f> normals(pts.size(), t.n);
  const auto e = estimate_splat_ellipses(pts, normals, 16);
  expect_axes_valid(e, normals);
  double ratio = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) ratio += e.v[i].norm() / e.u[i].norm();
  EXPECT_LT(ratio / double(pts.size()), 0.8);
  EXPECT_EQ(count_uncovered(pts, e, t.o, t.t1, t.t2, t.n, 400), 0u);
}

// Exact duplicates are estimated once: 2,000 copies of every point of a jittered 12 × 12 patch
// give each copy exactly the normal and ellipse of the patch estimated alone (so the cost is
// the patch's: before, every k-NN query around a copy visited all 2,000 and the search for the
// nearest distinct sample went to 4096 neighbours — minutes for this input).
TEST(SplatEllipses, DuplicatesAreEstimatedOnce) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> jitter(-0.02f, 0.02f);
  std::vector<vec3f> patch;
  for (int y = 0; y < 12; ++y)
    for (int x = 0; x < 12; ++x)
      patch.emplace_back(0.1f * float(x) + jitter(rng), 0.1f * float(y) + jitter(rng),
                         0.01f * std::sin(float(x + 2 * y)));
  std::vector<vec3f> copies;
  for (int c = 0; c < 2000; ++c) copies.insert(copies.end(), patch.begin(), patch.end());
  const estimated_splats one = estimate_normals_and_ellipses(patch, 16, 16, true, 1);
  const estimated_splats many = estimate_normals_and_ellipses(copies, 16, 16, true, 2);
  ASSERT_EQ(many.normals.size(), copies.size());
  std::size_t differ = 0;
  for (std::size_t i = 0; i < copies.size(); ++i) {
    const std::size_t j = i % patch.size();
    differ += many.normals[i] != one.normals[j] || many.axes.u[i] != one.axes.u[j] ||
              many.axes.v[i] != one.axes.v[j];
  }
  EXPECT_EQ(differ, 0u);
}

// Degenerate neighbourhoods: a single point, all duplicates, duplicates beside a distinct
// point, a line (λ₂ = 0 in the tangent plane), points stacked along the normal.
TEST(SplatEllipses, DegenerateLadder) {
  EXPECT_TRUE(estimate_splat_ellipses({}, {}, 16).u.empty());

  const std::vector<vec3f> up = {vec3f::UnitZ()};
  {  // one point at (0, 0, 2): 1e-6 × max(1, |p|∞)
    const std::vector<vec3f> one = {vec3f(0, 0, 2)};
    const auto e = estimate_splat_ellipses(one, up, 16);
    expect_axes_valid(e, up);
    EXPECT_NEAR(e.u[0].norm(), 2e-6f, 1e-10f);
    EXPECT_NEAR(e.v[0].norm(), 2e-6f, 1e-10f);
  }
  {  // 30 duplicates: a tiny disk, finite and non-zero
    const std::vector<vec3f> dup(30, vec3f(0.5f, 0.5f, 0.5f));
    const std::vector<vec3f> n(30, vec3f::UnitZ());
    const auto e = estimate_splat_ellipses(dup, n, 16);
    expect_axes_valid(e, n);
    EXPECT_NEAR(e.u[0].norm(), 1e-6f, 1e-10f);
  }
  {  // 40 duplicates and one point 0.3 away: the duplicates are one sample (estimated once,
     // every copy the same), so this is two samples 0.3 apart along x — each a needle reaching
     // the other, clamped to 10 % width.
    std::vector<vec3f> pts(40, vec3f(0, 0, 0));
    pts.push_back(vec3f(0.3f, 0, 0));
    const std::vector<vec3f> n(pts.size(), vec3f::UnitZ());
    const auto e = estimate_splat_ellipses(pts, n, 8);
    expect_axes_valid(e, n);
    for (const std::size_t i : {std::size_t{0}, std::size_t{40}}) {
      EXPECT_GE(e.u[i].norm(), 0.3f) << i;
      EXPECT_NEAR(e.v[i].norm() / e.u[i].norm(), splat_min_axis_ratio, 1e-5) << i;
    }
    for (std::size_t i = 1; i < 40; ++i) EXPECT_EQ(e.u[i], e.u[0]) << i;
  }
  {  // a line along x with normal z: minor axis = 10 % of the major
    std::vector<vec3f> line;
    for (int i = 0; i < 50; ++i) line.push_back(vec3f(0.1f * float(i), 0, 0));
    const std::vector<vec3f> n(line.size(), vec3f::UnitZ());
    const auto e = estimate_splat_ellipses(line, n, 6);
    expect_axes_valid(e, n);
    for (std::size_t i = 0; i < line.size(); ++i) {
      EXPECT_GT(std::abs(e.u[i].normalized().x()), 0.999f);
      EXPECT_NEAR(e.v[i].norm() / e.u[i].norm(), splat_min_axis_ratio, 1e-5);
    }
  }
  {  // stacked along the normal: every neighbour projects onto the centre → disk of the spacing
    std::vector<vec3f> stack;
    for (int i = 0; i < 10; ++i) stack.push_back(vec3f(0, 0, 0.25f * float(i)));
    const std::vector<vec3f> n(stack.size(), vec3f::UnitZ());
    const auto e = estimate_splat_ellipses(stack, n, 4);
    expect_axes_valid(e, n);
    for (const auto& u : e.u) EXPECT_NEAR(u.norm(), 0.25f, 1e-6f);
  }
}

/// Per sample, the distance to the farthest of its k nearest (itself included), from the k-NN
/// graph (tested against brute force in knn_test.cpp).
std::vector<float> neighbourhood_radius(const std::vector<vec3f>& pts, int k) {
  const knn_graph g = nearest_neighbour_graph(pts, k);
  std::vector<float> rho(pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) rho[i] = std::sqrt(g.dist2[i * g.k + g.k - 1]);
  return rho;
}

// ellipse_rule::local_spacing on an airborne LiDAR tile (scan lines, roofs, walls, tree crowns,
// isolated returns): no semi-axis is longer than local_spacing_reach (1.5) × the sample's
// neighbourhood radius ρ and the minor never exceeds the major. Pajarola's rule alone on the same
// input does reach beyond, so the bound is the rule's doing.
TEST(SplatEllipses, LocalSpacingBoundsEveryAxis) {
  const point_cloud tile = make_lidar_tile(60000, 3);
  const auto& pts = tile.positions;
  const std::vector<float> rho = neighbourhood_radius(pts, 12);
  estimation_options opt{.k_ellipses = 12};
  const auto local = estimate_normals_and_ellipses(pts, opt);
  opt.ellipses = ellipse_rule::neighbours;
  const auto plain = estimate_normals_and_ellipses(pts, opt);
  EXPECT_EQ(local.normals, plain.normals);
  std::size_t plain_over = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const float a = local.axes.u[i].norm(), b = local.axes.v[i].norm();
    ASSERT_LE(a, float(local_spacing_reach) * rho[i] * (1 + 1e-5f)) << i;
    ASSERT_LE(b, a * (1 + 1e-5f)) << i;
    ASSERT_GT(b, 0.0f) << i;
    plain_over += plain.axes.u[i].norm() > float(local_spacing_reach) * rho[i] * 1.01f;
  }
  std::printf("neighbours rule: %zu of %zu majors beyond 1.5 rho\n", plain_over, pts.size());
  EXPECT_GT(plain_over, 0u);
}

// A sample 60 spacings above a plane grid: Pajarola's rule stretches its splat over the 11 grid
// samples it reaches (major ≈ 60); the local rule holds it to local_spacing_outlier_factor (8) ×
// the median neighbourhood radius of those grid samples (ρ = √5 on the unit grid with k = 12).
TEST(SplatEllipses, IsolatedSampleBorrowsItsNeighboursSpacing) {
  std::vector<vec3f> pts;
  for (int j = 0; j < 41; ++j)
    for (int i = 0; i < 41; ++i) pts.emplace_back(float(i), float(j), 0.0f);
  pts.emplace_back(20.3f, 20.4f, 60.0f);
  const auto normals = estimate_normals(pts, 12);
  const auto local = estimate_splat_ellipses(pts, normals, 12);
  const auto plain = estimate_splat_ellipses(pts, normals, 12, 0, ellipse_rule::neighbours);
  const std::size_t top = pts.size() - 1;
  EXPECT_GT(plain.u[top].norm(), 40.0f);
  EXPECT_LE(local.u[top].norm(), float(local_spacing_outlier_factor) * std::sqrt(5.0f) * 1.0001f);
  // Grid samples away from the edges and from the lone sample: both rules agree.
  const std::size_t mid = 10 * 41 + 10;
  EXPECT_EQ(local.u[mid], plain.u[mid]);
  EXPECT_EQ(local.v[mid], plain.v[mid]);
}

// An isotropic Gaussian blob is no surface (thickness ≈ 1/3 > 0.1): the local rule gives every
// sample a disk (equal axes) no wider than non_surface_disk_factor × its 8th neighbour's
// distance; Pajarola's rule
// fits ellipses in arbitrary tangent planes, elongated for most samples.
TEST(SplatEllipses, BlobGetsDisks) {
  std::mt19937 rng(17);
  std::normal_distribution<float> g;
  std::vector<vec3f> pts(3000);
  for (auto& p : pts) p = vec3f(g(rng), g(rng), g(rng));
  const auto normals = estimate_normals(pts, 16);
  const auto local = estimate_splat_ellipses(pts, normals, 12);
  const auto plain = estimate_splat_ellipses(pts, normals, 12, 0, ellipse_rule::neighbours);
  const std::vector<float> d8 = knn_spacing(pts, 8);
  std::size_t disks = 0, round_plain = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const float a = local.u[i].norm(), b = local.v[i].norm();
    if (std::abs(a - b) <= 1e-5f * a) {
      ++disks;
      EXPECT_LE(a, float(non_surface_disk_factor) * d8[i] * (1 + 1e-5f)) << i;
    }
    round_plain += plain.v[i].norm() > 0.9f * plain.u[i].norm();
  }
  EXPECT_GT(disks, pts.size() * 95 / 100);
  EXPECT_LT(round_plain, pts.size() / 4);
}

// What the user sees on an airborne LiDAR tile without normals (issue 39): the estimated splats
// drawn at full detail against the cloud's own render (every position a view-facing square of
// 1.6 × its 8th-neighbour distance d₈), from 1.2 and 3 radii, z up, 320 × 240. Every non-surface
// splat (surface variation > 0.1) is a disk of at most non_surface_disk_factor × d₈, and the
// isolated returns high above the tile (sparse) get small round splats, not ellipses tens of
// metres wide. Measured (100 k returns): isolated returns ≤ 0.80 m, all round; interior holes
// (reference pixels ≥ 2 px inside its silhouette left empty) ≤ 0.81 %, all holes ≤ 2.26 % (the
// rest is the squares' overhang at silhouettes, which no splat in a tangent plane reproduces),
// covered ≤ 0.988 × the reference's. The rule before (0.8 d₈ disks for thick neighbourhoods
// only, no sparse rule) fails: isolated returns up to 47 m, 19 of them ellipses, interior holes
// up to 1.24 %, all holes up to 2.92 %.
TEST(SplatEllipses, LidarTileLooksLikeItsRender) {
  const point_cloud full = make_lidar_tile(100000, 5);
  const point_cloud clean = make_lidar_tile(100000, 5, false);
  ASSERT_LT(clean.size(), full.size());
  const estimation_options opt{.k_ellipses = 12};
  const auto est = estimate_normals_and_ellipses(full.positions, opt);

  // The bounds, on the full tile (isolated returns included).
  const std::vector<float> d8 = knn_spacing(full.positions, 8);
  const knn_graph g = nearest_neighbour_graph(full.positions, 12);
  std::size_t thick = 0;
  for (std::size_t i = 0; i < full.size(); ++i) {
    vec3d mean = vec3d::Zero();
    for (std::size_t j = 0; j < 12; ++j) mean += full.positions[g.index[i * 12 + j]].cast<double>();
    mean /= 12;
    mat3d cov = mat3d::Zero();
    for (std::size_t j = 0; j < 12; ++j) {
      const vec3d d = full.positions[g.index[i * 12 + j]].cast<double>() - mean;
      cov += d * d.transpose();
    }
    const vec3d l = Eigen::SelfAdjointEigenSolver<mat3d>(cov, Eigen::EigenvaluesOnly).eigenvalues();
    if (!(l[0] > local_spacing_max_thickness * l.sum() * 1.001)) continue;
    ++thick;
    ASSERT_LE(est.axes.u[i].norm(), float(non_surface_disk_factor) * d8[i] * (1 + 1e-4f)) << i;
    ASSERT_NEAR(est.axes.v[i].norm(), est.axes.u[i].norm(), 1e-4f * est.axes.u[i].norm()) << i;
  }
  EXPECT_GT(thick, full.size() / 50);  // the crowns and the walls' corners
  float isolated = 0;
  std::size_t not_round = 0;
  for (std::size_t i = clean.size(); i < full.size(); ++i) {
    isolated = std::max(isolated, est.axes.u[i].norm());
    not_round +=
        std::abs(est.axes.v[i].norm() - est.axes.u[i].norm()) > 1e-4f * est.axes.u[i].norm();
  }
  std::printf("isolated returns: largest splat %.2f m, %zu not round\n", isolated, not_round);
  EXPECT_EQ(not_round, 0u);
  EXPECT_LT(isolated, 2.0f);

  // Coverage, on the tile without its isolated returns (their reference squares, sized by
  // their 15–20 m spacing, would be most of the reference's pixels).
  point_cloud ref, mine;
  ref.origin = mine.origin = clean.origin;
  ref.positions = mine.positions = clean.positions;
  const auto e = estimate_normals_and_ellipses(clean.positions, opt);
  mine.normals = e.normals;
  mine.axis_u = e.axes.u;
  mine.axis_v = e.axes.v;
  vec3f lo = clean.positions.front(), hi = lo;
  for (const auto& p : clean.positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const vec3d centre = clean.origin + (0.5f * (lo + hi)).cast<double>();
  const double radius = 0.5 * double((hi - lo).norm());
  for (const double dist : {1.2, 3.0})
    for (const auto& [az, el] : {std::pair(30.0, 25.0), std::pair(160.0, 35.0)}) {
      const camera cam = camera::orbit(centre, radius, az, el, dist, 2, {320, 240});
      const image a = render_reference(ref, cam, {}), b = render_reference(mine, cam, {});
      std::size_t ca = 0, cb = 0, holes = 0;
      for (std::size_t i = 0; i < a.size(); ++i) {
        ca += a.covered(i);
        cb += b.covered(i);
        holes += a.covered(i) && !b.covered(i);
      }
      const input_likeness like = compare_to_input(a, b);
      const double all = double(holes) / double(ca),
                   inner = double(like.interior_holes) / double(like.interior_pixels),
                   covered = double(cb) / double(ca);
      std::printf(
          "lidar %.1f radii, azimuth %.0f: holes %.2f %% (interior %.2f %%), covered %.3f\n", dist,
          az, 100 * all, 100 * inner, covered);
      EXPECT_LE(inner, 0.01) << dist << " " << az;
      // All holes: the reference's view-facing squares overhang the tile's outer edge and the
      // silhouettes of roofs by 0.8·d₈, splats clipped at those edges do not (measured 1.79–
      // 3.02 %, 2.26 % before the clip; interior 0.37–0.93 %, 0.81 % before).
      EXPECT_LE(all, 0.032) << dist << " " << az;
      EXPECT_LE(covered, 1.03) << dist << " " << az;
    }
}

TEST(SplatEllipses, InvalidArguments) {
  const std::vector<vec3f> pts = {vec3f(0, 0, 0), vec3f(1, 0, 0)};
  const std::vector<vec3f> n = {vec3f::UnitZ(), vec3f::UnitZ()};
  EXPECT_THROW((void)estimate_splat_ellipses(pts, n, 1), InvalidArgument);
  EXPECT_THROW((void)estimate_splat_ellipses(pts, std::span(n).first(1), 16), InvalidArgument);
  const std::vector<vec3f> zero = {vec3f::UnitZ(), vec3f::Zero()};
  EXPECT_THROW((void)estimate_splat_ellipses(pts, zero, 16), InvalidArgument);
  const std::vector<vec3f> inf = {vec3f::UnitZ(),
                                  vec3f(0, std::numeric_limits<float>::infinity(), 0)};
  EXPECT_THROW((void)estimate_splat_ellipses(pts, inf, 16), InvalidArgument);
  std::vector<vec3f> bad = pts;
  bad[0].x() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW((void)estimate_splat_ellipses(bad, n, 16), InvalidArgument);
}

// Normals from estimate_normals feed the ellipses directly: on the sphere every splat is in its
// tangent plane and reaches its neighbours.
TEST(SplatEllipses, FromEstimatedNormalsOnASphere) {
  const auto pts = to_float(sphere_sample(5000, 1.0, 9), vec3d::Zero());
  const auto normals = estimate_normals(pts, 16);
  const auto e = estimate_splat_ellipses(pts, normals, 16);
  expect_axes_valid(e, normals);
}

}  // namespace
}  // namespace pbr_lod
