// The generic frame-coherent traversal against traverse(): on a point-octree (not POP, whose own
// tests cover its monotone policy) over a camera path that refines and coarsens, every frame
// emits the same primitives in the same order as a fresh traversal. The point-octree's policy
// is not monotone, which a coherent traversal that stopped at the first refining parent gets
// wrong (it did, on frame 3 of this path).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "pbr_lod/builders/point_octree.hpp"
#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/traverse/coherent.hpp"

namespace pbr_lod {
namespace {

/// Records every primitive's defining floats in emission order.
template <attributes A>
struct recording_sink {
  std::vector<float> seq;
  void point(const point_prim<A>& p) {
    seq.insert(seq.end(), {0.f, p.position.x(), p.position.y(), p.position.z(), p.size_px});
  }
  void splat(const splat_prim<A>& s) {
    seq.insert(seq.end(), {1.f, s.centre.x(), s.centre.y(), s.centre.z(), s.u.x(), s.v.y()});
  }
  void triangle(const triangle_prim<A>& t) {
    seq.insert(seq.end(), {2.f, t.p[0].x(), t.p[1].y(), t.p[2].z()});
  }
};

TEST(CoherentTraversal, PointOctreeMatchesTraverseAlongAPath) {
  const point_cloud cloud = sample_surface(make_demo_scene(24), 30000, 3);
  const auto tree = build_point_octree(point_set<with_normals_colours>::from(cloud));
  using tree_type = std::decay_t<decltype(tree)>;
  static_assert(IndexedHierarchy<tree_type>);
  const sphere b = bounding_sphere_about_box_centre(cloud.positions);
  coherent_traversal<tree_type, point_octree_policy> coherent(tree);
  std::size_t coherent_visits = 0, plain_visits = 0, frames_with_splats = 0;
  for (int i = 0; i < 24; ++i) {
    // Orbit and dolly in and out: cuts refine and coarsen between frames.
    const double dist = 1.6 + 2.5 * (1 + std::sin(0.5 * i));
    const camera cam = camera::orbit(cloud.origin + b.centre.cast<double>(), b.radius, 15.0 * i, 20,
                                     dist, 1, {320, 240});
    const view v(cam, tree.origin());
    const traverse_options o{.tolerance_px = 3,
                             .backface_cull = true,
                             .cull_volume = traverse_options::volume::view_cone};
    recording_sink<tree_type::attrs> plain, coh;
    const traverse_stats ps = traverse(tree, v, o, plain, point_octree_policy{});
    const traverse_stats cs = coherent.frame(v, o, coh, point_octree_policy{});
    ASSERT_EQ(plain.seq, coh.seq) << "frame " << i;
    EXPECT_EQ(ps.splats, cs.splats);
    EXPECT_EQ(ps.emitted_nodes + ps.emitted_leaves, cs.emitted_nodes + cs.emitted_leaves);
    EXPECT_EQ(coherent.drawn().size(), cs.emitted_nodes + cs.emitted_leaves);
    frames_with_splats += ps.splats > 0;
    plain_visits += ps.visited;
    coherent_visits += cs.visited;
  }
  EXPECT_GT(frames_with_splats, 20u);
  // The same view again: only the kept cut and its parents are evaluated.
  const camera cam =
      camera::orbit(cloud.origin + b.centre.cast<double>(), b.radius, 0, 20, 2.0, 1, {320, 240});
  const view v(cam, tree.origin());
  recording_sink<tree_type::attrs> first, again, plain;
  (void)coherent.frame(v, {.tolerance_px = 3}, first, point_octree_policy{});
  const traverse_stats repeat =
      coherent.frame(v, {.tolerance_px = 3}, again, point_octree_policy{});
  const traverse_stats fresh = traverse(tree, v, {.tolerance_px = 3}, plain, point_octree_policy{});
  EXPECT_EQ(again.seq, plain.seq);
  // The point-octree's policy is not monotone (its screen size has a per-node tilt factor), so
  // each frame checks every ancestor of the kept cut: exactly the nodes a fresh traversal
  // evaluates — the same cut, no saving. (POP's monotone policy saves: pop_test.cpp.)
  EXPECT_EQ(repeat.visited, fresh.visited);
  RecordProperty("coherent_visits", static_cast<int>(coherent_visits));
  RecordProperty("plain_visits", static_cast<int>(plain_visits));
}

}  // namespace
}  // namespace pbr_lod
