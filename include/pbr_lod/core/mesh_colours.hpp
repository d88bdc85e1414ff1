// pbr_lod — a textured mesh's colours at its vertices, for what draws a mesh from its vertices
// (the point builders, the ρ-grid's cells) and would otherwise draw it untextured.
#pragma once

#include <vector>

#include "pbr_lod/core/triangle_mesh.hpp"

namespace pbr_lod {

/// Per vertex of m: the mean of its texture's bilinear samples (sample_texture) at the texture
/// coordinates of the face corners at that vertex — a seam vertex, with other coordinates in
/// each face, averages them. A vertex no textured corner uses takes the texture's mean colour.
/// Empty when m is not textured (triangle_mesh::textured).
/// Throws InvalidArgument when the mesh does not validate (triangle_mesh::validate).
[[nodiscard]] std::vector<rgb8> texture_vertex_colours(const triangle_mesh& m);

}  // namespace pbr_lod
