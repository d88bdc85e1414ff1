// pbr_lod — triangle meshes.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/texture_image.hpp"

namespace pbr_lod {

/// V  vertices (positions relative to vertices.origin, optional per-vertex normals/colours)
/// F  #F by 3 vertex indices, counter-clockwise seen from the front
/// TC #F by 3 texture coordinates (per face corner), or empty, into `texture`
struct triangle_mesh {
  point_cloud vertices;
  std::vector<std::array<std::uint32_t, 3>> faces;
  std::vector<std::array<vec2f, 3>> face_texcoords;  ///< per corner; empty when untextured
  std::string texture_path;  ///< image file of the texture (absolute or as found), or empty
  /// The texture image, loaded by read_mesh from texture_path (null when the mesh names none or
  /// it could not be read: read_report's warnings say why). Shared, never modified: copies of a
  /// mesh share one image.
  std::shared_ptr<const texture_image> texture;

  [[nodiscard]] std::size_t num_vertices() const { return vertices.size(); }
  [[nodiscard]] std::size_t num_faces() const { return faces.size(); }
  /// Whether it is drawn texture-mapped: a texture that can be sampled and a coordinate for
  /// every face corner.
  [[nodiscard]] bool textured() const {
    return texture != nullptr && texture->valid() && face_texcoords.size() == faces.size();
  }

  /// Throws InvalidArgument when an index is out of range or lengths disagree.
  void validate(const std::string& what = "mesh") const {
    vertices.validate(what);
    const auto n = vertices.size();
    for (std::size_t f = 0; f < faces.size(); ++f)
      for (auto i : faces[f])
        if (i >= n)
          throw InvalidArgument(what + ": face " + std::to_string(f) + " references vertex " +
                                std::to_string(i) + ", but there are " + std::to_string(n));
    if (!face_texcoords.empty() && face_texcoords.size() != faces.size())
      throw InvalidArgument(what + ": face_texcoords has " + std::to_string(face_texcoords.size()) +
                            " entries, expected " + std::to_string(faces.size()));
  }
};

/// A non-owning view of a triangle mesh (what builders that only read a mesh take).
struct triangle_mesh_view {
  vec3d origin = vec3d::Zero();
  std::span<const vec3f> positions;
  std::span<const vec3f> normals;  ///< empty or one per vertex
  std::span<const rgb8> colours;   ///< empty or one per vertex
  std::span<const std::array<std::uint32_t, 3>> faces;

  triangle_mesh_view() = default;
  triangle_mesh_view(const triangle_mesh& m)  // NOLINT(google-explicit-constructor): a view
      : origin(m.vertices.origin),
        positions(m.vertices.positions),
        normals(m.vertices.normals),
        colours(m.vertices.colours),
        faces(m.faces) {}
};

}  // namespace pbr_lod
