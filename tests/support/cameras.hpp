// Test support: cameras with simple, known geometry.
#pragma once

#include "pbr_lod/core/camera.hpp"

namespace pbr_lod::test {

/// A camera at the world origin looking down −z with y up: eye coordinates are (x, y, −z).
inline camera origin_camera(int w, int h, double z_near = 0.1) {
  camera c;
  c.eye = vec3d::Zero();
  c.target = vec3d(0, 0, -1);
  c.up = vec3d::UnitY();
  c.fovy_degrees = 60;
  c.vp = {w, h};
  c.z_near = z_near;
  c.z_far = 100;
  return c;
}

}  // namespace pbr_lod::test
