// The Gaussian hierarchies' cuts as plain Gaussian clouds (what `pbrlod export` writes) and
// their depth, written once for gaussian_hierarchy and chunked_gaussian_hierarchy: anything with
// the Hierarchy interface, size_sphere() and gaussians(). Internal to src/builders.
#pragma once

#include <cstddef>
#include <utility>
#include <vector>

#include "pbr_lod/builders/gaussian_hierarchy.hpp"

namespace pbr_lod::detail {

/// The Gaussians of the given nodes (their leaves' or their merged ones), in that order; with a
/// view, merged ones widened by `lowpass_px2` as gaussian_policy draws them there.
template <class H>
gaussian_cloud gather_gaussians(const H& h, const std::vector<typename H::node_id>& ids,
                                const view* v = nullptr, float lowpass_px2 = 0) {
  gaussian_cloud out;
  out.origin = h.origin();
  out.sh_degree = h.sh_degree();
  const std::size_t stride = out.sh_stride();
  for (const auto n : ids) {
    const gaussian_range r = h.gaussians(n);
    const gaussian_cloud& s = *r.cloud;
    const bool widen = v != nullptr && !h.is_leaf(n);
    for (std::uint32_t i = r.first; i < r.first + r.count; ++i) {
      out.positions.push_back(s.positions[i]);
      out.scales.push_back(widen ? drawn_scale(s, i, *v, lowpass_px2) : s.scales[i]);
      out.rotations.push_back(s.rotations[i]);
      out.opacities.push_back(s.opacities[i]);
      out.sh.insert(out.sh.end(), s.sh.begin() + static_cast<std::ptrdiff_t>(i * stride),
                    s.sh.begin() + static_cast<std::ptrdiff_t>((i + 1) * stride));
    }
  }
  return out;
}

/// gaussian_policy, recording the nodes it emits.
template <class Id>
struct recording_gaussian_policy : gaussian_policy {
  std::vector<Id>* ids;
  template <class H, class S>
  void emit(const H&, Id n, const view&, float, const traverse_options&, S&) const {
    ids->push_back(n);
  }
};

/// The Gaussians a traversal of v with `o` and `policy` draws, as it draws them.
template <class H>
gaussian_cloud gaussian_cut(const H& h, const view& v, const traverse_options& o,
                            const gaussian_policy& policy) {
  std::vector<typename H::node_id> ids;
  counting_sink<H::attrs> none;
  recording_gaussian_policy<typename H::node_id> p;
  static_cast<gaussian_policy&>(p) = policy;
  p.ids = &ids;
  (void)traverse(h, v, o, none, p);
  return gather_gaussians(h, ids, &v, policy.merged_lowpass_px2);
}

/// Every node at depth `level` and every leaf above it, in preorder.
template <class H>
gaussian_cloud gaussian_level(const H& h, std::size_t level) {
  std::vector<typename H::node_id> ids;
  if (!h.empty()) {
    std::vector<std::pair<typename H::node_id, std::size_t>> stack{{h.root(), 0}};
    std::vector<typename H::node_id> kids;
    while (!stack.empty()) {
      const auto [n, d] = stack.back();
      stack.pop_back();
      if (h.is_leaf(n) || d == level) {
        ids.push_back(n);
        continue;
      }
      kids.clear();
      for (const auto c : h.children(n)) kids.push_back(c);
      for (auto it = kids.rbegin(); it != kids.rend(); ++it) stack.push_back({*it, d + 1});
    }
  }
  return gather_gaussians(h, ids);
}

/// Edges on the longest root-to-leaf path.
template <class H>
std::size_t gaussian_depth(const H& h) {
  if (h.empty()) return 0;
  std::size_t deepest = 0;
  std::vector<std::pair<typename H::node_id, std::size_t>> stack{{h.root(), 0}};
  while (!stack.empty()) {
    const auto [n, d] = stack.back();
    stack.pop_back();
    deepest = std::max(deepest, d);
    for (const auto c : h.children(n)) stack.push_back({c, d + 1});
  }
  return deepest;
}

}  // namespace pbr_lod::detail
