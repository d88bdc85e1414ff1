#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

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

/// Distance from p to the triangle (a, b, c): to the plane when p projects inside, else to the
/// nearest edge.
double triangle_distance(const vec3d& p, const vec3d& a, const vec3d& b, const vec3d& c) {
  const auto segment = [&](const vec3d& s, const vec3d& t) {
    const double l2 = (t - s).squaredNorm();
    const double u = l2 > 0 ? std::clamp((p - s).dot(t - s) / l2, 0.0, 1.0) : 0.0;
    return (s + u * (t - s) - p).norm();
  };
  const vec3d n = (b - a).cross(c - a);
  if (n.squaredNorm() > 0) {
    const vec3d q = p - n * (n.dot(p - a) / n.squaredNorm());
    // Inside when q is on the inner side of all three edges.
    const bool inside = (b - a).cross(q - a).dot(n) >= 0 && (c - b).cross(q - b).dot(n) >= 0 &&
                        (a - c).cross(q - c).dot(n) >= 0;
    if (inside) return (p - q).norm();
  }
  return std::min({segment(a, b), segment(b, c), segment(c, a)});
}

// Samples lie on the mesh (distance to the nearest triangle, brute force over all of them, at
// float rounding), and are spread by area, not by face: the faces larger than the median face
// hold a share of the samples equal to their share of the area (a sampler that picked faces
// uniformly would give them half). 4000 samples: the share's standard error is under 0.8 %.
TEST(Synthetic, SamplesLieOnTheSurface) {
  const auto m = make_demo_scene(8);
  const std::size_t n = 4000;
  const auto c = sample_surface(m, n, 1);
  ASSERT_EQ(c.size(), n);
  ASSERT_EQ(c.normals.size(), n);
  ASSERT_EQ(c.colours.size(), n);
  const auto& P = m.vertices.positions;
  std::vector<double> area(m.faces.size());
  for (std::size_t f = 0; f < m.faces.size(); ++f) {
    const auto& t = m.faces[f];
    area[f] =
        0.5 * (P[t[1]] - P[t[0]]).cast<double>().cross((P[t[2]] - P[t[0]]).cast<double>()).norm();
  }
  std::vector<double> sorted = area;
  std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(sorted.size() / 2),
                   sorted.end());
  const double median = sorted[sorted.size() / 2];
  double large_area = 0, total_area = 0;
  for (const double a : area) {
    total_area += a;
    large_area += a > median ? a : 0;
  }
  std::size_t on_large = 0;
  for (const auto& p : c.positions) {
    double best = std::numeric_limits<double>::infinity();
    std::size_t best_face = 0;
    for (std::size_t f = 0; f < m.faces.size(); ++f) {
      const auto& t = m.faces[f];
      const double d = triangle_distance(p.cast<double>(), P[t[0]].cast<double>(),
                                         P[t[1]].cast<double>(), P[t[2]].cast<double>());
      if (d < best) {
        best = d;
        best_face = f;
      }
    }
    ASSERT_LT(best, 1e-5) << p.transpose();
    on_large += area[best_face] > median;
  }
  const double share = large_area / total_area;
  ASSERT_GT(share, 0.6) << "the test needs faces of unequal area";
  EXPECT_NEAR(double(on_large) / double(n), share, 0.03);
  // Deterministic for a seed.
  EXPECT_EQ(sample_surface(m, 10, 5).positions, sample_surface(m, 10, 5).positions);
}

TEST(Synthetic, WavySurfaceHasUnitNormals) {
  const auto c = make_wavy_surface(1000);
  for (const auto& n : c.normals) EXPECT_NEAR(n.norm(), 1.0f, 1e-4f);
}

}  // namespace
}  // namespace pbr_lod
