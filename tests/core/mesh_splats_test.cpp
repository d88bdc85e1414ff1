// Tests for mesh_splats (core/mesh_splats.hpp): a mesh's vertices as splats bounding their dual
// cells.
#include "pbr_lod/core/mesh_splats.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/estimation.hpp"
#include "pbr_lod/core/mesh_normals.hpp"
#include "pbr_lod/core/synthetic.hpp"

namespace pbr_lod {
namespace {

/// Whether q, projected along splat i's normal into its plane, lies inside its ellipse.
bool inside(const point_cloud& s, std::size_t i, const vec3f& q, double slack = 1e-4) {
  const vec3d d = (q - s.positions[i]).cast<double>();
  const vec3d u = s.axis_u[i].cast<double>(), v = s.axis_v[i].cast<double>();
  const double x = d.dot(u) / u.squaredNorm(), y = d.dot(v) / v.squaredNorm();
  return x * x + y * y <= 1 + slack;
}

/// A flat n × n grid of unit spacing in the xz-plane (y = 0), two triangles a cell: an open
/// boundary all round.
triangle_mesh flat_grid(int n) {
  triangle_mesh m;
  for (int z = 0; z <= n; ++z)
    for (int x = 0; x <= n; ++x) m.vertices.positions.emplace_back(float(x), 0.f, float(z));
  const auto at = [&](int x, int z) { return std::uint32_t(z * (n + 1) + x); };
  for (int z = 0; z < n; ++z)
    for (int x = 0; x < n; ++x) {
      m.faces.push_back({at(x, z), at(x, z + 1), at(x + 1, z)});
      m.faces.push_back({at(x + 1, z), at(x, z + 1), at(x + 1, z + 1)});
    }
  return m;
}

// Every point of the surface lies, along some vertex's normal, inside that vertex's splat: the
// dual cells tile the surface and each ellipse holds its cell's projection. Brute force over
// all splats, on a scene with separate surfaces, open edges, a hole and a crease.
TEST(MeshSplats, CoverTheSurface) {
  const triangle_mesh mesh = make_hard_cases_scene(10);
  const point_cloud s = mesh_splats(mesh);
  ASSERT_GT(s.size(), 100u);
  const point_cloud samples = sample_surface(mesh, 5000, 11);
  ASSERT_EQ(samples.origin, s.origin);
  std::size_t uncovered = 0;
  for (const auto& q : samples.positions) {
    bool hit = false;
    for (std::size_t i = 0; i < s.size() && !hit; ++i) hit = inside(s, i, q);
    uncovered += hit ? 0 : 1;
  }
  EXPECT_EQ(uncovered, 0u);
}

// The splats stay within half an edge of an open boundary (an ellipse estimated from the k
// nearest neighbours reaches about two rings past it), and inside they are about the spacing.
TEST(MeshSplats, ReachHalfAnEdgePastAnOpenBoundary) {
  const int n = 20;
  const point_cloud s = mesh_splats(flat_grid(n));
  ASSERT_EQ(s.size(), std::size_t((n + 1) * (n + 1)));
  double overhang = 0, largest = 0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    EXPECT_NEAR(std::abs(s.normals[i].y()), 1.0, 1e-6);
    EXPECT_NEAR(s.axis_u[i].dot(s.normals[i]), 0.0, 1e-6);
    EXPECT_NEAR(s.axis_u[i].dot(s.axis_v[i]), 0.0, 1e-5);
    EXPECT_GE(s.axis_v[i].norm(), splat_min_axis_ratio * s.axis_u[i].norm() * (1 - 1e-5));
    largest = std::max(largest, double(s.axis_u[i].norm()));
    for (int k = 0; k < 64; ++k) {  // the rim's distance outside the square [0, n]²
      const double a = 2 * 3.14159265358979 * k / 64;
      const vec3f r =
          s.positions[i] + float(std::cos(a)) * s.axis_u[i] + float(std::sin(a)) * s.axis_v[i];
      overhang = std::max(
          {overhang, -double(r.x()), double(r.x()) - n, -double(r.z()), double(r.z()) - n});
    }
  }
  // Measured: 0.724 (corner vertices) and 0.951; the estimated ellipses (k = 12) overhang 3.46.
  EXPECT_LE(overhang, 0.75);
  EXPECT_LE(largest, 1.0 + 1e-4);
  const auto est = estimate_normals_and_ellipses(flat_grid(n).vertices.positions, 16, 12);
  double est_overhang = 0;
  for (std::size_t i = 0; i < s.size(); ++i)
    for (const vec3f& r :
         {vec3f(s.positions[i] + est.axes.u[i]), vec3f(s.positions[i] - est.axes.u[i])})
      est_overhang = std::max({est_overhang, -double(r.x()), double(r.x()) - n});
  std::printf("overhang %.4f, largest major %.4f, estimated ellipses' overhang %.4f\n", overhang,
              largest, est_overhang);
  EXPECT_GT(est_overhang, overhang);  // what the mesh's faces buy
}

// Normals: the mesh's own when it has them, else area-weighted; a vertex no face uses (or only
// faces of zero area) is left out, and colours stay with their vertices.
TEST(MeshSplats, NormalsColoursAndUnusedVertices) {
  triangle_mesh m = flat_grid(3);
  const std::vector<vec3f> aw = area_weighted_normals(m);
  const std::size_t used = m.vertices.size();
  m.vertices.positions.emplace_back(5.f, 5.f, 5.f);  // referenced by no face
  m.vertices.positions.emplace_back(6.f, 5.f, 5.f);  // only a zero-area face
  m.faces.push_back({std::uint32_t(used + 1), std::uint32_t(used + 1), 0u});
  for (std::size_t i = 0; i < m.vertices.size(); ++i)
    m.vertices.colours.push_back({std::uint8_t(i), 0, 0});
  point_cloud s = mesh_splats(m);
  ASSERT_EQ(s.size(), used);
  ASSERT_EQ(s.colours.size(), used);
  for (std::size_t i = 0; i < used; ++i) {
    EXPECT_EQ(s.colours[i].r, i);
    EXPECT_LT((s.normals[i] - aw[i]).norm(), 1e-6);
  }
  m.vertices.normals.assign(m.vertices.size(), vec3f(0, 0, -2));  // given: used, normalised
  s = mesh_splats(m);
  ASSERT_EQ(s.size(), used);
  EXPECT_LT((s.normals[0] - vec3f(0, 0, -1)).norm(), 1e-6);
  EXPECT_TRUE(mesh_splats(triangle_mesh{}).empty());
  m.faces.push_back({0u, 1u, 99u});
  EXPECT_THROW((void)mesh_splats(m), InvalidArgument);
}

}  // namespace
}  // namespace pbr_lod
