// pbr_lod — point-octree with generic homogeneous covariance and bounding elliptical splats.
//
// This work is based on:
//   R. Pajarola. Efficient Level-of-Details for Point Based Rendering. CGIM 2003.
// What each part implements:
//   §3, Fig. 3  top-down point-octree: split at the mean of a node's samples; one linear pass per
//               node partitions into octants and accumulates the children's average position,
//               normal and colour, the bounding-sphere radius about the mean and the normal-cone
//               semi-angle about the mean normal.
//   §4, EQ 2–4  generic homogeneous covariance M̄ = Σ p̂p̂ᵀ at the leaves, summed bottom-up
//               (Fig. 4), covariance in the tangent frame by n⁻¹·R·T·M̄·Tᵀ·Rᵀ
//               (covariance_method::generic_float / generic_double); the default is the
//               numerically stable pairwise merge (covariance_method::stable; see
//               core/covariance.hpp and docs/point-octree.md for why and how far the paper's
//               formulation drifts).
//   EQ 5–6      tangent-plane 2×2 covariance, its eigenvalues and eigenvectors as the ellipse
//               axes, scaled by f so the ellipse covers every child disk's oriented bounding box
//               (Fig. 6b; for a leaf, every sample's disk).
//   §4 end      splat ellipses of the input from its k nearest neighbours when it has none, and
//               normals from the same k-NN covariance (consistently oriented) when it has none.
//   §5, Fig. 9  normals and ellipse axes quantised to q bits (octant + (k²+k)/2 table).
//   §5, Table 2 node and sample records; save()/load() of a versioned, validated file.
//   §6, Fig. 10–11 LOD selection: view-cone culling, normal-cone back-face culling, projected
//               area A·d²/|(c−e)·w|² with the tilt factor cos(γ−θ) against τ — point_octree_policy.
//
// Threading: build() uses up to `options.threads` threads over the root's subtrees. A built
// point_octree is immutable; const member functions are safe for concurrent readers.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <numbers>
#include <optional>
#include <ranges>
#include <string>
#include <thread>
#include <vector>

#include "pbr_lod/core/attributes.hpp"
#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/memory.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/traverse/hierarchy.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod {

/// How node covariances are accumulated (Pajarola §4).
enum class covariance_method {
  stable,          ///< ours (default): centred scatter in double, Chan et al.'s pairwise merge
  generic_double,  ///< the paper's EQ 2–4 in world coordinates, summed in double
  generic_float,   ///< the paper's EQ 2–4 in world coordinates, summed in float
};

/// What the eigenvalues λ₁ ≥ λ₂ of the tangent covariance give before the scale f (EQ 5–6).
enum class ellipse_axis_rule {
  sqrt_eigenvalue,  ///< ours (default): a' = √λ₁, b' = √λ₂ — the standard deviations
  eigenvalue,       ///< the paper's text: a' = λ₁, b' = λ₂ (more elongated before scaling)
};

struct point_octree_options {
  /// Maximum samples per leaf. The paper's node stores the count in an unsigned char; small
  /// leaves give finer LOD steps, larger ones fewer nodes (docs: nodes per point vs leaf size).
  std::uint32_t leaf_size = 8;
  /// Depth limit: a node at this depth becomes a leaf whatever its size (guards adversarial
  /// inputs such as points on a geometric progression, which the mean split peels one by one).
  std::uint32_t max_depth = 48;
  covariance_method covariance = covariance_method::stable;
  ellipse_axis_rule axis_rule = ellipse_axis_rule::sqrt_eigenvalue;
  /// Ours, not the paper's: draw a node with its corners' bounding circle when that is smaller
  /// than the scaled EQ 5–6 ellipse or the ellipse's major axis exceeds the circle's diameter.
  /// false keeps the paper's ellipse wherever it is finite (both bound every child disk);
  /// docs/point-octree.md measures the two.
  bool circle_guard = true;
  /// Quantise normals and ellipse axes to this many bits (§5, Fig. 9); 0 keeps float vectors.
  /// 16 bits: worst error well under 1° (docs/normal-quantization.md).
  int normal_bits = 16;
  /// Neighbours for the PCA normal of a sample when the input has no normals (§4 end).
  int knn = 16;
  /// Neighbours each estimated splat ellipse bounds when the input has no ellipses (§4 end).
  /// The ellipse covers them, so it grows with k: 12 is the smallest k that leaves no gaps on a
  /// randomly sampled plane (8 leaves 0.15 % uncovered; docs/normal-quantization.md), while 16
  /// inflates every splat, and through the conservative bounding of Fig. 6b every node above.
  int knn_ellipses = 12;
  /// Where the scanner stood, in world coordinates: estimated normals are turned to face it (one
  /// parallel pass) instead of being made consistent over the k-NN graph (core/estimation.hpp).
  std::optional<vec3d> viewpoint = std::nullopt;
  /// Threads for the build, the normal and ellipse estimation included (0 = hardware
  /// concurrency).
  unsigned threads = 0;
  /// Called with the fraction done (0..1); return false to cancel (build() then throws
  /// pbr_lod::Cancelled and nothing is returned). May be called from the calling thread only.
  std::function<bool(double)> progress = {};
};

/// The attribute set of a point-octree built from input attributes `in`: normals and ellipses
/// always (estimated when absent), colour when the input has it, no material.
[[nodiscard]] constexpr attributes point_octree_attributes(attributes in) {
  return {.normal = true, .colour = in.colour, .material = false, .ellipse = true};
}

struct point_octree_build_stats {
  /// Whether the timings below were measured by this build; a loaded file has none (its bytes
  /// depend only on the input and the options, so two builds compare equal).
  bool has_timings = false;
  double seconds = 0;             ///< whole build, including estimation
  double estimation_seconds = 0;  ///< normals + splat ellipses from k-NN (0 when given)
  double tree_seconds = 0;        ///< octree + covariances + bounding ellipses
  std::size_t input_points = 0;
  std::size_t nodes = 0, leaves = 0, max_depth = 0;
  bool estimated_normals = false, estimated_ellipses = false;
  /// Input normals that were zero or not finite — "no normal" (3DGS files store zeros) — and
  /// were estimated from the positions (fill_missing_normals). Measured by the build; a loaded
  /// file reports 0.
  std::size_t normals_filled = 0;
  /// Nodes drawn with the bounding circle of their corners (point_octree::is_circle): where
  /// fit_ellipse's guard replaced the EQ 5–6 ellipse, and where the tangent covariance is round
  /// (λ₁ = λ₂), whose EQ 5–6 ellipse is that circle. Counted on the stored nodes, so a loaded
  /// file reports the same number as the build that wrote it.
  std::size_t circle_fallbacks = 0;
};

namespace detail {
template <attributes A>
struct point_octree_builder;
template <attributes A>
struct point_octree_io;
template <attributes In>
struct chunked_point_octree_builder;
}  // namespace detail
template <attributes A>
class chunked_point_octree;

template <attributes A>
class point_octree {
  static_assert(A.normal && A.ellipse && !A.material,
                "use point_octree<point_octree_attributes(input attributes)>");

 public:
  using node_id = std::uint32_t;
  /// Primitives: elliptical splats with normals (+ colour).
  static constexpr attributes attrs = {.normal = true, .colour = A.colour};

  /// One node (Fig. 7–8 merged into a flat record): the representative splat of its subtree and
  /// the bounds for culling. Render this node's splat when it is small enough on screen,
  /// otherwise its children (inner) or its samples (leaf).
  struct node {
    vec3f centre;         ///< p̄_c, mean of the subtree's samples — the split point (§3)
    float radius;         ///< bounding sphere about centre: samples and every splat drawn below
    vec3f normal;         ///< n̄_c, unit mean normal
    float cone_angle;     ///< θ_c, normal-cone semi-angle about n̄_c in radians (π = unbounded)
    vec3f axis_u;         ///< a·e₁, major semi-axis of the bounding elliptical disk e_c
    vec3f axis_v;         ///< b·e₂, minor semi-axis (⟂ axis_u, ⟂ normal)
    std::uint32_t first;  ///< inner: index of the first child; leaf: first sample
    std::uint32_t count;  ///< inner: children (1..8, contiguous); leaf: samples (contiguous)
    std::uint8_t leaf;    ///< 1 for a leaf
    std::uint8_t depth;   ///< root = 0
    friend bool operator==(const node&, const node&) = default;
  };

  /// With quantisation, per node and per sample: the table indices of the normal and the major
  /// axis and the two axis lengths, from which the stored vectors are derived (by the builder and
  /// again, bit for bit, by load()).
  struct orientation_code {
    std::uint32_t normal, axis;
    float a, b;
    friend bool operator==(const orientation_code&, const orientation_code&) = default;
  };

  point_octree() = default;

  // ---- the Hierarchy interface
  [[nodiscard]] vec3d origin() const { return samples_.origin; }
  [[nodiscard]] bool empty() const { return nodes_.empty(); }
  [[nodiscard]] node_id root() const { return 0; }
  [[nodiscard]] bool is_leaf(node_id n) const { return nodes_[n].leaf != 0; }
  [[nodiscard]] auto children(node_id n) const {
    const node& nd = nodes_[n];
    const std::uint32_t end = nd.leaf ? nd.first : nd.first + nd.count;
    return std::views::iota(nd.first, end);
  }
  [[nodiscard]] sphere bounding_sphere(node_id n) const {
    return {nodes_[n].centre, nodes_[n].radius};
  }
  [[nodiscard]] pbr_lod::normal_cone normal_cone(node_id n) const {
    return {nodes_[n].normal, nodes_[n].cone_angle};
  }
  /// The same cone with cos θ_c and sin θ_c from selection(n): back-face culling without
  /// trigonometry (§6).
  [[nodiscard]] pbr_lod::normal_cone_cs normal_cone_cs(node_id n) const {
    return {nodes_[n].normal, selection_[n].cos_cone, selection_[n].sin_cone};
  }
  /// Inner node: its bounding elliptical splat. Leaf: one splat per sample (full detail).
  template <class S>
  void emit(node_id n, const view&, S& sink) const {
    const node& nd = nodes_[n];
    if (!nd.leaf) {
      emit_node_splat(n, sink);
      return;
    }
    for (std::uint32_t i = nd.first; i < nd.first + nd.count; ++i) {
      splat_prim<attrs> s{samples_.positions[i], samples_.axis_u[i], samples_.axis_v[i]};
      s.normal = samples_.normals[i];
      if constexpr (A.colour) s.colour = samples_.colours[i];
      sink.splat(s);
    }
  }

  /// The node's own bounding elliptical splat e_c (for a leaf too: point_octree_policy draws a
  /// leaf this way when its splat is within the tolerance, as the paper selects any node).
  template <class S>
  void emit_node_splat(node_id n, S& sink) const {
    const node& nd = nodes_[n];
    splat_prim<attrs> s{nd.centre, nd.axis_u, nd.axis_v};
    s.normal = nd.normal;
    if constexpr (A.colour) s.colour = node_colours_[n];
    sink.splat(s);
  }
  /// The node as a one-pixel point at its mean, with its normal and colour.
  template <class S>
  void emit_node_point(node_id n, S& sink) const {
    point_prim<attrs> p{nodes_[n].centre, 1.0f};
    p.normal = nodes_[n].normal;
    if constexpr (A.colour) p.colour = node_colours_[n];
    sink.point(p);
  }

  // ---- inspection
  [[nodiscard]] const std::vector<node>& nodes() const { return nodes_; }
  [[nodiscard]] const node& at(node_id n) const { return nodes_[n]; }
  /// The samples, reordered so that every leaf's are contiguous.
  [[nodiscard]] const point_set<A>& samples() const { return samples_; }
  [[nodiscard]] rgb8 node_colour(node_id n) const requires(A.colour) { return node_colours_[n]; }
  [[nodiscard]] elliptical_disk disk(node_id n) const {
    const node& nd = nodes_[n];
    return {nd.centre, nd.normal, nd.axis_u, nd.axis_v};
  }
  [[nodiscard]] int normal_bits() const { return normal_bits_; }
  /// Whether node n's bounding ellipse is a circle (its axes equal to 10⁻⁶; the stored vectors
  /// differ in length by the rounding of unit e₁ and n × e₁ only): fit_ellipse()'s guard replaced
  /// the EQ 5–6 ellipse by the corners' bounding circle, or the tangent covariance is round
  /// (λ₁ = λ₂ to ≈ 10⁻⁶: a one-sample leaf with a circular disk, a symmetric grid), when the
  /// EQ 5–6 ellipse scaled to the farthest corner is that same circle and rounding alone decides
  /// whether the guard fires.
  [[nodiscard]] bool is_circle(node_id n) const {
    const float a = nodes_[n].axis_u.norm(), b = nodes_[n].axis_v.norm();
    return std::abs(a - b) <= 1e-6f * std::max(a, b);
  }
  /// The number of nodes for which is_circle() holds (stats().circle_fallbacks).
  [[nodiscard]] std::size_t count_circles() const {
    std::size_t c = 0;
    for (node_id n = 0; n < nodes_.size(); ++n) c += is_circle(n) ? 1 : 0;
    return c;
  }

  /// What LOD selection (§6) needs of a node beyond its geometry, derived once after build and
  /// load so the per-frame test needs no trigonometry: the disk's area A_e = π·a·b and the
  /// cosine and sine of the cone semi-angle θ_c.
  struct selection_record {
    float area;
    float cos_cone, sin_cone;
  };
  [[nodiscard]] const selection_record& selection(node_id n) const { return selection_[n]; }
  [[nodiscard]] static selection_record make_selection(const node& nd) {
    return {std::numbers::pi_v<float> * nd.axis_u.norm() * nd.axis_v.norm(),
            std::cos(nd.cone_angle), std::sin(nd.cone_angle)};
  }
  [[nodiscard]] const point_octree_build_stats& stats() const { return stats_; }
  /// Bytes the hierarchy occupies in memory (nodes, samples, codes), excluding vector slack.
  [[nodiscard]] std::size_t memory_bytes() const;

  // ---- storage (§5, Table 2)
  /// Writes the versioned file; throws IoError. Quantised normals and axes are written as their
  /// table indices, everything else as stored, so load(save(h)) == h exactly.
  void save(const std::string& path) const;
  /// Reads and validates a file written by save(): magic, version, attribute set, every count,
  /// index and range against the file size and the tree, finite values, and a checksum. Throws
  /// FormatError naming the element at fault.
  [[nodiscard]] static point_octree load(const std::string& path);
  /// Size in bytes of the file save() writes.
  [[nodiscard]] std::size_t file_bytes() const;

  friend bool operator==(const point_octree& a, const point_octree& b) { return a.equal(b); }

 private:
  friend struct detail::point_octree_builder<A>;
  friend struct detail::point_octree_io<A>;
  template <attributes In>
  friend struct detail::chunked_point_octree_builder;
  friend class chunked_point_octree<A>;
  [[nodiscard]] bool equal(const point_octree& o) const;
  void derive_selection(unsigned threads = resolve_threads(0)) {
    detail::resize_fresh(selection_, nodes_.size(), std::max(1u, threads));
    detail::parallel_chunks(nodes_.size(), std::max(1u, threads), 1u << 15,
                            [&](std::size_t lo, std::size_t hi) {
                              for (std::size_t i = lo; i < hi; ++i)
                                selection_[i] = make_selection(nodes_[i]);
                            });
  }

  std::vector<node> nodes_;
  [[no_unique_address]] detail::maybe<A.colour, std::vector<rgb8>, 0> node_colours_{};
  point_set<A> samples_;
  int normal_bits_ = 0;
  std::vector<orientation_code> node_codes_, sample_codes_;
  std::vector<selection_record> selection_;  // derived from nodes_ (not saved, not compared)
  point_octree_build_stats stats_;
};

/// Builds the point-octree of `points` (any attribute set: normals and splat ellipses are
/// estimated from k nearest neighbours when absent). Throws InvalidArgument on empty input or
/// non-finite coordinates, Cancelled when the progress callback says so.
template <attributes In>
[[nodiscard]] point_octree<point_octree_attributes(In)> build_point_octree(
    const point_set<In>& points, const point_octree_options& options = {});

/// Pajarola's screen-projection tolerance (§6, Fig. 11) as a traversal policy: the projected
/// area of a node's elliptical disk is A_screen = cos(γ − θ_c)·A_e·d²/|(c − e)·w|², with A_e = πab,
/// d the focal length in pixels, w the viewing direction, γ the angle between the disk normal
/// and the direction to the eye, θ_c the normal-cone semi-angle (cos = 1 while γ ≤ θ_c). The
/// tolerance τ is compared with the diameter of the circle of that area, 2·√(A_screen/π), so that
/// τ keeps its meaning of "pixels across" shared by every policy.
struct point_octree_policy : default_policy {
  template <class H>
  [[nodiscard]] float screen_size(const H& h, const typename H::node_id& n, const sphere& s,
                                  const view& v, const traverse_options&) const {
    const auto& nd = h.at(n);
    const auto& sel = h.selection(n);
    const vec3f ce = s.centre - v.eye;
    const float depth = ce.dot(v.forward);
    if (depth <= s.radius) return std::numeric_limits<float>::infinity();  // eye plane reached
    const float dist = ce.norm();
    const float cos_gamma = std::min(1.0f, std::abs(nd.normal.dot(ce)) / std::max(dist, 1e-30f));
    // cos(γ − θ_c) = cos γ·cos θ_c + sin γ·sin θ_c once γ > θ_c (cos γ < cos θ_c), else 1.
    float tilt = 1;
    if (cos_gamma < sel.cos_cone) {
      const float sin_gamma = std::sqrt(std::max(0.0f, 1 - cos_gamma * cos_gamma));
      tilt = cos_gamma * sel.cos_cone + sin_gamma * sel.sin_cone;
    }
    const float a_screen = tilt * sel.area * v.focal_px * v.focal_px / (depth * depth);
    return 2 * std::sqrt(std::max(0.0f, a_screen) / std::numbers::pi_v<float>);
  }
  /// A node within the tolerance draws its own splat e_c — a leaf too; a leaf still larger than
  /// the tolerance draws its samples. A whole model smaller than a pixel (the root drawn below
  /// one pixel) draws the pixel it falls in: a lone sample or exact duplicates have no spacing
  /// to size a splat (the estimate is a 10⁻⁶ floor), which would cover no pixel centre and
  /// vanish; render_reference draws such samples one pixel across too.
  template <class H, class S>
  void emit(const H& h, const typename H::node_id& n, const view& v, float size_px,
            const traverse_options& o, S& sink) const {
    if (n == h.root() && size_px < 1)
      h.emit_node_point(n, sink);
    else if (h.is_leaf(n) && !(size_px <= o.tolerance_px))
      h.emit(n, v, sink);
    else
      h.emit_node_splat(n, sink);
  }
};

}  // namespace pbr_lod

#include "pbr_lod/builders/detail/point_octree_impl.hpp"
#include "pbr_lod/builders/detail/point_octree_io.hpp"

namespace pbr_lod {
// The builder and the file code are compiled once, in src/builders/point_octree_instances.cpp,
// for every input attribute set a point set can have (any mix of normal, colour, ellipse); a
// program that builds or loads point-octrees does not compile the builder again in each file.
#define PBR_LOD_POINT_OCTREE_BUILD(EXTERN, NORMAL, COLOUR, ELLIPSE)                         \
  EXTERN template point_octree<point_octree_attributes(                                     \
      attributes{.normal = NORMAL, .colour = COLOUR, .ellipse = ELLIPSE})>                  \
  build_point_octree<attributes{.normal = NORMAL, .colour = COLOUR, .ellipse = ELLIPSE}>(   \
      const point_set<attributes{.normal = NORMAL, .colour = COLOUR, .ellipse = ELLIPSE}>&, \
      const point_octree_options&);
#define PBR_LOD_POINT_OCTREE_CLASS(EXTERN, COLOUR) \
  EXTERN template class point_octree<point_octree_attributes(attributes{.colour = COLOUR})>;

PBR_LOD_POINT_OCTREE_CLASS(extern, false)
PBR_LOD_POINT_OCTREE_CLASS(extern, true)
PBR_LOD_POINT_OCTREE_BUILD(extern, false, false, false)
PBR_LOD_POINT_OCTREE_BUILD(extern, true, false, false)
PBR_LOD_POINT_OCTREE_BUILD(extern, false, true, false)
PBR_LOD_POINT_OCTREE_BUILD(extern, true, true, false)
PBR_LOD_POINT_OCTREE_BUILD(extern, false, false, true)
PBR_LOD_POINT_OCTREE_BUILD(extern, true, false, true)
PBR_LOD_POINT_OCTREE_BUILD(extern, false, true, true)
PBR_LOD_POINT_OCTREE_BUILD(extern, true, true, true)

// The common interface (traverse/hierarchy.hpp): render, stats and tests drive it like any other.
static_assert(Hierarchy<point_octree<point_octree_attributes(positions_only)>>);
static_assert(Hierarchy<point_octree<point_octree_attributes(attributes{.colour = true})>>);
}  // namespace pbr_lod
