// Tests of the PMR builder (Dey & Hudson, IEEE Vis 2002). Each case says why its expectation
// holds. Random inputs are seeded (std::mt19937 rng(seed)): the properties checked hold for any
// dense sample, the seed only makes a failure reproducible.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <random>
#include <set>

#include "pbr_lod/builders/pmr.hpp"
#include "pbr_lod/core/estimation.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/raster/png.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "support/cameras.hpp"
#include "support/data.hpp"
#include "support/user_view.hpp"

namespace pbr_lod {
namespace {

static_assert(Hierarchy<pmr_hierarchy>);

std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("pbr_lod_pmr_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

/// n points uniformly on the sphere of radius r about c (double), optional radial noise.
std::vector<vec3d> sphere_points(std::size_t n, double r, const vec3d& c, std::uint32_t seed,
                                 double noise = 0) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0, 1);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<vec3d> p;
  while (p.size() < n) {
    vec3d d(g(rng), g(rng), g(rng));
    if (!(d.norm() > 1e-9)) continue;
    p.push_back(c + d.normalized() * r * (1 + noise * u(rng)));
  }
  return p;
}

/// A jittered grid on the plane z = 0 (spacing 1), heights ±amp.
std::vector<vec3d> plane_points(int side, double amp, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<vec3d> p;
  for (int y = 0; y < side; ++y)
    for (int x = 0; x < side; ++x) p.emplace_back(x + 0.3 * u(rng), y + 0.3 * u(rng), amp * u(rng));
  return p;
}

point_cloud cloud_of(const std::vector<vec3d>& p, const vec3d& origin = vec3d::Zero()) {
  point_cloud c;
  c.origin = origin;
  for (const auto& q : p) c.positions.push_back((q - origin).cast<float>());
  return c;
}

detail::pmr_cell_output analyse(const std::vector<vec3d>& p, std::vector<float> rho = {}) {
  return detail::pmr_process_cell({p, static_cast<std::uint32_t>(p.size()), rho});
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

/// Invariants every hierarchy must satisfy, whatever the input.
void expect_valid(const pmr_hierarchy& h, std::size_t n) {
  ASSERT_FALSE(h.empty());
  ASSERT_EQ(h.positions().size(), n);
  std::vector<int> seen(n, 0);
  for (const auto s : h.source()) ++seen.at(s);
  EXPECT_TRUE(std::all_of(seen.begin(), seen.end(), [](int c) { return c == 1; }))
      << "every input sample stored exactly once";
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_TRUE(all_finite(h.positions()[i])) << i;
    ASSERT_TRUE(all_finite(h.normals()[i])) << i;
    EXPECT_NEAR(h.normals()[i].norm(), 1.0f, 1e-4f) << i;
  }
  for (std::uint32_t l = 0; l < h.leaf_count(); ++l) {
    const auto& leaf = h.leaf(l);
    const sphere s = h.bounding_sphere(leaf.node);
    ASSERT_TRUE(all_finite(s.centre) && std::isfinite(s.radius));
    for (std::uint32_t g = leaf.first_point; g < leaf.first_point + leaf.point_count; ++g)
      EXPECT_TRUE(s.contains(h.positions()[g])) << "leaf sphere holds its samples";
    for (std::uint32_t i = 0; i < h.levels(); ++i) {
      const auto& L = h.level(l, i);
      EXPECT_TRUE(std::isfinite(L.mean_umbrella) && L.mean_umbrella >= 0);
      if (i > 0) {
        EXPECT_LE(L.points, h.level(l, i - 1).points) << "levels nest";
      }
      for (std::uint32_t t = L.first_tri; t < L.first_tri + L.tris; ++t)
        for (const auto g : h.triangles()[t]) {
          ASSERT_LT(g, n);
          EXPECT_TRUE(s.contains(h.positions()[g])) << "leaf sphere holds its triangles";
        }
    }
  }
}

// ---- poles and heights against the analytic medial axis

TEST(pmr_cell, PolesOfTwoConcentricSpheresAreTheirMedialAxis) {
  // Samples of the spheres |x| = 1 and |x| = 2. The medial axis of the shell between them is the
  // sphere |x| = 1.5; inside the small sphere it is the centre. A point of the inner sphere has
  // its farthest Voronoi vertex at the centre (distance 1, against 0.5 to the middle sphere), so
  // pole = 0 and h = 1; a point of the outer sphere is on the hull: its normal is the outward
  // hull normal (radial) and its height the distance to the middle sphere, 0.5. Sampling error:
  // the Voronoi vertices of n samples deviate from the medial axis by O(spacing²); with 1500 and
  // 3000 samples 5 % is generous and a wrong pole (say the nearest vertex) fails it.
  auto p = sphere_points(1500, 1, vec3d::Zero(), 1);
  const auto outer = sphere_points(3000, 2, vec3d::Zero(), 2);
  p.insert(p.end(), outer.begin(), outer.end());
  const auto c = analyse(p);
  ASSERT_EQ(c.dimension, 3);
  int inner_ok = 0, outer_ok = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const vec3d radial = p[i].normalized();
    const bool normal_ok = std::abs(c.normal[i].dot(radial)) > 0.995;
    if (i < 1500) {
      EXPECT_EQ(c.hull[i], 0);
      inner_ok += normal_ok && c.pole[i].norm() < 0.05 && std::abs(c.height[i] - 1) < 0.05;
    } else {
      EXPECT_EQ(c.hull[i], 1);
      outer_ok += normal_ok && c.normal[i].dot(radial) > 0 && std::abs(c.height[i] - 0.5) < 0.05;
    }
  }
  EXPECT_GE(inner_ok, 1500 * 99 / 100);
  EXPECT_GE(outer_ok, 3000 * 95 / 100);
}

TEST(pmr_cell, PlaneHasFarPolesAndSmallRatio) {
  // A plane's medial axis is at infinity: on a dense, slightly noisy sample (noise 1e-3 of the
  // spacing) the cells are long needles along the normal, h ≫ spacing and r ≈ spacing, so the
  // normal is ±z and r/h is tiny (≈ 2·noise/spacing) away from the sample's border.
  const auto p = plane_points(40, 1e-3, 3);
  const auto c = analyse(p);
  std::vector<double> ratio;
  int normals_ok = 0, interior = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (p[i].x() < 5 || p[i].x() > 34 || p[i].y() < 5 || p[i].y() > 34) continue;
    ++interior;
    normals_ok += std::abs(c.normal[i].z()) > 0.999;
    EXPECT_GT(c.height[i], 20.0) << i;
    ratio.push_back(c.radius[i] / c.height[i]);
  }
  EXPECT_GE(normals_ok, interior * 99 / 100);
  EXPECT_LT(median(ratio), 0.05);
}

TEST(pmr_cell, RatioIsSmallWhenDenseAndLargeWhenSparse) {
  // On a sphere of radius 1, h ≈ 1 and r ≈ the sample spacing ∝ 1/√n: 40 samples give r/h
  // near 0.5, 4000 samples ten times less.
  const auto dense = analyse(sphere_points(4000, 1, vec3d::Zero(), 4, 1e-3));
  const auto sparse = analyse(sphere_points(40, 1, vec3d::Zero(), 5, 1e-3));
  std::vector<double> rd, rs;
  for (std::size_t i = 0; i < dense.height.size(); ++i)
    rd.push_back(dense.radius[i] / dense.height[i]);
  for (std::size_t i = 0; i < sparse.height.size(); ++i)
    rs.push_back(sparse.radius[i] / sparse.height[i]);
  EXPECT_LT(median(rd), 0.1);
  EXPECT_GT(median(rs), 0.3);
  EXPECT_GT(median(rs), 5 * median(rd));
}

TEST(pmr_cell, DeletionRemovesDenseSamplesAndKeepsRatiosAboveThreshold) {
  // After deleting at threshold ρ no remaining sample has r/h < ρ (the loop runs until none
  // does), so a dense sphere loses most samples at ρ = 0.5 and a brute-force recomputation of the
  // survivors' ratios (a fresh triangulation of them alone) finds none below ρ.
  const auto p = sphere_points(3000, 1, vec3d::Zero(), 6, 1e-3);
  const std::vector<float> rho = {0.2f, 0.5f};
  const auto c = analyse(p, rho);
  std::vector<vec3d> kept;
  for (std::size_t i = 0; i < p.size(); ++i)
    if (c.levels[i] == 3) kept.push_back(p[i]);
  EXPECT_LT(kept.size(), p.size() / 4);
  EXPECT_GT(kept.size(), 20u);
  const auto again = analyse(kept);
  for (std::size_t i = 0; i < kept.size(); ++i)
    EXPECT_GE(again.radius[i] / again.height[i], 0.5 * (1 - 1e-9)) << i;
}

// ---- the hierarchy

pmr_options small_leaves(std::uint32_t leaf = 800) {
  pmr_options o;
  o.max_leaf_points = leaf;
  o.threads = 2;
  return o;
}

TEST(pmr_build, LevelsNestAndDecimate) {
  // Level i of a leaf is a prefix of its samples (P_0 ⊇ P_1 ⊇ …), each sample's level count is
  // consistent with the prefixes, and the dense wavy surface loses most samples by ρ = 1.
  const point_cloud in = make_wavy_surface(3000, 7);
  const auto h = build_pmr(in, small_leaves(400));
  expect_valid(h, in.size());
  EXPECT_GT(h.leaf_count(), 4u);
  for (std::uint32_t i = 1; i < h.levels(); ++i)
    EXPECT_LE(h.points_at_level(i), h.points_at_level(i - 1));
  EXPECT_EQ(h.points_at_level(0), in.size());
  EXPECT_LT(h.points_at_level(h.levels() - 1), in.size() / 3);
  EXPECT_GT(h.points_at_level(h.levels() - 1), 0u);
  EXPECT_GT(h.stats().removals, in.size() / 2);
}

TEST(pmr_build, UmbrellasAgreeWithTheSurfaceAndCoverIt) {
  // A dense sample of a smooth closed surface (the sphere, normals known): its level-0 umbrella
  // triangles lie flat on the surface (Dey et al.'s result the paper cites), so their normals are
  // within a few degrees of the true normal, and together they cover the sphere without holes:
  // every edge of the triangle set is shared by exactly two triangles.
  const auto p = sphere_points(3000, 1, vec3d::Zero(), 8, 1e-4);
  pmr_options o;
  o.max_leaf_points = 100000;  // one leaf: the whole surface in one triangulation
  const auto h = build_pmr(cloud_of(p), o);
  ASSERT_EQ(h.leaf_count(), 1u);
  const auto& L = h.level(0, 0);
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> edges;
  int flat = 0;
  for (std::uint32_t t = L.first_tri; t < L.first_tri + L.tris; ++t) {
    const auto& T = h.triangles()[t];
    const vec3f a = h.positions()[T[0]], b = h.positions()[T[1]], c = h.positions()[T[2]];
    const vec3f n = (b - a).cross(c - a).normalized();
    const vec3f truth = ((a + b + c) / 3 + h.origin().cast<float>()).normalized();
    flat += std::abs(n.dot(truth)) > std::cos(10 * std::numbers::pi_v<float> / 180);
    for (int k = 0; k < 3; ++k)
      ++edges[{std::min(T[k], T[(k + 1) % 3]), std::max(T[k], T[(k + 1) % 3])}];
  }
  EXPECT_GE(flat, static_cast<int>(L.tris) * 98 / 100);
  int boundary = 0;
  for (const auto& [e, cnt] : edges) boundary += cnt != 2;
  EXPECT_LE(boundary, static_cast<int>(edges.size()) / 100) << "edges not shared by two triangles";
  // Every sample has an umbrella at level 0.
  for (std::uint32_t k = 0; k < L.points; ++k)
    EXPECT_GT(h.umbrellas()[L.first_entry + k].count, 0u);
  // The estimated normals agree with the sphere's.
  int normals_ok = 0;
  for (std::size_t g = 0; g < p.size(); ++g)
    normals_ok +=
        std::abs(h.normals()[g].dot((h.positions()[g] + h.origin().cast<float>()).normalized())) >
        0.99f;
  EXPECT_GE(normals_ok, static_cast<int>(p.size()) * 99 / 100);
}

/// Counts what emit_level sends and how often each triangle comes.
struct triangle_sink {
  std::size_t points = 0;
  std::map<std::array<float, 9>, int> seen;
  void point(const point_prim<with_normals>&) { ++points; }
  void splat(const splat_prim<with_normals>&) {}
  void triangle(const triangle_prim<with_normals>& t) {
    std::array<std::array<float, 3>, 3> v;
    for (int k = 0; k < 3; ++k) v[k] = {t.p[k].x(), t.p[k].y(), t.p[k].z()};
    std::sort(v.begin(), v.end());
    std::array<float, 9> key;
    for (int k = 0; k < 9; ++k) key[k] = v[k / 3][k % 3];
    ++seen[key];
  }
};

TEST(pmr_build, SharedTriangleIsEmittedOnce) {
  // A triangle in the umbrellas of its three vertices is stored once per leaf and level and
  // drawn once (RENDER-NODE lines 9–11): with every sample drawn as its umbrella (pixel size 0),
  // the sink receives exactly the level's distinct triangles, though the umbrellas list about
  // three times as many.
  const point_cloud in = make_wavy_surface(3000, 9);
  const auto h = build_pmr(in, small_leaves(1000));
  for (std::uint32_t l = 0; l < h.leaf_count(); ++l)
    for (std::uint32_t i = 0; i < h.levels(); i += 3) {
      triangle_sink s;
      h.emit_level(l, i, 0.0f, s);
      const auto& L = h.level(l, i);
      std::size_t listed = 0;
      for (std::uint32_t k = 0; k < L.points; ++k) listed += h.umbrellas()[L.first_entry + k].count;
      EXPECT_EQ(s.seen.size(), L.tris);
      for (const auto& [k, c] : s.seen) EXPECT_EQ(c, 1);
      if (i == 0) {
        EXPECT_GT(listed, 2 * L.tris) << "umbrellas share their triangles";
      }
    }
  // With a pixel larger than every umbrella, each sample is one point.
  triangle_sink s;
  h.emit_level(0, 0, 1e9f, s);
  EXPECT_EQ(s.points, h.level(0, 0).points);
  EXPECT_TRUE(s.seen.empty());
}

TEST(pmr_build, TraversalPicksCoarserLevelsFarAway) {
  // §3: the level whose average umbrella radius is closest to factor × pixel size; the pixel
  // grows with distance, so a far view picks coarser levels (and draws fewer primitives) than a
  // near one, and a larger factor coarser ones than a smaller factor.
  const point_cloud in = make_wavy_surface(3000, 10);
  const auto h = build_pmr(in, small_leaves(400));
  const auto draw = [&](double dist, float factor, double& mean_level) {
    camera cam = camera::orbit(h.origin(), 1.5, 30, 20, dist, 1);
    cam.vp = {256, 256};
    const view v(cam, h.origin());
    std::vector<std::uint32_t> used(h.leaf_count(), 0);
    pmr_policy pol;
    pol.levels_used = &used;
    counting_sink<pmr_hierarchy::attrs> sink;
    traverse_options o;
    o.tolerance_px = factor;
    traverse(h, v, o, sink, pol);
    // Each drawn leaf's level is choose_level() (checked against brute force below) of the world
    // size of a pixel at the corner of its cell nearest the eye: the nearest of the 8 corners,
    // found by trying them all.
    for (std::uint32_t l = 0; l < h.leaf_count(); ++l) {
      const auto& nd = h.nodes()[h.leaf(l).node];
      if (frustum_test(v, h.bounding_sphere(h.leaf(l).node)) < 0) continue;
      vec3f nearest = nd.cell_min;
      for (int k = 0; k < 8; ++k) {
        const vec3f c = nd.cell_min + nd.cell_size * vec3f(float(k & 1), float((k >> 1) & 1),
                                                           float((k >> 2) & 1));
        if ((c - v.eye).squaredNorm() < (nearest - v.eye).squaredNorm()) nearest = c;
      }
      EXPECT_EQ(used[l], h.choose_level(l, pixel_size_pmr(v, nearest), factor))
          << "leaf " << l << " at distance " << dist;
    }
    mean_level = 0;
    for (const auto u : used) mean_level += u;
    mean_level /= static_cast<double>(used.size());
    return sink.total();
  };
  double near_l = 0, far_l = 0, far5_l = 0;
  const auto near_n = draw(1.5, 1, near_l);
  const auto far_n = draw(40, 1, far_l);
  draw(40, 5, far5_l);
  EXPECT_LT(near_l, far_l);
  EXPECT_LE(far_l, far5_l);
  EXPECT_GT(near_n, far_n);
}

TEST(pmr_build, UmbrellaRadiiAndAveragesMatchBruteForce) {
  // §2 Records: a sample's umbrella radius is the largest distance from it to a vertex of its
  // umbrella triangles, and each leaf level stores the average over its samples with an
  // umbrella; both recomputed here from the stored triangles (float storage: 1e-5 relative).
  const auto h = build_pmr(make_wavy_surface(2000, 20), small_leaves(500));
  std::size_t checked = 0;
  for (std::uint32_t l = 0; l < h.leaf_count(); ++l)
    for (std::uint32_t i = 0; i < h.levels(); ++i) {
      const auto& L = h.level(l, i);
      double sum = 0;
      std::size_t with = 0;
      for (std::uint32_t k = 0; k < L.points; ++k) {
        const auto& u = h.umbrellas()[L.first_entry + k];
        const vec3f p = h.positions()[h.leaf(l).first_point + k];
        double r = 0;
        for (std::uint32_t j = u.first; j < u.first + u.count; ++j) {
          const auto& T = h.triangles()[L.first_tri + h.umbrella_index()[j]];
          EXPECT_TRUE(std::find(T.begin(), T.end(), h.leaf(l).first_point + k) != T.end())
              << "every triangle of an umbrella contains its sample";
          for (const auto g : T)
            r = std::max(r, static_cast<double>((h.positions()[g] - p).norm()));
        }
        EXPECT_NEAR(u.radius, r, 1e-5 * r + 1e-7);
        if (u.count) {
          sum += u.radius;
          ++with;
          ++checked;
        }
      }
      EXPECT_NEAR(L.mean_umbrella, with ? sum / static_cast<double>(with) : 0.0,
                  1e-5 * L.mean_umbrella + 1e-7);
    }
  EXPECT_GT(checked, 2000u);
}

TEST(pmr_build, LevelChoiceIsTheClosestAverageUmbrellaRadius) {
  // §3 Selecting hierarchy, against a brute-force argmin over the stored averages: the level
  // whose average umbrella radius is closest to factor × pixel size (the factor ramped by §4:
  // unchanged up to 2 units, 1 from 4 units on, linear between).
  EXPECT_EQ(pmr_ramped_factor(5, 1), 5);
  EXPECT_EQ(pmr_ramped_factor(5, 2), 5);
  EXPECT_EQ(pmr_ramped_factor(5, 3), 3);
  EXPECT_EQ(pmr_ramped_factor(5, 4), 1);
  EXPECT_EQ(pmr_ramped_factor(5, 9), 1);
  const auto h = build_pmr(make_wavy_surface(2000, 18), small_leaves(500));
  for (std::uint32_t l = 0; l < h.leaf_count(); ++l) {
    const float u0 = h.level(l, 0).mean_umbrella;
    for (const float factor : {1.0f, 3.0f, 5.0f})
      for (const float px : {0.1f * u0, 0.5f * u0, 1.5f * u0, 3.0f * u0, 8.0f * u0}) {
        const float target = pmr_ramped_factor(factor, px / u0) * px;
        std::uint32_t best = 0;
        for (std::uint32_t i = 1; i < h.levels(); ++i)
          if (h.level(l, i).mean_umbrella > 0 &&
              std::abs(h.level(l, i).mean_umbrella - target) <
                  std::abs(h.level(l, best).mean_umbrella - target))
            best = i;
        EXPECT_EQ(h.choose_level(l, px, factor), best) << "leaf " << l << " px " << px;
      }
  }
}

TEST(pmr_build, FrustumCullsLeavesBehindTheEye) {
  // The common traversal culls by the nodes' bounding spheres: looking away from the model
  // draws nothing, looking at it draws every leaf.
  const auto h = build_pmr(make_wavy_surface(2000, 19), small_leaves(500));
  camera cam;
  cam.eye = h.origin() + vec3d(0, 0, 5);
  cam.vp = {128, 128};
  counting_sink<pmr_hierarchy::attrs> away, at;
  cam.target = h.origin() + vec3d(0, 0, 10);
  const auto st_away = traverse(h, view(cam, h.origin()), {}, away, pmr_policy{});
  cam.target = h.origin();
  const auto st_at = traverse(h, view(cam, h.origin()), {}, at, pmr_policy{});
  EXPECT_EQ(away.total(), 0u);
  EXPECT_EQ(st_away.emitted_leaves, 0u);
  EXPECT_EQ(st_at.emitted_leaves, h.leaf_count());
  EXPECT_GT(at.total(), 0u);
}

// ---- degenerate input stays finite and valid

TEST(pmr_degenerate, Ladder) {
  // CGAL's test ladder: 1 point, a repeated point, 2 points, collinear, coplanar, cospherical,
  // duplicates of everything, the corners of a cube (all on the hull). Each builds a valid
  // hierarchy with finite unit normals; degenerate triangulations keep every sample at every
  // level.
  std::vector<std::vector<vec3d>> cases;
  cases.push_back({vec3d(1, 2, 3)});
  cases.push_back({vec3d(1, 2, 3), vec3d(1, 2, 3), vec3d(1, 2, 3)});
  cases.push_back({vec3d(0, 0, 0), vec3d(1, 0, 0)});
  std::vector<vec3d> line, grid;
  for (int i = 0; i < 50; ++i) line.emplace_back(i, 2 * i, 3 * i);
  cases.push_back(line);
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 30; ++x) grid.emplace_back(x, y, 0);
  cases.push_back(grid);
  cases.push_back(sphere_points(500, 3, vec3d(1, 1, 1), 11));  // cospherical (up to rounding)
  auto dup = sphere_points(300, 1, vec3d::Zero(), 12, 0.01);
  const auto copy = dup;
  dup.insert(dup.end(), copy.begin(), copy.end());
  dup.insert(dup.end(), copy.begin(), copy.end());
  cases.push_back(dup);
  std::vector<vec3d> cube;
  for (int k = 0; k < 8; ++k) cube.emplace_back(k & 1, (k >> 1) & 1, (k >> 2) & 1);
  cases.push_back(cube);
  for (std::size_t c = 0; c < cases.size(); ++c) {
    SCOPED_TRACE("case " + std::to_string(c));
    const auto h = build_pmr(cloud_of(cases[c]), small_leaves(100));
    expect_valid(h, cases[c].size());
    const std::string path = temp_path("ladder.lod");
    h.save(path);
    EXPECT_TRUE(pmr_hierarchy::load(path) == h);
    std::filesystem::remove(path);
  }
  // Coplanar: every sample at every level, the plane's normal.
  const auto hg = build_pmr(cloud_of(grid), small_leaves(100000));
  EXPECT_EQ(hg.points_at_level(hg.levels() - 1), grid.size());
  for (const auto& n : hg.normals()) EXPECT_NEAR(std::abs(n.z()), 1.0f, 1e-6f);
  // Duplicates: 600 of the 900 samples repeat one; they are at level 0 only.
  const auto hd = build_pmr(cloud_of(dup), small_leaves(100000));
  EXPECT_EQ(hd.stats().duplicates, 600u);
  EXPECT_LE(hd.points_at_level(1), 300u);
}

TEST(pmr_degenerate, FarFromTheOriginMatchesNearTheOrigin) {
  // The same sphere 10⁷ units from the origin (double origin, float offsets, as a georeferenced
  // scan is read) and at the origin: the builder subtracts a double origin before CGAL and
  // floats, so the normals agree and the levels (nearly) too.
  const auto p = sphere_points(2000, 5, vec3d::Zero(), 13, 0.01);
  const vec3d far(1e7, -2e7, 3e6);
  std::vector<vec3d> q;
  for (const auto& x : p) q.push_back(x + far);
  const auto a = build_pmr(cloud_of(p), small_leaves(600));
  const auto b = build_pmr(cloud_of(q, far), small_leaves(600));
  expect_valid(b, q.size());
  EXPECT_NEAR((b.origin() - a.origin() - far).norm(), 0.0, 1e-6);
  std::vector<float> na(p.size()), nb(p.size());
  int agree = 0;
  std::vector<std::uint32_t> at_a(p.size()), at_b(p.size());
  for (std::size_t g = 0; g < p.size(); ++g) {
    at_a[a.source()[g]] = static_cast<std::uint32_t>(g);
    at_b[b.source()[g]] = static_cast<std::uint32_t>(g);
  }
  for (std::size_t i = 0; i < p.size(); ++i)
    agree += std::abs(a.normals()[at_a[i]].dot(b.normals()[at_b[i]])) > 0.999f;
  EXPECT_GE(agree, static_cast<int>(p.size()) * 99 / 100);
  const auto top = a.levels() - 1;
  EXPECT_NEAR(static_cast<double>(a.points_at_level(top)),
              static_cast<double>(b.points_at_level(top)),
              0.05 * static_cast<double>(a.points_at_level(top)) + 2);
}

TEST(pmr_degenerate, BadInputAndOptionsAreErrors) {
  EXPECT_THROW((void)build_pmr(point_cloud{}), InvalidArgument);
  point_cloud nan = cloud_of({vec3d(0, 0, 0), vec3d(1, 1, 1)});
  nan.positions[1].x() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW((void)build_pmr(nan), InvalidArgument);
  pmr_options o;
  o.rho = {0.5f, 0.2f};
  EXPECT_THROW((void)build_pmr(cloud_of({vec3d(0, 0, 0)}), o), InvalidArgument);
  o = {};
  o.max_leaf_points = 2;
  EXPECT_THROW((void)build_pmr(cloud_of({vec3d(0, 0, 0)}), o), InvalidArgument);
  o = {};
  o.progress = [](double f) { return f < 0.5; };
  EXPECT_THROW((void)build_pmr(make_wavy_surface(3000, 14), o), Cancelled);
}

// ---- the file

TEST(pmr_file, RoundTripIsExactAndDeterministic) {
  // load(save(h)) == h, and the bytes depend on the input and options only: one thread and two
  // give the same file.
  const point_cloud in = make_wavy_surface(2500, 15);
  auto o1 = small_leaves();
  o1.threads = 1;
  const auto h1 = build_pmr(in, o1);
  const auto h2 = build_pmr(in, small_leaves());
  const std::string p1 = temp_path("a.lod"), p2 = temp_path("b.lod");
  h1.save(p1);
  h2.save(p2);
  const auto read = [](const std::string& p) {
    std::ifstream f(p, std::ios::binary);
    return std::vector<char>(std::istreambuf_iterator<char>(f), {});
  };
  const auto b1 = read(p1);
  EXPECT_EQ(b1, read(p2));
  EXPECT_EQ(b1.size(), h1.file_bytes());
  const auto back = pmr_hierarchy::load(p1);
  EXPECT_TRUE(back == h1);
  back.save(p2);
  EXPECT_EQ(read(p2), b1);
  std::filesystem::remove(p1);
  std::filesystem::remove(p2);
}

// Colours (beyond the paper): every stored sample keeps its input point's colour, the file
// round-trips them, and a file without colours is exactly 3 bytes per sample smaller.
point_cloud coloured(point_cloud c) {
  c.colours.resize(c.size());
  for (std::size_t i = 0; i < c.size(); ++i)  // distinct per point, by its input index
    c.colours[i] = {std::uint8_t(i & 0xff), std::uint8_t((i >> 8) & 0xff), std::uint8_t(i % 251)};
  return c;
}

TEST(pmr_colours, EverySampleKeepsItsInputColourThroughTheFile) {
  point_cloud plain = make_wavy_surface(2500, 15);
  plain.colours.clear();
  const point_cloud in = coloured(plain);
  const auto h = build_pmr(in, small_leaves());
  ASSERT_TRUE(h.has_colours());
  ASSERT_EQ(h.colours().size(), in.size());
  for (std::size_t g = 0; g < in.size(); ++g)
    ASSERT_EQ(h.colours()[g], in.colours[h.source()[g]]) << g;
  const auto bare = build_pmr(plain, small_leaves());
  EXPECT_FALSE(bare.has_colours());
  EXPECT_EQ(h.file_bytes(), bare.file_bytes() + 3 * in.size());
  const std::string path = temp_path("coloured.lod");
  h.save(path);
  EXPECT_EQ(std::filesystem::file_size(path), h.file_bytes());
  EXPECT_TRUE(pmr_hierarchy::load(path) == h);
  std::filesystem::remove(path);
  EXPECT_THROW((void)pmr_colour_view(bare), InvalidArgument);
}

// Records what a traversal emits: points and triangle corners with their colours.
struct colour_recorder {
  std::vector<std::pair<vec3f, rgb8>> corners;
  std::size_t points = 0, triangles = 0;
  void point(const point_prim<with_normals_colours>& p) {
    ++points;
    corners.emplace_back(p.position, p.colour);
  }
  void splat(const splat_prim<with_normals_colours>&) {}
  void triangle(const triangle_prim<with_normals_colours>& t) {
    ++triangles;
    for (std::size_t k = 0; k < 3; ++k) corners.emplace_back(t.p[k], t.colour[k]);
  }
};

// Drawn through pmr_colour_view, every point and every triangle corner has the colour of the
// sample at its position (a colour taken from a triangle's first corner for all three, or from
// the wrong array index, fails), at a near and a far view (umbrellas and points).
TEST(pmr_colours, DrawnPrimitivesCarryTheColourOfTheirSample) {
  const point_cloud in = coloured(make_wavy_surface(2500, 15));
  const auto h = build_pmr(in, small_leaves());
  std::map<std::array<float, 3>, rgb8> at;
  for (std::size_t g = 0; g < h.positions().size(); ++g)
    at[{h.positions()[g].x(), h.positions()[g].y(), h.positions()[g].z()}] = h.colours()[g];
  const vec3d c = 0.5 * (h.input_min() + h.input_max());
  const double r = 0.5 * (h.input_max() - h.input_min()).norm();
  for (const double dist : {1.5, 30.0}) {
    const view v(camera::orbit(c, r, 30, 40, dist, 1, {256, 256}), h.origin());
    colour_recorder rec;
    (void)traverse(pmr_colour_view(h), v, {.tolerance_px = 1}, rec, pmr_policy{});
    ASSERT_FALSE(rec.corners.empty());
    if (dist < 2) {
      EXPECT_GT(rec.triangles, 0u);
    }
    for (const auto& [p, col] : rec.corners) {
      const auto it = at.find({p.x(), p.y(), p.z()});
      ASSERT_NE(it, at.end());
      ASSERT_EQ(col, it->second);
    }
  }
}

TEST(pmr_file, TruncatedOrCorruptedFilesAreErrors) {
  // Every prefix length tried and every corrupted byte tried gives a FormatError (never a crash
  // or an out-of-bounds read: this runs under ASan in CI).
  const auto h = build_pmr(make_wavy_surface(1500, 16), small_leaves(400));
  const std::string path = temp_path("c.lod"), bad = temp_path("bad.lod");
  h.save(path);
  std::ifstream f(path, std::ios::binary);
  const std::vector<char> bytes(std::istreambuf_iterator<char>(f), {});
  const auto write = [&](const std::vector<char>& b) {
    std::ofstream o(bad, std::ios::binary | std::ios::trunc);
    o.write(b.data(), static_cast<std::streamsize>(b.size()));
  };
  std::mt19937 rng(17);
  for (int k = 0; k < 40; ++k) {
    const std::size_t len = k == 0 ? 0 : rng() % bytes.size();
    write(std::vector<char>(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(len)));
    EXPECT_THROW((void)pmr_hierarchy::load(bad), FormatError) << "truncated at " << len;
  }
  for (int k = 0; k < 60; ++k) {
    auto b = bytes;
    const std::size_t at = k < 20 ? static_cast<std::size_t>(k * 7) % 200 : rng() % b.size();
    b[at] = static_cast<char>(b[at] ^ (1 + rng() % 255));
    write(b);
    try {
      (void)pmr_hierarchy::load(bad);
      ADD_FAILURE() << "corrupted byte " << at << " was accepted";
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << "names the file";
    }
  }
  EXPECT_THROW((void)pmr_hierarchy::load(temp_path("missing.lod")), IoError);
  std::filesystem::remove(path);
  std::filesystem::remove(bad);
}

// ---- a real scan

TEST(pmr_real_data, BunnyBuildsAndDecimates) {
  // The Stanford bunny at 1/16 resolution (1,889 points): several leaves, every sample stored,
  // the coarsest level a small fraction of the scan.
  const triangle_mesh m = read_mesh(test::data_file("bun_zipper_res3.ply"));
  const auto h = build_pmr(m.vertices, small_leaves(500));
  expect_valid(h, m.vertices.size());
  EXPECT_GT(h.leaf_count(), 2u);
  EXPECT_LT(h.points_at_level(h.levels() - 1), m.vertices.size() / 2);
}

// ---- what the user sees (issue 39): the finest cut against the input's own render

/// The finest cut: every leaf at level 0, every sample drawn as its umbrella.
buffer_sink<with_normals> finest_cut(const pmr_hierarchy& h) {
  buffer_sink<with_normals> cut;
  for (std::uint32_t l = 0; l < h.leaf_count(); ++l) h.emit_level(l, 0, 0.0f, cut);
  return cut;
}

/// The cut a view draws at factor 1 with the tool's default effects (shading, and the input's
/// colours when it has them).
image draw_cut(const pmr_hierarchy& h, const camera& cam) {
  const view v(cam, h.origin());
  render_options ro;
  ro.fx = no_effects;
  ro.fx.shading = true;
  ro.fx.colour = h.has_colours();
  const traverse_options t{.tolerance_px = 1};
  if (h.has_colours()) {
    const pmr_colour_view hc(h);
    return render<pmr_colour_view::attrs>(
        v, ro, [&](auto& sink) { traverse(hc, v, t, sink, pmr_policy{}); });
  }
  return render<pmr_hierarchy::attrs>(v, ro,
                                      [&](auto& sink) { traverse(h, v, t, sink, pmr_policy{}); });
}

render_options input_effects(bool colour) {
  render_options ro;
  ro.fx = no_effects;
  ro.fx.shading = true;
  ro.fx.colour = colour;
  return ro;
}

struct likeness {
  test::user_view_score views;
  double cut_to_input = 0;  ///< of the finest cut, over the input's diagonal
  double build_seconds = 0;
  double build_cpu_seconds = 0;  ///< of every thread
  std::size_t triangles = 0;     ///< at level 0
};

/// With PMR_PNG=DIR set: the views' input and cut renders as DIR/NAME_VIEW_{input,cut}.png.
void write_views(const std::string& name, const std::vector<camera>& cams,
                 const std::function<image(const camera&)>& input,
                 const std::function<image(const camera&)>& cut) {
  const char* dir = std::getenv("PMR_PNG");
  if (!dir) return;
  for (std::size_t v = 0; v < cams.size(); ++v) {
    const std::string base = std::string(dir) + "/" + name + "_" + std::to_string(v);
    write_png(base + "_input.png", input(cams[v]));
    write_png(base + "_cut.png", cut(cams[v]));
  }
}

/// With PMR_WORST set: the finest cut's triangles farthest from the mesh.
void print_worst(const triangle_mesh& mesh, const pmr_hierarchy& h);

/// The same against the points of `surface`.
void print_worst(const point_cloud& dense, double diag, const pmr_hierarchy& h) {
  const auto cut = finest_cut(h);
  const knn_index index(dense.positions);
  const vec3f shift = (h.origin() - dense.origin).cast<float>();
  std::vector<std::pair<double, std::size_t>> worst;
  for (std::size_t t = 0; t < cut.triangles.size(); ++t) {
    buffer_sink<with_normals> one;
    one.triangles.push_back(cut.triangles[t]);
    auto pos = test::cut_positions(one);
    for (auto& p : pos) p += shift;
    worst.emplace_back(distance_to(pos, index).max, t);
  }
  std::sort(worst.rbegin(), worst.rend());
  for (std::size_t k = 0; k < std::min<std::size_t>(12, worst.size()); ++k) {
    const auto& T = cut.triangles[worst[k].second].p;
    std::printf("  %.4f  (%.3f %.3f %.3f) (%.3f %.3f %.3f) (%.3f %.3f %.3f)\n",
                worst[k].first / diag, T[0].x() + shift.x(), T[0].y() + shift.y(),
                T[0].z() + shift.z(), T[1].x() + shift.x(), T[1].y() + shift.y(),
                T[1].z() + shift.z(), T[2].x() + shift.x(), T[2].y() + shift.y(),
                T[2].z() + shift.z());
  }
}

void print_worst(const triangle_mesh& mesh, const pmr_hierarchy& h) {
  if (std::getenv("PMR_WORST"))
    print_worst(sample_surface(mesh, 400000, 7), test::frame_of(mesh.vertices).diagonal, h);
}

/// PMR built from `points`, scored against the mesh it samples.
likeness score_against_mesh(const triangle_mesh& mesh, const point_cloud& points,
                            const pmr_options& o, const std::string& name = "") {
  const std::clock_t c0 = std::clock();
  const auto h = build_pmr(points, o);
  print_worst(mesh, h);
  likeness r;
  r.build_cpu_seconds = double(std::clock() - c0) / CLOCKS_PER_SEC;
  r.build_seconds = h.stats().build_seconds;
  r.triangles = h.triangles_at_level(0);
  const auto cams = test::user_views(test::frame_of(mesh.vertices));
  const render_options ro = input_effects(!mesh.vertices.colours.empty());
  r.views = test::score_views(
      cams, [&](const camera& c) { return render_reference(mesh, c, ro); },
      [&](const camera& c) { return draw_cut(h, c); });
  if (!name.empty())
    write_views(
        name, cams, [&](const camera& c) { return render_reference(mesh, c, ro); },
        [&](const camera& c) { return draw_cut(h, c); });
  r.cut_to_input = test::cut_to_input(mesh, test::cut_positions(finest_cut(h)), h.origin());
  return r;
}

/// PMR of a cloud scored against the cloud's own render (normals estimated for shading when it
/// has none) and its points.
likeness score_against_cloud(const point_cloud& cloud, const pmr_options& o,
                             const std::string& name = "") {
  const std::clock_t c0 = std::clock();
  const auto h = build_pmr(cloud, o);
  if (std::getenv("PMR_WORST")) print_worst(cloud, test::frame_of(cloud).diagonal, h);
  likeness r;
  r.build_cpu_seconds = double(std::clock() - c0) / CLOCKS_PER_SEC;
  r.build_seconds = h.stats().build_seconds;
  r.triangles = h.triangles_at_level(0);
  point_cloud shaded = cloud;
  if (shaded.normals.empty()) shaded.normals = estimate_normals(shaded.positions);
  const auto cams = test::user_views(test::frame_of(cloud));
  const render_options ro = input_effects(!cloud.colours.empty());
  r.views = test::score_views(
      cams, [&](const camera& c) { return render_reference(shaded, c, ro); },
      [&](const camera& c) { return draw_cut(h, c); });
  if (!name.empty())
    write_views(
        name, cams, [&](const camera& c) { return render_reference(shaded, c, ro); },
        [&](const camera& c) { return draw_cut(h, c); });
  const auto cut = test::cut_positions(finest_cut(h));
  const vec3f shift = (h.origin() - cloud.origin).cast<float>();
  std::vector<vec3f> moved(cut.size());
  for (std::size_t i = 0; i < cut.size(); ++i) moved[i] = cut[i] + shift;
  const knn_index index(cloud.positions);
  r.cut_to_input = distance_to(moved, index).max / test::frame_of(cloud).diagonal;
  return r;
}

void print(const char* name, const likeness& l) {
  std::printf(
      "%-22s psnr_interior min %6.2f mean %6.2f  iou_min %.4f  cut_to_input %.4f  "
      "build %.2f s (cpu %.2f s)  level-0 triangles %zu\n",
      name, l.views.psnr_interior_min, l.views.psnr_interior_mean, l.views.iou_min, l.cut_to_input,
      l.build_seconds, l.build_cpu_seconds, l.triangles);
}

pmr_options user_view_options() {
  pmr_options o;
  o.threads = 2;
  return o;
}

TEST(pmr_user_view, FinestCutLooksLikeTheHardCasesScene) {
  // Two spheres 0.04 apart and 0.1 above a floor with an open boundary and a square hole, a
  // wall meeting the floor in a crease, colours; PMR takes points, so the scene is sampled.
  // The paper's umbrellas join whatever Voronoi edges the tangent plane crosses: triangles from
  // a sphere to the floor, across the hole, fans along the open boundary — far from the surface
  // (cut → input), and drawn where the input shows background or another surface. With the
  // cocone and spacing rules (docs/pmr.md) the finest cut stays on the surface and looks like
  // the input from every user view. Floors a little below what the build reaches.
  const triangle_mesh scene = make_hard_cases_scene(32);
  const point_cloud points = sample_surface(scene, 40000, 3);
  const likeness l = score_against_mesh(scene, points, user_view_options());
  print("hard cases", l);
  EXPECT_GE(l.views.psnr_interior_min, 29.0);  // reached: 31.2 dB
  EXPECT_GE(l.views.iou_min, 0.98);            // 0.989
  EXPECT_LE(l.cut_to_input, 0.01);             // 0.0084
  // The same floors fail for the paper's umbrellas (rules and input normals off: 13.5 dB, 0.935,
  // 0.145): the test sees the defect.
  pmr_options paper = user_view_options();
  paper.cocone_degrees = 0;
  paper.edge_spacing = 0;
  paper.input_normals = false;
  const likeness old = score_against_mesh(scene, points, paper);
  print("hard cases, paper", old);
  EXPECT_LT(old.views.psnr_interior_min, 29.0);
  EXPECT_LT(old.views.iou_min, 0.98);
  EXPECT_GT(old.cut_to_input, 0.01);
}

/// Not run by default (--gtest_also_run_disabled_tests): the table of docs/pmr.md. PMR_COCONE,
/// PMR_EDGE, PMR_MARGIN override the options; PMR_INPUTS picks inputs (letters h d b y l).
TEST(pmr_user_view, DISABLED_Report) {
  pmr_options o = user_view_options();
  if (const char* e = std::getenv("PMR_COCONE")) o.cocone_degrees = std::stof(e);
  if (const char* e = std::getenv("PMR_EDGE")) o.edge_spacing = std::stof(e);
  if (const char* e = std::getenv("PMR_MARGIN")) o.neighbour_margin = std::stof(e);
  if (const char* e = std::getenv("PMR_NORMALS")) o.input_normals = std::stoi(e) != 0;
  const std::string which = std::getenv("PMR_INPUTS") ? std::getenv("PMR_INPUTS") : "hdbyl";
  std::printf("cocone %.1f deg, edge_spacing %.2f, margin %.2f, input normals %d\n",
              o.cocone_degrees, o.edge_spacing, o.neighbour_margin, int(o.input_normals));
  if (which.find('h') != std::string::npos) {
    const triangle_mesh scene = make_hard_cases_scene(48);
    print("hard cases 48 / 60k",
          score_against_mesh(scene, sample_surface(scene, 60000, 3), o, "hard"));
  }
  if (which.find('d') != std::string::npos) {
    const triangle_mesh scene = make_demo_scene();
    print("demo scene vertices", score_against_mesh(scene, scene.vertices, o, "demo"));
  }
  if (which.find('b') != std::string::npos) {
    const triangle_mesh m = read_mesh(test::data_file("bun_zipper.ply"));
    print("bunny", score_against_mesh(m, m.vertices, o, "bunny"));
  }
  if (which.find('y') != std::string::npos) {
    const triangle_mesh m = read_mesh(test::data_file("happy_vrip_res3.ply"));
    print("happy res3", score_against_mesh(m, m.vertices, o, "happy"));
  }
  if (which.find('l') != std::string::npos)
    print("lidar tile 60k", score_against_cloud(make_lidar_tile(60000, 1, false), o, "lidar"));
}

/// Per input sample, the number of levels it is in.
std::vector<int> level_counts(const pmr_hierarchy& h) {
  std::vector<int> n(h.source().size(), 0);
  for (std::uint32_t l = 0; l < h.leaf_count(); ++l)
    for (std::uint32_t i = 0; i < h.levels(); ++i)
      for (std::uint32_t k = 0; k < h.level(l, i).points; ++k)
        ++n[h.source()[h.leaf(l).first_point + k]];
  return n;
}

/// Not run by default: the fraction of samples whose level count agrees with a whole-cloud
/// build (one leaf, one triangulation), for the default leaves (PMR_MARGIN, PMR_LEAF override).
TEST(pmr_user_view, DISABLED_HaloAgreement) {
  pmr_options o = user_view_options();
  if (const char* e = std::getenv("PMR_MARGIN")) o.neighbour_margin = std::stof(e);
  if (const char* e = std::getenv("PMR_LEAF")) o.max_leaf_points = std::stoul(e);
  if (const char* e = std::getenv("PMR_TRI")) o.triangulation_points = std::stoul(e);
  if (const char* e = std::getenv("PMR_LEAVES")) o.neighbour_leaves = std::stoi(e) != 0;
  const auto run = [&](const char* name, const point_cloud& c) {
    pmr_options whole = o;
    whole.max_leaf_points = 1u << 30;
    const auto t0 = std::chrono::steady_clock::now();
    const auto a = level_counts(build_pmr(c, whole));
    const double ta = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const auto hb = build_pmr(c, o);
    const auto b = level_counts(hb);
    std::size_t same = 0;
    for (std::size_t i = 0; i < a.size(); ++i) same += a[i] == b[i];
    std::printf(
        "%-12s leaves %zu, triangulation_points %u, margin %.2f: same level count %.2f %%  "
        "(whole %.1f s, leaves %.1f s, triangulated %zu)\n",
        name, hb.leaf_count(), o.triangulation_points, o.neighbour_margin,
        100.0 * double(same) / double(a.size()), ta, hb.stats().build_seconds,
        hb.stats().triangulated_points);
  };
  const std::string which = std::getenv("PMR_INPUTS") ? std::getenv("PMR_INPUTS") : "b";
  if (which.find('b') != std::string::npos)
    run("bunny", read_mesh(test::data_file("bun_zipper.ply")).vertices);
  if (which.find('w') != std::string::npos) run("wavy 100k", make_wavy_surface(100000, 1));
  if (which.find('W') != std::string::npos) run("wavy 300k", make_wavy_surface(300000, 1));
}

}  // namespace
}  // namespace pbr_lod
