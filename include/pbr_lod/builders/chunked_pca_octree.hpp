// pbr_lod — the hierarchical PCA octree built out of core, in chunks, and opened lazily.
//
// Kalaiah & Varshney's octree splits a cell at its centre while it holds more than leaf_size
// points (§3), so the nodes above a chunk are found by counting, and a chunk's subtree needs
// only the chunk's points. Every node's statistics are the PCA of the points below it: the
// positions' and colours' moments merge up the tree (Chan et al.), the normals' PCA is taken
// about each node's own mean normal and needs two passes over its normals. An input larger than
// memory (a point_source read block by block) is built into a directory: a top file with the
// nodes above the chunks and the §3.1 codebooks, and one file per chunk with its subtree's
// records. chunked_pca_octree opens it and serves the Hierarchy interface and what
// pca_octree_policy needs, reading a chunk's file only when a traversal reaches below its root.
//
// How (docs/scale.md):
//  1. Bounds pass: the input's box gives the origin and the root cube (as build_pca_octree's).
//  2. Structure passes: one per level, counting the points of every cell above chunk_points by
//     octant (and their box: a cell of one repeated position is not split, as in memory).
//  3. Distribution pass: every point into its chunk's file, input order kept. When normals are
//     missing (none given, or some zero or not finite): the point-octree's k-NN halos, then chunk
//     after chunk in octree order fill_missing_normals over the chunk and its halo, whose points
//     of finished chunks carry their estimates (so one orientation spreads over the chunks).
//  4. Per chunk: its subtree and every node's statistics, by build_pca_octree's own code; its
//     normals in octree order and its root's moments kept for the top.
//  5. The top nodes (rank 0): the normals' sums and then their unwrapped second moments in two
//     passes over the chunks' normals in octree order (every sum in the in-memory order), the
//     positions' and colours' moments merged from the chunks' roots.
//  6. §3.1 (when quantising): the k-means samples picked by whole-tree node number (breadth
//     first, as in memory) from the chunks and the top, the codebooks trained once (rank 0);
//     then per chunk every node encoded, decoded, bounded (λ in units of the root's ‖σ_p‖) and
//     the chunk's file written.
//  7. The top nodes' bounds from the chunks' roots; the top file.
//
// Equal to the in-memory build: chunked_pca_octree::assemble() returns build_pca_octree's
// hierarchy of the same input bit for bit, and a traversal draws the same points (a node's
// random stream is keyed by its whole-tree number), when the input has normals. With missing
// normals the estimates are the in-memory build's up to orientation, which the in-memory build
// propagates over the whole input's k-NN graph at once (docs/scale.md).
//
// Limits: at most 2³² − 2 input points (as build_pca_octree).
//
// Thread safety: a chunked_pca_octree's const members may be called from several threads.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <ranges>
#include <string>
#include <vector>

#include "pbr_lod/builders/chunked.hpp"
#include "pbr_lod/builders/pca_octree.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/point_source.hpp"

namespace pbr_lod {

/// The chunked PCA octree's options (builders/chunked.hpp): `builder` the in-memory build's.
/// Its chunks are built builder.threads at a time (one thread each), so the budget is theirs
/// together.
using chunked_pca_octree_options = chunked_options<pca_octree_options>;

/// Peak bytes of a chunk's build per point: positions (twice), normals (twice), colours, the
/// permutation, the nodes (≈ one per three points at leaf_size 8) with their ranges.
inline constexpr std::uint64_t chunked_pca_bytes_per_point = 256;

/// Builds the PCA octree of `src` into the directory `dir`, whole or not at all (built as
/// `dir.partial` and renamed; an earlier build in `dir` is replaced only then, see
/// check_chunked_output and docs/scale.md). In the report, estimation_seconds is 0 (the input's
/// normals are used; else step 3's estimation) and chunk_build_seconds steps 4 and 6. Throws
/// InvalidArgument on an empty source, non-finite positions, more than
/// 2³² − 2 points or bad options; IoError when the directory cannot be written; Cancelled
/// through options.builder.progress.
chunked_build_report build_pca_octree_chunked(const point_source& src, const std::string& dir,
                                              const chunked_pca_octree_options& options = {});

/// Whether `dir` holds a chunked PCA octree (its top file).
[[nodiscard]] bool is_chunked_pca_octree(const std::string& dir);

namespace detail {
/// The top file "top.pbrlod": head "PBRLODSC" | u32 version | u32 flags (1: colours, 2:
/// quantised) | u32 leaf_size, max_depth | f32 γ, curvature c, λ_max, λ unit | u64 input points |
/// f64 origin[3], root cube min[3], root cube edge, input radius | u32 codebook sizes p, n, c |
/// the codebooks (as the PCA octree file) | u64 top nodes | u64 chunks | the top nodes' child
/// masks (a chunk's root: 0) and records (as the PCA octree file) | per top node: u32 chunk or
/// 0xffffffff, u32 whole-tree node number | per chunk: u32 top node, u64 points, u64 nodes, u8
/// its root's child mask, f32 its root's radius and cone angle | u64 FNV-1a checksum.
/// A chunk file "chunk-NNNNNN.pca": head "PBRLODSK" | u32 version | u32 flags | u32 chunk | u32
/// root depth | u64 points | u64 nodes | f64 cell min[3], cell edge | u32 levels | u32 per level:
/// the whole-tree number of its first node | child masks and records | u64 FNV-1a checksum.
inline constexpr file_format chunked_pca_format{
    "chunked PCA octree", {'P', 'B', 'R', 'L', 'O', 'D', 'S', 'C'}, 2};
inline constexpr file_format pca_chunk_format{
    "PCA octree chunk", {'P', 'B', 'R', 'L', 'O', 'D', 'S', 'K'}, 2};

/// A chunk as loaded: its subtree (node 0 its root, depths absolute) decoded with the top's
/// codebooks, and the whole-tree number of each level's first node.
struct pca_chunk {
  pca_data d;
  std::vector<std::uint32_t> level_first;   ///< per local level: its first node's local index
  std::vector<std::uint32_t> level_global;  ///< per local level: that node's whole-tree number
  std::uint64_t points = 0;
  [[nodiscard]] std::uint64_t global_id(std::uint32_t i) const;
};
/// Reads and validates chunk file `path` against the top (`top` holds the codebooks and options).
[[nodiscard]] pca_chunk load_pca_chunk(const std::string& path, const pca_data& top,
                                       std::uint32_t chunk, bool colour);
}  // namespace detail

/// A PCA octree stored as a directory by build_pca_octree_chunked, opened lazily: the top file at
/// open(), a chunk's file when a traversal first needs a node below the chunk's root (whose
/// record is in the top file). Models Hierarchy; draw it with pca_octree_policy like a
/// pca_octree<A>. A: pca_octree_attributes of the input's (colours need a directory built from an
/// input with colours).
template <attributes A = with_normals>
class chunked_pca_octree : public chunked_reader<detail::pca_chunk> {
  static_assert(A.normal && !A.material && !A.ellipse,
                "use chunked_pca_octree<pca_octree_attributes(input attributes)>");
  using base = chunked_reader<detail::pca_chunk>;

 public:
  static constexpr attributes attrs = A;
  using node = pca_node;
  /// The extension of its chunk files ("PBRLODSK", below).
  static constexpr const char* chunk_extension = "pca";

  /// Reads and validates the top file of `dir`; throws FormatError / IoError naming the file,
  /// and a FormatError saying so when `dir` is a folder an unfinished build left
  /// (check_chunked_folder).
  [[nodiscard]] static chunked_pca_octree open(const std::string& dir);

  // ---- the Hierarchy interface
  [[nodiscard]] vec3d origin() const { return top_.origin; }
  [[nodiscard]] bool empty() const { return top_.nodes.empty(); }
  [[nodiscard]] bool is_leaf(node_id n) const { return at(n).count == 0; }
  [[nodiscard]] auto children(node_id n) const {
    const pca_node& nd = at(n);
    if (n.chunk != top && nd.count) (void)chunk(n.chunk);  // the children are in the chunk's file
    return std::views::iota(nd.first, nd.first + std::uint32_t{nd.count}) |
           std::views::transform([this, c = n.chunk](std::uint32_t i) { return canonical(c, i); });
  }
  [[nodiscard]] sphere bounding_sphere(node_id n) const { return {at(n).mean, at(n).radius}; }
  [[nodiscard]] pbr_lod::normal_cone normal_cone(node_id n) const {
    return {at(n).normal_frame.col(2), at(n).cone_angle};
  }
  /// The node's generated points (§4) with the default render options (as pca_octree::emit).
  template <class S>
  void emit(node_id n, const view& v, S& sink) const {
    const pca_render_options o;
    emit_points(n, required_points(n, v, o), o, sink, point_size(n, v, o));
  }

  // ---- what pca_octree_policy needs (as pca_octree's)
  [[nodiscard]] std::uint32_t required_points(node_id n, const view& v,
                                              const pca_render_options& o) const {
    const auto [d, i] = where(n);
    return detail::pca_point_count(*d, i, v, o);
  }
  [[nodiscard]] float split_measure(node_id n, const view& v, const pca_render_options& o) const {
    return detail::pca_split_measure(bounding_sphere(n), v, o);
  }
  /// Points [0, count) of node n's random stream: the stream of its whole-tree number, so the
  /// points are those pca_octree draws for the same node.
  [[nodiscard]] float point_size(node_id n, const view& v, const pca_render_options& o) const {
    const auto [d, i] = where(n);
    return detail::pca_point_size(*d, i, v, o);
  }
  template <class S>
  void emit_points(node_id n, std::uint32_t count, const pca_render_options& o, S& sink,
                   float size = 0) const {
    const auto [d, i] = where(n);
    detail::pca_emit_points<A>(*d, i, global_id(n), count, size > 0 ? size : o.point_px, o, sink);
  }

  // ---- inspection
  [[nodiscard]] const pca_node& at(node_id n) const {
    const auto [d, i] = where(n);
    return d->nodes[i];
  }
  [[nodiscard]] const pca_colour& colour(node_id n) const requires(A.colour) {
    const auto [d, i] = where(n);
    return d->colours[i];
  }
  /// The node's number in build_pca_octree's breadth-first layout.
  [[nodiscard]] std::uint64_t global_id(node_id n) const {
    const std::uint32_t i = in_top(n);
    return i != top ? top_global_[i] : chunk(n.chunk).global_id(n.index);
  }
  [[nodiscard]] bool quantised() const { return top_.quantised; }
  [[nodiscard]] float gamma() const { return top_.gamma; }
  [[nodiscard]] vec3d cube_min() const { return top_.cube_min; }
  [[nodiscard]] double cube_size() const { return top_.cube_size; }
  [[nodiscard]] double input_radius() const { return top_.input_radius; }
  [[nodiscard]] std::uint64_t input_points() const { return top_.stats.input_points; }
  /// The top: its nodes (a chunk's root among them), codebooks and options.
  [[nodiscard]] const detail::pca_data& top_data() const { return top_; }
  /// Chunk c (read from its file on first use; throws FormatError if it is damaged or does not
  /// match the top file).
  [[nodiscard]] const detail::pca_chunk& chunk(std::uint32_t c) const;
  /// The whole hierarchy in memory, laid out as build_pca_octree lays it out (reads every chunk):
  /// equal to build_pca_octree of the same input (see the top of this header).
  [[nodiscard]] pca_octree<A> assemble() const;

 private:
  chunked_pca_octree() : base(chunk_extension) {}
  /// The pca_data holding node n and its index there (a chunk's root: the top's copy).
  [[nodiscard]] std::pair<const detail::pca_data*, std::uint32_t> where(node_id n) const {
    const std::uint32_t i = in_top(n);
    if (i != top) return {&top_, i};
    return {&chunk(n.chunk).d, n.index};
  }

  detail::pca_data top_;
  std::vector<std::uint32_t> top_global_;  // per top node: its whole-tree number
};

/// File name of chunk c of a chunked PCA octree.
[[nodiscard]] inline std::string pca_chunk_file_name(std::uint32_t c) {
  return chunk_file(c, chunked_pca_octree<>::chunk_extension);
}

extern template class chunked_pca_octree<with_normals>;
extern template class chunked_pca_octree<with_normals_colours>;
static_assert(Hierarchy<chunked_pca_octree<with_normals>> &&
              HasNormalCones<chunked_pca_octree<with_normals>>);

}  // namespace pbr_lod
