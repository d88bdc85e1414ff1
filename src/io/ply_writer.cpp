// pbr_lod — write_ply: point clouds and triangle meshes as PLY (see write.hpp for the layout).
//
// Our own writer rather than OpenMesh's because that one writes positions as float, and we want
// world coordinates in double so files 10⁷ units from the origin keep their precision.
// Numbers in ASCII files use std::to_chars' shortest round-trip form, so ASCII round trips are
// as exact as binary ones.
#include <cerrno>
#include <charconv>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>

#include "io_internal.hpp"
#include "pbr_lod/io/write.hpp"

#include "pbr_lod/core/atomic_file.hpp"

namespace pbr_lod {
namespace {

using detail::cat;

/// Appends values to a byte buffer (binary little endian) or a text buffer (ASCII), and flushes
/// it to the stream in large chunks.
class row_writer {
 public:
  row_writer(std::ofstream& out, const std::string& path, bool binary)
      : out_(out), path_(path), binary_(binary) {
    buf_.reserve(chunk + 256);
  }

  template <class T>
  void put(T v) {
    if (binary_) {
      if constexpr (std::endian::native == std::endian::big) v = detail::byte_swapped(v);
      const auto* b = reinterpret_cast<const char*>(&v);
      buf_.insert(buf_.end(), b, b + sizeof(T));
    } else {
      if (!first_in_row_) buf_.push_back(' ');
      first_in_row_ = false;
      char tmp[64];
      // Widen 8-bit values so they print as numbers, not characters.
      const auto r =
          std::to_chars(tmp, tmp + sizeof tmp, std::conditional_t<sizeof(T) == 1, int, T>(v));
      buf_.insert(buf_.end(), tmp, r.ptr);
    }
  }
  void end_row() {
    if (!binary_) buf_.push_back('\n');
    first_in_row_ = true;
    if (buf_.size() >= chunk) flush();
  }
  void flush() {
    out_.write(buf_.data(), static_cast<std::streamsize>(buf_.size()));
    if (!out_) throw IoError(path_ + ": cannot write: " + std::strerror(errno));
    buf_.clear();
  }

 private:
  static constexpr std::size_t chunk = std::size_t{1} << 20;
  std::ofstream& out_;
  const std::string& path_;
  bool binary_;
  bool first_in_row_ = true;
  std::vector<char> buf_;
};

std::string shortest(double v) {
  char tmp[64];
  const auto r = std::to_chars(tmp, tmp + sizeof tmp, v);
  return std::string(tmp, r.ptr);
}

/// The texture path as it should appear in the file: relative to the PLY's folder when it can
/// be (so the pair can be moved together), else as given.
std::string texture_reference(const std::string& ply_path, const std::string& texture) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path dir = fs::absolute(fs::path(ply_path), ec).parent_path();
  if (ec) return texture;
  const fs::path tex = fs::absolute(fs::path(texture), ec);
  if (ec) return texture;
  const fs::path rel = tex.lexically_normal().lexically_relative(dir.lexically_normal());
  return rel.empty() ? texture : rel.generic_string();
}

void write_impl(const std::string& path, const point_cloud& c, const triangle_mesh* mesh,
                bool binary) {
  const bool normals = !c.normals.empty();
  const bool colours = !c.colours.empty();
  const bool texcoords = mesh != nullptr && !mesh->face_texcoords.empty();
  const bool wide_indices = c.size() > static_cast<std::size_t>(std::numeric_limits<int>::max());

  std::string h = "ply\n";
  h += binary ? "format binary_little_endian 1.0\n" : "format ascii 1.0\n";
  h += "comment written by pbr_lod\n";
  h += "comment pbr_lod_origin " + shortest(c.origin.x()) + " " + shortest(c.origin.y()) + " " +
       shortest(c.origin.z()) + "\n";
  if (mesh != nullptr && !mesh->texture_path.empty()) {
    if (mesh->texture_path.find_first_of("\r\n") != std::string::npos)
      throw InvalidArgument(path + ": texture_path contains a line break");
    h += "comment TextureFile " + texture_reference(path, mesh->texture_path) + "\n";
  }
  h += cat("element vertex ", c.size(), "\n");
  h += "property double x\nproperty double y\nproperty double z\n";
  if (normals) h += "property float nx\nproperty float ny\nproperty float nz\n";
  if (colours) h += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (mesh != nullptr) {
    h += cat("element face ", mesh->faces.size(), "\n");
    h += wide_indices ? "property list uchar uint vertex_indices\n"
                      : "property list uchar int vertex_indices\n";
    if (texcoords) h += "property list uchar float texcoord\n";
  }
  h += "end_header\n";

  // Whole or not at all: written beside the target, renamed over it once complete.
  atomic_output file(path);
  std::ofstream out(file.temp_path(), std::ios::binary | std::ios::trunc);
  if (!out) throw IoError(path + ": cannot open for writing: " + std::strerror(errno));
  out.write(h.data(), static_cast<std::streamsize>(h.size()));

  row_writer w(out, path, binary);
  for (std::size_t i = 0; i < c.size(); ++i) {
    const vec3d p = c.world(i);  // origin + position, in double
    w.put(p.x());
    w.put(p.y());
    w.put(p.z());
    if (normals) {
      w.put(c.normals[i].x());
      w.put(c.normals[i].y());
      w.put(c.normals[i].z());
    }
    if (colours) {
      w.put(c.colours[i].r);
      w.put(c.colours[i].g);
      w.put(c.colours[i].b);
    }
    w.end_row();
  }
  if (mesh != nullptr) {
    for (std::size_t f = 0; f < mesh->faces.size(); ++f) {
      w.put(std::uint8_t{3});
      for (const std::uint32_t v : mesh->faces[f]) {
        if (wide_indices)
          w.put(v);
        else
          w.put(static_cast<std::int32_t>(v));
      }
      if (texcoords) {
        w.put(std::uint8_t{6});
        for (const vec2f& t : mesh->face_texcoords[f]) {
          w.put(t.x());
          w.put(t.y());
        }
      }
      w.end_row();
    }
  }
  w.flush();
  out.close();
  if (!out) throw IoError(path + ": cannot write: " + std::strerror(errno));
  file.commit();
}

}  // namespace

void write_ply(const std::string& path, const point_cloud& cloud, bool binary) {
  cloud.validate(path);
  write_impl(path, cloud, nullptr, binary);
}

void write_ply(const std::string& path, const triangle_mesh& mesh, bool binary) {
  mesh.validate(path);
  write_impl(path, mesh.vertices, &mesh, binary);
}

}  // namespace pbr_lod
