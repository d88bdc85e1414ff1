// pbr_lod — POP's RENDER-COHERENCY exactly as Chen & Nguyen 2001 §3.2 write it: two flags per
// node instead of a kept list of cut nodes. Measured against the generic cut-following
// coherent_traversal (pop_coherent_traversal) in docs/pop.md.
#pragma once

#include <cstdint>
#include <vector>

#include "pbr_lod/builders/pop.hpp"
#include "pbr_lod/traverse/coherent.hpp"

namespace pbr_lod {

/// The paper's frame-coherent traversal. flag1 marks the nodes drawn or culled in the last frame
/// (the cut); flag2 the nodes an upward search passed. A frame walks down from the root through
/// the unflagged nodes above the last cut without testing them; at a flagged node it refines
/// (RENDER below it) when the node is visible and too large, else climbs to the topmost parent
/// that no longer refines, draws that, and marks the way with flag2 so that the walk skips the
/// rest of that parent's subtree. The first frame, and any after reset(), is RENDER from the
/// root.
///
/// Deviations from the pseudo code, each needed for a correct cut: the climb stops at the root
/// (the printed loop has no exit there); a flagged leaf climbs like any other node (the printed
/// code draws it, visible or not, without looking at its parent, so a cut that reached a leaf
/// could never coarsen there again and a parent drawn by a sibling's climb would be drawn over
/// it); the node a climb ends at is flagged as drawn or
/// culled, as RENDER flags its nodes (the text says both procedures set flag1); an unflagged
/// leaf met on the walk (its flag cleared by an earlier climb) is drawn by RENDER. Children are
/// walked in traverse()'s order, so the cut, its order and the image equal traverse()'s.
/// traverse_stats::visited counts the nodes tested (culling and splat size), not the unflagged
/// nodes the walk passes without a test.
template <attributes A>
class pop_flag_traversal {
 public:
  using node_id = typename pop_tree<A>::node_id;

  explicit pop_flag_traversal(const pop_tree<A>& t)
      : t_(&t), flag1_(t.nodes().size(), 0), flag2_(t.nodes().size(), 0) {}

  template <Sink<A> S>
  traverse_stats frame(const view& v, const traverse_options& o, S& sink,
                       const pop_policy& p = {}) {
    st_ = {};
    if (t_->empty()) return st_;
    detail::counting_forwarder<A, S> out{sink};
    frame_state<S> f{v, o, p, out};
    if (first_) {
      render(t_->root(), f);
      first_ = false;
    } else {
      coherency(t_->root(), f);
    }
    st_.points = out.points;
    st_.splats = out.splats;
    st_.triangles = out.triangles;
    return st_;
  }

  /// Forgets the flags: the next frame starts with RENDER from the root.
  void reset() {
    std::fill(flag1_.begin(), flag1_.end(), 0);
    std::fill(flag2_.begin(), flag2_.end(), 0);
    first_ = true;
  }

  /// Nodes currently flagged as drawn or culled in the last frame (for tests).
  [[nodiscard]] bool flagged(node_id n) const { return flag1_[n] != 0; }

 private:
  using state = detail::node_state;

  template <class S>
  struct frame_state {
    const view& v;
    const traverse_options& o;
    const pop_policy& p;
    detail::counting_forwarder<A, S>& out;
  };

  template <class S>
  state test(node_id n, const frame_state<S>& f, float& size) {
    ++st_.visited;
    return detail::evaluate_node(*t_, n, f.v, f.o, f.p, size);
  }

  template <class S>
  void draw(node_id n, float size, const frame_state<S>& f) {
    if (t_->is_leaf(n))
      ++st_.emitted_leaves;
    else
      ++st_.emitted_nodes;
    f.p.emit(*t_, n, f.v, size, f.o, f.out);
  }

  void culled(state s) {
    if (s == state::culled_frustum) ++st_.culled_frustum;
    if (s == state::culled_backface) ++st_.culled_backface;
  }

  /// RENDER(node): the plain traversal below n; flags every node it draws or culls.
  template <class S>
  void render(node_id n, const frame_state<S>& f) {
    float size = 0;
    const state s = test(n, f, size);
    if (s == state::refine) {
      const auto kids = t_->children(n);
      for (auto it = kids.end(); it != kids.begin();) render(*--it, f);  // traverse()'s order
      return;
    }
    flag1_[n] = 1;
    if (s == state::draw)
      draw(n, size, f);
    else
      culled(s);
  }

  /// RENDER-COHERENCY(node).
  template <class S>
  void coherency(node_id n, const frame_state<S>& f) {
    if (!flag1_[n]) {
      if (t_->is_leaf(n)) {
        render(n, f);  // not in the pseudo code: a leaf whose flag a climb cleared
        return;
      }
      flag2_[n] = 0;
      const auto kids = t_->children(n);
      for (auto it = kids.end(); it != kids.begin();) {
        coherency(*--it, f);
        if (flag2_[n]) return;
      }
      return;
    }
    float size = 0;
    const state s = test(n, f, size);
    if (s == state::refine) {
      flag1_[n] = 0;
      render(n, f);
      return;
    }
    // Up (leaves too: see the deviations above) while the parent is culled or no longer refines.
    node_id child = n, current = n;
    state child_state = s;
    float child_size = size;
    for (;;) {
      child = current;
      flag1_[child] = 0;
      current = t_->parent(child);
      if (current == pop_tree<A>::no_node) break;
      float up_size = 0;
      const state up = test(current, f, up_size);
      if (up == state::refine) break;
      flag2_[current] = 1;
      child_state = up;
      child_size = up_size;
    }
    flag1_[child] = 1;
    if (child_state == state::draw)
      draw(child, child_size, f);
    else
      culled(child_state);
  }

  const pop_tree<A>* t_;
  std::vector<std::uint8_t> flag1_, flag2_;
  bool first_ = true;
  traverse_stats st_;
};

}  // namespace pbr_lod
