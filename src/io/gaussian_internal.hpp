// pbr_lod — internals of the Gaussian readers (gaussian_reader.cpp, spz_reader.cpp): the one
// place where the bad-value rule of io/gaussians.hpp is applied and the origin chosen, so every
// format obeys them alike. Not installed.
#pragma once

#include <optional>

#include "io_internal.hpp"
#include "pbr_lod/core/gaussians.hpp"

namespace pbr_lod::detail {

/// Collects Gaussians as decoded from a file (world positions in double, scales linear,
/// quaternions raw, opacities activated), applies the bad-value rule and builds the cloud.
class gaussian_collector {
 public:
  gaussian_collector(const std::string& path, read_report& report, int sh_degree);

  /// Reserves room for n Gaussians. Call only with a count the file size has backed.
  void reserve(std::size_t n);

  /// sigmoid(logit); ±inf give 1 / 0 and are counted as clamped, NaN stays NaN (→ dropped).
  double opacity_from_logit(double logit);

  /// One Gaussian. `sh`: sh_coefficients(degree) × 3 values, coefficient-major, RGB interleaved.
  void add(const vec3d& position, const vec3d& scale, const vec4d& wxyz, double opacity,
           const float* sh);

  /// The cloud, with the origin read.hpp's rule picks (`hint`: a stored origin); fills the
  /// report's counts and warnings.
  [[nodiscard]] gaussian_cloud finish(const std::optional<vec3d>& hint);

 private:
  const std::string& path_;
  read_report& report_;
  gaussian_cloud c_;
  std::vector<vec3d> world_;
  std::size_t total_ = 0, bad_position_ = 0, bad_shape_ = 0;
};

[[nodiscard]] gaussian_cloud read_gaussian_ply(const std::string& path, read_report& report);
[[nodiscard]] gaussian_cloud read_splat_file(const std::string& path, read_report& report);
[[nodiscard]] gaussian_cloud read_spz_file(const std::string& path, read_report& report);

}  // namespace pbr_lod::detail
