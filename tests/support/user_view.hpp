// Test support: what the user sees. A builder's cut is compared with the input's own render
// from the same views (interior PSNR, silhouette IoU: raster/metrics.hpp compare_to_input) and
// measured in object space (cut → input distance), so a test fails when a finest cut draws the
// wrong surface — a check against the builder's own finest cut cannot see that.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <functional>
#include <limits>
#include <vector>

#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/reference.hpp"
#include "pbr_lod/traverse/sink.hpp"

namespace pbr_lod::test {

/// The centre and radius of the axis-aligned box of p (world frame: origin added).
struct framing {
  vec3d centre = vec3d::Zero();
  double radius = 1;
  double diagonal = 2;
};

inline framing frame_of(const point_cloud& c) {
  vec3f lo = vec3f::Constant(std::numeric_limits<float>::max()), hi = -lo;
  for (const vec3f& p : c.positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  framing f;
  f.centre = c.origin + 0.5 * (lo + hi).cast<double>();
  f.diagonal = double((hi - lo).norm());
  f.radius = std::max(0.5 * f.diagonal, 1e-9);
  return f;
}

/// Orbit views (the pbrlod tool's --view AZ,EL,DIST) around `f`, size × size pixels: from the
/// front-right above, from behind, from the left low, and one close up.
inline std::vector<camera> user_views(const framing& f, int size = 256) {
  const viewport vp{size, size};
  return {camera::orbit(f.centre, f.radius, 30, 25, 2.6, 1, vp),
          camera::orbit(f.centre, f.radius, 160, 35, 2.6, 1, vp),
          camera::orbit(f.centre, f.radius, -70, 10, 2.6, 1, vp),
          camera::orbit(f.centre, f.radius, 10, 40, 1.3, 1, vp)};
}

/// The worst and mean of compare_to_input over several views.
struct user_view_score {
  double psnr_interior_min = std::numeric_limits<double>::infinity();
  double psnr_interior_mean = 0;
  double iou_min = 1;
  std::vector<input_likeness> per_view;
};

/// input_render(cam) is the input's own render, cut_render(cam) the builder's; each view's
/// likeness is kept (PSNR capped at 100 dB for the mean).
inline user_view_score score_views(const std::vector<camera>& cams,
                                   const std::function<image(const camera&)>& input_render,
                                   const std::function<image(const camera&)>& cut_render) {
  user_view_score s;
  for (const camera& c : cams) {
    const input_likeness l = compare_to_input(input_render(c), cut_render(c));
    s.per_view.push_back(l);
    s.psnr_interior_min = std::min(s.psnr_interior_min, l.psnr_interior);
    s.psnr_interior_mean += std::min(l.psnr_interior, 100.0) / double(cams.size());
    s.iou_min = std::min(s.iou_min, l.silhouette_iou);
  }
  return s;
}

/// Positions a cut covers, relative to the cut's origin: points, splat centres and the four
/// rims of each splat ellipse, and for triangles a barycentric lattice of 15 points (vertices,
/// edge points, interior) — a triangle spanning a gap has its interior far from the input.
template <attributes A>
std::vector<vec3f> cut_positions(const buffer_sink<A>& cut) {
  std::vector<vec3f> out;
  for (const auto& p : cut.points) out.push_back(p.position);
  for (const auto& s : cut.splats) {
    out.push_back(s.centre);
    for (const float sg : {-1.0f, 1.0f}) {
      out.push_back(s.centre + sg * s.u);
      out.push_back(s.centre + sg * s.v);
    }
  }
  const auto tri = [&](const std::array<vec3f, 3>& p) {
    constexpr int n = 4;
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        const float a = float(i) / n, b = float(j) / n;
        out.push_back(p[0] + a * (p[1] - p[0]) + b * (p[2] - p[0]));
      }
  };
  for (const auto& t : cut.triangles) tri(t.p);
  for (const auto& t : cut.textured_triangles) tri(t.triangle.p);
  return out;
}

/// The largest distance from a cut position (relative to `cut_origin`) to the input surface,
/// over the input's diagonal. The surface is a dense area-uniform sampling of the mesh (`n`
/// samples), so the answer is exact up to about half that sampling's spacing, which is far
/// below the floors the tests hold.
inline double cut_to_input(const triangle_mesh& input, const std::vector<vec3f>& cut,
                           const vec3d& cut_origin, std::size_t n = 400000) {
  point_cloud dense = sample_surface(input, n, 7);
  const vec3f shift = (cut_origin - dense.origin).cast<float>();
  std::vector<vec3f> moved(cut.size());
  for (std::size_t i = 0; i < cut.size(); ++i) moved[i] = cut[i] + shift;
  const knn_index index(dense.positions);
  return distance_to(moved, index).max / frame_of(input.vertices).diagonal;
}

/// Three images side by side for looking at a cut: the input's render `a`, the cut's `b` (same
/// size) and their absolute difference × 4 per channel.
inline image side_by_side_with_error(const image& a, const image& b) {
  image out(3 * a.width, a.height);
  std::fill(out.depth.begin(), out.depth.end(), 0.0f);  // opaque: write_png keys on depth
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      const rgb8 p = a.colour[a.index(x, y)], q = b.colour[b.index(x, y)];
      const auto diff = [](std::uint8_t u, std::uint8_t v) {
        return static_cast<std::uint8_t>(std::min(255, 4 * std::abs(int(u) - int(v))));
      };
      out.colour[out.index(x, y)] = p;
      out.colour[out.index(a.width + x, y)] = q;
      out.colour[out.index(2 * a.width + x, y)] =
          rgb8{diff(p.r, q.r), diff(p.g, q.g), diff(p.b, q.b)};
    }
  return out;
}

}  // namespace pbr_lod::test
