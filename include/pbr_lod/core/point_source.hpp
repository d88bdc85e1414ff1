// pbr_lod — point sources: an input read block by block, never whole, and as often as needed.
//
// Out-of-core builds (builders/chunked_point_octree.hpp) make several passes over an input larger
// than memory. A point_source hands out any range of its points, in the same order and with the
// same values every time: positions as float relative to one double-precision origin (the same
// origin and floats read_points would give for a file), and normals and colours when it has them.
// Sources here: a point cloud already in memory (tests, and inputs that fit), and a generated
// surface of any size made point by point from the index (scale tests without a file).
// io/point_source_file.hpp adds files (PLY, LAS, PCD) read in blocks.
//
// Thread safety: read() is const and may be called from several threads at once.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "pbr_lod/core/attributes.hpp"
#include "pbr_lod/core/math.hpp"
#include "pbr_lod/core/point_set.hpp"

namespace pbr_lod {

/// A block of points: `positions` always; `normals` / `colours` exactly when the source has them.
struct point_block {
  std::vector<vec3f> positions;
  std::vector<vec3f> normals;
  std::vector<rgb8> colours;
  [[nodiscard]] std::size_t size() const { return positions.size(); }
};

/// A chunked build shared by `ranks` processes (MPI ranks, say) that see the output folder on a
/// shared file system: each calls the build with its rank and a barrier over all of them.
struct distributed_build {
  int rank = 0, ranks = 1;
  std::function<void()> barrier = {};
};

class point_source {
 public:
  virtual ~point_source() = default;
  /// Which of normal and colour the points carry (never material or ellipse).
  [[nodiscard]] virtual attributes attrs() const = 0;
  /// Positions are relative to this (double precision, for data far from the world origin).
  [[nodiscard]] virtual vec3d origin() const = 0;
  [[nodiscard]] virtual std::uint64_t size() const = 0;
  /// Points [first, first + count) into `out`, replacing its contents. Throws InvalidArgument
  /// when the range is beyond size(), IoError / FormatError when the data cannot be read.
  virtual void read(std::uint64_t first, std::size_t count, point_block& out) const = 0;
  /// Where the scanner stood (world coordinates), when the source knows.
  [[nodiscard]] virtual std::optional<vec3d> sensor() const { return std::nullopt; }
  /// What to call the source in messages (a file name, say).
  [[nodiscard]] virtual std::string name() const = 0;
};

/// A point cloud in memory as a source (it must outlive the source). Its normals and colours are
/// passed on as they are.
class cloud_point_source final : public point_source {
 public:
  explicit cloud_point_source(const point_cloud& c, std::string name = "point cloud");
  [[nodiscard]] attributes attrs() const override;
  [[nodiscard]] vec3d origin() const override { return cloud_.origin; }
  [[nodiscard]] std::uint64_t size() const override { return cloud_.size(); }
  void read(std::uint64_t first, std::size_t count, point_block& out) const override;
  [[nodiscard]] std::optional<vec3d> sensor() const override { return cloud_.sensor; }
  [[nodiscard]] std::string name() const override { return name_; }

 private:
  const point_cloud& cloud_;
  std::string name_;
};

/// n samples of make_wavy_surface's surface, each made from its index alone (a hash of seed and
/// index gives its parameters), so any block is generated without the others and an input of
/// 10⁹ points costs no memory. Positions only, or with the analytic normals and colours.
class generated_point_source final : public point_source {
 public:
  generated_point_source(std::uint64_t n, std::uint64_t seed = 1, bool normals = false,
                         bool colours = true);
  [[nodiscard]] attributes attrs() const override {
    return {.normal = normals_, .colour = colours_};
  }
  [[nodiscard]] vec3d origin() const override { return vec3d::Zero(); }
  [[nodiscard]] std::uint64_t size() const override { return n_; }
  void read(std::uint64_t first, std::size_t count, point_block& out) const override;
  [[nodiscard]] std::string name() const override;

 private:
  std::uint64_t n_, seed_;
  bool normals_, colours_;
};

/// The whole source in memory (for tests and for comparing with an in-memory build).
[[nodiscard]] point_cloud read_all(const point_source& src);

}  // namespace pbr_lod
