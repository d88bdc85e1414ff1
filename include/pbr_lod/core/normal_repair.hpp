// pbr_lod — a zero or non-finite normal means "no normal for this point". Real files have them:
// scans re-saved with some normals zeroed, and every trained 3-D Gaussian Splatting `.ply`
// stores nx = ny = nz = 0 for all its points. fill_missing_normals estimates exactly those from
// the positions (the positions-only front-end of core/estimation.hpp), so builders that need a
// normal per point take such files instead of refusing them.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// What fill_missing_normals did.
struct normal_repair {
  std::size_t missing = 0;     ///< normals that were zero or not finite, now estimated
  bool all_estimated = false;  ///< every normal was missing: all estimated as for a bare cloud
};

/// True when n is no normal: not finite, or zero.
[[nodiscard]] inline bool missing_normal(const vec3f& n) {
  return !all_finite(n) || n.squaredNorm() == 0.0f;
}

/// Replaces every missing normal of `normals` (one per position, unit or missing) by an estimate:
///  * all missing: estimate_normals(positions, k, orient = true) — k-NN PCA, oriented along the
///    minimum spanning forest, exactly as a cloud without normals;
///  * some missing: the k-NN PCA normal of each such point (the eigenvector of the smallest
///    eigenvalue of its k nearest neighbours' covariance), turned to agree with the given
///    normals among those neighbours (the sign of Σ nᵢ·nⱼ); a point none of whose neighbours
///    has a normal takes its sign from neighbours estimated before it, in rounds, so that a
///    whole patch of missing normals is oriented from its rim inwards. A neighbourhood with no
///    spread (duplicates) keeps the nearest given normal, else +z.
/// Given normals are never changed. The result does not depend on `threads`. Throws
/// InvalidArgument when the spans differ in length, k < 3 or a position is not finite.
normal_repair fill_missing_normals(std::span<const vec3f> positions, std::span<vec3f> normals,
                                   int k = 16, unsigned threads = 0);

}  // namespace pbr_lod
