// pbr_lod — what the PCA octree's translation units share (not installed).
#pragma once

#include <algorithm>
#include <cstdint>

#include "pbr_lod/builders/pca_octree.hpp"
#include "pbr_lod/core/covariance.hpp"

namespace pbr_lod::detail {

/// Throws InvalidArgument naming the first bad option (knn matters only without input normals).
void pca_validate_options(const pca_octree_options& o, bool input_normals);
/// Number of threads for `requested` (0 = hardware concurrency).
unsigned pca_threads(unsigned requested);

/// §3 colour PCA of the colours c[0..n) (RGB / 255; pca_octree_stats.cpp).
pca_colour pca_colours(const rgb8* c, std::size_t n);
/// The same from the colours' mean and covariance.
pca_colour pca_colours_from(const vec3d& mean, const mat3d& cov);
/// §3 position PCA (pca_positions) from the points' mean and covariance.
pca_position_result pca_positions_from(const vec3d& mean, const mat3d& cov,
                                       const vec3d& mean_normal);
/// Count, mean and centred scatter of n points, or of n colours as RGB / 255 (two passes).
/// An inner node's are its children's merged (Chan et al.), so each point is summed once.
scatter_accumulator position_moments(const vec3d* p, std::size_t n);
scatter_accumulator colour_moments(const rgb8* c, std::size_t n);

/// pca_normals() in its three steps, for a caller that streams a node's normals in two passes
/// (the chunked build): the frame about the pole from the normals' sum (the first normal as
/// fallback), each normal's unwrapped second moment added to m (in the order pca_normals adds
/// them), and the ellipse from m.
mat3d pca_normal_pole(const vec3d& sum, std::size_t count, const vec3d& fallback);
void pca_normal_unwrap_add(const mat3d& frame_transposed, const vec3f& normal, Eigen::Matrix2d& m);
pca_normal_result pca_normal_finish(const mat3d& frame, Eigen::Matrix2d m, std::size_t count);

/// A node's statistics from its accumulated moments and its normals' PCA, as the build stores
/// them (σ_p floored at 10⁻¹⁵).
void pca_set_statistics(pca_node& nd, const scatter_accumulator& positions,
                        const pca_normal_result& normals);

/// What a leaf's points span (pca_node::extent, normal_extent, pca_colour::extent; colour may be
/// null): from its count points p (relative to the origin), unit normals n and colours c (null
/// without colour), about its statistics, which must be set, and its cell (for one point).
/// Tangentially only along the directions the points spread in, widened by their spacing, which
/// it returns (for pca_widen_leaf). With splat ellipses (u, v: each point's semi-axes, or null)
/// tangentially the box of the points' ellipses instead, and 0 (they need no widening); the
/// extents without them go to `for_parent` (what its parent's span is made of).
double pca_leaf_extents(pca_node& nd, pca_colour* colour, const vec3d* p, const vec3f* n,
                        const rgb8* c, std::size_t count, double parent_spacing,
                        const vec3f* u = nullptr, const vec3f* v = nullptr,
                        vec3f* for_parent = nullptr);
/// A leaf whose parent's points span a surface (not a line or a point): the tangential
/// directions its own points do not spread in (one point, two, a line of them — a scan line)
/// are widened by h too, so that it covers the patch its points stand for — when its frame's
/// f³ (its normal where its points span no plane) is within 30° of the parent's (parent_frame).
void pca_widen_leaf(pca_node& nd, double h, const mat3f& parent_frame);
/// The same for inner node i of d from its children's (set before): the box of their boxes'
/// corners in its frame, the cone of their cones, the ball of their colour balls. A leaf child c
/// contributes leaf_boxes[c] instead of its own extents when leaf_boxes is not empty
/// (pca_leaf_extents' for_parent).
void pca_inner_extents(pca_data& d, std::size_t i, std::span<const vec3f> leaf_boxes = {});

/// The points of a subtree being built: positions relative to the origin (double), unit normals,
/// colours (or empty). pca_build_subtree() reorders them into octree order.
struct pca_points {
  std::vector<vec3d> pos;
  std::vector<vec3f> normals;
  std::vector<rgb8> colours;
  std::vector<vec3f> axis_u, axis_v;  ///< splat ellipses (pca_input::axis_u), or empty
};
/// The root's moments of a subtree (merged into its parent's by the chunked build).
struct pca_subtree_moments {
  scatter_accumulator positions, colours;
  /// The root a leaf: the spacing its extents were widened by (pca_widen_leaf, which its parent
  /// outside the subtree applies); else 0.
  double root_leaf_h = 0;
};
/// §3 below one cell: the octree of `pts` under the cell at (cell_min, depth) of a root cube of
/// edge `root_size` (build_pca_data's rules, so a subtree equals the whole build's subtree at
/// that cell) into d.nodes (breadth first, absolute depths; d.colours when pts has colours) and
/// every node's statistics; pts end in octree order. d.cube_min / cube_size become the cell.
pca_subtree_moments pca_build_subtree(pca_data& d, pca_points& pts, const vec3d& cell_min,
                                      std::uint8_t depth, double root_size,
                                      const pca_octree_options& o, unsigned threads,
                                      double root_parent_spacing = 0);

/// Cells of every node from the root cube and the child masks (top-down). Before decoding:
/// μ_p is quantised relative to the node's cell.
void pca_derive_cells(pca_data& d, unsigned threads = 1);
/// λ, bounding-sphere radii and normal-cone angles (bottom-up), from the decoded statistics.
void pca_derive_bounds(pca_data& d, unsigned threads = 1);
/// The same with the unit of ‖σ_p‖ given (a chunk's nodes take the whole tree's root's), and
/// without touching nodes marked in `fixed` (their bounds are known: a chunk's root in the top).
void pca_derive_bounds_with(pca_data& d, float lambda_norm, unsigned threads,
                            const std::vector<char>* fixed = nullptr);

/// §3.1: k-means classification of σ_p, σ_n, σ_c, encoding of every node into its record and
/// decoding back into d.nodes / d.colours (so the hierarchy holds what the file holds). Fills
/// the quantisation-error stats and kmeans_seconds.
void pca_quantise(pca_data& d, const pca_octree_options& o, unsigned threads);

/// pca_quantise() in its steps, for a build whose nodes are not all in one pca_data (the chunked
/// build numbers them as build_pca_data would, breadth first):
/// the classification features of node i (pca_data's codebooks; colour when `fc`),
void pca_features(const pca_data& d, std::size_t i, pca_feature& fp, pca_feature& fn,
                  pca_feature* fc);
/// which of n nodes k-means samples for codebook `stream` (1: σ_p, 2: σ_n, 3: σ_c), ascending,
/// and the random state the seeding continues from,
std::vector<std::uint32_t> pca_kmeans_picks(std::size_t n, const pca_octree_options& o,
                                            std::uint64_t stream, std::uint64_t& rng);
/// the codebook trained on the picked nodes' features (in pick order),
std::vector<pca_feature> pca_kmeans_train(const std::vector<pca_feature>& xs, std::uint32_t k,
                                          const pca_octree_options& o, std::uint64_t& rng,
                                          unsigned threads);
/// and every node of d encoded against d's codebooks and decoded back (d.records,
/// d.colour_records, d.nodes, d.colours; the error stats of d.stats over d's nodes).
void pca_encode(pca_data& d, unsigned threads);

/// Reads/writes `bits` (≤ 32) bits of `v` at bit position `pos` of a little-endian byte
/// record, a byte at a time (a record holds one node; encode and decode touch every field).
template <std::size_t N>
void put_bits(std::array<std::uint8_t, N>& r, unsigned pos, std::uint32_t v, unsigned bits) {
  for (unsigned done = 0; done < bits;) {
    const unsigned off = pos & 7u, take = std::min(8u - off, bits - done);
    const std::uint32_t part = (v >> done) & ((1u << take) - 1u);
    r[pos >> 3] = static_cast<std::uint8_t>(r[pos >> 3] | (part << off));
    done += take;
    pos += take;
  }
}
template <std::size_t N>
std::uint32_t get_bits(const std::array<std::uint8_t, N>& r, unsigned pos, unsigned bits) {
  std::uint32_t v = 0;
  for (unsigned done = 0; done < bits;) {
    const unsigned off = pos & 7u, take = std::min(8u - off, bits - done);
    v |= ((static_cast<std::uint32_t>(r[pos >> 3]) >> off) & ((1u << take) - 1u)) << done;
    done += take;
    pos += take;
  }
  return v;
}

// The record layouts (§3.1, Fig. 5), bit offsets in a little-endian record.
//   13-byte node record: σ_p index 12 | σ_n index 12 | μ_p 32 (x, y, z: 10 bits for the world
//   axis least aligned with f_p³, 11 for the others) | f_p³ normal code 16 | f_p¹ angle about
//   f_p³ 8 | mean normal (f_n³) code 16 | f_n¹ angle 8.
//   4-byte colour record: σ_c index 6 | μ_c RGB 565 16 | f_c³ code 7 | f_c¹ angle 3.
struct pca_layout {
  static constexpr unsigned sp = 0, sn = 12, mu = 24, fp_axis = 56, fp_angle = 72, fn_axis = 80,
                            fn_angle = 96;
  static constexpr unsigned sc = 0, muc = 6, fc_axis = 22, fc_angle = 29;
  static constexpr int axis_bits = 16, angle_bits = 8, colour_axis_bits = 7, colour_angle_bits = 3;
};

/// The file's node part (pca_octree_io.cpp): the child masks breadth first, then the records
/// (quantised, or the float statistics). get_pca_nodes reads nn nodes below a root at
/// `root_depth` into d (whose codebooks, options, cube and `quantised` are set), checks the tree
/// and every record, derives the cells and decodes; bounds are the caller's. Bytes per node
/// without its mask: pca_record_bytes.
struct byte_writer;
struct byte_reader;
void put_pca_nodes(byte_writer& w, const pca_data& d);
void get_pca_nodes(byte_reader& r, pca_data& d, std::uint64_t nn, bool colour,
                   std::uint8_t root_depth, const std::string& path);
std::size_t pca_record_bytes(bool quantised, bool colour);
/// The codebooks as the files store them (pca_feature_dims numbers an entry, float), their
/// bytes, and the validating read of kp, kn, kc entries into d.
void put_pca_codebooks(byte_writer& w, const pca_data& d);
std::uint64_t pca_codebook_bytes(std::uint64_t kp, std::uint64_t kn, std::uint64_t kc);
/// Reads and checks the build options every PCA file stores after its flags (leaf size, max
/// depth, γ, curvature c, λ_max); throws FormatError naming the file and the value.
void get_pca_options(byte_reader& r, pca_data& d);
void get_pca_codebooks(byte_reader& r, pca_data& d, std::uint32_t kp, std::uint32_t kn,
                       std::uint32_t kc, const std::string& path);

/// The bits each axis of μ_p gets, from the decoded f_p³ (10 for the axis least aligned).
std::array<unsigned, 3> pca_mean_bits(const vec3f& f3);

}  // namespace pbr_lod::detail
