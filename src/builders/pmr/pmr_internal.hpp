// PMR builder internals shared by the in-memory build (pmr_build.cpp) and the chunked one
// (chunked_pmr_build.cpp). Internal to src/builders.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "pbr_lod/builders/pmr.hpp"
#include "pbr_lod/core/binary.hpp"

namespace pbr_lod::detail {

/// An octree cell during the build, in double, in the frame of the hierarchy's origin.
struct pmr_cell {
  vec3d lo = vec3d::Zero();
  double size = 0;
  std::uint32_t depth = 0;
};

/// The split point of a cell and the octant of a point (bit 0: x ≥ mid.x, 1: y, 2: z). Both
/// builds use these, so a chunk's cells are the in-memory build's to the last bit.
[[nodiscard]] inline vec3d pmr_cell_mid(const vec3d& lo, double size) {
  return lo + vec3d::Constant(size / 2);
}
[[nodiscard]] inline int pmr_octant(const vec3d& p, const vec3d& mid) {
  return (p.x() >= mid.x() ? 1 : 0) | (p.y() >= mid.y() ? 2 : 0) | (p.z() >= mid.z() ? 4 : 0);
}
[[nodiscard]] inline pmr_cell pmr_child_cell(const pmr_cell& c, int octant) {
  const double h = c.size / 2;
  return {c.lo + vec3d((octant & 1) ? h : 0, (octant & 2) ? h : 0, (octant & 4) ? h : 0), h,
          c.depth + 1};
}
/// The root cell of points whose local (origin-relative) box is [lo, hi].
[[nodiscard]] inline pmr_cell pmr_root_cell(const vec3d& lo, const vec3d& hi) {
  double size = (hi - lo).maxCoeff();
  if (!(size > 0)) size = 1;
  return {lo, size, 0};
}

/// Throws InvalidArgument naming the bad option.
void validate_pmr_options(const pmr_options& o);

/// One chunk of a chunked build: the points of `cloud` are the chunk's own (the first `owned`,
/// in input order) and then its halo (points of other chunks near it); `input` gives each one's
/// index in the whole input of `input_total` points. The part is built as build_pmr builds the
/// subtree below `root` — same leaves, same neighbourhoods, same Voronoi work — with origin and
/// input bounds of the whole input. Triangle vertices in the halo become foreign samples (their
/// normals zero until the owning chunk's are known), and triangles are not yet wound
/// (pmr_wind_triangles, once they are).
struct pmr_part_input {
  const point_cloud& cloud;
  std::uint32_t owned;
  std::span<const std::uint64_t> input;
  std::uint64_t input_total;
  vec3d origin, input_min, input_max;
  pmr_cell root;
};
[[nodiscard]] pmr_data build_pmr_part(const pmr_part_input& in, const pmr_options& options);

/// Each triangle's vertices in input order (source), then counter-clockwise about their normals
/// (the rasteriser shades a triangle seen from its back as such).
void pmr_wind_triangles(pmr_data& d);

/// An inner node's bounding sphere from its children's (as build_pmr bounds it).
void pmr_bound_inner(pmr_node& nd, std::span<const pmr_node> children);

/// The build counts in the file's order, to write and to read.
[[nodiscard]] std::array<std::size_t, 6> stat_counts(const pmr_build_stats& s);
[[nodiscard]] std::array<std::size_t*, 6> stat_fields(pmr_build_stats& s);

/// A node record as the PMR file stores it (48 bytes); get_node checks sizes and the leaf flag.
void put_node(byte_writer& w, const pmr_node& n);
[[nodiscard]] pmr_node get_node(byte_reader& r, std::size_t k);

}  // namespace pbr_lod::detail
