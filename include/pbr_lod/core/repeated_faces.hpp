// pbr_lod — exact repeats among a mesh's triangles. Real exports repeat triangles (a part
// instanced onto itself, a face written once per material, a mesh merged with its own copy):
// every repeat adds nothing to the surface, but a builder that samples, bounds or splits per
// triangle pays for each one — and a spatial tree built over thousands of copies of one
// triangle recursed deep enough to overflow the stack (the ρ-grid's AABB tree, 50,000 repeats).
// Builders drop the repeats first, so their cost and stack depth do not depend on them.
#pragma once

#include <cstdint>
#include <vector>

#include "pbr_lod/core/triangle_mesh.hpp"

namespace pbr_lod {

/// The indices of m's faces that are not an exact repeat of an earlier face, ascending: a face
/// repeats another when its corners are the same three positions (as stored, bit for bit) in
/// the same cyclic order — whether it uses the same vertex indices or copies of them. The other
/// winding is another face (the back of a two-sided sheet). The first of a set of repeats is
/// kept. O(F log F).
[[nodiscard]] std::vector<std::uint32_t> unique_faces(const triangle_mesh& m);

}  // namespace pbr_lod
