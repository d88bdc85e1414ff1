// Uses the installed headers and the shared library the way README.md shows: a hierarchy built
// from a cloud, traversed into a host renderer's own sink (here: arrays it would upload).
#include <pbr_lod/builders/point_octree.hpp>
#include <pbr_lod/core/bounds.hpp>
#include <pbr_lod/core/synthetic.hpp>
#include <pbr_lod/traverse/traverse.hpp>
#include <pbr_lod/version.hpp>

#include <cstdio>
#include <vector>

// README "A host renderer's Sink": what the traversal selects, copied into vertex arrays.
template <pbr_lod::attributes A>
struct vertex_buffers {
  std::vector<pbr_lod::point_prim<A>> points;
  std::vector<pbr_lod::splat_prim<A>> splats;  // elliptical splats: centre, u, v, normal, colour
  std::vector<pbr_lod::triangle_prim<A>> triangles;
  void point(const pbr_lod::point_prim<A>& p) { points.push_back(p); }
  void splat(const pbr_lod::splat_prim<A>& s) { splats.push_back(s); }
  void triangle(const pbr_lod::triangle_prim<A>& t) { triangles.push_back(t); }
};

int main() {
  const auto scene = pbr_lod::make_demo_scene(8);  // compiled code from libpbr_lod
  const auto cloud = pbr_lod::sample_surface(scene, 5000, 1);
  const auto tree =
      pbr_lod::build_point_octree(pbr_lod::point_set<pbr_lod::with_normals>::from(cloud));
  const pbr_lod::sphere b = pbr_lod::bounding_sphere_about_box_centre(cloud.positions);
  const auto cam = pbr_lod::camera::orbit(cloud.origin + b.centre.cast<double>(), b.radius, 30, 20,
                                          3, 1, {640, 480});
  vertex_buffers<decltype(tree)::attrs> frame;
  const auto st = pbr_lod::traverse(tree, pbr_lod::view(cam, tree.origin()), {.tolerance_px = 2},
                                    frame, pbr_lod::point_octree_policy{});
  std::printf("pbr_lod %s: %zu splats from %zu nodes visited\n", pbr_lod::version(),
              frame.splats.size(), st.visited);
  return !frame.splats.empty() && frame.splats.size() == st.splats ? 0 : 1;
}
