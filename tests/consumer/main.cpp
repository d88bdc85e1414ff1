// Uses the installed headers and the shared library: builds a view and projects a sphere.
#include <pbr_lod/core/camera.hpp>
#include <pbr_lod/core/synthetic.hpp>
#include <pbr_lod/traverse/screen_size.hpp>
#include <pbr_lod/traverse/sink.hpp>
#include <pbr_lod/version.hpp>

#include <cstdio>

int main() {
  const auto scene = pbr_lod::make_demo_scene(8);  // compiled code from libpbr_lod
  const pbr_lod::view v(pbr_lod::camera{}, pbr_lod::vec3d::Zero());
  const float r = pbr_lod::projected_radius_exact(v, {pbr_lod::vec3f::Zero(), 0.1f});
  std::printf("pbr_lod %s: %zu triangles, sphere radius %.2f px\n", pbr_lod::version(),
              scene.num_faces(), static_cast<double>(r));
  return scene.num_faces() > 0 && r > 0 ? 0 : 1;
}
