// pbr_lod — a cloud of 3-D Gaussians (3-D Gaussian Splatting, Kerbl et al. 2023), as the readers
// of io/gaussians.hpp return it and the Gaussian builder will take it.
//
// Values are stored *activated*, once, so nothing downstream applies exp or sigmoid again:
//   scales     standard deviations along the Gaussian's local axes (exp of a 3DGS file's
//              log scales), ≥ 0;
//   rotations  unit quaternions (w, x, y, z) rotating the local axes into the world;
//   opacities  in [0, 1] (sigmoid of a 3DGS file's logit);
//   sh         spherical-harmonic colour coefficients (not activated: colour = 0.5 + SH · basis,
//              as in 3DGS), see sh_index for the layout.
// The covariance of Gaussian i is R diag(s²) Rᵀ with R the rotation matrix of rotations[i].
//
// Positions are float relative to a double origin, as in point_cloud (core/point_set.hpp):
// world position = origin + positions[i], computed in double.
#pragma once

#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// The constant of the degree-0 real spherical harmonic, 1 / (2 √π): colour = 0.5 + C0 · dc.
inline constexpr double sh_c0 = 0.28209479177387814;

/// Highest spherical-harmonic degree stored (the 3DGS files' maximum).
inline constexpr int max_sh_degree = 3;

/// Coefficients per colour channel for SH degree d: (d + 1)² (1, 4, 9, 16).
[[nodiscard]] constexpr int sh_coefficients(int degree) {
  return (degree + 1) * (degree + 1);
}

/// G  #G Gaussians. Every vector has #G entries, except `sh`, which has
/// #G × sh_coefficients(sh_degree) × 3.
struct gaussian_cloud {
  vec3d origin = vec3d::Zero();
  std::vector<vec3f> positions;  ///< means, relative to `origin`
  std::vector<vec3f> scales;     ///< standard deviations along the local x, y, z axes, ≥ 0
  std::vector<vec4f> rotations;  ///< unit quaternions (w, x, y, z): local axes → world
  std::vector<float> opacities;  ///< in [0, 1]
  int sh_degree = 0;             ///< 0–3
  /// Per Gaussian, coefficient-major with RGB interleaved, DC first:
  /// sh[sh_index(i, k, c)] is coefficient k (0 = DC, then degree 1's three, …; the order of
  /// the 3DGS basis) of channel c (0 R, 1 G, 2 B). A 3DGS PLY stores its f_rest_* channel-major
  /// instead (all R coefficients, then G, then B); the readers and the writer convert.
  std::vector<float> sh;

  [[nodiscard]] std::size_t size() const { return positions.size(); }
  [[nodiscard]] bool empty() const { return positions.empty(); }

  /// SH coefficients per Gaussian (all three channels).
  [[nodiscard]] std::size_t sh_stride() const {
    return static_cast<std::size_t>(sh_coefficients(sh_degree)) * 3;
  }
  [[nodiscard]] std::size_t sh_index(std::size_t i, int k, int c) const {
    return i * sh_stride() + static_cast<std::size_t>(k) * 3 + static_cast<std::size_t>(c);
  }

  /// World position of Gaussian i, in double.
  [[nodiscard]] vec3d world(std::size_t i) const { return origin + positions[i].cast<double>(); }

  /// The view-independent colour of Gaussian i: 0.5 + C0 · dc per channel (not clamped: 3DGS
  /// clamps only after adding the view-dependent bands).
  [[nodiscard]] vec3f base_colour(std::size_t i) const {
    const float* dc = &sh[sh_index(i, 0, 0)];
    const auto c = [](float v) { return static_cast<float>(0.5 + sh_c0 * v); };
    return {c(dc[0]), c(dc[1]), c(dc[2])};
  }

  /// Throws InvalidArgument unless: every vector has the right length, sh_degree is 0–3, every
  /// value is finite, scales are ≥ 0, opacities in [0, 1] and rotations unit length
  /// (|‖q‖ − 1| ≤ 10⁻³). What the readers return always passes. `what` names the data.
  void validate(const std::string& what = "gaussian cloud") const {
    const std::size_t n = positions.size();
    const auto fail = [&](const std::string& m) { throw InvalidArgument(what + ": " + m); };
    if (sh_degree < 0 || sh_degree > max_sh_degree)
      fail("sh_degree " + std::to_string(sh_degree) + " is not 0–3");
    const auto check = [&](std::size_t got, std::size_t want, const char* name) {
      if (got != want)
        fail(std::string(name) + " has " + std::to_string(got) + " entries, expected " +
             std::to_string(want));
    };
    check(scales.size(), n, "scales");
    check(rotations.size(), n, "rotations");
    check(opacities.size(), n, "opacities");
    check(sh.size(), n * sh_stride(), "sh");
    if (!all_finite(origin)) fail("origin is not finite");
    for (std::size_t i = 0; i < n; ++i) {
      const std::string at = " of Gaussian " + std::to_string(i);
      if (!all_finite(positions[i])) fail("the position" + at + " is not finite");
      if (!all_finite(scales[i]) || scales[i].minCoeff() < 0.0f)
        fail("the scale" + at + " is negative or not finite");
      if (!all_finite(rotations[i]) || std::abs(rotations[i].norm() - 1.0f) > 1e-3f)
        fail("the rotation" + at + " is not a unit quaternion");
      if (!(opacities[i] >= 0.0f && opacities[i] <= 1.0f))
        fail("the opacity" + at + " is not in [0, 1]");
    }
    for (std::size_t j = 0; j < sh.size(); ++j)
      if (!std::isfinite(sh[j])) fail("SH coefficient " + std::to_string(j) + " is not finite");
  }
};

}  // namespace pbr_lod
