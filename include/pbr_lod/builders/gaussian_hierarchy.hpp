// pbr_lod — level-of-detail hierarchies of 3-D Gaussians (Kerbl et al. 2024, "A Hierarchical 3D
// Gaussian Representation for Real-Time Rendering of Very Large Datasets", ACM TOG 43(4)).
//
// Input: a gaussian_cloud (core/gaussians.hpp; io/gaussians.hpp reads 3DGS .ply, .splat, .spz).
// Paper → code (docs/gaussian-hierarchy.md has the full table):
//   §4.1 hierarchy generation   a binary tree by recursive median splits of the Gaussians' means
//                               along the longest axis of their 3σ boxes (the authors' k-d tree
//                               generator); leaves hold `leaf_size` Gaussians (theirs: one; ours:
//                               two).
//   §4.1 merging (eqs. 2–4)     an inner node is one Gaussian moment-matched from its children's:
//                               weights w_i ∝ o_i · S(s_i), S the surface proxy s₀s₁ + s₀s₂ + s₁s₂;
//                               μ = Σ w_i μ_i, Σ = Σ w_i (Σ_i + (μ_i − μ)(μ_i − μ)ᵀ), the SH
//                               coefficients averaged with the same weights; scales and rotation
//                               from Σ's eigen-decomposition (right-handed).
//   opacity                     the weighted opacity-area Σ o_i S(s_i) is conserved. Where the
//                               children overlap it exceeds the merged Gaussian's S(s): by
//                               default the Gaussian grows (s·√o, opacity 1), a valid 3DGS
//                               Gaussian that exports as drawn; merged_opacity::conserve keeps
//                               o = Σ o_i S(s_i) / S(s) > 1 as the paper does (the rasteriser's
//                               α ≤ 0.99 makes it flat-topped; an exported cut has it clamped).
//   §4.2 cut                    the node's projected size (pixels) against the tolerance: size =
//                               2 · the projected radius of its largest standard deviation, made
//                               monotone (a node is at least as large as its children), so the
//                               cut is the one traversal of traverse/traverse.hpp with
//                               gaussian_policy.
// Degenerate input stays finite: zero weights (zero scales or opacities) fall back to equal
// weights; a merged Gaussian of zero size takes its most opaque child's opacity; the eigen-
// decomposition runs in double on origin-relative positions (scans 10⁷ units away keep their
// precision).
//
// The hierarchy stores every Gaussian once as a gaussian_cloud: the input's, reordered so each
// leaf's are contiguous, then one per inner node in preorder. Nodes are numbered in preorder
// (the left child of inner node n is n + 1). File: "PBRLODGH" version 1 (save/load, whole or not
// at all; every count, index and value validated on load).
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "pbr_lod/core/attributes.hpp"
#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/gaussians.hpp"
#include "pbr_lod/traverse/primitives.hpp"
#include "pbr_lod/traverse/screen_size.hpp"
#include "pbr_lod/traverse/sink.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod {
namespace detail {
struct byte_writer;  // core/binary.hpp
}  // namespace detail

/// Where a merged Gaussian's children overlap, its conserved opacity-area Σ oᵢS(sᵢ) exceeds its
/// own surface S(s) (docs/gaussian-hierarchy.md measures both rules).
enum class merged_opacity {
  grow,  ///< opacity 1 and the scales × √(Σ oᵢS(sᵢ) / S(s)): every node a valid 3DGS Gaussian
  conserve,  ///< o = Σ oᵢS(sᵢ) / S(s) > 1, the paper's (a 3DGS file cannot store it)
};

struct gaussian_hierarchy_options {
  /// Gaussians per leaf, 1–64. 1 is the paper's: one merged Gaussian per input Gaussian, a
  /// hierarchy 2.27 × its input (SH degree 3, nodes included). 2 (the default) drops only the
  /// merges of single pairs: about 0.6 merged Gaussians per input one (1.74 ×), the same
  /// Gaussians in every cut that draws a node above the pairs, a quarter less to build
  /// (docs/gaussian-hierarchy.md).
  int leaf_size = 2;
  merged_opacity opacity = merged_opacity::grow;
  unsigned threads = 0;  ///< 0 = every core (core/parallel.hpp)
};

struct gaussian_hierarchy_stats {
  std::size_t input = 0;  ///< Gaussians in the input
  std::size_t inner = 0;  ///< merged Gaussians (one per inner node)
  std::size_t nodes = 0;  ///< inner nodes and leaves
  std::size_t depth = 0;  ///< edges on the longest root-to-leaf path
  double seconds = 0;     ///< wall time of the build
};

namespace detail {

/// Gaussian i of `g` as a primitive (its covariance from `scale` and its rotation).
[[nodiscard]] inline gaussian_prim gaussian_at(const gaussian_cloud& g, std::size_t i,
                                               const vec3f& scale) {
  return {g.positions[i], gaussian_covariance(scale, g.rotations[i]), g.opacities[i], g.sh_degree,
          g.sh.data() + i * g.sh_stride()};
}
/// Gaussian i of `g` as a primitive (its covariance from its scale and rotation).
[[nodiscard]] inline gaussian_prim gaussian_at(const gaussian_cloud& g, std::size_t i) {
  return gaussian_at(g, i, g.scales[i]);
}

/// `scale` with its two largest axes widened by `lowpass_px2` square pixels at depth `z` of a
/// view with focal length `focal_px`: s → √(s² + lowpass · (z / focal)²), the smallest axis (the
/// normal of a flat Gaussian) kept (gaussian_policy::merged_lowpass_px2 says why). Unchanged for
/// lowpass ≤ 0 or a Gaussian at or behind the eye.
[[nodiscard]] inline vec3f widened_scale(const vec3f& scale, float z, float focal_px,
                                         float lowpass_px2) {
  if (!(lowpass_px2 > 0) || !(z > 0) || !(focal_px > 0)) return scale;
  const float w = z / focal_px, add = lowpass_px2 * w * w;
  int small = 0;
  for (int k = 1; k < 3; ++k)
    if (scale[k] < scale[small]) small = k;
  vec3f out = scale;
  for (int k = 0; k < 3; ++k)
    if (k != small) out[k] = std::sqrt(scale[k] * scale[k] + add);
  return out;
}
/// The scale Gaussian i of `g` is drawn with in v: widened by `lowpass_px2` (widened_scale, at
/// its depth in v), or as stored.
[[nodiscard]] inline vec3f drawn_scale(const gaussian_cloud& g, std::size_t i, const view& v,
                                       float lowpass_px2) {
  return lowpass_px2 > 0
             ? widened_scale(g.scales[i], v.to_eye(g.positions[i]).z(), v.focal_px, lowpass_px2)
             : g.scales[i];
}

/// Gaussian i of `g` as an ellipse splat: its two largest axes at 2σ (as_splat_prim), its normal
/// the axis of its smallest scale with the sign its rotation gives it (for a mesh's or a scan's
/// Gaussians the surface normal; merged ones keep their children's side), its colour the
/// view-independent one.
[[nodiscard]] inline splat_prim<attributes{.normal = true, .colour = true}> gaussian_splat(
    const gaussian_cloud& g, std::size_t i, const vec3f& sc) {
  constexpr attributes a{.normal = true, .colour = true};
  const vec4f& q = g.rotations[i];
  const Eigen::Matrix3f r = Eigen::Quaternionf(q[0], q[1], q[2], q[3]).toRotationMatrix();
  int small = 0;
  for (int k = 1; k < 3; ++k)
    if (sc[k] < sc[small]) small = k;
  const int a1 = (small + 1) % 3, a2 = (small + 2) % 3;
  const int big = sc[a1] >= sc[a2] ? a1 : a2, mid = big == a1 ? a2 : a1;
  splat_prim<a> out = as_splat_prim<a>(gaussian_at(g, i, sc));  // the colour
  out.u = r.col(big) * (2 * sc[big]);
  out.v = r.col(mid) * (2 * sc[mid]);
  out.normal = r.col(small);
  return out;
}
[[nodiscard]] inline splat_prim<attributes{.normal = true, .colour = true}> gaussian_splat(
    const gaussian_cloud& g, std::size_t i) {
  return gaussian_splat(g, i, g.scales[i]);
}

/// Gaussians [first, first + count) of `g` to `sink`: gaussian_prim to a GaussianSink
/// (raster/gaussians.hpp; the z-buffer rasteriser, which draws it as below), gaussian_splat() of
/// each to any other sink — or, where that ellipse covers less than a pixel on the screen, a
/// one-pixel point (a Gaussian rasteriser's low-pass still draws such a Gaussian as a dot; an
/// ellipse that small, or seen edge on, would cover no pixel centre). `lowpass_px2` > 0 widens
/// each one's large axes first (widened_scale; the cut's merged Gaussians, gaussian_policy).
template <class S>
void emit_gaussians(const gaussian_cloud& g, std::uint32_t first, std::uint32_t count,
                    const view& v, S& sink, float lowpass_px2 = 0) {
  constexpr attributes a{.normal = true, .colour = true};
  for (std::uint32_t i = first; i < first + count; ++i) {
    const vec3f sc = drawn_scale(g, i, v, lowpass_px2);
    if constexpr (GaussianSink<S>) {
      sink.gaussian(gaussian_at(g, i, sc));
    } else {
      const splat_prim<a> s = gaussian_splat(g, i, sc);
      const float z = v.to_eye(s.centre).z();
      const float k = z > 0 ? v.focal_px / z : 0.0f;
      const vec3f ray = (s.centre - v.eye).normalized();
      const float pixels = 3.14159265f * k * k * std::abs(s.u.cross(s.v).dot(ray));
      if (!(pixels >= 1.0f))
        sink.point(point_prim<a>{s.centre, 1.0f, s.normal, s.colour});
      else
        sink.splat(s);
    }
  }
}

/// The Gaussians a node draws: [first, first + count) of *cloud.
struct gaussian_range {
  const gaussian_cloud* cloud = nullptr;
  std::uint32_t first = 0, count = 0;
};

}  // namespace detail

struct gaussian_policy;

class gaussian_hierarchy {
 public:
  using node_id = std::uint32_t;
  /// Sinks without gaussian() get splats with colours (as_splat_prim).
  static constexpr attributes attrs{.normal = true, .colour = true};

  struct node {
    std::uint32_t gaussian = 0;  ///< leaf: its first Gaussian; inner: its merged Gaussian
    std::uint32_t count = 0;     ///< leaf: its Gaussians (≥ 1); inner: 0
    std::uint32_t right = 0;     ///< inner: the right child (the left is this node + 1)
    float size = 0;              ///< largest standard deviation in the subtree's cut (world)
    sphere bounds;               ///< holds every Gaussian of the subtree to 3σ
  };

  /// The children of a node: none, or n + 1 and right.
  struct child_range {
    std::array<node_id, 2> ids{};
    std::uint32_t n = 0;
    [[nodiscard]] const node_id* begin() const { return ids.data(); }
    [[nodiscard]] const node_id* end() const { return ids.data() + n; }
  };

  [[nodiscard]] vec3d origin() const { return g_.origin; }
  [[nodiscard]] int sh_degree() const { return g_.sh_degree; }
  [[nodiscard]] bool empty() const { return nodes_.empty(); }
  [[nodiscard]] node_id root() const { return 0; }
  [[nodiscard]] bool is_leaf(node_id n) const { return nodes_[n].count != 0; }
  [[nodiscard]] child_range children(node_id n) const {
    if (is_leaf(n)) return {};
    return {{n + 1, nodes_[n].right}, 2};
  }
  [[nodiscard]] sphere bounding_sphere(node_id n) const { return nodes_[n].bounds; }

  /// An inner node sends its merged Gaussian, its large axes widened by `merged_lowpass_px2`
  /// (gaussian_policy), a leaf its own as stored (detail::emit_gaussians).
  template <class S>
  void emit(node_id n, const view& v, S& sink, float merged_lowpass_px2 = 0) const {
    const node& d = nodes_[n];
    detail::emit_gaussians(g_, d.gaussian, d.count == 0 ? 1 : d.count, v, sink,
                           d.count == 0 ? merged_lowpass_px2 : 0.0f);
  }

  /// Gaussian i as an ellipse splat (detail::gaussian_splat).
  [[nodiscard]] splat_prim<attrs> splat_of(std::size_t i) const {
    return detail::gaussian_splat(g_, i);
  }
  /// Gaussian i of the store as a primitive (its covariance from scale and rotation).
  [[nodiscard]] gaussian_prim prim(std::size_t i) const { return detail::gaussian_at(g_, i); }

  /// The sphere the cut measures (gaussian_policy): the node's size about its Gaussian's mean.
  [[nodiscard]] sphere size_sphere(node_id n) const {
    return {g_.positions[nodes_[n].gaussian], nodes_[n].size};
  }
  /// The Gaussians node n draws: a leaf's, or its merged one.
  [[nodiscard]] detail::gaussian_range gaussians(node_id n) const {
    const node& d = nodes_[n];
    return {&g_, d.gaussian, d.count == 0 ? 1 : d.count};
  }

  [[nodiscard]] const std::vector<node>& nodes() const { return nodes_; }
  /// Every Gaussian stored: the input's (leaf order), then the inner nodes' (preorder).
  [[nodiscard]] const gaussian_cloud& store() const { return g_; }
  [[nodiscard]] std::size_t input_gaussians() const { return input_; }
  [[nodiscard]] std::size_t inner_gaussians() const { return g_.size() - input_; }
  /// Edges on the longest root-to-leaf path.
  [[nodiscard]] std::size_t depth() const;

  /// The Gaussians a traversal of v with `o` and `p` draws, as a cloud in the hierarchy's frame,
  /// merged ones widened as `p` draws them for v: what `pbrlod export` writes as a standard 3DGS
  /// file, which any 3DGS renderer then draws as the cut's frame.
  [[nodiscard]] gaussian_cloud cut(const view& v, const traverse_options& o,
                                   const gaussian_policy& p) const;
  [[nodiscard]] gaussian_cloud cut(const view& v, const traverse_options& o) const;
  /// The view-independent cut at tree depth `level`: every node at that depth, and every leaf
  /// above it (level 0: the root's Gaussian; a level at or beyond depth(): the input).
  [[nodiscard]] gaussian_cloud level(std::size_t level) const;

  void save(const std::string& path) const;
  /// Throws IoError or FormatError (naming the element at fault).
  [[nodiscard]] static gaussian_hierarchy load(const std::string& path);
  [[nodiscard]] std::vector<unsigned char> serialize() const;
  [[nodiscard]] static gaussian_hierarchy parse(const std::vector<unsigned char>& bytes,
                                                const std::string& path);
  [[nodiscard]] std::size_t file_bytes() const;
  /// Equal when their files would be.
  friend bool operator==(const gaussian_hierarchy& a, const gaussian_hierarchy& b) {
    return a.serialize() == b.serialize();
  }

 private:
  friend class chunked_gaussian_hierarchy;  // assemble()
  friend gaussian_hierarchy build_gaussian_hierarchy(const gaussian_cloud&,
                                                     const gaussian_hierarchy_options&,
                                                     gaussian_hierarchy_stats*);
  /// The file's bytes but its checksum into w, calling flush() whenever w holds about 1 MiB.
  void serialize_into(detail::byte_writer& w, const std::function<void()>& flush) const;

  gaussian_cloud g_;
  std::size_t input_ = 0;
  std::vector<node> nodes_;
};

/// Builds the hierarchy (Kerbl et al. 2024 §4.1). The same input and options give the same
/// hierarchy and file bytes whatever the thread count. Throws InvalidArgument for an empty
/// input, one that does not validate() or has more than 2³¹ Gaussians, or a leaf_size outside
/// 1–64.
[[nodiscard]] gaussian_hierarchy build_gaussian_hierarchy(
    const gaussian_cloud& input, const gaussian_hierarchy_options& options = {},
    gaussian_hierarchy_stats* stats = nullptr);

/// The cut of Kerbl et al. 2024 §4.2: a node's screen size is twice the projected radius of a
/// sphere of its `size` about its Gaussian's mean; refine while that exceeds the tolerance. For
/// gaussian_hierarchy and chunked_gaussian_hierarchy (builders/chunked_gaussian_hierarchy.hpp).
struct gaussian_policy {
  /// Square pixels added to the variance of a merged Gaussian's two large axes (in its own
  /// plane, at its depth) when the cut draws it; 0 (the default, the paper's) draws it as
  /// stored. For Gaussians made from a mesh or a scan (flat discs that tile a surface): the
  /// full render draws the leaves beneath, each widened by the rasteriser's low-pass (0.3 px²,
  /// Kerbl et al. 2023), and their union covers its region to the edges, while one moment-
  /// matched Gaussian of a few pixels fades out before its neighbours begin and the background
  /// shows through a lattice of gaps; 1 closes them (+8 dB on the bunny's Gaussians from 10
  /// radii). Trained scenes, whose Gaussians overlap many times over, lose by it (−6 dB on the
  /// donut): docs/gaussian-hierarchy.md has the table. A leaf's Gaussians are drawn as stored.
  float merged_lowpass_px2 = 0.0f;

  template <class H>
  [[nodiscard]] float screen_size(const H& h, typename H::node_id n, const sphere&, const view& v,
                                  const traverse_options& o) const {
    return 2 * projected_radius(o.metric, v, h.size_sphere(n));
  }
  template <class H>
  [[nodiscard]] bool refine(const H& h, typename H::node_id n, float size_px,
                            const traverse_options& o) const {
    return !h.is_leaf(n) && size_px > o.tolerance_px;
  }
  template <class H, class S>
  void emit(const H& h, typename H::node_id n, const view& v, float, const traverse_options&,
            S& sink) const {
    h.emit(n, v, sink, merged_lowpass_px2);
  }
};

}  // namespace pbr_lod
