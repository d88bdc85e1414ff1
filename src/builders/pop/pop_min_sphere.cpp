// pbr_lod — CGAL's exact smallest enclosing sphere of spheres, for the POP builder's
// pop_sphere_rule::exact (beyond Chen & Nguyen 2001 §3.1). Its own object library (see
// src/builders/sources.cmake), so CGAL and -frounding-math stay in this file.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Min_sphere_of_spheres_d.h>
#include <CGAL/Min_sphere_of_spheres_d_traits_3.h>

#include <vector>

#include "pbr_lod/builders/pop.hpp"

namespace pbr_lod::detail {

namespace {
using kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
// Tag_true: the result in plain doubles (square roots taken), 0.32 µs per 4 spheres
// (DEPENDENCIES.md) — as fast as the default and without the a + b·√t representation.
using traits = CGAL::Min_sphere_of_spheres_d_traits_3<kernel, double, CGAL::Tag_true>;
using min_sphere = CGAL::Min_sphere_of_spheres_d<traits>;
}  // namespace

bool min_sphere_of_spheres(const vec3d* c, const double* r, std::size_t n, vec3d& centre,
                           double& radius) {
  if (n == 0) return false;
  thread_local std::vector<traits::Sphere> spheres;
  spheres.clear();
  for (std::size_t i = 0; i < n; ++i)
    spheres.emplace_back(kernel::Point_3(c[i].x(), c[i].y(), c[i].z()), r[i]);
  min_sphere ms(spheres.begin(), spheres.end());  // its accessors are non-const
  auto it = ms.center_cartesian_begin();
  centre.x() = *it++;
  centre.y() = *it++;
  centre.z() = *it;
  radius = ms.radius();
  return true;
}

}  // namespace pbr_lod::detail
