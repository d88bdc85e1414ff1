// pbr_lod — PMR built out of core, in chunks, and opened lazily.
//
// PMR's octree is split by sample counts at cell midpoints (Dey & Hudson §2), and every leaf is
// processed on its own from its samples and its neighbours' within a margin: the leaves are
// natural chunks. An input larger than memory (a point_source read block by block) is built into
// a directory: a top file with the octree nodes above the chunks, and one PMR file per chunk — a
// subtree of at most `chunk_points` samples built in memory from its points and its halo (the
// points of other chunks within the neighbour margin). chunked_pmr opens the directory and
// serves the Hierarchy interface and what pmr_policy needs, reading a chunk's file only when a
// traversal reaches into it.
//
// How (docs/scale.md):
//  1. Bounds pass: the input's box gives the origin and the root cell (as build_pmr's).
//  2. Structure passes: one per level, counting the points of every cell that holds more than
//     chunk_points by octant; a cell of at most chunk_points becomes a chunk.
//  3. Distribution pass: every point into its chunk's file (input order kept), and in the same
//     pass into the halo of every other chunk whose cell, widened by neighbour_margin × its edge
//     (the largest margin any leaf below it uses), holds it.
//  4. Per chunk: the subtree, its leaves' Voronoi work and records over chunk + halo
//     (build_pmr's code); triangle vertices in the halo are stored in the chunk as foreign
//     samples; the chunk's normals go to a file in input order.
//  5. Without input normals, each chunk has oriented its normals by build_pmr's propagation over
//     its own umbrella edges; the chunks are then made to agree with each other the same way one
//     level up (rank 0): over the graph of chunks weighted by Σ n·n' of the umbrella edges that
//     join them, most agreeing first, from the chunk of the sample farthest from the centre.
//  6. Per chunk: its flip, the foreign samples' normals from the file, the triangles wound about
//     the final normals, the chunk's file written.
//  7. The top nodes' bounding spheres bottom up from the chunks' roots; the top file.
//
// Equal to the in-memory build: chunked_pmr::assemble() returns build_pmr's hierarchy of the same
// input with neighbour_leaves = false (a chunk's halo is a margin) and triangulation_points at
// most chunk_points, sample for sample and bit for bit, when the input has normals (they orient the
// pole vectors sample by sample). Without normals, positions, levels, umbrellas and nodes are
// equal; build_pmr propagates signs over the whole input's umbrella edges in one order, the chunked
// build within each chunk and then between chunks, and where a surface is ambiguous (thin
// sheets, sharp folds) the two can settle a sample's sign differently (docs/scale.md measures how
// often).
//
// Limits: at most 2³² − 2 input points (the PMR file's 32-bit sample indices).
//
// Thread safety: a chunked_pmr's const members may be called from several threads.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <ranges>
#include <string>
#include <utility>
#include <vector>

#include "pbr_lod/builders/chunked.hpp"
#include "pbr_lod/builders/pmr.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/point_source.hpp"

namespace pbr_lod {

/// The chunked PMR's options (builders/chunked.hpp): `builder` the in-memory build's. Its
/// chunks are built builder.threads at a time (one thread each), so the budget is theirs together.
using chunked_pmr_options = chunked_options<pmr_options>;

/// Peak bytes of a chunk's build per own sample: its records and halo, one leaf's triangulation
/// at a time, the part's records. Measured ≈ 340 with halos of half the chunk (docs/scale.md);
/// the rest is room for denser halos.
inline constexpr std::uint64_t chunked_pmr_bytes_per_point = 512;

/// Builds PMR of `src` into the directory `dir`, whole or not at all (built as `dir.partial` and
/// renamed; an earlier build in `dir` is replaced only then, see check_chunked_output and
/// docs/scale.md). In the report, estimation_seconds is step 4 (the parts: the Voronoi work) and
/// chunk_build_seconds steps 5–6. Throws InvalidArgument on an empty source, non-finite positions,
/// more than 2³² − 2 points or bad options; IoError when the directory cannot be written; Cancelled
/// through options.builder.progress.
chunked_build_report build_pmr_chunked(const point_source& src, const std::string& dir,
                                       const chunked_pmr_options& options = {});

/// Whether `dir` holds a chunked PMR (its top file).
[[nodiscard]] bool is_chunked_pmr(const std::string& dir);

namespace detail {
/// The top file "top.pbrlod": head "PBRLODMC" | u32 version | u32 flags (1: colours) | f64
/// origin[3], input min[3], input max[3] | u32 max_leaf_points | f32 neighbour_margin | u32
/// thresholds, f32 each | u64 × 6 build counts (as the PMR file) | f32 input sphere centre[3],
/// radius | u64 top nodes | u64 chunks |
/// the top nodes as PMR node records (a chunk's root: its record in the chunk) | u32 per top
/// node: its chunk or 0xffffffff | per chunk: u32 top node, u64 samples, u64 leaves, u64 nodes |
/// u64 FNV-1a checksum.
inline constexpr file_format chunked_pmr_format{
    "chunked PMR", {'P', 'B', 'R', 'L', 'O', 'D', 'M', 'C'}, 1};
struct chunked_pmr_access;
}  // namespace detail

/// A PMR hierarchy stored as a directory by build_pmr_chunked, opened lazily: the top file at
/// open(), a chunk's file when a traversal first needs a node below the chunk's root (whose
/// record is in the top file). Models Hierarchy; draw it with pmr_policy like a pmr_hierarchy.
/// A (with_normals or with_normals_colours): the primitives' attributes; colours need a
/// directory built from an input with colours.
template <attributes A = with_normals>
class chunked_pmr : public chunked_reader<pmr_hierarchy> {
  using base = chunked_reader<pmr_hierarchy>;

 public:
  static constexpr attributes attrs = A;
  /// The extension of its chunk files: each a PMR file of one subtree.
  static constexpr const char* chunk_extension = "pmr";

  /// Reads and validates the top file of `dir`; throws FormatError / IoError naming the file,
  /// and a FormatError saying so when `dir` is a folder an unfinished build left
  /// (check_chunked_folder).
  [[nodiscard]] static chunked_pmr open(const std::string& dir);

  // ---- the Hierarchy interface
  [[nodiscard]] vec3d origin() const { return origin_; }
  [[nodiscard]] bool empty() const { return top_nodes_.empty(); }
  [[nodiscard]] bool is_leaf(node_id n) const { return at(n).leaf != 0; }
  [[nodiscard]] auto children(node_id n) const {
    const detail::pmr_node& nd = at(n);
    std::uint32_t first = 0, end = 0;
    if (!nd.leaf) {
      first = nd.first;
      end = nd.first + nd.count;
      if (n.chunk != top) (void)chunk(n.chunk);  // the children are in the chunk's file
    }
    return std::views::iota(first, end) |
           std::views::transform([this, c = n.chunk](std::uint32_t i) { return canonical(c, i); });
  }
  [[nodiscard]] sphere bounding_sphere(node_id n) const { return {at(n).centre, at(n).radius}; }
  /// Every leaf below n by the paper's rule with factor 1 (as pmr_hierarchy::emit).
  template <class S>
  void emit(node_id n, const view& v, S& sink) const {
    if (n.chunk != top) {
      chunk(n.chunk).template emit<A>(n.index, v, sink);
      return;
    }
    for (const node_id c : children(n)) emit(c, v, sink);
  }

  // ---- what pmr_policy needs: leaves are numbered across the chunks
  [[nodiscard]] std::uint32_t leaf_of(node_id n) const {
    return leaf_offset_[n.chunk] + chunk(n.chunk).leaf_of(n.index);
  }
  [[nodiscard]] float pixel_size(node_id n, const view& v) const {
    return pmr_hierarchy::pixel_size_of(at(n), v);
  }
  [[nodiscard]] std::uint32_t choose_level(std::uint32_t leaf, float pixel, float factor) const {
    const std::uint32_t c = chunk_of_leaf(leaf);
    return chunk(c).choose_level(leaf - leaf_offset_[c], pixel, factor);
  }
  template <class S>
  void emit_level(std::uint32_t leaf, std::uint32_t lvl, float pixel, S& sink) const {
    const std::uint32_t c = chunk_of_leaf(leaf);
    chunk(c).template emit_level<A>(leaf - leaf_offset_[c], lvl, pixel, sink);
  }

  // ---- inspection
  [[nodiscard]] const detail::pmr_node& at(node_id n) const {
    const std::uint32_t i = in_top(n);
    return i != top ? top_nodes_[i] : chunk(n.chunk).nodes()[n.index];
  }
  [[nodiscard]] std::uint32_t levels() const { return static_cast<std::uint32_t>(rho_.size() + 1); }
  [[nodiscard]] std::uint64_t input_points() const { return stats_.input_points; }
  [[nodiscard]] std::uint64_t leaf_count() const { return leaf_offset_.back(); }
  [[nodiscard]] vec3d input_min() const { return input_min_; }
  /// The input's bounding sphere about the centre of its box (relative to origin()), as
  /// bounding_sphere_about_box_centre gives it for the hierarchy's positions.
  [[nodiscard]] sphere input_sphere() const { return input_sphere_; }
  [[nodiscard]] vec3d input_max() const { return input_max_; }
  /// Build counts summed over the chunks (duplicates, triangulated points, removals, ...).
  [[nodiscard]] const pmr_build_stats& stats() const { return stats_; }
  /// Chunk c's subtree (read from its file on first use; throws FormatError if it is damaged or
  /// does not match the top file). Its last foreign() samples are other chunks' vertices.
  [[nodiscard]] const pmr_hierarchy& chunk(std::uint32_t c) const;
  /// The whole hierarchy in memory, laid out as build_pmr lays it out (reads every chunk): equal
  /// to build_pmr of the same input when it has normals (see the top of this header).
  [[nodiscard]] pmr_hierarchy assemble() const;

 private:
  friend struct detail::chunked_pmr_access;
  chunked_pmr() : base(chunk_extension) {}
  [[nodiscard]] std::uint32_t chunk_of_leaf(std::uint32_t leaf) const;
  void assemble_levels(detail::pmr_data& d, std::pair<std::uint32_t, std::uint32_t> leaf,
                       const std::vector<std::uint32_t>& global) const;

  vec3d origin_ = vec3d::Zero(), input_min_ = vec3d::Zero(), input_max_ = vec3d::Zero();
  std::vector<float> rho_;
  pmr_build_stats stats_;
  sphere input_sphere_;
  std::vector<detail::pmr_node> top_nodes_;
  std::vector<std::uint32_t> leaf_offset_;  // per chunk: its first leaf's number; then the total
};

/// File name of chunk c of a chunked PMR.
[[nodiscard]] inline std::string pmr_chunk_file_name(std::uint32_t c) {
  return chunk_file(c, chunked_pmr<>::chunk_extension);
}

extern template class chunked_pmr<with_normals>;
extern template class chunked_pmr<with_normals_colours>;
static_assert(Hierarchy<chunked_pmr<with_normals>>);

}  // namespace pbr_lod
