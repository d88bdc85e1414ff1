// pbr_lod — the generic view-dependent LOD traversal.
//
// Depth-first over any Hierarchy: cull a node whose bounding sphere lies outside the view
// frustum (planes a parent lies fully inside are not tested again for its subtree), cull a node
// whose normal cone faces away from the eye (when the hierarchy has cones and back-face culling
// is on), then either refine into the children or emit the node. The default rule — QSplat's,
// and POP's and Pajarola's up to their choice of size estimate — is: refine while the node's
// projected diameter exceeds the screen-space tolerance, emit otherwise (and always emit a leaf).
//
// Method-specific behaviour plugs in through a Policy (see default_policy): the size estimate
// (Pajarola's tilted-area metric, PMR's per-leaf level choice), the refine rule, and the emit
// step. The traversal itself stays one loop; the policies are specialisations of it.
//
// A policy whose method decides from something other than a bounding sphere (the ρ-grid's
// incremental homogeneous positions and bounds tables) may also define, all optional:
//   p.root_state(h, v, o) -> State        per-entry state carried down the stack (the root's)
//   p.visit(h, n, state, v, o) -> visit_result
//                                         replaces the sphere tests, the size estimate and the
//                                         refine rule: cull, emit or refine n
//   p.for_each_child(h, n, state, f)      calls f(child, child_state) for n's children in the
//                                         order they are to be visited (replaces h.children(n))
//   p.emit(h, n, state, v, size_px, o, sink)
//                                         emit() with the node's state (the ρ-grid draws a cell
//                                         at its screen position from H); used instead of the
//                                         six-argument emit() when the policy has it
// A policy without them compiles to the loop it always had: the entry holds no state (an empty
// member takes no room) and none of the hooks' branches exist.
#pragma once

#include <algorithm>
#include <concepts>
#include <cstddef>
#include <utility>
#include <vector>

#include "pbr_lod/traverse/hierarchy.hpp"

namespace pbr_lod {

struct traverse_options {
  /// Refine while a node's screen size (projected diameter, pixels) exceeds this. 1 = full
  /// detail at pixel accuracy; larger values trade accuracy for speed.
  float tolerance_px = 1;
  /// How the screen size is estimated (exact, or one of the papers' approximations).
  projection_metric metric = projection_metric::exact;
  bool frustum_cull = true;
  /// Needs HasNormalCones; ignored otherwise.
  bool backface_cull = false;
  /// Cull against the six frustum planes (exact) or Pajarola's enclosing view cone (cheaper).
  enum class volume { planes, view_cone } cull_volume = volume::planes;
};

/// Where v's cut is drawn at k × k the resolution (render_options::supersample = k): the k× view
/// with k times the tolerance, since k of its pixels are one of v's — the same nodes as v's cut.
struct supersampled_cut {
  view drawn;
  traverse_options options;
  supersampled_cut(const view& v, const traverse_options& t, int k)
      : drawn(k == 1 ? v : v.supersampled(k)), options(t) {  // throws for k < 1
    options.tolerance_px = t.tolerance_px * static_cast<float>(std::max(k, 1));
  }
};

struct traverse_stats {
  std::size_t visited = 0;          ///< nodes whose bounds were tested
  std::size_t culled_frustum = 0;   ///< subtrees rejected by the frustum
  std::size_t culled_backface = 0;  ///< subtrees rejected by their normal cone
  std::size_t emitted_nodes = 0;    ///< inner nodes emitted (the cut above the leaves)
  std::size_t emitted_leaves = 0;   ///< leaves emitted at full detail
  /// Primitives by kind; points counts point_prim and screen_rect_prim alike (the same cell drawn
  /// from its 3-D position or from its screen rectangle), so the stats do not depend on the sink.
  std::size_t points = 0, splats = 0, triangles = 0;
  std::size_t gaussians = 0;  ///< gaussian_prim sent to a GaussianSink
  [[nodiscard]] std::size_t primitives() const { return points + splats + triangles + gaussians; }
};

/// The default policy: screen size = projected diameter under the chosen metric; refine while it
/// exceeds the tolerance; emit with the hierarchy's own emit().
struct default_policy {
  template <Hierarchy H>
  [[nodiscard]] float screen_size(const H&, const typename H::node_id&, const sphere& s,
                                  const view& v, const traverse_options& o) const {
    return 2 * projected_radius(o.metric, v, s);
  }
  template <Hierarchy H>
  [[nodiscard]] bool refine(const H& h, const typename H::node_id& n, float size_px,
                            const traverse_options& o) const {
    return !h.is_leaf(n) && size_px > o.tolerance_px;
  }
  template <Hierarchy H, class S>
  void emit(const H& h, const typename H::node_id& n, const view& v, float /*size_px*/,
            const traverse_options& /*o*/, S& sink) const {
    h.emit(n, v, sink);
  }
};

/// What a policy's visit() decides for a node.
struct visit_result {
  enum class verdict { cull, emit, refine } what;
  float size_px;  ///< the node's screen size, passed on to the policy's emit()
};

namespace detail {
struct no_traverse_state {};
template <class P, class H>
concept has_root_state = requires(const P& p, const H& h, const view& v,
                                  const traverse_options& o) {
  p.root_state(h, v, o);
};
template <class P, class H>
struct traverse_state {
  using type = no_traverse_state;
};
template <class P, class H>
requires has_root_state<P, H>
struct traverse_state<P, H> {
  using type = decltype(std::declval<const P&>().root_state(
      std::declval<const H&>(), std::declval<const view&>(),
      std::declval<const traverse_options&>()));
};
template <class P, class H, class State>
concept has_visit = requires(const P& p, const H& h, const typename H::node_id& n, const State& s,
                             const view& v, const traverse_options& o) {
  { p.visit(h, n, s, v, o) } -> std::same_as<visit_result>;
};

template <class P, class H, class State, class Out>
concept has_state_emit = requires(const P& p, const H& h, const typename H::node_id& n,
                                  const State& s, const view& v, float size,
                                  const traverse_options& o, Out& out) {
  p.emit(h, n, s, v, size, o, out);
};

/// Forwards to a sink and counts what passes, so the stats know primitives by kind.
template <attributes A, class S>
struct counting_forwarder {
  S& inner;
  std::size_t points = 0, splats = 0, triangles = 0, gaussians = 0;
  void point(const point_prim<A>& p) {
    ++points;
    inner.point(p);
  }
  void splat(const splat_prim<A>& q) {
    ++splats;
    inner.splat(q);
  }
  void triangle(const triangle_prim<A>& t) {
    ++triangles;
    inner.triangle(t);
  }
  /// Screen rectangles to a sink that takes them, counted as points (traverse_stats::points).
  void screen_rect(const screen_rect_prim<A>& r) requires ScreenRectSink<S, A> {
    ++points;
    inner.screen_rect(r);
  }
  /// Textured triangles to a sink that takes them, counted as triangles.
  void textured_triangle(const textured_triangle_prim<A>& t) requires TexturedTriangleSink<S, A> {
    ++triangles;
    inner.textured_triangle(t);
  }
  /// Gaussians to a sink that takes them (the emitter sends the others splats).
  void gaussian(const gaussian_prim& g) requires GaussianSink<S> {
    ++gaussians;
    inner.gaussian(g);
  }
  /// Occluders pass through to a sink that takes them (not counted: they are not primitives).
  void occluder(const occluder_prim& o) requires OccluderSink<S> { inner.occluder(o); }
};
}  // namespace detail

/// Traverses h for view v and sends the selected nodes' primitives to sink. The view must be
/// expressed relative to h.origin() (construct it as view(camera, h.origin())).
template <Hierarchy H, Sink<H::attrs> S, class Policy = default_policy>
traverse_stats traverse(const H& h, const view& v, const traverse_options& o, S& sink,
                        const Policy& policy = {}) {
  traverse_stats st;
  if (h.empty()) return st;
  detail::counting_forwarder<H::attrs, S> out{sink};
  using node_id = typename H::node_id;
  using state_type = typename detail::traverse_state<Policy, H>::type;
  struct entry {
    node_id node;
    int planes;  // frustum planes still straddled by the parent
    [[no_unique_address]] state_type state;
  };
  std::vector<entry> stack;
  stack.reserve(256);
  const int all_planes = o.frustum_cull ? 0x3f : 0;
  if constexpr (detail::has_root_state<Policy, H>)
    stack.push_back({h.root(), all_planes, policy.root_state(h, v, o)});
  else
    stack.push_back({h.root(), all_planes, {}});
  while (!stack.empty()) {
    const entry e = stack.back();
    stack.pop_back();
    ++st.visited;
    int planes = e.planes;
    float size;
    bool refine;
    if constexpr (detail::has_visit<Policy, H, state_type>) {
      const visit_result r = policy.visit(h, e.node, e.state, v, o);
      if (r.what == visit_result::verdict::cull) {
        ++st.culled_frustum;
        continue;
      }
      size = r.size_px;
      refine = r.what == visit_result::verdict::refine;
    } else {
      const sphere s = h.bounding_sphere(e.node);
      if (o.cull_volume == traverse_options::volume::view_cone) {
        if (o.frustum_cull && outside_view_cone(v, s)) {
          ++st.culled_frustum;
          continue;
        }
      } else if (planes != 0) {
        planes = frustum_test(v, s, planes);
        if (planes < 0) {
          ++st.culled_frustum;
          continue;
        }
      }
      if constexpr (HasNormalCones<H>) {
        if (o.backface_cull && node_back_facing(h, e.node, s, v.eye)) {
          ++st.culled_backface;
          continue;
        }
      }
      size = policy.screen_size(h, e.node, s, v, o);
      refine = policy.refine(h, e.node, size, o);
    }
    if (refine) {
      if constexpr (requires {
                      policy.for_each_child(h, e.node, e.state, [](node_id, state_type) {});
                    }) {
        // The stack pops last-pushed first: reverse what the policy gave to visit it in order.
        const std::size_t first = stack.size();
        policy.for_each_child(h, e.node, e.state, [&](const node_id& c, const state_type& cs) {
          stack.push_back({c, planes, cs});
        });
        std::reverse(stack.begin() + static_cast<std::ptrdiff_t>(first), stack.end());
      } else {
        for (const auto& c : h.children(e.node)) stack.push_back({c, planes, e.state});
      }
      continue;
    }
    if (h.is_leaf(e.node))
      ++st.emitted_leaves;
    else
      ++st.emitted_nodes;
    if constexpr (detail::has_state_emit<Policy, H, state_type, decltype(out)>)
      policy.emit(h, e.node, e.state, v, size, o, out);
    else
      policy.emit(h, e.node, v, size, o, out);
  }
  st.points = out.points;
  st.splats = out.splats;
  st.triangles = out.triangles;
  st.gaussians = out.gaussians;
  return st;
}

}  // namespace pbr_lod
