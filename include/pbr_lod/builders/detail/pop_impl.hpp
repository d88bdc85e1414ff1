// pbr_lod — POP coherent traversal (implementation of builders/pop.hpp; the builder and the file
// format are compiled in src/builders/pop_build.cpp).
#pragma once

#include <algorithm>

namespace pbr_lod {

template <attributes A>
pop_coherent_traversal<A>::pop_coherent_traversal(const pop_tree<A>& t) : t_(&t) {
  const std::size_t n = t.nodes().size();
  rank_.assign(n, 0);
  stamp_.assign(n, 0);
  added_.assign(n, 0);
  state_.assign(n, draw);
  size_.assign(n, 0);
  if (n == 0) return;
  traversal_ranks(t, rank_);  // orders any cut as the plain traversal emits it
}

template <attributes A>
auto pop_coherent_traversal<A>::eval(node_id n, const view& v, const traverse_options& o,
                                     const pop_policy& p, float& size) -> state {
  ++st_.visited;
  const sphere s = t_->bounding_sphere(n);
  if (o.frustum_cull) {
    if (o.cull_volume == traverse_options::volume::view_cone) {
      if (outside_view_cone(v, s)) return culled_frustum;
    } else if (frustum_test(v, s, 0x3f) < 0) {
      return culled_frustum;
    }
  }
  if (o.backface_cull && back_facing(s, t_->normal_cone(n), v.eye)) return culled_backface;
  size = p.screen_size(*t_, n, s, v, o);
  return p.refine(*t_, n, size, o) ? refine : draw;
}

template <attributes A>
auto pop_coherent_traversal<A>::cached(node_id n, const view& v, const traverse_options& o,
                                       const pop_policy& p) -> state {
  if (stamp_[n] != frame_) {
    stamp_[n] = frame_;
    state_[n] = eval(n, v, o, p, size_[n]);
  }
  return state_[n];
}

template <attributes A>
void pop_coherent_traversal<A>::add(node_id n, state s) {
  if (added_[n] == frame_) return;
  added_[n] = frame_;
  next_.push_back(n);
  if (s == culled_frustum) ++st_.culled_frustum;
  if (s == culled_backface) ++st_.culled_backface;
}

template <attributes A>
void pop_coherent_traversal<A>::descend(node_id f, const view& v, const traverse_options& o,
                                        const pop_policy& p) {
  std::vector<node_id> stack{f};
  while (!stack.empty()) {
    const node_id n = stack.back();
    stack.pop_back();
    const state s = cached(n, v, o, p);
    if (s == refine)
      for (const node_id c : t_->children(n)) stack.push_back(c);
    else
      add(n, s);
  }
}

template <attributes A>
template <Sink<A> S>
traverse_stats pop_coherent_traversal<A>::frame(const view& v, const traverse_options& o, S& sink,
                                                const pop_policy& p) {
  st_ = {};
  drawn_.clear();
  if (t_->empty()) return st_;
  if (++frame_ == 0) {  // stamps wrapped: forget them all
    std::fill(stamp_.begin(), stamp_.end(), 0u);
    std::fill(added_.begin(), added_.end(), 0u);
    frame_ = 1;
  }
  next_.clear();
  if (front_.empty()) {
    descend(t_->root(), v, o, p);  // RENDER(root)
  } else {
    for (const node_id f : front_) {
      if (added_[f] == frame_) continue;
      if (cached(f, v, o, p) == refine) {  // down: RENDER(f)
        descend(f, v, o, p);
        continue;
      }
      // Up: while the parent need not refine any more, the parent replaces the node. A parent
      // that refines has ancestors that all refine (monotone rule), so the search stops there.
      node_id a = f;
      for (node_id q = t_->parent(a); q != pop_tree<A>::no_node; q = t_->parent(a)) {
        if (cached(q, v, o, p) == refine) break;
        a = q;
      }
      add(a, state_[a]);
    }
  }
  for (const node_id n : next_)
    if (state_[n] == draw) drawn_.push_back(n);
  std::sort(drawn_.begin(), drawn_.end(),
            [&](node_id a, node_id b) { return rank_[a] < rank_[b]; });
  detail::counting_forwarder<A, S> out{sink};
  for (const node_id n : drawn_) {
    if (t_->is_leaf(n))
      ++st_.emitted_leaves;
    else
      ++st_.emitted_nodes;
    p.emit(*t_, n, v, size_[n], o, out);
  }
  st_.points = out.points;
  st_.splats = out.splats;
  st_.triangles = out.triangles;
  front_.swap(next_);
  return st_;
}

}  // namespace pbr_lod
