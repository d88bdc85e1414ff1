// pbr_lod — a cloud of 3-D Gaussians (3-D Gaussian Splatting, Kerbl et al. 2023), as the readers
// of io/gaussians.hpp return it and the Gaussian builder will take it.
//
// Values are stored *activated*, once, so nothing downstream applies exp or sigmoid again:
//   scales     standard deviations along the Gaussian's local axes (exp of a 3DGS file's
//              log scales), ≥ 0;
//   rotations  unit quaternions (w, x, y, z) rotating the local axes into the world;
//   opacities  in [0, 1] (sigmoid of a 3DGS file's logit); a Gaussian hierarchy's merged Gaussians
//              may exceed 1 (Kerbl et al. 2024 §4.1; the rasteriser's α ≤ 0.99 bounds them);
//   sh         spherical-harmonic colour coefficients (not activated: colour = 0.5 + SH · basis,
//              as in 3DGS), see sh_index for the layout.
// The covariance of Gaussian i is R diag(s²) Rᵀ with R the rotation matrix of rotations[i].
//
// Positions are float relative to a double origin, as in point_cloud (core/point_set.hpp):
// world position = origin + positions[i], computed in double.
#pragma once

#include <array>
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

/// The colour of a Gaussian seen along unit direction `dir` (from the eye towards its mean), as
/// 3DGS evaluates it (Kerbl et al. 2023, its CUDA rasteriser's computeColorFromSH): the real
/// spherical-harmonic basis of degree ≤ `degree` with 3DGS's constants and signs, colour =
/// 0.5 + Σ_k sh_k · Y_k(dir), clamped below at 0 (not above: 3DGS does not). `sh` holds
/// sh_coefficients(degree) × 3 floats, coefficient-major with RGB interleaved (gaussian_cloud's
/// layout).
[[nodiscard]] inline vec3f sh_colour(const float* sh, int degree, const vec3f& dir) {
  const auto coef = [sh](int k) { return vec3f(sh[3 * k], sh[3 * k + 1], sh[3 * k + 2]); };
  vec3f c = static_cast<float>(sh_c0) * coef(0);
  if (degree >= 1) {
    constexpr float c1 = 0.4886025119029199f;
    const float x = dir.x(), y = dir.y(), z = dir.z();
    c += -c1 * y * coef(1) + c1 * z * coef(2) - c1 * x * coef(3);
    if (degree >= 2) {
      constexpr float c2[5] = {1.0925484305920792f, -1.0925484305920792f, 0.31539156525252005f,
                               -1.0925484305920792f, 0.5462742152960396f};
      const float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
      c += c2[0] * xy * coef(4) + c2[1] * yz * coef(5) + c2[2] * (2 * zz - xx - yy) * coef(6) +
           c2[3] * xz * coef(7) + c2[4] * (xx - yy) * coef(8);
      if (degree >= 3) {
        constexpr float c3[7] = {-0.5900435899266435f, 2.890611442640554f,   -0.4570457994644658f,
                                 0.3731763325901154f,  -0.4570457994644658f, 1.445305721320277f,
                                 -0.5900435899266435f};
        c += c3[0] * y * (3 * xx - yy) * coef(9) + c3[1] * xy * z * coef(10) +
             c3[2] * y * (4 * zz - xx - yy) * coef(11) +
             c3[3] * z * (2 * zz - 3 * xx - 3 * yy) * coef(12) +
             c3[4] * x * (4 * zz - xx - yy) * coef(13) + c3[5] * z * (xx - yy) * coef(14) +
             c3[6] * x * (xx - 3 * yy) * coef(15);
      }
    }
  }
  return (c.array() + 0.5f).max(0.0f).matrix();
}

/// The covariance R diag(s²) Rᵀ of a Gaussian with scales s (standard deviations) and unit
/// quaternion q = (w, x, y, z), as its upper triangle (xx, xy, xz, yy, yz, zz).
[[nodiscard]] inline std::array<float, 6> gaussian_covariance(const vec3f& s, const vec4f& q) {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                          {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                          {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
  const double d[3] = {double(s[0]) * s[0], double(s[1]) * s[1], double(s[2]) * s[2]};
  const auto e = [&](int i, int j) {
    return static_cast<float>(r[i][0] * d[0] * r[j][0] + r[i][1] * d[1] * r[j][1] +
                              r[i][2] * d[2] * r[j][2]);
  };
  return {e(0, 0), e(0, 1), e(0, 2), e(1, 1), e(1, 2), e(2, 2)};
}

/// G  #G Gaussians. Every vector has #G entries, except `sh`, which has
/// #G × sh_coefficients(sh_degree) × 3.
struct gaussian_cloud {
  vec3d origin = vec3d::Zero();
  std::vector<vec3f> positions;  ///< means, relative to `origin`
  std::vector<vec3f> scales;     ///< standard deviations along the local x, y, z axes, ≥ 0
  std::vector<vec4f> rotations;  ///< unit quaternions (w, x, y, z): local axes → world
  std::vector<float> opacities;  ///< ≥ 0; in [0, 1] but for a hierarchy's merged Gaussians
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
  /// value is finite, scales are ≥ 0, opacities in [0, max_opacity] and rotations unit length
  /// (|‖q‖ − 1| ≤ 10⁻³). What the readers return always passes. `what` names the data;
  /// max_opacity is +∞ for a hierarchy's store (merged opacities may exceed 1).
  void validate(const std::string& what = "gaussian cloud", float max_opacity = 1.0f) const {
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
      if (!(opacities[i] >= 0.0f && opacities[i] <= max_opacity))
        fail("the opacity" + at + " is not in [0, " + std::to_string(max_opacity) + "]");
    }
    for (std::size_t j = 0; j < sh.size(); ++j)
      if (!std::isfinite(sh[j])) fail("SH coefficient " + std::to_string(j) + " is not finite");
  }
};

}  // namespace pbr_lod
