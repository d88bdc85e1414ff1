// Test support: the textured Spot cow (../shared/data/cow.obj and its PNG) as a POP tree, its
// camera, and its reference frame — every triangle texture-mapped from its own corners,
// supersampled — which POP's Figure 5 tests and benchmarks measure against.
#pragma once

#include "pbr_lod/builders/pop.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "support/data.hpp"

namespace pbr_lod::test {

struct spot_cow {
  triangle_mesh mesh = read_mesh(data_file("cow.obj"));
  pop_tree<with_normals_colours> tree = build_pop<with_normals_colours>(mesh);
  texture_image tex = *mesh.texture;

  static const spot_cow& get() {
    static const spot_cow s;
    return s;
  }
  /// Azimuth 30°, elevation 20°, `dist` radii from its bounding sphere's centre, size² pixels.
  [[nodiscard]] camera cam(double dist, int size) const {
    const sphere b = bounding_sphere_about_box_centre(tree.positions());
    return camera::orbit(tree.origin() + b.centre.cast<double>(), b.radius, 30, 20, dist, 1,
                         {size, size});
  }
  /// The full mesh, every triangle texture-mapped from its own (unquantised) corners, drawn at
  /// ss × ss the resolution and box-filtered down (render_options::supersample).
  [[nodiscard]] image reference(double dist, int size, int ss, render_options ro) const {
    ro.supersample = ss;
    return render<with_normals_colours>(
        view(cam(dist, size), mesh.vertices.origin), ro, [&](auto& sink, const view&) {
          for (std::size_t f = 0; f < mesh.faces.size(); ++f) {
            textured_triangle_prim<with_normals_colours> t;
            for (std::size_t k = 0; k < 3; ++k) {
              t.triangle.p[k] = mesh.vertices.positions[mesh.faces[f][k]];
              t.triangle.normal[k] = vec3f::UnitZ();
            }
            t.uv = mesh.face_texcoords[f];
            t.texture = &tex;
            sink.textured_triangle(t);
          }
        });
  }
};

}  // namespace pbr_lod::test
