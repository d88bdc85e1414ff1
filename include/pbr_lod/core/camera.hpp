// pbr_lod — pinhole camera, viewport, frustum, and the projection of a sphere's size to pixels.
//
// A `camera` lives in world space (double). Hierarchies store coordinates relative to their own
// double-precision origin, so traversal and rasterisation use a `view`: the camera expressed in
// that relative frame, in float. Building the view subtracts the origin in double, which is what
// keeps scans 10⁷ units from the world origin exact to float precision *near the data*.
//
// Screen convention: pixel (0,0) is the top-left pixel, its centre at (0.5, 0.5); x grows right,
// y grows down. Eye space: x right, y up, z = depth along the viewing direction (positive in front
// of the eye).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

struct viewport {
  int width = 512;
  int height = 512;
};

/// World-space pinhole camera.
struct camera {
  vec3d eye = vec3d(0, 0, 3);
  vec3d target = vec3d::Zero();
  vec3d up = vec3d::UnitY();
  double fovy_degrees = 40;  ///< vertical field of view
  viewport vp{};
  double z_near = 1e-3;  ///< distances along the view direction, world units
  double z_far = 1e3;

  /// The pbrlod tool's `--view AZ,EL,DIST`: azimuth and elevation in degrees around `centre`,
  /// distance in multiples of `radius`. `up_axis` is 1 for y-up (scans), 2 for z-up (LiDAR).
  /// Near and far planes bracket the sphere with margin.
  [[nodiscard]] static camera orbit(const vec3d& centre, double radius, double azimuth_deg,
                                    double elevation_deg, double distance, int up_axis = 1,
                                    viewport vp = {}) {
    if (!(radius > 0) || !std::isfinite(radius)) radius = 1;
    const double az = azimuth_deg * std::numbers::pi / 180,
                 el = elevation_deg * std::numbers::pi / 180;
    // Direction from the centre to the eye in a y-up frame, then permuted for z-up.
    const vec3d dir_yup(std::cos(el) * std::sin(az), std::sin(el), std::cos(el) * std::cos(az));
    camera c;
    if (up_axis == 2) {
      c.up = vec3d::UnitZ();
      c.eye = centre + distance * radius * vec3d(dir_yup.z(), dir_yup.x(), dir_yup.y());
    } else {
      c.up = vec3d::UnitY();
      c.eye = centre + distance * radius * dir_yup;
    }
    c.target = centre;
    c.vp = vp;
    const double d = distance * radius;
    c.z_near = std::max(d - 1.5 * radius, d * 1e-4);
    c.z_far = d + 1.5 * radius;
    return c;
  }
};

/// Plane n·p + d = 0 with unit n; the positive side (n·p + d ≥ 0) is inside.
struct plane {
  vec3f n = vec3f::UnitZ();
  float d = 0;
  [[nodiscard]] float distance(const vec3f& p) const { return n.dot(p) + d; }
};

/// A camera expressed relative to an origin, in float: what traversal and rasterisers use.
class view {
 public:
  vec3f eye;    ///< eye position relative to the origin
  vec3f right;  ///< unit eye-space axes
  vec3f up;
  vec3f forward;
  float focal_px;  ///< focal length in pixels: (height/2) / tan(fovy/2)
  float tan_half_fovy;
  int width, height;
  float z_near, z_far;
  /// Cosine and sine of ω, the semi-angle of the cone about `forward` through the image corners
  /// (Pajarola's viewing cone, which view-cone culling tests against: traverse/culling.hpp).
  float cos_cone, sin_cone;
  /// left, right, bottom, top, near, far — inside is the positive side of every plane
  std::array<plane, 6> frustum;

  view(const camera& cam, const vec3d& origin) {
    if (cam.vp.width <= 0 || cam.vp.height <= 0)
      throw InvalidArgument("view: viewport must be at least 1x1 pixels, got " +
                            std::to_string(cam.vp.width) + "x" + std::to_string(cam.vp.height));
    if (!(cam.fovy_degrees > 0 && cam.fovy_degrees < 180))
      throw InvalidArgument("view: fovy must lie in (0, 180) degrees");
    if (!(cam.z_near > 0 && cam.z_far > cam.z_near))
      throw InvalidArgument("view: need 0 < z_near < z_far");
    const vec3d f = (cam.target - cam.eye);
    if (!(f.norm() > 0) || !all_finite(f)) throw InvalidArgument("view: eye equals target");
    const vec3d fw = f.normalized();
    vec3d r = fw.cross(cam.up);
    if (!(r.norm() > 1e-12)) r = fw.cross(any_orthogonal(fw.cast<float>()).cast<double>());
    r.normalize();
    const vec3d u = r.cross(fw);
    eye = (cam.eye - origin).cast<float>();
    right = r.cast<float>();
    up = u.cast<float>();
    forward = fw.cast<float>();
    width = cam.vp.width;
    height = cam.vp.height;
    tan_half_fovy = static_cast<float>(std::tan(cam.fovy_degrees * std::numbers::pi / 360));
    focal_px = static_cast<float>(0.5 * height) / tan_half_fovy;
    z_near = static_cast<float>(cam.z_near);
    z_far = static_cast<float>(cam.z_far);
    // Side planes pass through the eye; their normals point inwards.
    const float hx = 0.5f * static_cast<float>(width) / focal_px;  // tan of half the x fov
    const float hy = tan_half_fovy;
    const float tan_cone = std::sqrt(hx * hx + hy * hy);
    cos_cone = 1 / std::sqrt(1 + tan_cone * tan_cone);
    sin_cone = tan_cone * cos_cone;
    const auto side = [&](const vec3f& n) {
      const vec3f nn = n.normalized();
      return plane{nn, -nn.dot(eye)};
    };
    frustum[0] = side(forward * hx + right);  // left:   x/z ≥ −hx
    frustum[1] = side(forward * hx - right);  // right:  x/z ≤ hx
    frustum[2] = side(forward * hy + up);     // bottom
    frustum[3] = side(forward * hy - up);     // top
    frustum[4] = plane{forward, -(forward.dot(eye) + z_near)};
    frustum[5] = plane{-forward, forward.dot(eye) + z_far};
  }

  /// Eye-space coordinates of p (x right, y up, z depth).
  [[nodiscard]] vec3f to_eye(const vec3f& p) const {
    const vec3f d = p - eye;
    return {d.dot(right), d.dot(up), d.dot(forward)};
  }
  /// Screen position (pixels, y down) of an eye-space point with z > 0.
  [[nodiscard]] vec2f eye_to_screen(const vec3f& e) const {
    const float s = focal_px / e.z();
    return {0.5f * static_cast<float>(width) + e.x() * s,
            0.5f * static_cast<float>(height) - e.y() * s};
  }
  /// World-space size of one pixel at depth z (eye space).
  [[nodiscard]] float pixel_size_at_depth(float z) const { return z / focal_px; }

  /// The same view at k × k the resolution (render_options::supersample): k times the width,
  /// height and focal length, the same frustum and cone. A projected size in this view is k
  /// times the size in *this (exactly so for k a power of two), so a traversal with k times the
  /// tolerance selects the same cut. Throws InvalidArgument unless 1 ≤ k and the k× viewport
  /// fits an int.
  [[nodiscard]] view supersampled(int k) const {
    constexpr int max_side = 1 << 16;
    if (k < 1 || width > max_side / k || height > max_side / k)
      throw InvalidArgument("view: supersample factor " + std::to_string(k) + " for " +
                            std::to_string(width) + "x" + std::to_string(height) +
                            " pixels (expected k >= 1 and a k-fold viewport of at most " +
                            std::to_string(max_side) + " pixels per side)");
    view s = *this;
    s.width = width * k;
    s.height = height * k;
    s.focal_px = focal_px * static_cast<float>(k);
    return s;
  }
};

}  // namespace pbr_lod
