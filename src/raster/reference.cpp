// pbr_lod — reference renders of meshes and point clouds at full detail (raster/reference.hpp).
// The point cloud's splat radius comes from the k-NN spacing of its samples (core/knn.hpp), the
// classic choice of surface splatting for unstructured points (Pfister et al. 2000; Zwicker et
// al. 2001 use the same neighbourhood size to close the surface).
#include "pbr_lod/raster/reference.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/raster/rasterizer.hpp"

namespace pbr_lod {

namespace {

/// Every triangle of m into sink (the reference render's primitives): texture-mapped where m is
/// textured and the sink takes such triangles (a textured mesh is seen with its texture).
template <attributes A, class S>
void emit_mesh(const triangle_mesh& m, const std::vector<vec3f>& normals, S& sink,
               bool texture_map = true) {
  const auto& p = m.vertices.positions;
  textured_triangle_prim<A> t;
  t.texture = m.texture.get();
  const bool tex = texture_map && m.textured();
  for (std::size_t i = 0; i < m.faces.size(); ++i) {
    const auto& f = m.faces[i];
    for (std::size_t k = 0; k < 3; ++k) {
      t.triangle.p[k] = p[f[k]];
      t.triangle.normal[k] = normals[f[k]];
      if constexpr (A.colour)
        t.triangle.colour[k] =
            m.vertices.colours.empty() ? rgb8{255, 255, 255} : m.vertices.colours[f[k]];
    }
    if constexpr (A.colour && TexturedTriangleSink<S, A>) {
      if (tex) {
        t.uv = m.face_texcoords[i];
        sink.textured_triangle(t);
        continue;
      }
    }
    sink.triangle(t.triangle);
  }
}

template <attributes A>
image render_mesh(const triangle_mesh& m, const view& v, const render_options& opt,
                  const std::vector<vec3f>& normals) {
  return render<A>(v, opt, [&](auto& sink, const view&) { emit_mesh<A>(m, normals, sink); });
}

/// Splat radius per point: factor × k-NN spacing; points whose spacing is 0 (duplicates, a
/// single point) take the median of the others, or 0 when there is none.
std::vector<float> splat_radii(const point_cloud& c, const render_options& opt) {
  std::vector<float> r = knn_spacing(c.positions, std::max(opt.reference_knn, 1));
  std::vector<float> positive;
  for (float x : r)
    if (x > 0) positive.push_back(x);
  float fallback = 0;
  if (!positive.empty()) {
    auto mid = positive.begin() + static_cast<std::ptrdiff_t>(positive.size() / 2);
    std::nth_element(positive.begin(), mid, positive.end());
    fallback = *mid;
  }
  const float factor = std::isfinite(opt.reference_radius_factor)
                           ? std::max(opt.reference_radius_factor, 0.0f)
                           : 0.0f;
  for (float& x : r) x = factor * (x > 0 ? x : fallback);
  return r;
}

/// Every point of c into sink, as a splat (with normals or ellipses) or a square.
template <attributes A, class S>
void emit_cloud(const point_cloud& c, const view& v, const std::vector<float>& radius, S& sink) {
  const bool ellipses = !c.axis_u.empty();
  for (std::size_t i = 0; i < c.size(); ++i) {
    const vec3f& p = c.positions[i];
    if constexpr (A.normal) {
      splat_prim<A> s;
      s.centre = p;
      if (ellipses) {
        s.u = c.axis_u[i];
        s.v = c.axis_v[i];
        const vec3f n = s.u.cross(s.v);
        s.normal = !c.normals.empty()    ? c.normals[i]
                   : n.squaredNorm() > 0 ? vec3f(n.normalized())
                                         : vec3f::UnitZ();
      } else {
        const vec3f n = c.normals[i];
        const float r = radius[i] > 0
                            ? radius[i]
                            : 0.5f * v.pixel_size_at_depth(std::max(v.to_eye(p).z(), v.z_near));
        const vec3f t = n.squaredNorm() > 0 ? any_orthogonal(n) : vec3f::UnitX();
        s.u = t * r;
        s.v = n.squaredNorm() > 0 ? vec3f(n.normalized().cross(t) * r) : vec3f(vec3f::UnitY() * r);
        s.normal = n;
      }
      if constexpr (A.colour) s.colour = c.colours[i];
      sink.splat(s);
    } else {
      point_prim<A> q;
      q.position = p;
      const float z = v.to_eye(p).z();
      // Side = projected diameter; points behind the eye are dropped by the rasteriser.
      q.size_px = z > 0 ? 2 * radius[i] / v.pixel_size_at_depth(z) : 1.0f;
      if constexpr (A.colour) q.colour = c.colours[i];
      sink.point(q);
    }
  }
}

/// The reference radius of each point (none when the cloud has its own ellipses).
std::vector<float> cloud_radii(const point_cloud& c, const render_options& opt) {
  return c.axis_u.empty() ? splat_radii(c, opt) : std::vector<float>{};
}

template <attributes A>
image render_cloud(const point_cloud& c, const view& v, const render_options& opt) {
  const std::vector<float> radius = cloud_radii(c, opt);
  return render<A>(v, opt, [&](auto& sink, const view& dv) { emit_cloud<A>(c, dv, radius, sink); });
}

template <attributes A>
void emit_cloud_widened(const point_cloud& c, const view& v, const render_options& opt,
                        buffer_sink<with_normals_colours>& out) {
  widening_sink<A, with_normals_colours, buffer_sink<with_normals_colours>> w{out};
  emit_cloud<A>(c, v, cloud_radii(c, opt), w);
}

}  // namespace

image render_reference(const triangle_mesh& m, const camera& cam, const render_options& opt) {
  m.validate("render_reference: mesh");
  const view v(cam, m.vertices.origin);
  std::vector<vec3f> normals = m.vertices.normals;
  if (normals.empty()) normals = area_weighted_normals(m);
  if (!m.vertices.colours.empty() || m.textured())
    return render_mesh<with_normals_colours>(m, v, opt, normals);
  return render_mesh<with_normals>(m, v, opt, normals);
}

image render_reference(const point_cloud& c, const camera& cam, const render_options& opt) {
  c.validate("render_reference: point cloud");
  const view v(cam, c.origin);
  const bool normal = !c.normals.empty() || !c.axis_u.empty();
  const bool colour = !c.colours.empty();
  if (normal && colour) return render_cloud<with_normals_colours>(c, v, opt);
  if (normal) return render_cloud<with_normals>(c, v, opt);
  if (colour) return render_cloud<attributes{.colour = true}>(c, v, opt);
  return render_cloud<positions_only>(c, v, opt);
}

attributes reference_primitives(const triangle_mesh& m, const camera& cam,
                                buffer_sink<with_normals_colours>& out) {
  m.validate("reference_primitives: mesh");
  (void)view(cam, m.vertices.origin);  // the same camera checks as render_reference
  std::vector<vec3f> normals = m.vertices.normals;
  if (normals.empty()) normals = area_weighted_normals(m);
  // (A host renderer takes the triangles untextured: gl_viewer draws no texture.)
  const bool colour = !m.vertices.colours.empty();
  if (colour) {
    emit_mesh<with_normals_colours>(m, normals, out, false);
    return with_normals_colours;
  }
  widening_sink<with_normals, with_normals_colours, buffer_sink<with_normals_colours>> w{out};
  emit_mesh<with_normals>(m, normals, w);
  return with_normals;
}

attributes reference_primitives(const point_cloud& c, const camera& cam, const render_options& opt,
                                buffer_sink<with_normals_colours>& out) {
  c.validate("reference_primitives: point cloud");
  const view v(cam, c.origin);
  const bool normal = !c.normals.empty() || !c.axis_u.empty();
  const bool colour = !c.colours.empty();
  if (normal && colour) {
    emit_cloud<with_normals_colours>(c, v, cloud_radii(c, opt), out);
    return with_normals_colours;
  }
  if (normal) {
    emit_cloud_widened<with_normals>(c, v, opt, out);
    return with_normals;
  }
  if (colour) {
    emit_cloud_widened<attributes{.colour = true}>(c, v, opt, out);
    return attributes{.colour = true};
  }
  emit_cloud_widened<positions_only>(c, v, opt, out);
  return positions_only;
}

}  // namespace pbr_lod
