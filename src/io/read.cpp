// pbr_lod — read_mesh / read_points: dispatch on the file extension to the format parsers.
#include "pbr_lod/io/read.hpp"

#include "io_internal.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/io/texture.hpp"

namespace pbr_lod {

namespace {

[[noreturn]] void unsupported(const std::string& path, const std::string& ext, const char* what) {
  detail::format_error(path, "",
                       ext.empty() ? detail::cat("no file extension; ", what)
                                   : detail::cat("unsupported extension '", ext, "'; ", what));
}

/// The mesh without its texture image (read_points has no use for it).
triangle_mesh read_mesh_geometry(const std::string& path, read_report& r) {
  const std::string ext = detail::lower_extension(path);
  detail::raw_geometry g;
  if (ext == ".ply")
    g = detail::read_ply_file(path, r);
  else if (ext == ".obj")
    g = detail::read_obj_file(path, r);
  else if (ext == ".off")
    g = detail::read_off_file(path, r);
  else if (ext == ".pcd" || ext == ".las" || ext == ".laz")
    detail::format_error(path, "", "a point cloud format, not a mesh: use read_points");
  else
    unsupported(path, ext, "read_mesh reads .ply, .obj and .off");
  return detail::finish_mesh(std::move(g), path, r);
}

/// Loads the texture a textured mesh names. One that cannot be read (missing, not a PNG) leaves
/// the mesh untextured with a warning naming the file and the reason: its geometry is still
/// good for every builder, and a colour build that needs the texture says it has none.
void load_texture(triangle_mesh& m, const std::string& path, read_report& r) {
  if (m.face_texcoords.empty() || m.texture_path.empty()) return;
  try {
    m.texture = std::make_shared<const texture_image>(read_png_texture(m.texture_path));
  } catch (const Error& e) {
    r.warnings.push_back(
        detail::cat(path, ": texture not loaded, the mesh is read untextured: ", e.what()));
  }
}

}  // namespace

triangle_mesh read_mesh(const std::string& path, read_report* report) {
  read_report local;
  read_report& r = report ? *report : local;
  r = read_report{};
  triangle_mesh m = read_mesh_geometry(path, r);
  load_texture(m, path, r);
  return m;
}

point_cloud read_points(const std::string& path, read_report* report) {
  const std::string ext = detail::lower_extension(path);
  read_report local;
  read_report& r = report ? *report : local;
  r = read_report{};
  if (ext == ".ply" || ext == ".obj" || ext == ".off")
    return std::move(read_mesh_geometry(path, r).vertices);
  detail::raw_geometry g;
  if (ext == ".pcd")
    g = detail::read_pcd_file(path, r);
  else if (ext == ".las" || ext == ".laz")  // the format byte says whether it is compressed
    g = detail::read_las_file(path, r);
  else
    unsupported(path, ext, "read_points reads .ply, .obj, .off, .pcd, .las and .laz");
  return std::move(detail::finish_mesh(std::move(g), path, r).vertices);
}

}  // namespace pbr_lod
