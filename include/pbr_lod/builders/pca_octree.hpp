// pbr_lod — hierarchical PCA octree with randomised rendering ("statistical point geometry").
//
// This work is based on:
//   A. Kalaiah, A. Varshney. Statistical Point Geometry. Eurographics Symposium on Geometry
//   Processing (SGP) 2003.
// What each part implements (code in src/builders/pca_octree_*.cpp unless said otherwise):
//   §3          top-down octree until a node holds at most leaf_size points; per node an
//               independent PCA of position (μ_p, f_p, σ_p), of the normals on the unit sphere
//               (rotate the mean normal to +z, unwrap to the tangent plane at the pole, 2-D PCA:
//               f_n, σ_n) and of colour (μ_c, f_c, σ_c) when the scene has colour; the
//               degenerate rules (σ floor 1e-15; two zero variances keep the principal direction
//               and align z with the mean normal; three use the normal and any tangent pair);
//               extent γ·σ_p with γ = 3.5; curvature scale λ (see pca_octree_options).
//               pca_octree_build.cpp. Not in the paper (docs/pca-octree.md, deviations): what a
//               node's points span (pca_node::extent, normal_extent, pca_colour::extent) bounds
//               every generated value; small nodes of two surfaces are split on (§6's remedy).
//   §3.1, Fig 5 k-means over σ_p, σ_n, σ_c (codebook sizes are options, the paper uses 64–4096),
//               12/12/6-bit indices; μ_p in 32 bits (10-11-11 over the node's octree cell),
//               f_p as the f_p³ axis (16 bits) and a rotation about it (8 bits), f_n likewise
//               (24 bits), μ_c 5-6-5, f_c 7 + 3 bits: 13 bytes a node, 17 with colour.
//               pca_octree_quantise.cpp; the file format in pca_octree_io.cpp.
//   §4          randomised rendering (pca_generator::paper): the paper's trivariate Box–Muller
//               generator for position and colour, the 2-D one for normals, truncated at γ and
//               at the span; a·ln a + c·a points for the span's projected area a, c = 0.2. The
//               default (pca_generator::span) spreads tangential positions uniformly over the
//               span on a low-discrepancy sequence, at most node_points points a node, grown to
//               cover, each with the node's mean normal and colour (pca_attribute_draw::mean;
//               sampled as printed with pca_attribute_draw::sampled). Seeded per (seed, node,
//               point), so the same seed gives the same points in any traversal order.
//               pca_octree_render.cpp (generation) and emit() below (to the Sink).
//   Fig. 6      view-dependent cut kept across frames: pca_octree_cut (split, merge with merge
//               counters and time stamps, normal-cone culling).
//
// Layout: a flat node array in breadth-first order. An inner node's children are contiguous
// [first, first + count), one per non-empty octant in octant order (bit 0 = +x half, 1 = +y,
// 2 = +z), all after it. Every node, inner or leaf, is drawn the same way: randomly generated
// points from its statistics. Refine a node while it needs more than split_points points.
//
// Threading: build() uses up to `options.threads` threads; the result does not depend on how
// many. A built pca_octree is immutable; const member functions are safe for concurrent
// readers. pca_octree_cut holds per-frame state and is for one thread.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <numbers>
#include <ranges>
#include <span>
#include <string>
#include <vector>

#include "pbr_lod/core/attributes.hpp"
#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/traverse/hierarchy.hpp"
#include "pbr_lod/traverse/ranks.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod {

struct pca_octree_options {
  /// A node with more than this many points is split (§3: "terminating at nodes which have
  /// less than a user-specified number of points"). Larger leaves: fewer nodes, coarser finest
  /// level.
  std::uint32_t leaf_size = 8;
  /// Depth limit; a node at this depth is a leaf whatever its size. Guards duplicates and
  /// adversarial inputs; 21 levels already split a cell below float resolution of its root.
  std::uint32_t max_depth = 21;
  /// γ (§3): generated positions, normals and colours are truncated at γ·σ; 3.5 σ holds more
  /// than 99.7 % of a Gaussian.
  float gamma = 3.5f;
  /// c of the curvature scale λ = c·√(σ_n¹/‖σ_p‖) (§3). The paper's λ has units of
  /// length^-1/2 and gives no c; ours measures ‖σ_p‖ in units of the root's ‖σ_p‖ so that λ
  /// does not depend on the model's scale, and clamps λ to [1, lambda_max] so that a flat
  /// patch (σ_n¹ = 0) keeps its ellipsoid instead of collapsing to a point. 0 turns λ off
  /// (λ = 1).
  float curvature_c = 1.0f;
  float lambda_max = 2.0f;
  /// A node of at most leaf_size points is still split (down to max_depth) while two of its
  /// normals differ by more than this angle (degrees; measured against the node's first
  /// normal): such a node holds two surfaces (the sides of a thin sheet, two surfaces close
  /// together, a crease), and one ellipsoid would bridge them. §6 of the paper names the
  /// problem and suggests separating "spatial- and normal-coherent parts"; 180 turns it off.
  /// 20 by default: a leaf is one plane and (drawn with its mean attributes) one normal, so a
  /// leaf that bends further shows as a facet on curved models (docs/pca-octree.md: 60 → 20
  /// gains 0.5–2 dB against the input's render for a fifth more nodes).
  float surface_angle = 20.0f;
  /// The same for colours: a node of at most leaf_size points is still split while one of its
  /// colours lies farther than this from its first point's (RGB in [0, 1], Euclidean), so a leaf
  /// does not average across a colour edge (a checkerboard's tiles, a texture's features) into a
  /// colour none of its points has. 2 (beyond the RGB cube's diagonal, the default) turns it
  /// off: 0.2 gains the hard-cases scene 0.5 dB but draws 5.4 points a covered pixel instead of
  /// 4.2 (its smaller leaves), beyond the ~4 the point budget aims at.
  float colour_tolerance = 2.0f;
  /// Classify and quantise the nodes (§3.1): 13 bytes a node (17 with colour). false keeps the
  /// float statistics (for measuring what quantisation costs; 120 bytes a node, 184 with colour).
  bool quantise = true;
  /// k-means codebook sizes (§3.1; the paper uses 64–4096). Indices take 12, 12 and 6 bits, so
  /// at most 4096, 4096 and 64.
  std::uint32_t position_codebook = 1024;
  std::uint32_t normal_codebook = 1024;
  std::uint32_t colour_codebook = 64;
  /// Lloyd iterations after k-means++ seeding; the clustering runs on a seeded sample of at most
  /// kmeans_sample nodes, then every node takes its nearest codebook entry. k-means++ costs
  /// sample × codebook distance evaluations per codebook: 16 k × 1024 keeps it a fraction of
  /// the build (65 k made it a third of a 1 M-point build).
  std::uint32_t kmeans_iterations = 8;
  std::uint32_t kmeans_sample = 1u << 14;
  std::uint64_t kmeans_seed = 1;
  /// Neighbours for the PCA normal of a sample when the input has no normals (core/estimation).
  int knn = 16;
  /// Threads for the build, the normal estimation included (0 = hardware concurrency). The file
  /// does not depend on it.
  unsigned threads = 0;
  /// Called with the fraction done (0..1); return false to cancel (build throws Cancelled).
  std::function<bool(double)> progress = {};
};

/// Primitive attributes of a PCA octree built from input attributes `in`: normals always
/// (estimated from k nearest neighbours when absent), colour when the input has it.
[[nodiscard]] constexpr attributes pca_octree_attributes(attributes in) {
  return {.normal = true, .colour = in.colour};
}

struct pca_octree_build_stats {
  // Timings exist only on the object build() returned: the file holds none (deterministic
  // bytes), so a loaded hierarchy reports them as absent (has_timings == false).
  bool has_timings = false;
  double seconds = 0;             ///< whole build
  double estimation_seconds = 0;  ///< k-NN normals (0 when the input had normals)
  double tree_seconds = 0;        ///< octree + per-node PCA
  double kmeans_seconds = 0;      ///< classification (§3.1 k-means) of σ_p, σ_n, σ_c
  double quantise_seconds = 0;    ///< encoding + decoding of the node records
  std::size_t input_points = 0;
  std::size_t nodes = 0, leaves = 0, max_depth = 0;
  bool estimated_normals = false;
  /// Input normals that were zero or not finite (no normal), estimated from the positions
  /// (fill_missing_normals). Measured by the build; a loaded file reports 0.
  std::size_t normals_filled = 0;
  // What quantisation cost (build only; 0 without quantisation). Positions relative to the
  // node's octree cell edge, angles in degrees, σ errors relative to the node's σ_p¹.
  double max_mean_error_cell = 0;        ///< max |μ_p − μ_p'|∞ / cell edge
  double max_axis_error_deg = 0;         ///< max angle between f_p^i and its decoded axis (±)
  double mean_sigma_p_error = 0;         ///< mean |σ_p − σ_p'|∞ / σ_p¹
  double mean_sigma_n_error_deg = 0;     ///< mean |σ_n − σ_n'|∞
  double max_normal_axis_error_deg = 0;  ///< max angle between mean normal and decoded one
};

/// One node, decoded (what the renderer uses). Positions relative to the hierarchy's origin.
struct pca_node {
  vec3f mean = vec3f::Zero();  ///< μ_p
  /// f_p: columns f¹, f², f³, right-handed; f³ is the direction of least variance (≈ normal).
  mat3f frame = mat3f::Identity();
  vec3f sigma = vec3f::Zero();  ///< σ_p: standard deviations along f¹..f³, σ¹ ≥ σ² ≥ σ³ ≥ 1e-15
  /// f_n: column 2 the mean normal, columns 0 and 1 the normal ellipse's axes.
  mat3f normal_frame = mat3f::Identity();
  vec2f normal_sigma = vec2f::Zero();  ///< σ_n in radians on the unwrapped tangent plane
  float lambda = 1;                    ///< curvature scale λ (derived from σ_n, σ_p)
  /// What the node's points span (generation never leaves it): half-extents about `mean` along
  /// f¹, f², f³. A leaf's are its points' largest |f^k·(p − μ_p)|, the tangential ones (f¹, f²)
  /// widened by half the points' spacing (each point stands for the patch around it, as in the
  /// input's own render); an inner node's hold its children's boxes. At least 1e-15.
  vec3f extent = vec3f::Zero();
  /// Largest angle (radians) between a normal of the node and its mean normal (an inner node:
  /// over its children's cones). Generated normals stay within it.
  float normal_extent = 0;
  // ---- structure
  std::uint32_t first = 0;  ///< inner: first child; leaf: 0
  std::uint8_t count = 0;   ///< inner: children (1..8); leaf: 0
  std::uint8_t mask = 0;    ///< octants holding a child (bit o = octant o); 0 for a leaf
  std::uint8_t depth = 0;   ///< root = 0
  // ---- derived after build and load (not stored)
  vec3d cell_min = vec3d::Zero();  ///< the node's octree cell (μ_p is quantised within it)
  double cell_size = 0;
  float radius = 0;      ///< about `mean`: holds every point the subtree generates
  float cone_angle = 0;  ///< about the mean normal: holds every normal the subtree generates
  friend bool operator==(const pca_node&, const pca_node&) = default;
};

/// Colour statistics of a node (μ_c, f_c, σ_c; RGB in [0, 1]).
struct pca_colour {
  vec3f mean = vec3f::Zero();
  mat3f frame = mat3f::Identity();
  vec3f sigma = vec3f::Zero();
  /// Largest distance of a colour of the node from `mean` (an inner node: over its children's
  /// balls). Generated colours stay within it.
  float extent = 0;
  friend bool operator==(const pca_colour&, const pca_colour&) = default;
};

namespace detail {
struct chunked_pca_access;

/// A codebook entry (§3.1 classes): up to 6 numbers, unused ones 0 (see pca_data).
using pca_feature = Eigen::Matrix<float, 6, 1>;
/// How many numbers of a position, normal and colour class the file stores.
inline constexpr int pca_feature_dims[3] = {6, 3, 4};

/// Everything a pca_octree holds, independent of its attribute set (colours empty without).
struct pca_data {
  vec3d origin = vec3d::Zero();
  vec3d cube_min = vec3d::Zero();  ///< root cell, relative to origin
  double cube_size = 0;
  /// The input's bounds: origin is the centre of its box, this the distance from there to its
  /// farthest point (so that a --view frames the input and the hierarchy alike).
  double input_radius = 0;
  std::vector<pca_node> nodes;
  std::vector<pca_colour> colours;  ///< per node, or empty
  // options the file records
  std::uint32_t leaf_size = 8, max_depth = 21;
  float gamma = 3.5f, curvature_c = 1, lambda_max = 2;
  float lambda_norm = 1;  ///< root ‖σ_p‖, the unit of ‖σ_p‖ in λ
  bool quantised = true;
  // §3.1 storage: codebooks and per-node records (13 bytes; 4 more with colour). A class holds
  // the statistics k-means groups plus the extents that bound generation (pca_feature):
  //   position: log₂(σ_p^k / cell edge), k = 1..3, then log₂(extent^k / cell edge);
  //   normal: σ_n¹, σ_n² and the normal extent, radians;   colour: σ_c¹..³ and the extent.
  std::vector<pca_feature> codebook_p;
  std::vector<pca_feature> codebook_n;
  std::vector<pca_feature> codebook_c;
  std::vector<std::array<std::uint8_t, 13>> records;
  std::vector<std::uint32_t> colour_records;
  pca_octree_build_stats stats;
  friend bool operator==(const pca_data& a, const pca_data& b);
};

/// Input of the compiled builder: spans over the point set (normals, colours may be empty).
struct pca_input {
  vec3d origin = vec3d::Zero();
  std::span<const vec3f> positions;
  std::span<const vec3f> normals;
  std::span<const rgb8> colours;
  /// Each point's splat ellipse (two tangent semi-axis vectors), or empty: the patch of the
  /// surface the point stands for (a mesh's vertex: its dual cell, core/mesh_splats.hpp). A leaf
  /// then spans its points' patches instead of their box widened by an estimated spacing.
  std::span<const vec3f> axis_u, axis_v;
};

[[nodiscard]] pca_data build_pca_data(const pca_input& in, const pca_octree_options& options);
void save_pca_data(const pca_data& d, const std::string& path);
[[nodiscard]] pca_data load_pca_data(const std::string& path, bool colour);
[[nodiscard]] std::size_t pca_file_bytes(const pca_data& d);

// ---- the statistics of §3, exposed for the tests (pca_octree_build.cpp)
struct pca_position_result {
  vec3d mean = vec3d::Zero();
  mat3d frame = mat3d::Identity();
  vec3d sigma = vec3d::Zero();
  int zero_variances = 0;  ///< how many σ were (numerically) zero before the floor
};
/// §3 position PCA of n points with the degenerate rules; `mean_normal` is the unit average
/// normal the rules align z with.
[[nodiscard]] pca_position_result pca_positions(const vec3d* p, std::size_t n,
                                                const vec3d& mean_normal);
struct pca_normal_result {
  mat3d frame = mat3d::Identity();  ///< column 2: mean normal; 0, 1: ellipse axes
  vec2d sigma = vec2d::Zero();
};
/// §3 normal PCA on the unit sphere: mean normal to +z, unwrap, 2-D PCA about the pole.
/// `fallback` is used as the mean when the normals cancel out.
[[nodiscard]] pca_normal_result pca_normals(const vec3f* n, std::size_t count,
                                            const vec3d& fallback);
/// The unwrap of §3: unit n in the frame's coordinates → (θ·cos ψ, θ·sin ψ), θ the angle from
/// the frame's z axis, ψ the azimuth from its x axis (the paper's (θ sin φ, θ cos φ) with φ
/// measured from y). Preserves arc length along longitudes.
[[nodiscard]] vec2d unwrap_normal(const mat3d& frame, const vec3d& n);
/// Inverse of unwrap_normal: the unit direction at angle |uv| from z towards uv.
[[nodiscard]] vec3d wrap_normal(const mat3d& frame, const vec2d& uv);

struct pca_sample {
  vec3f position;
  vec3f normal;
  rgb8 colour;
};
/// Decodes one quantised record (used by build and load, so both give the same bits).
void pca_decode_node(const pca_data& d, std::uint32_t n, pca_node& out, pca_colour* colour);

}  // namespace detail

template <attributes A>
class pca_octree;
/// Builds the PCA octree of `points` (normals estimated from k nearest neighbours when absent;
/// a zero or non-finite normal is no normal and is estimated too: stats().normals_filled).
/// Throws InvalidArgument on empty input, non-finite coordinates or bad options; Cancelled
/// when the progress callback says so.
template <attributes In>
[[nodiscard]] pca_octree<pca_octree_attributes(In)> build_pca_octree(
    const point_set<In>& points, const pca_octree_options& options = {});

/// How a node's points are generated (§4; docs/pca-octree.md, "Deviations"). Both stay inside
/// what the node's points span (pca_node::extent, normal_extent, pca_colour::extent).
enum class pca_generator : std::uint8_t {
  /// Tangential positions (along f¹, f²) uniform over the span, from a per-node rotation of
  /// Roberts' R2 low-discrepancy sequence (any first k points of a node are spread evenly, so a
  /// node needs about as many points as its projection has pixels); the offset along f³
  /// Gaussian (σ_p³) truncated at the span; normals and colours the paper's Gaussians
  /// truncated at their extents. density × (projected area of the span) points.
  span,
  /// §4 as printed: the Box–Muller generators for positions, normals and colours, truncated at
  /// γ·λ·σ and at the extents; a·ln a + c·a points for the projected span's area a.
  paper,
};

/// What normal and colour a generated point carries (§4; docs/pca-octree.md, "Deviations").
enum class pca_attribute_draw : std::uint8_t {
  /// The node's expected values: its mean normal and mean colour. Without the position of a
  /// point to condition on, the mean is the estimate of least expected squared error; a draw
  /// independent of the input's value there has twice the error (E‖X − Y‖² = 2σ² for X, Y
  /// independent of one distribution, σ² for the mean).
  mean,
  /// §4 as printed: each point's normal from the node's normal ellipse, its colour from the
  /// colour ellipsoid (Box–Muller), truncated at γ and at the node's cone and ball.
  sampled,
};

/// How a PCA octree is drawn (§4).
struct pca_render_options {
  pca_generator generator = pca_generator::span;
  pca_attribute_draw attribute_draw = pca_attribute_draw::mean;
  /// pca_generator::span: points per point-sized cell of a node's projected span (its tiles
  /// take (longer side in points + 1)² cells each, so a slanted view does not open gaps). Below
  /// 1 the hard-cases scene opens holes (0.6: IoU 0.93 instead of 0.98).
  float density = 1.0f;
  std::uint64_t seed = 1;  ///< the random stream; the same seed gives the same image
  float c = 0.2f;          ///< c of a·ln a + c·a (§4: 0.2 sufficed for the paper's models)
  /// Size of a generated point in pixels. The paper draws one-pixel points (1); a point of s
  /// pixels covers s² pixels, so the required count is computed on the area in units of s².
  float point_px = 1;
  /// Refine a node needing more than this many points (§4: 40).
  float split_points = 40;
  /// Fig. 6 DoMerge in pca_octree_cut. 0: a cut node asks its parent to merge as soon as the
  /// parent need not split, so the kept cut is exactly the fresh traversal's. > 0: the paper's
  /// hysteresis ("screen-space size less than a threshold (8)"), read as an area: a node that
  /// is drawn asks only while its projected bounding sphere covers fewer than merge_px pixels
  /// (in units of point_px²; culled nodes ask always), and still only when its parent need not
  /// split. The cut is then at least as fine as the fresh traversal's and changes less often.
  float merge_px = 0;
  /// Upper bound on the points of one node (a node reaching the eye plane counts the whole
  /// viewport as its area: at 512² that is 3.3 M points, so this cap applies).
  std::uint32_t max_points = 1u << 20;
  /// pca_generator::span: most points a node draws. A node that needs more (a leaf seen close,
  /// which cannot split) draws this many, each point_px·√(needed / node_points) pixels wide, so
  /// its points still cover its span: a frame costs about node_points a drawn node instead of a
  /// point a pixel (§6 of the paper leaves point size against count open). 0: no limit.
  std::uint32_t node_points = 16;
  /// A node whose count node_points caps draws its points this much wider again: they share
  /// its span's area exactly at 1, but points on the R2 sequence are not a grid and leave about
  /// a fifth of it uncovered (16 points: 21–24 %; 1.25×: 6–9 %), where the surface behind shows
  /// through. 1.3, measured: against the meshes' renders (the tool, four views at 512²) the
  /// bunny +1.4 dB min, the hard cases +2.6, the demo +1.2; against the clouds' own splat
  /// renders (FinestCutLooksLikeTheInput, 256²) the hard cases' min −1.1 dB (mean +0.0) and the
  /// bunny's −0.3, IoU −0.01 — wider points cross silhouettes and depth contours. Not the
  /// default until one rule wins on both.
  float capped_coverage = 1.0f;
};

namespace detail {
/// Required number of points (§4) for node n seen in view v: for the area a, in units of
/// o.point_px² pixels, of the node's projected span (the box of half-extents pca_node::extent
/// about μ_p along f_p, dilated by half a point), o.density·a (pca_generator::span) or
/// a·ln a + c·a (paper); at least 1. A node reaching the eye plane counts the whole viewport.
[[nodiscard]] float pca_required_points(const pca_data& d, std::uint32_t n, const view& v,
                                        const pca_render_options& o);
/// Points [first, first + count) of node n's stream for `seed` (§4, generator g): point k
/// depends only on (seed, n, k), so any first k points are the same whatever the total.
void pca_generate(const pca_data& d, std::uint32_t n, std::uint64_t seed, std::uint32_t first,
                  std::uint32_t count, pca_sample* out, pca_generator g = pca_generator::span,
                  pca_attribute_draw a = pca_attribute_draw::mean);
/// The same for node n of d drawing the stream of node `stream_id` of the whole hierarchy (a
/// chunk of a chunked PCA octree holds a subtree; its nodes draw their whole-tree numbers).
void pca_generate(const pca_data& d, std::uint32_t n, std::uint64_t stream_id, std::uint64_t seed,
                  std::uint32_t first, std::uint32_t count, pca_sample* out,
                  pca_generator g = pca_generator::span,
                  pca_attribute_draw a = pca_attribute_draw::mean);

/// What pca_octree and chunked_pca_octree draw for node n of d (see pca_octree's members of the
/// same names); stream_id is the node's number in the whole hierarchy.
[[nodiscard]] inline std::uint32_t pca_point_count(const pca_data& d, std::uint32_t n,
                                                   const view& v, const pca_render_options& o) {
  float p = pca_required_points(d, n, v, o);
  if (o.generator == pca_generator::span && o.node_points > 0)
    p = std::min(p, static_cast<float>(o.node_points));
  if (!(p < static_cast<float>(o.max_points))) return o.max_points;
  return std::max<std::uint32_t>(1, static_cast<std::uint32_t>(std::ceil(p)));
}
/// The size (pixels) of node n's points: o.point_px, grown by √(needed / drawn) ×
/// o.capped_coverage when o.node_points caps the count (pca_render_options::node_points).
[[nodiscard]] inline float pca_point_size(const pca_data& d, std::uint32_t n, const view& v,
                                          const pca_render_options& o) {
  if (o.generator != pca_generator::span || o.node_points == 0) return o.point_px;
  const float p = pca_required_points(d, n, v, o);
  const auto cap = static_cast<float>(o.node_points);
  if (!(p > cap)) return o.point_px;
  return o.point_px * std::min(std::sqrt(p / cap) * o.capped_coverage, 1e4f);
}
[[nodiscard]] inline float pca_split_measure(const sphere& s, const view& v,
                                             const pca_render_options& o) {
  const float r = projected_radius_exact(v, s);
  if (!std::isfinite(r)) return std::numeric_limits<float>::infinity();
  const float a = std::numbers::pi_v<float> * r * r / (o.point_px * o.point_px);
  return a > 1 ? a * std::log(a) + o.c * a : 1.0f;
}
template <attributes A, class S>
void pca_emit_points(const pca_data& d, std::uint32_t n, std::uint64_t stream_id,
                     std::uint32_t count, float size, const pca_render_options& o, S& sink) {
  std::array<pca_sample, 64> buf;
  for (std::uint32_t first = 0; first < count; first += buf.size()) {
    const auto k = std::min<std::uint32_t>(buf.size(), count - first);
    pca_generate(d, n, stream_id, o.seed, first, k, buf.data(), o.generator, o.attribute_draw);
    for (std::uint32_t i = 0; i < k; ++i) {
      point_prim<A> p{buf[i].position, size};
      p.normal = buf[i].normal;
      if constexpr (A.colour) p.colour = buf[i].colour;
      sink.point(p);
    }
  }
}
}  // namespace detail

template <attributes A>
class pca_octree {
  static_assert(A.normal && !A.material && !A.ellipse,
                "use pca_octree<pca_octree_attributes(input attributes)>");

 public:
  using node_id = std::uint32_t;
  using node = pca_node;
  static constexpr attributes attrs = A;

  pca_octree() = default;

  // ---- the Hierarchy interface
  [[nodiscard]] vec3d origin() const { return d_.origin; }
  [[nodiscard]] bool empty() const { return d_.nodes.empty(); }
  [[nodiscard]] node_id root() const { return 0; }
  [[nodiscard]] bool is_leaf(node_id n) const { return d_.nodes[n].count == 0; }
  [[nodiscard]] auto children(node_id n) const {
    const node& nd = d_.nodes[n];
    return std::views::iota(nd.first, nd.first + nd.count);
  }
  [[nodiscard]] sphere bounding_sphere(node_id n) const {
    return {d_.nodes[n].mean, d_.nodes[n].radius};
  }
  [[nodiscard]] pbr_lod::normal_cone normal_cone(node_id n) const {
    return {d_.nodes[n].normal_frame.col(2), d_.nodes[n].cone_angle};
  }
  /// The node's generated points (§4) with the default render options: inner nodes and leaves
  /// alike (a leaf's statistics are the finest representation the hierarchy holds).
  template <class S>
  void emit(node_id n, const view& v, S& sink) const {
    const pca_render_options o;
    emit_points(n, required_points(n, v, o), o, sink, point_size(n, v, o));
  }

  /// §4: the number of points node n needs in view v, clamped to [1, o.max_points].
  [[nodiscard]] std::uint32_t required_points(node_id n, const view& v,
                                              const pca_render_options& o) const {
    return detail::pca_point_count(d_, n, v, o);
  }
  /// The split test's count (Fig. 6 DoSplit): a·ln a + c·a for the area a of the node's
  /// projected bounding sphere (exact silhouette, in units of point_px²); monotone down the tree.
  [[nodiscard]] float split_measure(node_id n, const view& v, const pca_render_options& o) const {
    return detail::pca_split_measure(bounding_sphere(n), v, o);
  }
  /// The size in pixels of node n's points (o.point_px unless o.node_points caps its count).
  [[nodiscard]] float point_size(node_id n, const view& v, const pca_render_options& o) const {
    return detail::pca_point_size(d_, n, v, o);
  }
  /// Sends points [0, count) of node n's random stream to the sink, as squares of `size` pixels
  /// (0: o.point_px).
  template <class S>
  void emit_points(node_id n, std::uint32_t count, const pca_render_options& o, S& sink,
                   float size = 0) const {
    detail::pca_emit_points<A>(d_, n, n, count, size > 0 ? size : o.point_px, o, sink);
  }

  // ---- inspection
  [[nodiscard]] const std::vector<node>& nodes() const { return d_.nodes; }
  [[nodiscard]] const node& at(node_id n) const { return d_.nodes[n]; }
  [[nodiscard]] const pca_colour& colour(node_id n) const requires(A.colour) {
    return d_.colours[n];
  }
  [[nodiscard]] bool quantised() const { return d_.quantised; }
  [[nodiscard]] float gamma() const { return d_.gamma; }
  /// The root's octree cell (relative to origin()).
  [[nodiscard]] vec3d cube_min() const { return d_.cube_min; }
  [[nodiscard]] double cube_size() const { return d_.cube_size; }
  /// Distance from origin() (the centre of the input's box) to the input's farthest point.
  [[nodiscard]] double input_radius() const { return d_.input_radius; }
  [[nodiscard]] std::size_t codebook_size_p() const { return d_.codebook_p.size(); }
  [[nodiscard]] std::size_t codebook_size_n() const { return d_.codebook_n.size(); }
  [[nodiscard]] std::size_t codebook_size_c() const { return d_.codebook_c.size(); }
  [[nodiscard]] const pca_octree_build_stats& stats() const { return d_.stats; }
  /// Bytes of one node record in the file: 13 (17 with colour) quantised, as §3.1; the child
  /// mask (1 byte) and the codebooks come on top (file_bytes()).
  [[nodiscard]] std::size_t record_bytes() const {
    return d_.quantised ? (A.colour ? 17 : 13) : (A.colour ? 184 : 120);
  }
  [[nodiscard]] std::size_t file_bytes() const { return detail::pca_file_bytes(d_); }
  [[nodiscard]] const detail::pca_data& data() const { return d_; }

  // ---- storage (§3.1)
  /// Writes the versioned file ("PBRLODSG" v1); throws IoError. load(save(t)) == t exactly.
  void save(const std::string& path) const { detail::save_pca_data(d_, path); }
  /// Reads and validates a file written by save(): magic, version, attribute set, options,
  /// every count against the file size, codebook indices, normal codes, the tree shape, finite
  /// values, a checksum. Throws IoError (cannot read) or FormatError naming the file and the
  /// element at fault.
  [[nodiscard]] static pca_octree load(const std::string& path) {
    pca_octree t;
    t.d_ = detail::load_pca_data(path, A.colour);
    return t;
  }

  friend bool operator==(const pca_octree& a, const pca_octree& b) { return a.d_ == b.d_; }

 private:
  template <attributes In>
  friend pca_octree<pca_octree_attributes(In)> build_pca_octree(const point_set<In>&,
                                                                const pca_octree_options&);
  friend struct detail::chunked_pca_access;
  detail::pca_data d_;
};

extern template class pca_octree<with_normals>;
extern template class pca_octree<with_normals_colours>;
static_assert(Hierarchy<pca_octree<with_normals>> && HasNormalCones<pca_octree<with_normals>>);
static_assert(Hierarchy<pca_octree<with_normals_colours>>);

template <attributes In>
pca_octree<pca_octree_attributes(In)> build_pca_octree(const point_set<In>& points,
                                                       const pca_octree_options& options) {
  detail::pca_input in;
  in.origin = points.origin;
  in.positions = points.positions;
  if constexpr (In.normal) in.normals = points.normals;
  if constexpr (In.colour) in.colours = points.colours;
  if constexpr (In.ellipse) {
    in.axis_u = points.axis_u;
    in.axis_v = points.axis_v;
  }
  pca_octree<pca_octree_attributes(In)> t;
  t.d_ = detail::build_pca_data(in, options);
  return t;
}

/// §4 as a policy of the common traversal. The split test (Fig. 6 DoSplit: more than
/// split_points points) is taken on the node's bounding sphere — the paper's "enclosing-sphere
/// shortcut" — because a parent's sphere holds its children's: a node that must split has
/// ancestors that all must, so the cut is well defined and pca_octree_cut can keep it across
/// frames. A drawn node gets the count of its own projected ellipsoid (a·ln a + c·a).
struct pca_octree_policy : default_policy {
  pca_render_options render{};
  template <class H>
  [[nodiscard]] float screen_size(const H& h, const typename H::node_id& n, const sphere&,
                                  const view& v, const traverse_options&) const {
    return h.split_measure(n, v, render);
  }
  template <class H>
  [[nodiscard]] bool refine(const H& h, const typename H::node_id& n, float points,
                            const traverse_options&) const {
    return !h.is_leaf(n) && points > render.split_points;
  }
  template <class H, class S>
  void emit(const H& h, const typename H::node_id& n, const view& v, float, const traverse_options&,
            S& sink) const {
    h.emit_points(n, h.required_points(n, v, render), render, sink, h.point_size(n, v, render));
  }
};

/// Fig. 6: the view-dependent cut kept across frames — the traversal of pca_octree_policy
/// specialised for coherence. An active list (doubly linked, in depth-first order) holds the
/// cut: the nodes drawn and the nodes culled. Each frame walks it once:
///   * a node whose parent need not split any more (culled, or few enough points) sends the
///     parent a merge request; the parent counts them with a time stamp (a stale stamp resets
///     the count to one) and, when every child has asked, replaces its children in the list
///     (merge) and is examined in turn;
///   * otherwise a node that must split is replaced by its children in place (split) and the
///     walk continues with the first child;
///   * otherwise it is drawn (or stays culled: frustum, or normal cone — the cone's width covers
///     the widest normal-ellipse intercept, γ·σ_n¹, of the subtree).
/// By default the parent test stands for the paper's "screen-space size below 8 pixels" (which
/// pca_render_options::merge_px restores, with its hysteresis): with it, the cut after a frame
/// is exactly the fresh traversal's (the split test is monotone, see
/// pca_octree_policy), so the frame draws the same points, in the same order, while evaluating
/// only the list's nodes and their parents. Generated points live in a cache bank of 16-point
/// blocks: a node keeps the blocks it filled while it stays in the cut and generates only the
/// points it lacks; split frees the parent's blocks, merge the children's. The stream is
/// counter-based, so cached and fresh points are the same. traverse_stats::visited counts the
/// nodes evaluated this frame. One thread; the hierarchy must outlive the cut.
template <attributes A>
class pca_octree_cut {
 public:
  using node_id = std::uint32_t;
  static constexpr node_id none = std::numeric_limits<node_id>::max();
  static constexpr std::uint32_t block_points = 16;

  explicit pca_octree_cut(const pca_octree<A>& t, bool use_cache = true)
      : t_(&t), cache_(use_cache) {
    const std::size_t n = t.nodes().size();
    parent_.assign(n, none);
    rank_.assign(n, 0);
    prev_.assign(n, none);
    next_.assign(n, none);
    stamp_.assign(n, 0);
    state_.assign(n, 0);
    merge_stamp_.assign(n, 0);
    merge_count_.assign(n, 0);
    blocks_.resize(n);
    filled_.assign(n, 0);
    if (n == 0) return;
    // A frame emits its cut in traverse()'s order.
    traversal_ranks(t, rank_, [&](node_id p, node_id c) { parent_[c] = p; });
  }

  struct frame_stats {
    std::size_t splits = 0, merges = 0;
    std::size_t points_cached = 0;     ///< points drawn from the bank
    std::size_t points_generated = 0;  ///< points generated into the bank (or on the fly)
  };

  /// Draws one frame; the first frame (or after reset()) starts from the root.
  template <Sink<A> S>
  traverse_stats frame(const view& v, const traverse_options& o, S& sink,
                       const pca_octree_policy& p = {}) {
    st_ = {};
    fs_ = {};
    drawn_.clear();
    if (t_->empty()) return st_;
    if (++frame_ == 0) {
      std::fill(stamp_.begin(), stamp_.end(), 0u);
      std::fill(merge_stamp_.begin(), merge_stamp_.end(), 0u);
      frame_ = 1;
    }
    if (head_ == none) head_ = t_->root();
    node_id n = head_;
    while (n != none) {
      const node_id q = parent_[n];
      if (q != none && state(q, v, o, p) != refine && wants_merge(n, v, o, p)) {
        if (merge_stamp_[q] != frame_) {
          merge_stamp_[q] = frame_;
          merge_count_[q] = 1;
        } else {
          ++merge_count_[q];
        }
        if (merge_count_[q] == t_->at(q).count) {
          merge(q);
          n = q;
          continue;
        }
        n = next_[n];
        continue;
      }
      const int s = state(n, v, o, p);
      if (s == refine) {
        n = split(n);
        continue;
      }
      if (s == culled_frustum) ++st_.culled_frustum;
      if (s == culled_backface) ++st_.culled_backface;
      if (s == draw) drawn_.push_back(n);
      n = next_[n];
    }
    std::sort(drawn_.begin(), drawn_.end(),
              [&](node_id a, node_id b) { return rank_[a] < rank_[b]; });
    detail::counting_forwarder<A, S> out{sink};
    for (const node_id d : drawn_) {
      ++(t_->is_leaf(d) ? st_.emitted_leaves : st_.emitted_nodes);
      const std::uint32_t count = t_->required_points(d, v, p.render);
      const float size = t_->point_size(d, v, p.render);
      if (cache_)
        emit_cached(d, count, size, p.render, out);
      else {
        fs_.points_generated += count;
        t_->emit_points(d, count, p.render, out, size);
      }
    }
    st_.points = out.points;
    return st_;
  }

  /// Forgets the cut and the bank: the next frame starts from the root.
  void reset() {
    for (node_id n = head_; n != none; n = next_[n]) release(n);
    head_ = none;
  }
  /// The active list (the cut: drawn and culled nodes), in list order.
  [[nodiscard]] std::vector<node_id> cut() const {
    std::vector<node_id> c;
    for (node_id n = head_; n != none; n = next_[n]) c.push_back(n);
    return c;
  }
  /// The nodes drawn in the last frame, in the order drawn (the plain traversal's).
  [[nodiscard]] const std::vector<node_id>& drawn() const { return drawn_; }
  [[nodiscard]] const frame_stats& last_frame() const { return fs_; }
  /// Blocks of the bank in use.
  [[nodiscard]] std::size_t blocks_in_use() const {
    return bank_.size() / block_points - free_.size();
  }

 private:
  enum : int { culled_frustum, culled_backface, refine, draw };

  int state(node_id n, const view& v, const traverse_options& o, const pca_octree_policy& p) {
    if (stamp_[n] == frame_) return state_[n];
    stamp_[n] = frame_;
    ++st_.visited;
    const sphere s = t_->bounding_sphere(n);
    int r = draw;
    if (o.frustum_cull &&
        (o.cull_volume == traverse_options::volume::view_cone ? outside_view_cone(v, s)
                                                              : frustum_test(v, s, 0x3f) < 0))
      r = culled_frustum;
    else if (o.backface_cull && node_back_facing(*t_, n, s, v.eye))
      r = culled_backface;
    else if (p.refine(*t_, n, p.screen_size(*t_, n, s, v, o), o))
      r = refine;
    state_[n] = static_cast<std::uint8_t>(r);
    return r;
  }
  /// Fig. 6 DoMerge (see pca_render_options::merge_px).
  bool wants_merge(node_id n, const view& v, const traverse_options& o,
                   const pca_octree_policy& p) {
    if (!(p.render.merge_px > 0)) return true;
    const int s = state(n, v, o, p);
    if (s == culled_frustum || s == culled_backface) return true;
    const float r = projected_radius_exact(v, t_->bounding_sphere(n));
    const float px = p.render.point_px;
    return std::isfinite(r) && std::numbers::pi_v<float> * r * r / (px * px) < p.render.merge_px;
  }
  /// Replaces n in the list by its children; returns the first child.
  node_id split(node_id n) {
    ++fs_.splits;
    release(n);
    const auto& nd = t_->at(n);
    node_id before = prev_[n];
    const node_id after = next_[n];
    for (node_id c = nd.first; c < nd.first + nd.count; ++c) {
      link(before, c);
      before = c;
    }
    link(before, after);
    return nd.first;
  }
  /// Replaces q's children (contiguous in the list) by q.
  void merge(node_id q) {
    ++fs_.merges;
    const auto& nd = t_->at(q);
    const node_id first = nd.first, last = nd.first + nd.count - 1;
    const node_id before = prev_[first], after = next_[last];
    for (node_id c = first; c <= last; ++c) release(c);
    link(before, q);
    link(q, after);
  }
  void link(node_id a, node_id b) {
    if (a == none)
      head_ = b;
    else
      next_[a] = b;
    if (b != none) prev_[b] = a;
  }
  void release(node_id n) {
    for (const std::uint32_t b : blocks_[n]) free_.push_back(b);
    blocks_[n].clear();
    filled_[n] = 0;
  }
  template <class S>
  void emit_cached(node_id n, std::uint32_t count, float size, const pca_render_options& r,
                   S& sink) {
    auto& bl = blocks_[n];
    if (filled_[n] < count) {
      while (bl.size() * block_points < count) {
        if (free_.empty()) {
          free_.push_back(static_cast<std::uint32_t>(bank_.size() / block_points));
          bank_.resize(bank_.size() + block_points);
        }
        bl.push_back(free_.back());
        free_.pop_back();
      }
      for (std::uint32_t first = filled_[n]; first < count;) {
        const std::uint32_t k = std::min(block_points - first % block_points, count - first);
        detail::pca_generate(t_->data(), n, r.seed, first, k,
                             &bank_[bl[first / block_points] * block_points + first % block_points],
                             r.generator, r.attribute_draw);
        first += k;
      }
      fs_.points_generated += count - filled_[n];
      fs_.points_cached += filled_[n];
      filled_[n] = count;
    } else {
      fs_.points_cached += count;
    }
    for (std::uint32_t i = 0; i < count; ++i) {
      const detail::pca_sample& g = bank_[bl[i / block_points] * block_points + i % block_points];
      point_prim<A> pt{g.position, size};
      pt.normal = g.normal;
      if constexpr (A.colour) pt.colour = g.colour;
      sink.point(pt);
    }
  }

  const pca_octree<A>* t_;
  bool cache_;
  std::vector<node_id> parent_, rank_, prev_, next_;
  node_id head_ = none;
  std::vector<std::uint32_t> stamp_, merge_stamp_;
  std::vector<std::uint8_t> state_, merge_count_;
  std::uint32_t frame_ = 0;
  std::vector<node_id> drawn_;
  traverse_stats st_;
  frame_stats fs_;
  // the cache bank: blocks of 16 generated points, per node the blocks it holds and how many
  // of its points are filled
  std::vector<detail::pca_sample> bank_;
  std::vector<std::uint32_t> free_;
  std::vector<std::vector<std::uint32_t>> blocks_;
  std::vector<std::uint32_t> filled_;
};

}  // namespace pbr_lod
