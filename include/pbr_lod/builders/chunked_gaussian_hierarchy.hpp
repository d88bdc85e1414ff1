// pbr_lod — the Gaussian hierarchy built out of core, in chunks, and opened lazily.
//
// A Gaussian scene larger than memory (a gaussian_source: io/gaussians.hpp opens a 3DGS .ply or
// .splat as one, read by rows) is built into a folder: a top file with the nodes above the
// chunks, and one ordinary Gaussian hierarchy file per chunk — a subtree of at most
// `chunk_points` Gaussians, built in memory on its own by build_gaussian_hierarchy.
// chunked_gaussian_hierarchy opens the folder and serves the Hierarchy interface, reading a
// chunk's file only when a traversal first refines below the chunk's root.
//
// How (docs/scale.md, docs/gaussian-hierarchy.md):
//  1. Key pass: every Gaussian's split key — its mean, its 3σ reach and its index, 16 bytes — is
//     read into memory (the one part of the build that grows with the input: 160 MB for 10⁷).
//  2. The top of the tree is split in memory exactly as build_gaussian_hierarchy splits it
//     (Kerbl et al. 2024 §4.1: median along the longest axis of the 3σ box, ties by index),
//     until a subtree holds at most chunk_points Gaussians: that subtree is a chunk.
//  3. Distribution pass: every Gaussian is appended to its chunk's file (input order kept).
//  4. Per chunk: build_gaussian_hierarchy of its Gaussians, saved; its root kept.
//  5. The top nodes are merged bottom up from the chunks' roots (the same moment matching) and
//     written last.
//
// Equal to the in-memory build: the tree's shape depends on the counts alone, a split on the set
// it splits (not on its order), and a leaf's Gaussians go in input order; so every chunk is the
// in-memory build's subtree and every top node its node, bit for bit —
// chunked_gaussian_hierarchy::assemble() returns build_gaussian_hierarchy's hierarchy of the same
// input and options, whatever the chunk size, thread count or number of ranks.
//
// Thread safety: a chunked_gaussian_hierarchy's const members may be called from several threads.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "pbr_lod/builders/chunked.hpp"
#include "pbr_lod/builders/gaussian_hierarchy.hpp"
#include "pbr_lod/core/gaussian_source.hpp"

namespace pbr_lod {

/// The chunked Gaussian hierarchy's options (builders/chunked.hpp): `builder` the in-memory
/// build's. block_points is in Gaussians.
using chunked_gaussian_hierarchy_options = chunked_options<gaussian_hierarchy_options>;

/// Peak bytes of a chunk's build per Gaussian of SH degree `degree`, from the build's arrays: the
/// chunk's Gaussians read (one record each), the store (the input's and the inner Gaussians: two
/// records), the nodes (two of 32 bytes) and the split keys (16); the file is written in pieces.
/// Degree 3: 852 bytes.
[[nodiscard]] constexpr std::uint64_t gaussian_chunk_bytes(int degree) {
  const auto record = static_cast<std::uint64_t>(11 + 3 * sh_coefficients(degree)) * 4;
  return 3 * record + 2 * 32 + 16;
}

/// Builds the Gaussian hierarchy of `src` into the folder `dir`, whole or not at all (built in a
/// staging folder and renamed; an earlier build in `dir` is replaced only then, see
/// check_chunked_output). Chunks are built one after another, each on every thread. Throws
/// InvalidArgument on an empty source, more than 2³¹ Gaussians, a block that does not validate
/// or bad options; IoError when the folder cannot be written.
chunked_build_report build_gaussian_hierarchy_chunked(
    const gaussian_source& src, const std::string& dir,
    const chunked_gaussian_hierarchy_options& options = {});

/// Whether `dir` holds a chunked Gaussian hierarchy (its top file).
[[nodiscard]] bool is_chunked_gaussian_hierarchy(const std::string& dir);

/// A Gaussian hierarchy stored as a folder by build_gaussian_hierarchy_chunked, opened lazily:
/// the top file at open(), a chunk's file when a traversal first needs its nodes below the
/// chunk's root (the root's Gaussian is in the top file). Models Hierarchy; draw it with
/// gaussian_policy like a gaussian_hierarchy.
class chunked_gaussian_hierarchy : public chunked_reader<gaussian_hierarchy> {
  using base = chunked_reader<gaussian_hierarchy>;

 public:
  using base::top, base::root, base::chunk_count;
  using typename base::node_id;
  static constexpr attributes attrs = gaussian_hierarchy::attrs;
  /// The extension of its chunk files: each an ordinary Gaussian hierarchy file.
  static constexpr const char* chunk_extension = "gh";

  /// A top node: its Gaussians in the top store (a chunk's root: the chunk's root Gaussian), its
  /// children (inner top nodes: first and first + 1; chunks' roots have theirs in the chunk),
  /// and what the cut measures.
  struct top_node {
    std::uint32_t gaussian = 0, count = 0;  ///< count: 0 inner, else a leaf's Gaussians
    std::uint32_t first = 0;                ///< inner top node: its children's top index
    float size = 0;
    sphere bounds;
  };
  struct child_range {
    std::array<node_id, 2> ids{};
    std::uint32_t n = 0;
    [[nodiscard]] const node_id* begin() const { return ids.data(); }
    [[nodiscard]] const node_id* end() const { return ids.data() + n; }
  };

  /// Reads and validates the top file of `dir`; throws FormatError / IoError naming the file,
  /// and a FormatError saying so when `dir` is a folder an unfinished build left.
  [[nodiscard]] static chunked_gaussian_hierarchy open(const std::string& dir);

  // ---- the Hierarchy interface
  [[nodiscard]] vec3d origin() const { return top_g_.origin; }
  [[nodiscard]] int sh_degree() const { return top_g_.sh_degree; }
  [[nodiscard]] bool empty() const { return top_nodes_.empty(); }
  [[nodiscard]] bool is_leaf(node_id n) const {
    const std::uint32_t i = in_top(n);
    return i != top ? top_nodes_[i].count != 0 : chunk(n.chunk).is_leaf(n.index);
  }
  [[nodiscard]] child_range children(node_id n) const {
    child_range out;
    const std::uint32_t i = in_top(n);
    if (i != top && frontier_[i] == top) {
      if (top_nodes_[i].count == 0)
        out = {{canonical(top, top_nodes_[i].first), canonical(top, top_nodes_[i].first + 1)}, 2};
      return out;
    }
    for (const std::uint32_t k : chunk(n.chunk).children(n.index))
      out.ids[out.n++] = node_id{n.chunk, k};
    return out;
  }
  [[nodiscard]] sphere bounding_sphere(node_id n) const {
    const std::uint32_t i = in_top(n);
    return i != top ? top_nodes_[i].bounds : chunk(n.chunk).bounding_sphere(n.index);
  }
  /// As gaussian_hierarchy::emit.
  template <class S>
  void emit(node_id n, const view& v, S& sink, float merged_lowpass_px2 = 0) const {
    const detail::gaussian_range r = gaussians(n);
    detail::emit_gaussians(*r.cloud, r.first, r.count, v, sink,
                           is_leaf(n) ? 0.0f : merged_lowpass_px2);
  }

  // ---- what gaussian_policy, the cuts and inspection need
  [[nodiscard]] sphere size_sphere(node_id n) const {
    const std::uint32_t i = in_top(n);
    if (i == top) return chunk(n.chunk).size_sphere(n.index);
    return {top_g_.positions[top_nodes_[i].gaussian], top_nodes_[i].size};
  }
  [[nodiscard]] detail::gaussian_range gaussians(node_id n) const {
    const std::uint32_t i = in_top(n);
    if (i == top) return chunk(n.chunk).gaussians(n.index);
    const top_node& t = top_nodes_[i];
    return {&top_g_, t.gaussian, t.count == 0 ? 1 : t.count};
  }
  /// The Gaussians a traversal of v with `o` and `p` draws, as gaussian_hierarchy::cut.
  [[nodiscard]] gaussian_cloud cut(const view& v, const traverse_options& o,
                                   const gaussian_policy& p) const;
  [[nodiscard]] gaussian_cloud cut(const view& v, const traverse_options& o) const;
  /// The view-independent cut at tree depth `level`, as gaussian_hierarchy::level (reads the
  /// chunks it reaches).
  [[nodiscard]] gaussian_cloud level(std::size_t level) const;
  /// Edges on the longest root-to-leaf path (reads every chunk).
  [[nodiscard]] std::size_t depth() const;
  [[nodiscard]] std::uint64_t input_gaussians() const { return input_; }
  /// The input's means' bounding sphere about the centre of their box (relative to origin()), as
  /// bounding_sphere_about_box_centre gives it.
  [[nodiscard]] sphere input_sphere() const { return input_sphere_; }
  /// Gaussians stored over the folder: the input's and one per inner node.
  [[nodiscard]] std::uint64_t stored_gaussians() const { return input_ + leaves_ - 1; }
  [[nodiscard]] const std::vector<top_node>& top_nodes() const { return top_nodes_; }
  /// Chunk c's subtree (read from its file on first use; throws FormatError if it is damaged or
  /// does not match the top file).
  [[nodiscard]] const gaussian_hierarchy& chunk(std::uint32_t c) const;
  /// The whole hierarchy in memory (reads every chunk): equal to build_gaussian_hierarchy of the
  /// same input and options, and save() gives its bytes.
  [[nodiscard]] gaussian_hierarchy assemble() const;

 private:
  friend struct gaussian_chunked_build;
  chunked_gaussian_hierarchy() : base(chunk_extension) {}
  void validate(const std::string& path) const;
  [[nodiscard]] std::vector<unsigned char> serialize_top() const;

  gaussian_cloud top_g_;  // the top nodes' Gaussians (origin and degree: the hierarchy's)
  std::vector<top_node> top_nodes_;
  std::uint64_t input_ = 0, leaves_ = 0;
  sphere input_sphere_;
};

namespace detail {
/// The top file: head "PBRLODGC" | u32 version | u32 SH degree | f64 origin[3] | u64 input
/// Gaussians | u64 leaves | f32 input sphere[4] | u64 top nodes | u64 chunks | u64 top Gaussians |
/// the top Gaussians (the Gaussian hierarchy file's records) | per top node: u32 gaussian, u32
/// count, u32 first, f32 size, f32 sphere[4] | u32 per top node: its chunk or 0xffffffff | per
/// chunk: u32 top node, u64 Gaussians, u64 nodes | u64 FNV-1a checksum. Top nodes are in
/// breadth-first order.
inline constexpr file_format chunked_gaussian_top_format{
    "chunked Gaussian hierarchy", {'P', 'B', 'R', 'L', 'O', 'D', 'G', 'C'}, 1};
}  // namespace detail

static_assert(Hierarchy<chunked_gaussian_hierarchy>);

}  // namespace pbr_lod
