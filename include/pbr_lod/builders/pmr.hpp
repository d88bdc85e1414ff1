// pbr_lod — PMR: a Voronoi-based hierarchy of points and umbrella triangles per octree leaf.
//
// This work is based on:
//   T. K. Dey, J. Hudson. PMR: Point to Mesh Rendering, a Feature-Based Approach.
//   IEEE Visualization 2002.
//   (the pole, height and radius of a Voronoi cell: N. Amenta, M. Bern. Surface reconstruction by
//   Voronoi filtering. Discrete Comput. Geom. 22, 1999.)
// What each part implements:
//   §2 Spatial decomposition  octree with at most `max_leaf_points` samples per leaf; a 3-D
//               Delaunay triangulation (CGAL) per octree node of at most `triangulation_points`
//               samples (its leaves together) plus every sample of the leaves neighbouring it
//               (the paper's rule); only the node's own samples are written —
//               src/builders/pmr/pmr_build.cpp (octree, gathering, assembly) and
//               src/builders/pmr/pmr_voronoi.cpp (everything CGAL).
//   §2 Point hierarchy  pole (farthest Voronoi vertex; hull cells: direction from the outward
//               hull facet normals), height h, normal estimate, tangent polygon, radius r, and
//               the iterative deletion of samples with r/h < ρ for ρ in `rho`, the Delaunay
//               triangulation updated by CGAL vertex removal — pmr_voronoi.cpp.
//   §2 Triangle hierarchy  the umbrella of p at level i = the Delaunay triangles dual to the
//               Voronoi edges of V_p that the tangent polygon crosses, kept where they lie on
//               the surface: the dual edge meets the cocone of all three vertices (Amenta,
//               Choi, Dey, Leekha 2002, the flatness result the paper cites) and no edge is
//               longer than `edge_spacing` × the local sample spacing — pmr_voronoi.cpp.
//   §2 Records  umbrella radius per sample and level, average umbrella radius per level per
//               leaf, triangles shared by umbrellas stored once per leaf and level; the file
//               (save()/load(), "PBRLODPM" v1) — src/builders/pmr/pmr_io.cpp. Beyond the paper: the
//               input's colours, kept per sample when it has them (pmr_colour_view draws them).
//   §3 Viewing  pixel size at the leaf's corner nearest the eye, the level whose average
//               umbrella radius is closest to factor × pixel size (with the paper's ramp of the
//               factor), point vs umbrella by 2 × umbrella radius vs pixel size, every shared
//               triangle drawn once — pmr_policy with the generic traverse().
//
// Layout. Samples are stored leaf by leaf; inside a leaf, ordered by how many levels they
// survive (most first), so level i of a leaf is a prefix of its samples: P_0 ⊇ P_1 ⊇ … nest by
// construction. Nodes are a flat array in breadth-first order; an inner node's children are
// nodes [first, first + count); a leaf's `first` is its index in leaves(). For leaf ℓ and level
// i, level(ℓ, i) gives the number of samples at that level, their average umbrella radius and
// ranges into triangles() (the level's distinct umbrella triangles, as sample indices) and
// umbrellas() (one entry per sample of the level: its triangles as indices into that range,
// and its umbrella radius). Render rule (§3): a leaf picks one level; each sample of it is a
// point when the pixel is larger than twice its umbrella radius, else its umbrella triangles
// (each triangle once).
//
// Threading: build() processes leaves on up to `options.threads` threads, each leaf's
// triangulation alive only while it is processed. A built pmr_hierarchy is immutable; const
// member functions are safe for concurrent readers.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <ranges>
#include <span>
#include <string>
#include <vector>

#include "pbr_lod/core/attributes.hpp"
#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/traverse/hierarchy.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod {

struct pmr_options {
  /// Samples per octree leaf at most (§2: 8,000–12,000 balance the per-leaf triangulations
  /// against per-leaf overhead when drawing). Smaller leaves: less memory per triangulation,
  /// more neighbour samples triangulated twice.
  std::uint32_t max_leaf_points = 10000;
  /// Depth limit of the octree (guards piles of near-duplicate samples, which no split
  /// separates).
  std::uint32_t max_depth = 21;
  /// Decimation thresholds ρ₁ < ρ₂ < … (§2: 0.1 to 1.0 in steps of 0.1–0.2). Level 0 is the
  /// input; level i keeps the samples whose ratio r/h stayed ≥ ρᵢ under iterative deletion.
  /// At most 31 thresholds, each in (0, 10], strictly increasing.
  std::vector<float> rho = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f, 0.7f, 0.8f, 0.9f, 1.0f};
  /// Samples per Delaunay triangulation at most: the Voronoi work (§2) runs once for the
  /// highest octree node holding at most this many samples — all its leaves in one
  /// triangulation, so a leaf's neighbours inside it are all there, as the paper's halo rule
  /// wants, and an input of at most this many samples gives the whole-cloud result (a leaf
  /// holding more is a triangulation by itself). Not below max_leaf_points in effect.
  std::uint32_t triangulation_points = 1u << 17;
  /// Neighbour samples triangulated with a triangulation's node: those of the leaves within
  /// this fraction of the node's edge length of its cube — with neighbour_leaves, every sample
  /// of every such leaf, so each leaf's triangulation holds all samples of the leaves that
  /// share a face, edge or vertex with it (the paper's rule); else only the samples inside
  /// that margin. The chunked build (builders/chunked_pmr.hpp) takes the margin only.
  float neighbour_margin = 0.1f;
  bool neighbour_leaves = true;
  /// Umbrella triangles only where the surface is (docs/pmr.md, "Umbrellas on the surface"). A
  /// triangle of p's umbrella is kept when its dual Voronoi edge also meets the cocone of its
  /// two other vertices — the points seen within `cocone_degrees` of their tangent planes
  /// (Amenta, Choi, Dey, Leekha 2002: θ = π/8) — so it lies flat for all three, and when its
  /// longest edge is at most `edge_spacing` × the largest local spacing of its vertices (the
  /// distance to a vertex's 4th nearest Delaunay neighbour at that level), so it joins samples
  /// that are neighbours on the surface, not across a gap, a hole or an open boundary. 0 turns
  /// a rule off (both 0: the paper's umbrellas).
  float cocone_degrees = 22.5f;
  float edge_spacing = 3.0f;
  /// When the input has normals: they give the tangent planes of the umbrellas and the
  /// cocones, and are the drawn normals (the pole vector still drives the decimation, §2). A
  /// pole is a poor normal where the sampling is too sparse for the shape (a plate thinner
  /// than the spacing, sparse vertices of a CAD mesh); the input's normal is not. false: the
  /// poles everywhere, the input's normals only orient them (the paper's inputs have none).
  bool input_normals = true;
  /// Threads for the build (0 = hardware concurrency). The output does not depend on it.
  unsigned threads = 0;
  /// Called with the fraction done (0..1) from the calling thread; return false to cancel
  /// (build then throws pbr_lod::Cancelled after the leaves being processed finish; nothing is
  /// returned).
  std::function<bool(double)> progress = {};
};

struct pmr_build_stats {
  double build_seconds = 0;  ///< not stored in the file (files are deterministic): 0 after load
  std::size_t input_points = 0;
  std::size_t duplicates = 0;           ///< samples equal to an earlier one (level 0 only)
  std::size_t triangulated_points = 0;  ///< Σ over leaves of own + neighbour samples
  std::size_t removals = 0;             ///< vertex removals over all leaf triangulations
  std::size_t flat_leaves = 0;          ///< leaves whose triangulation had dimension < 3
  std::size_t hull_points = 0;          ///< own samples with unbounded cells
  friend bool operator==(const pmr_build_stats&, const pmr_build_stats&) = default;
};

namespace detail {

/// One octree node. Children [first, first + count) for an inner node; for a leaf, `first` is
/// its index in the leaf array and count is 0.
struct pmr_node {
  vec3f cell_min = vec3f::Zero();  ///< the octree cell: a cube of edge cell_size (§3 corners)
  float cell_size = 0;
  vec3f centre = vec3f::Zero();  ///< bounding sphere of every primitive the subtree emits
  float radius = 0;
  std::uint32_t first = 0;
  std::uint32_t count = 0;
  std::uint32_t leaf = 0;  ///< 1 for a leaf
  std::uint32_t depth = 0;
  friend bool operator==(const pmr_node&, const pmr_node&) = default;
};

/// One level of one leaf.
struct pmr_level {
  std::uint32_t points = 0;     ///< samples at this level: the leaf's first `points`
  float mean_umbrella = 0;      ///< average umbrella radius over those with an umbrella
  std::uint32_t first_tri = 0;  ///< the level's distinct triangles: triangles[first_tri, +tris)
  std::uint32_t tris = 0;
  std::uint32_t first_entry = 0;  ///< umbrellas[first_entry, + points): one per sample
  friend bool operator==(const pmr_level&, const pmr_level&) = default;
};

/// A sample's umbrella at one level: umbrella_index[first, first + count) are indices into the
/// level's triangle range; radius = largest distance from the sample to their vertices.
struct pmr_umbrella {
  std::uint32_t first = 0;
  std::uint32_t count = 0;
  float radius = 0;
  friend bool operator==(const pmr_umbrella&, const pmr_umbrella&) = default;
};

struct pmr_leaf {
  std::uint32_t first_point = 0;  ///< the leaf's samples: positions[first_point, + point_count)
  std::uint32_t point_count = 0;
  std::uint32_t node = 0;  ///< its node
  friend bool operator==(const pmr_leaf&, const pmr_leaf&) = default;
};

struct pmr_data {
  vec3d origin = vec3d::Zero();
  vec3d input_min = vec3d::Zero(), input_max = vec3d::Zero();  ///< world bounds of the input
  std::uint32_t max_leaf_points = 0;
  float neighbour_margin = 0;
  std::vector<float> rho;             ///< thresholds; levels = rho.size() + 1
  std::vector<vec3f> positions;       ///< relative to origin, leaf by leaf (see layout)
  std::vector<vec3f> normals;         ///< unit, from the level-0 Voronoi diagram (§2 Records)
  std::vector<rgb8> colours;          ///< the input's, per stored sample; empty when it had none
  std::vector<std::uint32_t> source;  ///< input index of each stored sample
  /// A part of a chunked build (builders/chunked_pmr.hpp): the last `foreign` samples are no
  /// leaf's, only vertices of umbrella triangles that reach into other chunks, and source holds
  /// indices into an input of `input_total` points. 0 and 0 for a whole hierarchy.
  std::uint32_t foreign = 0;
  std::uint64_t input_total = 0;
  std::vector<pmr_node> nodes;
  std::vector<pmr_leaf> leaf_list;
  std::vector<pmr_level> levels;  ///< leaf_list.size() × (rho.size() + 1), leaf-major
  std::vector<std::array<std::uint32_t, 3>> triangles;  ///< sample indices (global)
  std::vector<pmr_umbrella> umbrellas;
  std::vector<std::uint32_t> umbrella_index;
  pmr_build_stats stats;  ///< counts are stored; build_seconds is not
  friend bool operator==(const pmr_data& a, const pmr_data& b);
};

// ---- compiled in src/builders/ (CGAL only in pmr_voronoi.cpp)

/// Input of one leaf's Voronoi processing: points[0, own) are the leaf's own samples, the rest
/// its neighbours'; all distinct, in a local frame (the leaf's centre subtracted in double).
struct pmr_cell_input {
  std::span<const vec3d> points;
  std::uint32_t own = 0;
  std::span<const float> rho;
  /// The umbrella rules of pmr_options (0: off).
  float cocone_degrees = 0;
  float edge_spacing = 0;
  /// Empty, or per point a unit normal (zero: none) for the umbrellas' tangent planes and the
  /// cocones in place of the pole vector (pmr_options::input_normals).
  std::span<const vec3d> normals = {};
};

/// What the Voronoi processing finds for the own samples.
struct pmr_cell_output {
  int dimension = 3;                   ///< of the initial triangulation (< 3: no decimation)
  std::vector<std::uint8_t> levels;    ///< per own sample: levels it is in (1 .. rho.size()+1)
  std::vector<vec3d> normal;           ///< per own sample: unit normal estimate at level 0
  std::vector<vec3d> pole;             ///< farthest Voronoi vertex (hull: p − h·n), level 0
  std::vector<double> height, radius;  ///< h and r at level 0 (h = +inf: no finite pole)
  std::vector<std::uint8_t> hull;      ///< 1 when the cell is unbounded
  /// Per level i, per own sample alive at i (in own-index order): its umbrella triangles as
  /// sorted triples of point indices (into points), and its umbrella radius.
  struct level_umbrellas {
    std::vector<std::uint32_t> sample;  ///< own index
    std::vector<std::uint32_t> first;   ///< into tris; size sample.size() + 1
    std::vector<std::array<std::uint32_t, 3>> tris;
    std::vector<double> radius;
  };
  std::vector<level_umbrellas> umbrellas;
  std::size_t removals = 0;
};

/// The Voronoi part of §2 for one leaf (CGAL Delaunay_triangulation_3 with vertex removal).
[[nodiscard]] pmr_cell_output pmr_process_cell(const pmr_cell_input& in);

[[nodiscard]] pmr_data build_pmr_data(const point_cloud& cloud, const pmr_options& options);
void save_pmr_data(const pmr_data& d, const std::string& path);
struct chunked_pmr_access;
[[nodiscard]] pmr_data load_pmr_data(const std::string& path);
[[nodiscard]] std::size_t pmr_file_bytes(const pmr_data& d);

}  // namespace detail

/// The paper's ramp of the tolerance factor (§4): the factor applies unchanged while the pixel
/// is at most 2 units, falls linearly to 1 at 4 units, and is 1 beyond. The unit here is the
/// leaf's level-0 average umbrella radius (the full-detail sampling), which keeps the rule
/// scale-independent as the paper's hierarchy is (docs/pmr.md: deviations).
[[nodiscard]] inline float pmr_ramped_factor(float factor, float pixel_in_units) {
  if (!(pixel_in_units > 2)) return factor;
  if (pixel_in_units >= 4) return 1;
  return factor + (1 - factor) * (pixel_in_units - 2) / 2;
}

class pmr_hierarchy {
 public:
  using node_id = std::uint32_t;
  /// Points and triangles with normals (the estimated normals).
  static constexpr attributes attrs = with_normals;

  pmr_hierarchy() = default;

  // ---- the Hierarchy interface
  [[nodiscard]] vec3d origin() const { return d_.origin; }
  [[nodiscard]] bool empty() const { return d_.nodes.empty(); }
  [[nodiscard]] node_id root() const { return 0; }
  [[nodiscard]] bool is_leaf(node_id n) const { return d_.nodes[n].leaf != 0; }
  [[nodiscard]] auto children(node_id n) const {
    const auto& nd = d_.nodes[n];
    const std::uint32_t end = nd.leaf ? nd.first : nd.first + nd.count;
    return std::views::iota(nd.leaf ? end : nd.first, end);
  }
  [[nodiscard]] sphere bounding_sphere(node_id n) const {
    return {d_.nodes[n].centre, d_.nodes[n].radius};
  }
  /// A leaf: its level and primitives chosen by the paper's rule with factor 1. An inner node
  /// (reached only by traversals that stop above the leaves): every leaf below it the same way.
  /// Primitives carry the attributes Out (with colour: pmr_colour_view).
  template <attributes Out = attrs, class S>
  void emit(node_id n, const view& v, S& sink) const {
    std::vector<node_id> stack{n};
    while (!stack.empty()) {
      const node_id m = stack.back();
      stack.pop_back();
      if (is_leaf(m)) {
        const float ps = pixel_size(m, v);
        emit_level<Out>(d_.nodes[m].first, choose_level(d_.nodes[m].first, ps, 1), ps, sink);
        continue;
      }
      for (node_id c = d_.nodes[m].first + d_.nodes[m].count; c-- > d_.nodes[m].first;)
        stack.push_back(c);
    }
  }

  // ---- §3 viewing, step by step
  /// World size of a pixel at the corner of the node's octree cell nearest the eye (§3).
  [[nodiscard]] float pixel_size(node_id n, const view& v) const {
    return pixel_size_of(d_.nodes[n], v);
  }
  [[nodiscard]] static float pixel_size_of(const detail::pmr_node& nd, const view& v) {
    vec3f corner;
    for (int k = 0; k < 3; ++k)
      corner[k] =
          nd.cell_min[k] + (v.eye[k] > nd.cell_min[k] + 0.5f * nd.cell_size ? nd.cell_size : 0.0f);
    return pixel_size_pmr(v, corner);
  }
  /// The level of leaf `leaf` whose average umbrella radius is closest to factor × pixel size,
  /// the factor ramped (pmr_ramped_factor); ties go to the finer level. A pixel size ≤ 0 (the
  /// corner behind the eye) picks level 0.
  [[nodiscard]] std::uint32_t choose_level(std::uint32_t leaf, float pixel, float factor) const {
    if (!(pixel > 0)) return 0;
    const float u0 = level(leaf, 0).mean_umbrella;
    const float f = u0 > 0 ? pmr_ramped_factor(factor, pixel / u0) : factor;
    const float target = f * pixel;
    std::uint32_t best = 0;
    float best_d = std::numeric_limits<float>::infinity();
    for (std::uint32_t i = 0; i < levels(); ++i) {
      const float u = level(leaf, i).mean_umbrella;
      if (!(u > 0) && i > 0) continue;  // a level without umbrellas has no scale to match
      const float dist = std::abs(u - target);
      if (dist < best_d) {
        best_d = dist;
        best = i;
      }
    }
    return best;
  }
  /// Sends level `lvl` of leaf `leaf`: each sample a point when pixel > 2 × its umbrella radius,
  /// else its umbrella's triangles, each distinct triangle once (§3 RENDER-NODE). Out: the
  /// primitives' attributes (normals; colours only when has_colours()).
  template <attributes Out = attrs, class S>
  void emit_level(std::uint32_t leaf, std::uint32_t lvl, float pixel, S& sink) const {
    const auto& L = level(leaf, lvl);
    const std::uint32_t first = d_.leaf_list[leaf].first_point;
    std::vector<unsigned char> drawn(L.tris, 0);
    for (std::uint32_t k = 0; k < L.points; ++k) {
      const auto& u = d_.umbrellas[L.first_entry + k];
      const std::uint32_t s = first + k;
      if (u.count == 0 || pixel > 2 * u.radius) {
        point_prim<Out> p{d_.positions[s], 1};
        p.normal = d_.normals[s];
        if constexpr (Out.colour) p.colour = d_.colours[s];
        sink.point(p);
        continue;
      }
      for (std::uint32_t j = u.first; j < u.first + u.count; ++j) {
        const std::uint32_t t = d_.umbrella_index[j];
        if (drawn[t]) continue;
        drawn[t] = 1;
        const auto& T = d_.triangles[L.first_tri + t];
        triangle_prim<Out> tri{{d_.positions[T[0]], d_.positions[T[1]], d_.positions[T[2]]}};
        tri.normal = {d_.normals[T[0]], d_.normals[T[1]], d_.normals[T[2]]};
        if constexpr (Out.colour)
          tri.colour = {d_.colours[T[0]], d_.colours[T[1]], d_.colours[T[2]]};
        sink.triangle(tri);
      }
    }
  }

  /// The leaf index of leaf node n (for choose_level and emit_level).
  [[nodiscard]] std::uint32_t leaf_of(node_id n) const { return d_.nodes[n].first; }

  // ---- inspection
  [[nodiscard]] std::uint32_t levels() const {
    return static_cast<std::uint32_t>(d_.rho.size() + 1);
  }
  [[nodiscard]] const std::vector<float>& rho() const { return d_.rho; }
  [[nodiscard]] std::size_t leaf_count() const { return d_.leaf_list.size(); }
  [[nodiscard]] const detail::pmr_leaf& leaf(std::uint32_t l) const { return d_.leaf_list[l]; }
  [[nodiscard]] const detail::pmr_level& level(std::uint32_t leaf, std::uint32_t i) const {
    return d_.levels[static_cast<std::size_t>(leaf) * levels() + i];
  }
  [[nodiscard]] const std::vector<detail::pmr_node>& nodes() const { return d_.nodes; }
  [[nodiscard]] const std::vector<vec3f>& positions() const { return d_.positions; }
  [[nodiscard]] const std::vector<vec3f>& normals() const { return d_.normals; }
  /// The input's colours, one per stored sample, when it had colours; else empty.
  [[nodiscard]] const std::vector<rgb8>& colours() const { return d_.colours; }
  [[nodiscard]] bool has_colours() const { return !d_.colours.empty(); }
  /// Input index of each stored sample (a permutation of the input).
  [[nodiscard]] const std::vector<std::uint32_t>& source() const { return d_.source; }
  [[nodiscard]] const std::vector<std::array<std::uint32_t, 3>>& triangles() const {
    return d_.triangles;
  }
  [[nodiscard]] const std::vector<detail::pmr_umbrella>& umbrellas() const { return d_.umbrellas; }
  [[nodiscard]] const std::vector<std::uint32_t>& umbrella_index() const {
    return d_.umbrella_index;
  }
  [[nodiscard]] vec3d input_min() const { return d_.input_min; }
  [[nodiscard]] vec3d input_max() const { return d_.input_max; }
  [[nodiscard]] std::uint32_t max_leaf_points() const { return d_.max_leaf_points; }
  [[nodiscard]] float neighbour_margin() const { return d_.neighbour_margin; }
  [[nodiscard]] const pmr_build_stats& stats() const { return d_.stats; }
  /// A chunk of a chunked build (builders/chunked_pmr.hpp): its last foreign() samples are other
  /// chunks' (umbrella vertices only), and source() indexes an input of input_total() points.
  [[nodiscard]] std::uint32_t foreign() const { return d_.foreign; }
  [[nodiscard]] std::uint64_t input_total() const { return d_.input_total; }
  /// Samples over all leaves at level i.
  [[nodiscard]] std::size_t points_at_level(std::uint32_t i) const {
    std::size_t n = 0;
    for (std::uint32_t l = 0; l < leaf_count(); ++l) n += level(l, i).points;
    return n;
  }
  /// Distinct umbrella triangles over all leaves at level i (a triangle used by two leaves is
  /// stored by each: leaves may be drawn at different levels).
  [[nodiscard]] std::size_t triangles_at_level(std::uint32_t i) const {
    std::size_t n = 0;
    for (std::uint32_t l = 0; l < leaf_count(); ++l) n += level(l, i).tris;
    return n;
  }
  [[nodiscard]] std::size_t file_bytes() const { return detail::pmr_file_bytes(d_); }

  // ---- storage
  /// Writes the versioned file ("PBRLODPM" v1); throws IoError. load(save(h)) == h exactly.
  void save(const std::string& path) const { detail::save_pmr_data(d_, path); }
  /// Maps the file (mmap) and reads it with every count, offset and index validated before use,
  /// then a checksum; throws IoError (cannot open) or FormatError naming the element at fault.
  [[nodiscard]] static pmr_hierarchy load(const std::string& path) {
    pmr_hierarchy h;
    h.d_ = detail::load_pmr_data(path);
    return h;
  }
  friend bool operator==(const pmr_hierarchy& a, const pmr_hierarchy& b) { return a.d_ == b.d_; }

 private:
  friend pmr_hierarchy build_pmr(const point_cloud&, const pmr_options&);
  friend struct detail::chunked_pmr_access;
  detail::pmr_data d_;
};

static_assert(Hierarchy<pmr_hierarchy>);

/// A pmr_hierarchy whose primitives also carry the input's colours (it must have them:
/// has_colours()): the same nodes, levels and primitives as the hierarchy, for pmr_policy or any
/// other. Holds a pointer to the hierarchy, which must outlive it.
class pmr_colour_view {
 public:
  using node_id = pmr_hierarchy::node_id;
  static constexpr attributes attrs = with_normals_colours;

  /// Throws InvalidArgument when h has no colours.
  explicit pmr_colour_view(const pmr_hierarchy& h) : h_(&h) {
    if (!h.has_colours()) throw InvalidArgument("pmr: the hierarchy has no colours");
  }
  [[nodiscard]] vec3d origin() const { return h_->origin(); }
  [[nodiscard]] bool empty() const { return h_->empty(); }
  [[nodiscard]] node_id root() const { return h_->root(); }
  [[nodiscard]] bool is_leaf(node_id n) const { return h_->is_leaf(n); }
  [[nodiscard]] auto children(node_id n) const { return h_->children(n); }
  [[nodiscard]] sphere bounding_sphere(node_id n) const { return h_->bounding_sphere(n); }
  template <class S>
  void emit(node_id n, const view& v, S& sink) const {
    h_->emit<attrs>(n, v, sink);
  }
  // What pmr_policy uses besides the Hierarchy interface.
  [[nodiscard]] const std::vector<detail::pmr_node>& nodes() const { return h_->nodes(); }
  [[nodiscard]] float pixel_size(node_id n, const view& v) const { return h_->pixel_size(n, v); }
  [[nodiscard]] std::uint32_t leaf_of(node_id n) const { return h_->leaf_of(n); }
  [[nodiscard]] std::uint32_t choose_level(std::uint32_t leaf, float pixel, float factor) const {
    return h_->choose_level(leaf, pixel, factor);
  }
  template <class S>
  void emit_level(std::uint32_t leaf, std::uint32_t lvl, float pixel, S& sink) const {
    h_->emit_level<attrs>(leaf, lvl, pixel, sink);
  }
  [[nodiscard]] const pmr_hierarchy& hierarchy() const { return *h_; }

 private:
  const pmr_hierarchy* h_;
};

static_assert(Hierarchy<pmr_colour_view>);

/// Builds the PMR hierarchy of a point cloud from its positions (§2); its colours, when it has
/// them, are kept per sample (pmr_colour_view), its normals only orient the estimated ones. Throws
/// InvalidArgument on empty input, NaN/Inf coordinates, more than 2³² − 2 samples or bad
/// options; Cancelled when the progress callback says so.
[[nodiscard]] inline pmr_hierarchy build_pmr(const point_cloud& cloud,
                                             const pmr_options& options = {}) {
  pmr_hierarchy h;
  h.d_ = detail::build_pmr_data(cloud, options);
  return h;
}

/// PMR's viewing (§3) as a policy of the generic traversal: descend to every leaf the frustum
/// keeps (RENDER), and at a leaf pick the level from the pixel size at its nearest corner with
/// factor = traverse_options::tolerance_px (ramped), then points or umbrellas per sample
/// (RENDER-NODE). `levels_used`, when set, receives the level chosen per leaf (for Fig. 7).
struct pmr_policy : default_policy {
  template <class H>
  [[nodiscard]] bool refine(const H& h, const typename H::node_id& n, float /*size_px*/,
                            const traverse_options& /*o*/) const {
    return !h.is_leaf(n);
  }
  template <class H, class S>
  void emit(const H& h, const typename H::node_id& n, const view& v, float /*size_px*/,
            const traverse_options& o, S& sink) const {
    if (!h.is_leaf(n)) {
      h.emit(n, v, sink);
      return;
    }
    const std::uint32_t leaf = h.leaf_of(n);
    const float ps = h.pixel_size(n, v);
    const std::uint32_t lvl = h.choose_level(leaf, ps, o.tolerance_px);
    if (levels_used) (*levels_used)[leaf] = lvl;
    h.emit_level(leaf, lvl, ps, sink);
  }
  std::vector<std::uint32_t>* levels_used = nullptr;
};

}  // namespace pbr_lod
