// The parts of the Gaussian hierarchy's build (gaussian_build.cpp) that its chunked build
// (gaussian_chunked.cpp) repeats above the chunks, so that both give the same bytes: the tree's
// shape, the median split and the moment-matching merge. Internal to src/builders.
#pragma once

#include <cstdint>
#include <map>
#include <span>

#include "pbr_lod/builders/gaussian_hierarchy.hpp"

namespace pbr_lod::detail {

/// Leaves (and so inner nodes, one fewer) of a subtree over c Gaussians: memoised, since the
/// sizes on one level take at most two values. A range of c Gaussians splits into ⌊c/2⌋ and
/// ⌈c/2⌉, so the shape depends on the count alone.
class gaussian_tree_shape {
 public:
  explicit gaussian_tree_shape(std::uint32_t leaf_size) : leaf_size_(leaf_size) {}
  std::uint32_t leaves(std::uint32_t c) {
    if (c <= leaf_size_) return 1;
    const auto it = memo_.find(c);
    if (it != memo_.end()) return it->second;
    const std::uint32_t l = leaves(c / 2) + leaves(c - c / 2);
    memo_.emplace(c, l);
    return l;
  }
  /// Read-only after every size reachable from the root has been memoised (leaves(n) once).
  [[nodiscard]] std::uint32_t leaves_known(std::uint32_t c) const {
    return c <= leaf_size_ ? 1 : memo_.at(c);
  }
  [[nodiscard]] std::uint32_t leaf_size() const { return leaf_size_; }

 private:
  std::uint32_t leaf_size_;
  std::map<std::uint32_t, std::uint32_t> memo_;
};

/// A Gaussian as the median splits see it: its mean, its 3σ reach (3 × its largest scale) and its
/// input index, side by side so that the splits stream through one array instead of gathering
/// from the input's.
struct gaussian_split_key {
  vec3f p;
  float reach;
  std::uint32_t g;
};

/// Kerbl et al. 2024 §4.1's split: puts the ⌊c/2⌋ Gaussians of `keys` (c of them) lowest along
/// the longest axis of their 3σ box first (ties by input index, so the split is a function of the
/// set alone, not of its order).
void split_at_median(std::span<gaussian_split_key> keys);

/// Moment-matches the Gaussians of `g` at `parts` (Kerbl et al. 2024 eqs. 2–4, the opacity rule
/// of gaussian_hierarchy.hpp) into slot `slot` of `g`.
void merge_gaussians(gaussian_cloud& g, std::span<const std::uint32_t> parts, std::size_t slot,
                     merged_opacity opacity);

/// The sphere holding a and b.
[[nodiscard]] sphere enclose(const sphere& a, const sphere& b);
/// Gaussian i's 3σ sphere.
[[nodiscard]] inline sphere gaussian_reach(const gaussian_cloud& g, std::size_t i) {
  return {g.positions[i], 3 * g.scales[i].maxCoeff()};
}

}  // namespace pbr_lod::detail
