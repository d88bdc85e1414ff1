// pbr_lod — the order in which traverse() visits a whole tree. Frame-coherent traversals (POP's,
// the PCA octree's cut) keep a cut across frames and must still emit it in the order a fresh
// traverse() would, so they rank every node once by that order.
#pragma once

#include <vector>

#include "pbr_lod/traverse/hierarchy.hpp"

namespace pbr_lod {

/// rank[n] = the position of node n in traverse()'s order over the whole tree, for a policy
/// that keeps the hierarchy's child order: traverse() pops a node, then pushes its children in
/// order, i.e. pre-order with the children reversed. on_child(parent, child) sees every edge
/// once. rank must hold an entry for every node id reached from the root.
template <Hierarchy H, class Rank, class OnChild>
void traversal_ranks(const H& h, std::vector<Rank>& rank, OnChild&& on_child) {
  if (h.empty()) return;
  std::vector<typename H::node_id> stack{h.root()};
  Rank next = 0;
  while (!stack.empty()) {
    const auto m = stack.back();
    stack.pop_back();
    rank[m] = next++;
    for (const auto c : h.children(m)) {
      on_child(m, c);
      stack.push_back(c);
    }
  }
}

template <Hierarchy H, class Rank>
void traversal_ranks(const H& h, std::vector<Rank>& rank) {
  traversal_ranks(h, rank, [](const auto&, const auto&) {});
}

}  // namespace pbr_lod
