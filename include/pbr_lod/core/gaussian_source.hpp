// pbr_lod — 3-D Gaussians read block by block: the input of the chunked (out-of-core) Gaussian
// hierarchy build, as point_source is the point builders'. A file is opened as one by
// io/gaussians.hpp (open_gaussian_source); a cloud in memory and a generated scene are here.
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/gaussian_splats.hpp"
#include "pbr_lod/core/gaussians.hpp"

namespace pbr_lod {

/// Gaussians read by index range, in blocks. Every block passes gaussian_cloud::validate.
/// Thread safety: const members may be called from several threads.
class gaussian_source {
 public:
  virtual ~gaussian_source() = default;
  [[nodiscard]] virtual int sh_degree() const = 0;
  /// Positions are relative to this (double precision, for data far from the world origin).
  [[nodiscard]] virtual vec3d origin() const = 0;
  [[nodiscard]] virtual std::uint64_t size() const = 0;
  /// Gaussians [first, first + count) into `out`, replacing its contents (its origin and degree
  /// the source's). Throws InvalidArgument when the range is beyond size(), IoError /
  /// FormatError when the data cannot be read.
  virtual void read(std::uint64_t first, std::size_t count, gaussian_cloud& out) const = 0;
  /// What to call the source in messages (a file name, say).
  [[nodiscard]] virtual std::string name() const = 0;
};

namespace detail {
/// Gaussians [first, first + count) of `g` into `out`.
inline void copy_gaussians(const gaussian_cloud& g, std::size_t first, std::size_t count,
                           gaussian_cloud& out) {
  if (first > g.size() || count > g.size() - first)
    throw InvalidArgument("gaussian source: Gaussians [" + std::to_string(first) + ", " +
                          std::to_string(first + count) + ") beyond its " +
                          std::to_string(g.size()));
  const auto at = [first](auto& v, std::size_t per = 1) {
    return v.begin() + static_cast<std::ptrdiff_t>(first * per);
  };
  const auto n = static_cast<std::ptrdiff_t>(count);
  const std::size_t stride = g.sh_stride();
  out.origin = g.origin;
  out.sh_degree = g.sh_degree;
  out.positions.assign(at(g.positions), at(g.positions) + n);
  out.scales.assign(at(g.scales), at(g.scales) + n);
  out.rotations.assign(at(g.rotations), at(g.rotations) + n);
  out.opacities.assign(at(g.opacities), at(g.opacities) + n);
  out.sh.assign(at(g.sh, stride), at(g.sh, stride) + n * static_cast<std::ptrdiff_t>(stride));
}
}  // namespace detail

/// A Gaussian cloud in memory as a source (valid): one it refers to, which must outlive the
/// source, or one moved into it (a file read whole: .spz, an ASCII PLY).
class cloud_gaussian_source final : public gaussian_source {
 public:
  explicit cloud_gaussian_source(const gaussian_cloud& c, std::string name = "Gaussian cloud")
      : cloud_(c), name_(std::move(name)) {}
  cloud_gaussian_source(gaussian_cloud&& c, std::string name)
      : owned_(std::make_unique<const gaussian_cloud>(std::move(c))),
        cloud_(*owned_),
        name_(std::move(name)) {}
  [[nodiscard]] int sh_degree() const override { return cloud_.sh_degree; }
  [[nodiscard]] vec3d origin() const override { return cloud_.origin; }
  [[nodiscard]] std::uint64_t size() const override { return cloud_.size(); }
  void read(std::uint64_t first, std::size_t count, gaussian_cloud& out) const override {
    detail::copy_gaussians(cloud_, first, count, out);
  }
  [[nodiscard]] std::string name() const override { return name_; }

 private:
  std::unique_ptr<const gaussian_cloud> owned_;  // set when the cloud was moved in
  const gaussian_cloud& cloud_;
  std::string name_;
};

/// make_gaussian_scene(n, sh_degree, seed) generated block by block: a scene of 10⁸ Gaussians
/// costs no memory, and equals the whole one.
class generated_gaussian_source final : public gaussian_source {
 public:
  explicit generated_gaussian_source(std::uint64_t n, int sh_degree = 3, std::uint32_t seed = 1)
      : n_(n), degree_(sh_degree), seed_(seed) {
    if (sh_degree < 0 || sh_degree > max_sh_degree)
      throw InvalidArgument("generated_gaussian_source: sh_degree must be 0–3");
  }
  [[nodiscard]] int sh_degree() const override { return degree_; }
  [[nodiscard]] vec3d origin() const override { return vec3d::Zero(); }
  [[nodiscard]] std::uint64_t size() const override { return n_; }
  void read(std::uint64_t first, std::size_t count, gaussian_cloud& out) const override {
    make_gaussian_scene_range(n_, degree_, seed_, first, count, out);
  }
  [[nodiscard]] std::string name() const override {
    return "generated-gaussians:" + std::to_string(n_);
  }

 private:
  std::uint64_t n_;
  int degree_;
  std::uint32_t seed_;
};

}  // namespace pbr_lod
