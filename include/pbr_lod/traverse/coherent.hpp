// pbr_lod — frame-coherent traversal of any hierarchy (POP's RENDER-COHERENCY, Chen & Nguyen
// 2001 §3.2, made generic): keeps the previous frame's cut and moves from it instead of starting
// at the root.
#pragma once

#include <algorithm>
#include <concepts>
#include <cstdint>
#include <limits>
#include <vector>

#include "pbr_lod/traverse/hierarchy.hpp"
#include "pbr_lod/traverse/ranks.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod {

/// A hierarchy whose node ids index its node array (0 … nodes().size() − 1): a coherent
/// traversal keeps per-node state in plain arrays.
template <class H>
concept IndexedHierarchy = Hierarchy<H> && std::unsigned_integral<typename H::node_id> &&
    requires(const H& h) {
  { h.nodes().size() } -> std::convertible_to<std::size_t>;
};

/// A policy that declares `static constexpr bool monotone_refine = true`: whenever a node
/// refines, so do all its ancestors (POP's: a parent's sphere holds its children's, so its
/// splat is at least as large and its culling tests at most as strict). A screen size with a
/// per-node tilt factor (the point-octree's A_screen) is not monotone.
template <class P>
concept monotone_refine_policy = requires {
  requires P::monotone_refine;
};

namespace detail {

/// What traverse() decides for one node, in its order: outside the view volume, back-facing,
/// refine, or draw (with its screen size in `size`). Shared by the coherent traversals.
enum class node_state : std::uint8_t { culled_frustum, culled_backface, refine, draw };

template <class H, class Policy>
node_state evaluate_node(const H& h, const typename H::node_id& n, const view& v,
                         const traverse_options& o, const Policy& p, float& size) {
  const sphere s = h.bounding_sphere(n);
  if (o.frustum_cull) {
    if (o.cull_volume == traverse_options::volume::view_cone) {
      if (outside_view_cone(v, s)) return node_state::culled_frustum;
    } else if (frustum_test(v, s, 0x3f) < 0) {
      return node_state::culled_frustum;
    }
  }
  if constexpr (HasNormalCones<H>) {
    if (o.backface_cull && node_back_facing(h, n, s, v.eye)) return node_state::culled_backface;
  }
  size = p.screen_size(h, n, s, v, o);
  return p.refine(h, n, size, o) ? node_state::refine : node_state::draw;
}

}  // namespace detail

/// Keeps the previous frame's cut — the nodes drawn and the nodes culled — and moves from each
/// of them down (when it must now refine) or up (while its parent need not refine any more),
/// instead of starting at the root. Produces exactly the cut traverse() gives with the same
/// options and policy, and emits it in traverse()'s order, so images are byte-identical. For a
/// monotone policy the upward search stops at the first parent that refines; for any other it
/// checks every ancestor up to the root (the plain traversal stops at the topmost node that does
/// not refine), so each frame also evaluates the cut's ancestors. traverse_stats::visited counts
/// the nodes evaluated this frame.
///
/// Policy: screen_size / refine / emit as default_policy (policies with per-entry state, such
/// as the ρ-grid's, need traverse()). One instance per hierarchy and camera path; not
/// thread-safe.
template <IndexedHierarchy H, class Policy = default_policy>
class coherent_traversal {
 public:
  using node_id = typename H::node_id;
  static constexpr node_id no_node = std::numeric_limits<node_id>::max();

  explicit coherent_traversal(const H& h) : h_(&h) {
    const std::size_t n = h.nodes().size();
    parent_.assign(n, no_node);
    stamp_.assign(n, 0);
    added_.assign(n, 0);
    state_.assign(n, draw);
    size_.assign(n, 0);
    // Every node's parent (found on traverse()'s walk; the ranks themselves are not needed).
    std::vector<node_id> rank(n, 0);
    traversal_ranks(h, rank, [&](node_id p, node_id c) { parent_[c] = p; });
  }

  /// Draws one frame. The first frame (or after reset()) starts at the root.
  template <Sink<H::attrs> S>
  traverse_stats frame(const view& v, const traverse_options& o, S& sink, const Policy& p = {}) {
    st_ = {};
    drawn_.clear();
    if (h_->empty()) return st_;
    if (++frame_ == 0) {  // stamps wrapped: forget them all
      std::fill(stamp_.begin(), stamp_.end(), 0u);
      std::fill(added_.begin(), added_.end(), 0u);
      frame_ = 1;
    }
    next_.clear();
    if (front_.empty())
      descend(h_->root(), v, o, p);
    else
      for (const node_id f : front_) move_from(f, v, o, p);
    // next_ is already in traverse()'s order (see move_from), so the drawn nodes need no sort.
    for (const node_id n : next_)
      if (state_[n] == draw) drawn_.push_back(n);
    emit_cut(v, o, sink, p);
    front_.swap(next_);
    return st_;
  }

  /// Forgets the cut: the next frame starts at the root.
  void reset() { front_.clear(); }
  /// The nodes drawn in the last frame, in drawing order.
  [[nodiscard]] const std::vector<node_id>& drawn() const { return drawn_; }
  /// The last frame's cut: drawn and culled nodes (unordered).
  [[nodiscard]] const std::vector<node_id>& front() const { return front_; }

 private:
  // The values of detail::node_state, unscoped for brevity here.
  enum state : std::uint8_t { culled_frustum, culled_backface, refine, draw };
  static_assert(static_cast<int>(detail::node_state::draw) == draw &&
                static_cast<int>(detail::node_state::refine) == refine &&
                static_cast<int>(detail::node_state::culled_backface) == culled_backface);

  /// The tests of traverse() for one node, in its order.
  state eval(node_id n, const view& v, const traverse_options& o, const Policy& p, float& size) {
    ++st_.visited;
    return static_cast<state>(detail::evaluate_node(*h_, n, v, o, p, size));
  }

  state cached(node_id n, const view& v, const traverse_options& o, const Policy& p) {
    if (stamp_[n] != frame_) {
      stamp_[n] = frame_;
      state_[n] = eval(n, v, o, p, size_[n]);
    }
    return state_[n];
  }

  void add(node_id n, state s) {
    if (added_[n] == frame_) return;
    added_[n] = frame_;
    next_.push_back(n);
    if (s == culled_frustum) ++st_.culled_frustum;
    if (s == culled_backface) ++st_.culled_backface;
  }

  /// RENDER(f) of the paper: the cut below f, added in traverse()'s order (depth first, the
  /// last child first: the same stack).
  void descend(node_id f, const view& v, const traverse_options& o, const Policy& p) {
    stack_.assign(1, f);
    while (!stack_.empty()) {
      const node_id n = stack_.back();
      stack_.pop_back();
      const state s = cached(n, v, o, p);
      if (s == refine)
        for (const node_id c : h_->children(n)) stack_.push_back(c);  // as traverse() does
      else
        add(n, s);
    }
  }

  /// From one node of the last cut: down when it must refine now, else up while the parent need
  /// not refine any more. Monotone policy: a parent that refines has ancestors that all refine,
  /// so the upward search stops there.
  ///
  /// Order: the last cut is visited in traverse()'s order, and each of its nodes adds either its
  /// own subtree's cut (depth first, so in order) or an ancestor that every earlier node of the
  /// last cut below that ancestor already added (they all climb to the same topmost
  /// non-refining node). So next_ comes out in traverse()'s order, and the next frame visits it
  /// in that order again — the node records are read front to back, as traverse() reads them,
  /// instead of in the order the last frame happened to add them, with a sort at the end (which
  /// cost more than the ≈ 4 % of node evaluations coherence saves on POP).
  void move_from(node_id f, const view& v, const traverse_options& o, const Policy& p) {
    if (added_[f] == frame_) return;
    if constexpr (!monotone_refine_policy<Policy>) {
      if (const node_id a = topmost_stop(f, v, o, p); a != no_node) {
        add(a, state_[a]);
        return;
      }
    }
    if (cached(f, v, o, p) == refine) {
      descend(f, v, o, p);
      return;
    }
    node_id a = f;
    for (node_id q = parent_[a]; q != no_node; q = parent_[a]) {
      if (cached(q, v, o, p) == refine) break;
      a = q;
    }
    add(a, state_[a]);
  }

  /// The topmost strict ancestor of f that does not refine (it is in traverse()'s cut and f's
  /// subtree is not), or no_node when they all refine. Stops early at an ancestor already in
  /// this frame's cut.
  node_id topmost_stop(node_id f, const view& v, const traverse_options& o, const Policy& p) {
    node_id top = no_node;
    for (node_id q = parent_[f]; q != no_node; q = parent_[q]) {
      if (added_[q] == frame_) return q;
      if (cached(q, v, o, p) != refine) top = q;
    }
    return top;
  }

  template <class S>
  void emit_cut(const view& v, const traverse_options& o, S& sink, const Policy& p) {
    detail::counting_forwarder<H::attrs, S> out{sink};
    for (const node_id n : drawn_) {
      if (h_->is_leaf(n))
        ++st_.emitted_leaves;
      else
        ++st_.emitted_nodes;
      p.emit(*h_, n, v, size_[n], o, out);
    }
    st_.points = out.points;
    st_.splats = out.splats;
    st_.triangles = out.triangles;
  }

  const H* h_;
  std::vector<node_id> parent_;
  std::vector<std::uint32_t> stamp_, added_;
  std::vector<state> state_;
  std::vector<float> size_;
  std::uint32_t frame_ = 0;
  std::vector<node_id> front_, next_, drawn_, stack_;
  traverse_stats st_;
};

}  // namespace pbr_lod
