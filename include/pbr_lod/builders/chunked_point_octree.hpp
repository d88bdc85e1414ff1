// pbr_lod — the point-octree built out of core, in chunks, and opened lazily.
//
// An input larger than memory (a point_source read block by block) is built into a directory:
// a top file with the nodes above the chunks, and one ordinary point-octree file per chunk — a
// subtree of at most `chunk_points` samples, built in memory on its own. The result is the
// hierarchy build_point_octree makes of the same input, node for node and bit for bit (see
// "Equal to the in-memory build" below); chunked_point_octree opens the directory and serves the
// Hierarchy interface, reading a chunk's file only when a traversal first refines into it.
//
// How (docs/scale.md):
//  1. Structure passes. Pajarola's split point is the mean of a node's samples (§3), so the top
//     of the tree is found level by level: one streaming pass per level accumulates, for every
//     node still larger than a chunk, its octants' counts and position sums — block by block
//     exactly as the in-memory octant pass sums them (same order, same doubles) — and gives the
//     next level's means. A node of at most chunk_points samples becomes a chunk.
//  2. Distribution pass: every point is appended to its chunk's file (input order kept).
//  3. Halo pass: normals and splat ellipses come from the k nearest neighbours (§4 end), which
//     may lie in other chunks (and a splat is bounded by its neighbours' own spacing). Three times
//     a point's k-th neighbour distance within its chunk bounds how far either can be from it;
//     per cell of an 8³ grid over each chunk the largest such reach, and one pass collects, for
//     every chunk, the points of other chunks within reach of its cells (its halo).
//  4. Per chunk: estimation over chunk + halo, quantisation (§5); the quantised normals go back
//     to a file in input order.
//  5. Two attribute passes give every top node its normal and colour sums (in the in-memory
//     block order) and its normal cone.
//  6. Per chunk: the subtree is built from its input (count, mean, normal and colour sums) and
//     saved; its root's covariance summary is kept.
//  7. The top nodes are finished bottom up from the chunks' roots (EQ 4, EQ 5–6) and written.
//
// An input that fits one chunk (and one process) skips steps 2–7: it is read whole and built by
// build_point_octree, which writes the folder those steps would.
//
// Equal to the in-memory build: every chunk's subtree, its samples and every top node equal
// build_point_octree's (chunked_point_octree::assemble() returns that tree), given
//  * normals in the input, or normals oriented towards a viewpoint (options.builder.viewpoint):
//    the default orientation propagates signs over the k-NN graph of the whole input, which a
//    chunk and its halo only see part of — a chunk's normals may then come out flipped as a
//    whole relative to the in-memory build;
//  * no two neighbours of a point at exactly the same distance where only one of them is among
//    its k nearest (ties are broken by position on a Morton curve over the searched set's box,
//    which differs between a chunk's search and the whole input's).
//
// Thread safety: a chunked_point_octree's const members may be called from several threads.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <ranges>
#include <string>
#include <vector>

#include "pbr_lod/builders/chunked.hpp"
#include "pbr_lod/builders/point_octree.hpp"
#include "pbr_lod/core/point_source.hpp"

namespace pbr_lod {

/// The chunked point-octree's options (builders/chunked.hpp): `builder` the in-memory build's.
using chunked_point_octree_options = chunked_options<point_octree_options>;

/// Peak bytes of a chunk's build per sample, measured (docs/scale.md): the chunk's records and
/// halo, the k-NN graph of the estimation, the builder's working arrays and the nodes. The chunks
/// are estimated and built one after another, each on every thread: one chunk at a time.
inline constexpr std::uint64_t chunk_bytes_per_point = 512;

/// Builds the point-octree of `src` into the directory `dir`, whole or not at all (built as
/// `dir.partial` and renamed; an earlier build in `dir` is replaced only then, see
/// check_chunked_output and docs/scale.md). Throws InvalidArgument on an empty source or non-finite
/// positions, IoError when the directory cannot be written, Cancelled through the progress
/// callback of options.builder.
chunked_build_report build_point_octree_chunked(const point_source& src, const std::string& dir,
                                                const chunked_point_octree_options& options = {});

/// Whether `dir` holds a chunked point-octree (its top file).
[[nodiscard]] bool is_chunked_point_octree(const std::string& dir);

/// A point-octree stored as a directory by build_point_octree_chunked, opened lazily: the top
/// file is read at open(), a chunk's file when a traversal first needs its nodes below the
/// chunk's root (the root's record is in the top file). Models Hierarchy; draw it with
/// point_octree_policy like a point_octree.
template <attributes A>
class chunked_point_octree : public chunked_reader<point_octree<A>> {
  using base = chunked_reader<point_octree<A>>;
  using base::canonical, base::in_top, base::chunk_top_, base::frontier_, base::dir_;
  using base::chunk_samples_, base::chunk_nodes_;

 public:
  using tree = point_octree<A>;
  using node = typename tree::node;
  using selection_record = typename tree::selection_record;
  using base::top, base::root, base::chunk_count;
  using typename base::node_id;
  static constexpr attributes attrs = tree::attrs;
  /// The extension of its chunk files: each an ordinary point-octree file.
  static constexpr const char* chunk_extension = "po";

  /// Reads and validates the top file of `dir`; throws FormatError / IoError naming the file,
  /// and a FormatError saying so when `dir` is a folder an unfinished build left
  /// (check_chunked_folder).
  [[nodiscard]] static chunked_point_octree open(const std::string& dir);

  // ---- the Hierarchy interface
  [[nodiscard]] vec3d origin() const { return origin_; }
  [[nodiscard]] bool empty() const { return top_nodes_.empty(); }
  [[nodiscard]] bool is_leaf(node_id n) const { return at(n).leaf != 0; }
  [[nodiscard]] auto children(node_id n) const {
    const node& nd = at(n);
    std::uint32_t first = 0, end = 0;
    if (!nd.leaf) {
      first = nd.first;
      end = nd.first + nd.count;
      if (n.chunk != top) (void)chunk(n.chunk);  // the children are in the chunk's file
    }
    return std::views::iota(first, end) |
           std::views::transform([this, c = n.chunk](std::uint32_t i) { return canonical(c, i); });
  }
  [[nodiscard]] sphere bounding_sphere(node_id n) const {
    const node& nd = at(n);
    return {nd.centre, nd.radius};
  }
  [[nodiscard]] pbr_lod::normal_cone normal_cone(node_id n) const {
    return {at(n).normal, at(n).cone_angle};
  }
  [[nodiscard]] pbr_lod::normal_cone_cs normal_cone_cs(node_id n) const {
    return {at(n).normal, selection(n).cos_cone, selection(n).sin_cone};
  }
  template <class S>
  void emit(node_id n, const view& v, S& sink) const {
    if (!at(n).leaf) {
      emit_node_splat(n, sink);
      return;
    }
    chunk(n.chunk).emit(n.index, v, sink);  // leaves are always in chunks
  }
  template <class S>
  void emit_node_splat(node_id n, S& sink) const {
    const node& nd = at(n);
    splat_prim<attrs> s{nd.centre, nd.axis_u, nd.axis_v};
    s.normal = nd.normal;
    if constexpr (A.colour) s.colour = node_colour(n);
    sink.splat(s);
  }
  template <class S>
  void emit_node_point(node_id n, S& sink) const {
    const node& nd = at(n);
    point_prim<attrs> p{nd.centre, 1.0f};
    p.normal = nd.normal;
    if constexpr (A.colour) p.colour = node_colour(n);
    sink.point(p);
  }

  // ---- what point_octree_policy and inspection need
  [[nodiscard]] const node& at(node_id n) const {
    const std::uint32_t i = in_top(n);
    return i != top ? top_nodes_[i] : chunk(n.chunk).at(n.index);
  }
  [[nodiscard]] const selection_record& selection(node_id n) const {
    const std::uint32_t i = in_top(n);
    return i != top ? top_selection_[i] : chunk(n.chunk).selection(n.index);
  }
  [[nodiscard]] rgb8 node_colour(node_id n) const requires(A.colour) {
    const std::uint32_t i = in_top(n);
    return i != top ? top_colours_[i] : chunk(n.chunk).node_colour(n.index);
  }
  [[nodiscard]] std::uint64_t input_points() const { return input_points_; }
  /// The input's bounding sphere about the centre of its box (relative to origin()), as
  /// bounding_sphere_about_box_centre gives it for the input's positions.
  [[nodiscard]] sphere input_sphere() const { return input_sphere_; }
  [[nodiscard]] int normal_bits() const { return normal_bits_; }
  /// Chunk c's subtree (read from its file on first use; throws FormatError if it is damaged or
  /// does not match the top file).
  [[nodiscard]] const tree& chunk(std::uint32_t c) const;
  /// The whole hierarchy in memory, laid out as build_point_octree lays it out (reads every
  /// chunk): equal to build_point_octree of the same input, and save() gives its bytes.
  [[nodiscard]] tree assemble() const;

 private:
  template <attributes In>
  friend struct detail::chunked_point_octree_builder;
  chunked_point_octree() : base(chunk_extension) {}
  void validate(const std::string& path) const;

  vec3d origin_ = vec3d::Zero();
  int normal_bits_ = 0;
  std::uint64_t input_points_ = 0;
  std::vector<node> top_nodes_;
  std::vector<rgb8> top_colours_;
  std::vector<typename tree::orientation_code> top_codes_;
  std::vector<selection_record> top_selection_;
  sphere input_sphere_;
};

namespace detail {
/// The top file: head "PBRLODPC" | u32 version | u32 flags (1 colour, 2 quantised) | u32 normal
/// bits | f64 origin[3] | u64 input points | f32 input sphere centre[3], f32 radius | u64 top
/// nodes | u64 chunks | the top nodes as point-octree node records (a chunk's root: its record
/// in the chunk) | u32 per top node: its chunk or 0xffffffff | per chunk: u32 top node,
/// u64 samples, u64 nodes | u64 FNV-1a checksum.
inline constexpr file_format chunked_top_format{
    "chunked point-octree", {'P', 'B', 'R', 'L', 'O', 'D', 'P', 'C'}, 1};
}  // namespace detail

/// File name of chunk c in a chunked point-octree directory.
[[nodiscard]] inline std::string chunk_file_name(std::uint32_t c) {
  return chunk_file(c,
                    chunked_point_octree<point_octree_attributes(attributes{})>::chunk_extension);
}

extern template class chunked_point_octree<point_octree_attributes(attributes{})>;
extern template class chunked_point_octree<point_octree_attributes(attributes{.colour = true})>;
static_assert(Hierarchy<chunked_point_octree<point_octree_attributes(attributes{})>>);

}  // namespace pbr_lod
