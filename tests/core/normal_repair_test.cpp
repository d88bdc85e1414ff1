// fill_missing_normals: a zero or non-finite normal is "no normal"; only those are estimated,
// oriented to agree with the given ones, and the given normals never change.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/normal_repair.hpp"

namespace pbr_lod {
namespace {

/// n points on the unit sphere (seeded; random is fine: the property holds for any sampling
/// dense enough for 16 neighbours to span a tangent plane) and their outward normals.
void sphere(std::size_t n, std::vector<vec3f>& p, std::vector<vec3f>& nrm) {
  std::mt19937 rng(5);
  std::normal_distribution<float> g;
  for (std::size_t i = 0; i < n; ++i) {
    const vec3f v = vec3f(g(rng), g(rng), g(rng)).normalized();
    p.push_back(v);
    nrm.push_back(v);
  }
}

// Every 7th normal zeroed and every 11th NaN: exactly those are replaced; each estimate lies
// within 5° of the true outward normal (16 neighbours on a unit sphere of 4000 points span
// ≈ 0.13 rad, whose curvature tilts a PCA normal far less) and points outward.
TEST(NormalRepair, SomeMissingAreEstimatedAndOriented) {
  std::vector<vec3f> p, truth;
  sphere(4000, p, truth);
  std::vector<vec3f> n = truth;
  std::size_t expect = 0;
  for (std::size_t i = 0; i < n.size(); ++i) {
    if (i % 7 == 0)
      n[i].setZero();
    else if (i % 11 == 0)
      n[i].x() = std::numeric_limits<float>::quiet_NaN();
    else
      continue;
    ++expect;
  }
  const normal_repair r = fill_missing_normals(p, n);
  EXPECT_EQ(r.missing, expect);
  EXPECT_FALSE(r.all_estimated);
  const float cos5 = std::cos(5 * std::numbers::pi_v<float> / 180);
  for (std::size_t i = 0; i < n.size(); ++i) {
    if (i % 7 != 0 && i % 11 != 0) {
      EXPECT_EQ(n[i], truth[i]) << "given normal " << i << " changed";
      continue;
    }
    EXPECT_NEAR(n[i].norm(), 1.0f, 1e-5f) << i;
    EXPECT_GT(n[i].dot(truth[i]), cos5) << "normal " << i;
  }
}

// A 60×60 plane whose normals are +z except a 20×20 block in the middle that has none: the
// block is oriented from its rim inwards (its inner points have no given neighbour) — all +z.
TEST(NormalRepair, MissingPatchIsOrientedFromItsRim) {
  std::vector<vec3f> p, n;
  for (int y = 0; y < 60; ++y)
    for (int x = 0; x < 60; ++x) {
      p.emplace_back(0.1f * x, 0.1f * y, 0.001f * std::sin(float(x * y)));
      const bool hole = x >= 20 && x < 40 && y >= 20 && y < 40;
      n.push_back(hole ? vec3f::Zero() : vec3f(0, 0, 1));
    }
  EXPECT_EQ(fill_missing_normals(p, n).missing, 400u);
  for (const vec3f& v : n) EXPECT_GT(v.z(), 0.99f);
}

// Every normal missing (a 3DGS file): all estimated as for a bare cloud — on a closed surface
// the spanning-forest orientation is outward.
TEST(NormalRepair, AllMissingAreEstimatedAsForABareCloud) {
  std::vector<vec3f> p, truth;
  sphere(3000, p, truth);
  std::vector<vec3f> n(p.size(), vec3f::Zero());
  const normal_repair r = fill_missing_normals(p, n);
  EXPECT_EQ(r.missing, p.size());
  EXPECT_TRUE(r.all_estimated);
  for (std::size_t i = 0; i < n.size(); ++i) EXPECT_GT(n[i].dot(truth[i]), 0.95f) << i;
}

// A missing normal among duplicates of its own position (no spread to fit a plane to) takes
// the nearest given normal; nothing missing leaves everything as it was; thread counts agree.
TEST(NormalRepair, DuplicatesNothingMissingAndThreads) {
  std::vector<vec3f> p(40, vec3f(1, 2, 3)), n(40, vec3f(0, 1, 0));
  n[5].setZero();
  fill_missing_normals(p, n);
  EXPECT_EQ(n[5], vec3f(0, 1, 0));
  const std::vector<vec3f> before = n;
  EXPECT_EQ(fill_missing_normals(p, n).missing, 0u);
  EXPECT_EQ(n, before);
  std::vector<vec3f> q, truth;
  sphere(5000, q, truth);
  for (std::size_t i = 0; i < truth.size(); i += 3) truth[i].setZero();
  std::vector<vec3f> a = truth, b = truth;
  fill_missing_normals(q, a, 16, 1);
  fill_missing_normals(q, b, 16, 2);
  EXPECT_EQ(a, b);
}

TEST(NormalRepair, BadArgumentsAreErrors) {
  std::vector<vec3f> p(10, vec3f(0, 0, 0)), n(9, vec3f::Zero());
  EXPECT_THROW(fill_missing_normals(p, n), InvalidArgument);
  n.resize(10);
  EXPECT_THROW(fill_missing_normals(p, n, 2), InvalidArgument);
  n[3] = vec3f(0, 0, 1);
  p[4].x() = std::numeric_limits<float>::infinity();
  EXPECT_THROW(fill_missing_normals(p, n), InvalidArgument);
}

}  // namespace
}  // namespace pbr_lod
