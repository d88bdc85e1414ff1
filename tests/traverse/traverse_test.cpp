#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/traverse/traverse.hpp"
#include "support/policies.hpp"
#include "support/sphere_tree.hpp"

namespace pbr_lod {
namespace {

using tree_n = test::sphere_tree<with_normals>;

point_set<with_normals> demo_points(std::size_t n) {
  return point_set<with_normals>::from(sample_surface(make_demo_scene(16), n, 7));
}

camera looking_at_scene(double az = 30, double el = 20, double dist = 3) {
  return camera::orbit(vec3d(0, 1, 0), 2.5, az, el, dist, 1, {256, 256});
}

using recording_policy = test::recording_policy<default_policy>;

// Culling is conservative and complete: with tolerance 0 every sample inside the frustum is
// emitted (its leaf is never culled), and every culled leaf lies wholly outside.
TEST(Traverse, FrustumKeepsInsideCullsOutside) {
  const auto pts = demo_points(20000);
  const tree_n tree(pts, 8);
  const view v(looking_at_scene(80, 10, 1.2), pts.origin);  // close up: much is outside
  std::vector<std::uint32_t> emitted;
  counting_sink<tree_n::attrs> sink;
  const traverse_options o{.tolerance_px = 0};
  const auto st = traverse(tree, v, o, sink, recording_policy{{}, &emitted});
  EXPECT_GT(st.culled_frustum, 0u);
  std::vector<char> drawn(pts.size(), 0);
  for (auto n : emitted) {
    ASSERT_TRUE(tree.is_leaf(n));  // tolerance 0: only leaves
    for (auto i : tree.samples(n)) drawn[i] = 1;
  }
  std::size_t inside = 0, drawn_outside = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const bool in = frustum_test(v, sphere{pts.positions[i], 0}) >= 0;
    inside += in;
    if (in) {
      EXPECT_TRUE(drawn[i]) << "sample " << i << " inside the frustum was not drawn";
    }
    drawn_outside += (!in && drawn[i]);
  }
  EXPECT_GT(inside, 0u);
  EXPECT_LT(inside, pts.size());
  EXPECT_EQ(sink.points, static_cast<std::size_t>(std::count(drawn.begin(), drawn.end(), 1)));
  // Leaves straddling the frustum are drawn whole, so some outside samples are drawn — but not
  // many more than the inside ones.
  EXPECT_LT(drawn_outside, inside);
}

// With no culling and tolerance 0, every sample is emitted exactly once.
TEST(Traverse, FullDetailEmitsEverySampleOnce) {
  const auto pts = demo_points(5000);
  const tree_n tree(pts, 4);
  const view v(looking_at_scene(), pts.origin);
  std::vector<std::uint32_t> emitted;
  counting_sink<tree_n::attrs> sink;
  const auto st = traverse(tree, v, {.tolerance_px = 0, .frustum_cull = false}, sink,
                           recording_policy{{}, &emitted});
  EXPECT_EQ(sink.points, pts.size());
  EXPECT_EQ(st.points, pts.size());
  EXPECT_EQ(st.visited, tree.size());  // nothing culled, all refined
  std::multiset<std::uint32_t> seen;
  for (auto n : emitted)
    for (auto i : tree.samples(n)) seen.insert(i);
  EXPECT_EQ(seen.size(), pts.size());
  for (std::uint32_t i = 0; i < pts.size(); ++i) EXPECT_EQ(seen.count(i), 1u);
}

/// The cut by definition, written as plain recursion: a subtree whose sphere is outside the
/// frustum is dropped; a node that is a leaf or whose exact projected diameter is at most the
/// tolerance is emitted; any other node is refined.
void reference_cut(const tree_n& t, tree_n::node_id n, const view& v, float tol,
                   std::vector<std::uint32_t>& out) {
  const sphere s = t.bounding_sphere(n);
  if (frustum_test(v, s) < 0) return;
  if (t.is_leaf(n) || 2 * projected_radius_exact(v, s) <= tol) {
    out.push_back(n);
    return;
  }
  for (const auto c : t.children(n)) reference_cut(t, c, v, tol, out);
}

// The cut: exactly the nodes of the recursive definition (so every emitted inner node is at most
// `tolerance` pixels large and its parent was larger: a traversal that refined one level too far
// or stopped one level early keeps every node under the tolerance but fails this); a larger
// tolerance never emits more primitives.
TEST(Traverse, ToleranceControlsTheCut) {
  const auto pts = demo_points(20000);
  const tree_n tree(pts, 8);
  const view v(looking_at_scene(), pts.origin);
  std::size_t previous = std::numeric_limits<std::size_t>::max();
  for (float tol : {0.5f, 1.0f, 2.0f, 4.0f, 8.0f, 16.0f}) {
    std::vector<std::uint32_t> emitted;
    counting_sink<tree_n::attrs> sink;
    traverse(tree, v, {.tolerance_px = tol}, sink, recording_policy{{}, &emitted});
    for (auto n : emitted)
      if (!tree.is_leaf(n)) {
        EXPECT_LE(2 * projected_radius_exact(v, tree.bounding_sphere(n)), tol);
      }
    std::vector<std::uint32_t> want;
    reference_cut(tree, tree.root(), v, tol, want);
    std::sort(emitted.begin(), emitted.end());
    std::sort(want.begin(), want.end());
    EXPECT_EQ(emitted, want) << "tolerance " << tol;
    EXPECT_LE(sink.total(), previous) << "tolerance " << tol;
    previous = sink.total();
  }
  // 16 px on a 256² image: leaves of 8 samples whose parent exceeds 16 px, a small fraction.
  EXPECT_LT(previous, pts.size() / 5);
}

// Back-face culling only removes subtrees whose every sample faces away from the eye.
TEST(Traverse, BackfaceCullingIsConservative) {
  const auto pts = demo_points(20000);
  const tree_n tree(pts, 8);
  const view v(looking_at_scene(200, 30, 3), pts.origin);
  std::vector<std::uint32_t> with, without;
  counting_sink<tree_n::attrs> s1, s2;
  const auto st = traverse(tree, v, {.tolerance_px = 0, .backface_cull = true}, s1,
                           recording_policy{{}, &with});
  traverse(tree, v, {.tolerance_px = 0, .backface_cull = false}, s2,
           recording_policy{{}, &without});
  EXPECT_GT(st.culled_backface, 0u);
  EXPECT_LT(s1.points, s2.points);
  std::vector<char> kept(pts.size(), 0);
  for (auto n : with)
    for (auto i : tree.samples(n)) kept[i] = 1;
  for (auto n : without)
    for (auto i : tree.samples(n))
      if (!kept[i]) {
        // dropped by back-face culling: must face away
        EXPECT_GT((pts.positions[i] - v.eye).dot(pts.normals[i]), -1e-4f) << "sample " << i;
      }
}

// The approximate metrics under-estimate size off-axis (distance ≤ eye z ≤ the exact ellipse),
// so they refine less than exact; PMR's nearest-corner estimate over-estimates, so it refines
// more. Node by node for every sphere in front of the eye, then on whole cuts at 16 and 64 px,
// where the cut holds inner nodes (at 4 px this view draws every sample whatever the metric, and
// a traversal that ignored the metric would pass).
TEST(Traverse, ApproximateMetricsDrawNoMoreThanExact) {
  const auto pts = demo_points(20000);
  const tree_n tree(pts, 8);
  const view v(looking_at_scene(), pts.origin);
  std::size_t in_front = 0, nodes = 0;
  std::vector<tree_n::node_id> stack{tree.root()};
  while (!stack.empty()) {
    const auto n = stack.back();
    stack.pop_back();
    ++nodes;
    for (const auto c : tree.children(n)) stack.push_back(c);
    const sphere sp = tree.bounding_sphere(n);
    if (!(v.to_eye(sp.centre).z() > 1.01f * sp.radius)) continue;
    ++in_front;
    const float exact = projected_radius(projection_metric::exact, v, sp);
    const float eye_z = projected_radius(projection_metric::eye_z, v, sp);
    const float dist = projected_radius(projection_metric::distance, v, sp);
    EXPECT_LE(eye_z, exact * (1 + 1e-5f)) << "node " << n;
    EXPECT_LE(dist, eye_z * (1 + 1e-5f)) << "node " << n;
  }
  EXPECT_GT(in_front, nodes / 2);
  for (const float tol : {16.0f, 64.0f}) {
    const auto count = [&](projection_metric m) {
      counting_sink<tree_n::attrs> s;
      traverse(tree, v, {.tolerance_px = tol, .metric = m}, s);
      return s.total();
    };
    const auto exact = count(projection_metric::exact);
    EXPECT_LT(exact, pts.positions.size()) << "the cut holds inner nodes";
    EXPECT_LT(count(projection_metric::eye_z), exact) << tol;
    EXPECT_LT(count(projection_metric::distance), count(projection_metric::eye_z)) << tol;
    EXPECT_GT(count(projection_metric::pmr_corner), exact) << tol;
  }
}

// The same scene 10⁷ units from the origin, with the camera moved along, selects the same cut:
// the hierarchy stores coordinates relative to its origin and the view subtracts it in double.
// At 16 px the cut holds inner nodes, so the nodes' screen sizes decide it (at 2 px, as this test
// once ran, it was every visible leaf: only the culling was compared).
TEST(Traverse, FarFromOriginSelectsTheSameCut) {
  auto cloud = sample_surface(make_demo_scene(16), 10000, 3);
  const auto near_pts = point_set<with_normals>::from(cloud);
  cloud.origin += vec3d(1e7, 4e6, -2e7);
  const auto far_pts = point_set<with_normals>::from(cloud);
  const tree_n near_tree(near_pts), far_tree(far_pts);
  camera cam = looking_at_scene();
  const view v_near(cam, near_pts.origin);
  cam.eye += cloud.origin;
  cam.target += cloud.origin;
  const view v_far(cam, far_pts.origin);
  counting_sink<tree_n::attrs> a, b;
  std::vector<std::uint32_t> cut_a, cut_b;
  const auto sa =
      traverse(near_tree, v_near, {.tolerance_px = 16}, a, recording_policy{{}, &cut_a});
  const auto sb = traverse(far_tree, v_far, {.tolerance_px = 16}, b, recording_policy{{}, &cut_b});
  EXPECT_EQ(sa.visited, sb.visited);
  EXPECT_EQ(a.total(), b.total());
  // The same nodes, not only as many (the trees are built from the same relative floats).
  EXPECT_EQ(cut_a, cut_b);
  EXPECT_GT(sa.emitted_nodes, 0u) << "the cut is above the leaves somewhere";
  EXPECT_GT(sa.emitted_leaves, 0u) << "and reaches the leaves elsewhere";
}

TEST(Traverse, EmptyHierarchyEmitsNothing) {
  const point_set<with_normals> none;
  const tree_n tree(none);
  counting_sink<tree_n::attrs> s;
  const auto st = traverse(tree, view(looking_at_scene(), vec3d::Zero()), {}, s);
  EXPECT_EQ(st.visited, 0u);
  EXPECT_EQ(s.total(), 0u);
}

// Buffer sink keeps what a host renderer copies, in emission order, and replays it unchanged.
TEST(Sinks, BufferSinkReplays) {
  const auto pts = demo_points(2000);
  const tree_n tree(pts);
  const view v(looking_at_scene(), pts.origin);
  buffer_sink<tree_n::attrs> buf;
  const auto st = traverse(tree, v, {.tolerance_px = 2}, buf);
  EXPECT_EQ(buf.points.size(), st.points);
  counting_sink<tree_n::attrs> c;
  buf.replay(c);
  EXPECT_EQ(c.points, st.points);
}

// Replay sends the primitives in the order they were received, interleaved kinds included: the
// rasteriser keeps the first of two fragments at equal depth, so a replay that grouped points
// before triangles would change which one wins. Primitives put into the arrays directly (no
// recorded order) still replay, after the recorded ones.
TEST(Sinks, BufferSinkReplaysInterleavedKindsInOrder) {
  using seq = std::vector<std::pair<char, int>>;  // (kind, id) in the order received
  struct order_sink {
    seq got;
    void point(const point_prim<positions_only>& p) { got.emplace_back('p', int(p.size_px)); }
    void splat(const splat_prim<positions_only>& s) { got.emplace_back('s', int(s.centre.x())); }
    void triangle(const triangle_prim<positions_only>& t) {
      got.emplace_back('t', int(t.p[0].x()));
    }
  };
  buffer_sink<positions_only> buf;
  const vec3f o = vec3f::Zero();
  const auto pt = [&](float id) { buf.point({o, id}); };
  const auto sp = [&](float id) { buf.splat({vec3f(id, 0, 0), o, o}); };
  const auto tr = [&](float id) { buf.triangle({{vec3f(id, 0, 0), o, o}}); };
  pt(1), pt(2), tr(3), sp(4), pt(5), tr(6), tr(7), sp(8), pt(9);
  buf.points.push_back({o, 0});  // no recorded order: replayed last
  order_sink rec;
  buf.replay(rec);
  const seq want{{'p', 1}, {'p', 2}, {'t', 3}, {'s', 4}, {'p', 5},
                 {'t', 6}, {'t', 7}, {'s', 8}, {'p', 9}, {'p', 0}};
  EXPECT_EQ(rec.got, want);
  buf.clear();
  order_sink empty;
  buf.replay(empty);
  EXPECT_TRUE(empty.got.empty());
}

// A policy with an emit() that takes the node's state gets it (traverse() prefers that overload
// when the policy has one): here the state is the node's depth, carried down by
// for_each_child, so every emitted node's state must equal its depth found by a separate walk
// of the tree. The same policy sends a screen rectangle to a sink that takes them and a point
// otherwise; counting_forwarder counts both as points, and forwards the rectangles only to a
// ScreenRectSink (a sink without the hook never sees one).
struct depth_state_policy : default_policy {
  std::vector<std::pair<int, std::uint32_t>>* seen;  // (state, node) per emitted node
  template <Hierarchy H>
  [[nodiscard]] int root_state(const H&, const view&, const traverse_options&) const {
    return 0;
  }
  template <Hierarchy H, class F>
  void for_each_child(const H& h, const typename H::node_id& n, int depth, F&& f) const {
    for (const auto& c : h.children(n)) f(c, depth + 1);
  }
  template <Hierarchy H, class S>
  void emit(const H&, const typename H::node_id& n, const int& depth, const view&, float,
            const traverse_options&, S& sink) const {
    seen->emplace_back(depth, n);
    if constexpr (ScreenRectSink<S, H::attrs>) {
      screen_rect_prim<H::attrs> r{depth, 0, depth, 0, 1, vec3f::Zero()};
      if constexpr (H::attrs.normal) r.normal = vec3f::UnitZ();
      sink.screen_rect(r);
    } else {
      point_prim<H::attrs> p{vec3f::Zero(), float(depth)};
      if constexpr (H::attrs.normal) p.normal = vec3f::UnitZ();
      sink.point(p);
    }
  }
};

TEST(Traverse, PolicyEmitGetsTheNodeState) {
  const auto pts = demo_points(2000);
  const tree_n tree(pts);
  const view v(looking_at_scene(), pts.origin);
  std::vector<int> depth_of(1, 0);  // by node id
  for (std::vector<std::uint32_t> stack{tree.root()}; !stack.empty();) {
    const std::uint32_t n = stack.back();
    stack.pop_back();
    for (const std::uint32_t c : tree.children(n)) {
      depth_of.resize(std::max<std::size_t>(depth_of.size(), c + 1));
      depth_of[c] = depth_of[n] + 1;
      stack.push_back(c);
    }
  }
  std::vector<std::pair<int, std::uint32_t>> seen;
  buffer_sink<tree_n::attrs> buf;
  const auto st = traverse(tree, v, {.tolerance_px = 4}, buf, depth_state_policy{{}, &seen});
  ASSERT_GT(seen.size(), 10u);
  int deepest = 0;
  for (const auto& [state, node] : seen) {
    EXPECT_EQ(state, depth_of[node]);
    deepest = std::max(deepest, state);
  }
  EXPECT_GT(deepest, 1);
  EXPECT_EQ(st.points, seen.size());
  EXPECT_EQ(buf.screen_rects.size(), seen.size());
  EXPECT_TRUE(buf.points.empty());
  // Without the hook: points, counted alike.
  struct point_counter {
    std::size_t points = 0;
    void point(const point_prim<tree_n::attrs>&) { ++points; }
    void splat(const splat_prim<tree_n::attrs>&) {}
    void triangle(const triangle_prim<tree_n::attrs>&) {}
  } pc;
  seen.clear();
  const auto st2 = traverse(tree, v, {.tolerance_px = 4}, pc, depth_state_policy{{}, &seen});
  EXPECT_EQ(st2.points, st.points);
  EXPECT_EQ(pc.points, st.points);
  // A buffer replays its rectangles to a sink that takes them and as as_point_prim() to one that
  // does not, in the order received.
  counting_sink<tree_n::attrs> cs;
  buf.replay(cs);
  EXPECT_EQ(cs.points, st.points);
  point_counter pc2;
  buf.replay(pc2);
  EXPECT_EQ(pc2.points, st.points);
}

// as_point_prim: the rectangle's larger side as the square's size, the 3-D position and the
// attributes carried over; a degenerate rectangle is a one-pixel point.
TEST(Sinks, ScreenRectAsPoint) {
  constexpr attributes NC{.normal = true, .colour = true};
  screen_rect_prim<NC> r{0, 0, 3 * 256 + 128, 2 * 256, 5, vec3f(1, 2, 3)};
  r.normal = vec3f::UnitY();
  r.colour = {1, 2, 3};
  const point_prim<NC> p = as_point_prim(r);
  EXPECT_EQ(p.position, vec3f(1, 2, 3));
  EXPECT_FLOAT_EQ(p.size_px, 3.5f);
  EXPECT_EQ(p.normal, vec3f::UnitY());
  EXPECT_EQ(p.colour, (rgb8{1, 2, 3}));
  r.x1 = r.x0;
  r.y1 = r.y0;
  EXPECT_FLOAT_EQ(as_point_prim(r).size_px, 0);
}

}  // namespace
}  // namespace pbr_lod
