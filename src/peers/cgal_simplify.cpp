// pbr_lod — CGAL's point-set simplifications as LOD peers (peers/cgal_simplify.hpp). Each keeps
// an index beside its point, so the kept points take their attributes with them.
#include "pbr_lod/peers/cgal_simplify.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/grid_simplify_point_set.h>
#include <CGAL/hierarchy_simplify_point_set.h>
#include <CGAL/property_map.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "pbr_lod/core/error.hpp"

namespace pbr_lod::peers {
namespace {
using kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using indexed_point = std::pair<kernel::Point_3, std::uint32_t>;
using point_map = CGAL::First_of_pair_property_map<indexed_point>;

std::vector<indexed_point> indexed(const point_cloud& in) {
  std::vector<indexed_point> p(in.size());
  for (std::size_t i = 0; i < in.size(); ++i) {
    const vec3f& q = in.positions[i];
    p[i] = {{q.x(), q.y(), q.z()}, static_cast<std::uint32_t>(i)};
  }
  return p;
}

/// The indices of [first, end), sorted: the kept points in input order.
std::vector<std::uint32_t> kept(std::vector<indexed_point>::const_iterator first,
                                std::vector<indexed_point>::const_iterator end) {
  std::vector<std::uint32_t> k;
  for (auto it = first; it != end; ++it) k.push_back(it->second);
  std::sort(k.begin(), k.end());
  return k;
}

template <class T>
std::vector<T> pick(const std::vector<T>& v, const std::vector<std::uint32_t>& keep) {
  if (v.empty()) return {};
  std::vector<T> out;
  out.reserve(keep.size());
  for (const auto i : keep) out.push_back(v[i]);
  return out;
}

}  // namespace

point_cloud subset(const point_cloud& in, const std::vector<std::uint32_t>& keep) {
  point_cloud out;
  out.origin = in.origin;
  out.sensor = in.sensor;
  for (const auto i : keep)
    if (i >= in.size())
      throw InvalidArgument("subset: index " + std::to_string(i) + " is past the cloud's " +
                            std::to_string(in.size()) + " points");
  out.positions = pick(in.positions, keep);
  out.normals = pick(in.normals, keep);
  out.colours = pick(in.colours, keep);
  out.materials = pick(in.materials, keep);
  out.axis_u = pick(in.axis_u, keep);
  out.axis_v = pick(in.axis_v, keep);
  return out;
}

point_cloud grid_simplify(const point_cloud& in, double cell) {
  if (!(cell > 0) || !std::isfinite(cell))
    throw InvalidArgument("grid_simplify: the cell size must be positive and finite, got " +
                          std::to_string(cell));
  in.validate("grid_simplify: input");
  auto p = indexed(in);
  const auto end = CGAL::grid_simplify_point_set(p, cell, CGAL::parameters::point_map(point_map()));
  return subset(in, kept(p.cbegin(), end));
}

point_cloud hierarchy_simplify(const point_cloud& in, unsigned size, double max_variation) {
  if (size == 0) throw InvalidArgument("hierarchy_simplify: the cluster size must be at least 1");
  if (!(max_variation > 0) || !(max_variation <= 1.0 / 3.0))
    throw InvalidArgument("hierarchy_simplify: the surface variation must lie in (0, 1/3], got " +
                          std::to_string(max_variation));
  in.validate("hierarchy_simplify: input");
  if (in.empty()) return subset(in, {});
  auto p = indexed(in);
  const auto end = CGAL::hierarchy_simplify_point_set(
      p, CGAL::parameters::point_map(point_map()).size(size).maximum_variation(max_variation));
  return subset(in, kept(p.cbegin(), end));
}

}  // namespace pbr_lod::peers
