// pbr_lod — point containers.
//
// Two containers:
//  * point_cloud: what a file reader returns. The attributes are known only at run time; an
//    absent attribute is an empty vector (24 bytes per cloud, nothing per point).
//  * point_set<A>: what builders take. Structure of arrays, the attribute set A fixed at compile
//    time; an attribute not in A is not a member (sizeof shows it).
//
// Both store positions in float *relative to a double-precision origin*, so data 10⁷ units from
// the world origin (georeferenced scans) keeps sub-millimetre precision: the world position of
// sample i is origin + positions[i] (computed in double).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "pbr_lod/core/attributes.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// P  #P positions (float, relative to `origin`); every other vector is either empty (attribute
/// absent) or has exactly #P entries.
struct point_cloud {
  vec3d origin = vec3d::Zero();
  std::vector<vec3f> positions;
  std::vector<vec3f> normals;           ///< unit normals, or empty
  std::vector<rgb8> colours;            ///< or empty
  std::vector<std::uint8_t> materials;  ///< or empty
  std::vector<vec3f> axis_u;            ///< splat ellipse semi-axis vectors (tangent), or empty
  std::vector<vec3f> axis_v;            ///< second semi-axis, orthogonal to axis_u, or empty
  /// Where the scanner stood, in world coordinates, when the file says (a PCD's points are in
  /// its sensor's frame: the origin). Orients estimated normals without the k-NN graph.
  std::optional<vec3d> sensor;

  [[nodiscard]] std::size_t size() const { return positions.size(); }
  [[nodiscard]] bool empty() const { return positions.empty(); }

  /// Which attributes this cloud actually carries.
  [[nodiscard]] attributes present() const {
    return {.normal = !normals.empty(),
            .colour = !colours.empty(),
            .material = !materials.empty(),
            .ellipse = !axis_u.empty()};
  }

  /// World position of sample i, in double.
  [[nodiscard]] vec3d world(std::size_t i) const { return origin + positions[i].cast<double>(); }

  /// Throws InvalidArgument when an attribute vector has the wrong length or a position is not
  /// finite. `what` names the data in the message (a file name, say).
  void validate(const std::string& what = "point cloud") const {
    const auto check = [&](std::size_t n, const char* name) {
      if (n != 0 && n != positions.size())
        throw InvalidArgument(what + ": " + name + " has " + std::to_string(n) +
                              " entries, expected 0 or " + std::to_string(positions.size()));
    };
    check(normals.size(), "normals");
    check(colours.size(), "colours");
    check(materials.size(), "materials");
    check(axis_u.size(), "axis_u");
    check(axis_v.size(), "axis_v");
    if (axis_u.size() != axis_v.size())
      throw InvalidArgument(what + ": axis_u and axis_v differ in length");
    if (!all_finite(origin)) throw InvalidArgument(what + ": origin is not finite");
    for (std::size_t i = 0; i < positions.size(); ++i)
      if (!all_finite(positions[i]))
        throw InvalidArgument(what + ": position " + std::to_string(i) + " is not finite");
  }
};

/// Moves the cloud's origin to `new_origin` (double), re-expressing every position relative to
/// it. Done in double, so no precision is lost beyond the final float rounding.
inline void rebase(point_cloud& cloud, const vec3d& new_origin) {
  const vec3d shift = cloud.origin - new_origin;
  for (auto& p : cloud.positions) p = (p.cast<double>() + shift).cast<float>();
  cloud.origin = new_origin;
}

/// Structure-of-arrays point set with a compile-time attribute set A.
template <attributes A>
class point_set {
 public:
  static constexpr attributes attrs = A;

  vec3d origin = vec3d::Zero();
  std::vector<vec3f> positions;
  [[no_unique_address]] detail::maybe<A.normal, std::vector<vec3f>, 0> normals{};
  [[no_unique_address]] detail::maybe<A.colour, std::vector<rgb8>, 1> colours{};
  [[no_unique_address]] detail::maybe<A.material, std::vector<std::uint8_t>, 2> materials{};
  [[no_unique_address]] detail::maybe<A.ellipse, std::vector<vec3f>, 3> axis_u{};
  [[no_unique_address]] detail::maybe<A.ellipse, std::vector<vec3f>, 4> axis_v{};

  [[nodiscard]] std::size_t size() const { return positions.size(); }
  [[nodiscard]] bool empty() const { return positions.empty(); }
  [[nodiscard]] vec3d world(std::size_t i) const { return origin + positions[i].cast<double>(); }

  /// Bytes of per-point storage (the figure "bytes per point" in the docs refers to).
  [[nodiscard]] static constexpr std::size_t bytes_per_point() { return A.bytes_per_point(); }

  void resize(std::size_t n) {
    positions.resize(n);
    if constexpr (A.normal) normals.resize(n);
    if constexpr (A.colour) colours.resize(n);
    if constexpr (A.material) materials.resize(n);
    if constexpr (A.ellipse) {
      axis_u.resize(n);
      axis_v.resize(n);
    }
  }

  /// Copies the attributes A from a cloud; throws InvalidArgument when the cloud lacks one of
  /// them (the message says which). Attributes the cloud has beyond A are dropped.
  [[nodiscard]] static point_set from(const point_cloud& c, const std::string& what = "input") {
    c.validate(what);
    const attributes have = c.present();
    // An empty cloud has every attribute (each vector holds its 0 entries): the builder, not
    // this copy, then says what is wrong — that there are no points.
    if (!c.empty() && !have.contains(A))
      throw InvalidArgument(what + " has attributes " + have.to_string() + " but " + A.to_string() +
                            " were requested");
    point_set s;
    s.origin = c.origin;
    s.positions = c.positions;
    if constexpr (A.normal) s.normals = c.normals;
    if constexpr (A.colour) s.colours = c.colours;
    if constexpr (A.material) s.materials = c.materials;
    if constexpr (A.ellipse) {
      s.axis_u = c.axis_u;
      s.axis_v = c.axis_v;
    }
    return s;
  }

  /// Back to a run-time-attribute cloud (for writers and the tool).
  [[nodiscard]] point_cloud to_cloud() const {
    point_cloud c;
    c.origin = origin;
    c.positions = positions;
    if constexpr (A.normal) c.normals = normals;
    if constexpr (A.colour) c.colours = colours;
    if constexpr (A.material) c.materials = materials;
    if constexpr (A.ellipse) {
      c.axis_u = axis_u;
      c.axis_v = axis_v;
    }
    return c;
  }
};

}  // namespace pbr_lod
