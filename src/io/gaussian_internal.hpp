// pbr_lod — internals of the Gaussian readers (gaussian_reader.cpp, spz_reader.cpp): the one
// place where the bad-value rule of io/gaussians.hpp is applied and the origin chosen, so every
// format obeys them alike. Not installed.
#pragma once

#include <functional>
#include <memory>
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

  /// From now on add() applies the rule and counts, but keeps only the box of what it keeps: the
  /// first pass of a streamed file (gaussian_source).
  void count_only() { count_only_ = true; }
  /// Gaussians kept so far.
  [[nodiscard]] std::size_t kept() const { return count_only_ ? kept_ : world_.size(); }
  /// After a count_only() pass: the origin finish() would choose, and the report it would fill.
  [[nodiscard]] vec3d finish_counting(const std::optional<vec3d>& hint);
  /// The Gaussians kept so far relative to `origin` (as finish() makes them), and starts over.
  [[nodiscard]] gaussian_cloud take(const vec3d& origin);

 private:
  void report_counts();

  const std::string& path_;
  read_report& report_;
  gaussian_cloud c_;
  std::vector<vec3d> world_;
  std::size_t total_ = 0, bad_position_ = 0, bad_shape_ = 0;
  bool count_only_ = false;
  std::size_t kept_ = 0;
  finite_box box_;  // count_only(): the kept positions' box
};

struct gs_plan;
struct ply_header;

/// A Gaussian file whose Gaussians are rows of one size, read by row number: a .splat, or a
/// binary 3DGS PLY without lists up to its vertex element. Thread safety: const members may be
/// called from several threads.
class gaussian_rows {
 public:
  /// nullptr for a file that is not such (an ASCII PLY, one with lists, a .spz); FormatError /
  /// IoError for one that cannot be read.
  [[nodiscard]] static std::unique_ptr<gaussian_rows> open(const std::string& path);
  ~gaussian_rows();
  gaussian_rows(const gaussian_rows&) = delete;
  gaussian_rows& operator=(const gaussian_rows&) = delete;

  [[nodiscard]] std::uint64_t rows() const { return rows_; }
  [[nodiscard]] int degree() const;
  /// The origin the file states (a PLY's "comment pbr_lod_origin").
  [[nodiscard]] std::optional<vec3d> origin_hint() const;
  /// Rows [first, first + n) into `out`, stopping before row r when more(r) is false.
  void decode(std::uint64_t first, std::uint64_t n, gaussian_collector& out,
              const std::function<bool(std::uint64_t)>& more = {}) const;

 private:
  explicit gaussian_rows(const std::string& path);
  static void splat_row(const unsigned char* p, gaussian_collector& out);

  std::string path_;
  posix_file file_;
  std::unique_ptr<ply_header> header_;  // a PLY's (plan_ points into it)
  std::unique_ptr<gs_plan> plan_;
  std::uint64_t offset_ = 0, row_bytes_ = 0, rows_ = 0;
  bool swap_ = false;
};

[[nodiscard]] gaussian_cloud read_gaussian_ply(const std::string& path, read_report& report);
[[nodiscard]] gaussian_cloud read_splat_file(const std::string& path, read_report& report);
[[nodiscard]] gaussian_cloud read_spz_file(const std::string& path, read_report& report);

}  // namespace pbr_lod::detail
