// pbr_lod — ρ-grid packed point trees: recursive ρ×ρ×ρ grids with implicit positions.
//
// This work is based on:
//   X. Duguet, G. Drettakis. Flexible Point-Based Rendering on Mobile Devices. IEEE CG&A 24(4),
//   2004 (INRIA RR; the text in shared/papers).
// What each part implements:
//   §2, §3.2     a non-leaf cell holds a ρ³-bit childhood code (bit j set = child j non-empty);
//                empty cells cost nothing; positions are implicit in the cell path.
//   §3.1         sampling: every non-empty cell (inner or leaf) is sampled at the point of the
//                surface closest to its centre (CGAL AABB tree closest-point query; for a point
//                cloud, the cell's own input point closest to the centre); the sample's
//                attribute is σ bits: a q-bit quantised normal (13 by default) + an m-bit
//                material index (3 by default). A scene without normals or materials stores none.
//                "Evidently, we need more bits if we have more materials or colors": an input
//                with colours adds a c-bit quantised RGB colour (5:6:5 by default) to σ, stored
//                beside the 16-bit normal/material attribute; an input without stores no bit.
//   §3.2, Eq. 1–4 the packed bitstreams: NIS (codes in pre-order, then the leaf attributes) and
//                IS (attribute + code per cell, interleaved in pre-order); rho_grid_cost() is
//                Eq. 4 (Table 1).
//   §3.3         the in-core runtime structure: per inner cell its code, its attribute and a
//                32-bit index into one contiguous child table; leaves hold their attribute only.
//   §4, §4.1     flexible rendering (rho_grid_hierarchy.hpp, rho_grid_policy.hpp): the grid as a
//                Hierarchy and the paper's traversal as a policy of the common traverse — transform
//                factorisation (displacement tables), conservative screen bounds from a bounds
//                table, the splat condition dx ≤ w·s, dy ≤ w·s in homogeneous coordinates,
//                frustum culling; §5.1 the same traversal in fixed point.
//   §4.2         one-pass shadows for a directional light: the light's child order
//                (rho_grid_policy.hpp) and the shading sink (raster/one_pass_shadows.hpp).
// The build runs level by level (§5.2: "constructed level-by-level"): only the cells of the
// current level are held besides the output, so memory stays bounded by the structure itself.
//
// Threading: build uses TBB over the cells of a level. A built rho_grid is immutable; const
// member functions are safe for concurrent readers.
#pragma once

#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/math.hpp"
#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"

namespace pbr_lod {

/// Storage cost per leaf sample of a ρ-grid in bits, Eq. 4: (ρ³ + σ)/(ρ² − 1) — the hierarchy
/// with σ-bit attributes at every inner cell, assuming ρ² non-empty children per inner cell.
/// σ = 0 is Eq. 3 (codes only). Table 1 of the paper lists this for σ ∈ {0,4,8,12,16,32,48}.
[[nodiscard]] constexpr double rho_grid_cost(int rho, int sigma) {
  const double r = rho;
  return (r * r * r + sigma) / (r * r - 1);
}

/// Deepest subdivision supported for a given ρ: the leaf path (k base-ρ³ digits) fits in 63 bits.
/// This is the tree depth k of the leaves (the root cube at depth 0), the paper's level + 1.
[[nodiscard]] constexpr int rho_grid_max_leaf_depth(int rho) {
  int k = 0;
  unsigned long long cells = 1;
  const unsigned long long step = static_cast<unsigned long long>(rho) * rho * rho;
  while (cells <= (1ull << 63) / step) {
    cells *= step;
    ++k;
  }
  return k;
}

/// Finest level (as the paper numbers levels, rho_grid_options::level) supported for a given ρ:
/// 20 for ρ = 2, 12 for ρ = 3, 9 for ρ = 4, 8 for ρ = 5.
[[nodiscard]] constexpr int rho_grid_max_level(int rho) {
  return rho_grid_max_leaf_depth(rho) - 1;
}

/// Bits per channel (red, green, blue) of a c-bit colour: c/3 each, the remainder to green,
/// then red — 16 → 5:6:5, 12 → 4:4:4, 8 → 3:3:2, the classic packed formats.
[[nodiscard]] constexpr std::array<int, 3> rho_grid_colour_split(int colour_bits) {
  const int b = colour_bits / 3, rem = colour_bits % 3;
  return {b + (rem >= 2 ? 1 : 0), b + (rem >= 1 ? 1 : 0), b};
}
/// An 8-bit RGB colour quantised to colour_bits (rho_grid_colour_split): each channel rounded to
/// the nearest of its 2^bits evenly spaced levels; red in the low bits.
[[nodiscard]] constexpr std::uint32_t rho_grid_encode_colour(const rgb8& c, int colour_bits) {
  const auto [br, bg, bb] = rho_grid_colour_split(colour_bits);
  const auto q = [](std::uint8_t v, int bits) {
    const std::uint32_t m = (1u << bits) - 1u;
    return (std::uint32_t(v) * m + 127u) / 255u;
  };
  return q(c.r, br) | (q(c.g, bg) << br) | (q(c.b, bb) << (br + bg));
}
/// The colour a code stands for: each channel's level scaled back to 0…255 (rounded), so 0 and
/// the top level decode to 0 and 255 exactly; the error of encode then decode is at most half a
/// level, 255 / (2·(2^bits − 1)) (4.1 for 5 bits, 2.0 for 6).
[[nodiscard]] constexpr rgb8 rho_grid_decode_colour(std::uint32_t code, int colour_bits) {
  const auto [br, bg, bb] = rho_grid_colour_split(colour_bits);
  const auto d = [](std::uint32_t q, int bits) {
    const std::uint32_t m = (1u << bits) - 1u;
    return std::uint8_t(((q & m) * 255u + m / 2) / m);
  };
  return {d(code, br), d(code >> br, bg), d(code >> (br + bg), bb)};
}

struct rho_grid_options {
  /// The level of the leaves as the paper numbers it (Table 2's oct/7, tri/4, ...): the leaves
  /// are the cells of a ρ^(level+1) grid over the bounding cube — oct/7 is a 256³ grid, tri/4 a
  /// 243³ grid. (Level 0 is the first ρ×ρ×ρ grid; the cube itself is level −1, which builds a
  /// single cell.) Range [−1, rho_grid_max_level(ρ)].
  /// Unset: rho_grid_auto_level — for a mesh the coarsest level with at least 512 leaves across
  /// the cube (about a pixel per leaf when the model fills a 512-pixel view: tri/5, oct/8); for
  /// a point cloud no finer than its sampling (the finest level whose occupied leaves hold ≥ 4
  /// input points on average: about two point spacings across), so that the leaves of a sparse
  /// cloud still tile its surface and do not draw as isolated dots.
  std::optional<int> level = std::nullopt;
  /// Bits of the quantised normal (pbr_lod::normal_quantizer, 6..16), 0 for none. 13 as in the
  /// paper (and Botsch 2002). Ignored (no bits) when the input has no normals: a point cloud
  /// without normals. A mesh always has geometric normals.
  int normal_bits = 13;
  /// A point cloud without normals: neighbours of the k-NN PCA normal estimated for every point
  /// (core/estimation.hpp, the point-octree's front end), so that its cells are shaded like the
  /// other builders'. 0 keeps no normals (normal_bits ignored), as the paper's builder would: its
  /// inputs are meshes. Ours, not the paper's; docs/rho-grid.md measures both.
  int knn = 16;
  /// Where the scanner stood, in world coordinates: estimated normals face it (one pass) instead
  /// of being made consistent over the k-NN graph (point_cloud::sensor is used when this is
  /// unset).
  std::optional<vec3d> viewpoint = std::nullopt;
  /// Bits of the material index (0..8), 0 for none; 3 = 8 materials as in the paper. Ignored
  /// when the input has no materials. Materials ≥ 2^bits are an InvalidArgument.
  int material_bits = 3;
  /// Bits of the quantised colour (0, or 3…16; rho_grid_colour_split: 16 = 5:6:5), 0 for none.
  /// Ignored (no bits) when the input has no colours. A sample takes the colour at its closest
  /// point (a mesh: interpolated from the vertex colours; a cloud: the sample point's).
  int colour_bits = 16;
  /// Threads for the build (0 = hardware concurrency). The grid does not depend on it.
  unsigned threads = 0;
  /// Keep the sampled surface point of every cell (world = origin + value) in sample_points
  /// (tests: every sample lies on the surface). Costs 12 bytes per cell.
  bool keep_sample_points = false;
  /// Called after each level with the fraction done (0..1); return false to cancel (the build
  /// then throws pbr_lod::Cancelled).
  std::function<bool(double)> progress = {};
};

/// What a build measured. Bits per leaf sample are of the actual streams and structure.
struct rho_grid_stats {
  int rho = 0, level = 0, sigma = 0;  ///< level as in rho_grid_options
  std::size_t samples = 0;            ///< leaf samples n
  std::size_t inner_cells = 0;        ///< N, non-empty non-leaf cells (Eq. 1)
  double bits_per_sample_nis = 0;     ///< NIS stream payload bits / n
  double bits_per_sample_is = 0;      ///< IS stream payload bits / n
  double bits_per_sample_incore = 0;  ///< memory_bytes()·8 / n
  /// Whether build_seconds was measured by this build; a loaded file has no timings (its bytes
  /// depend only on the input and the options, so two builds compare equal).
  bool has_timings = false;
  double build_seconds = 0;
  /// The point cloud had no normals and the build estimated them (rho_grid_options::knn).
  bool estimated_normals = false;
  double estimation_seconds = 0;  ///< of the k-NN normals, inside build_seconds
  /// Normals of a point cloud that were zero or not finite — "no normal" (3DGS files store
  /// zeros) — and were estimated from the positions (fill_missing_normals, k = knn or 16; all of
  /// them when all are missing). Measured by the build; a loaded file reports 0.
  std::size_t normals_filled = 0;
  /// Largest bytes held by the build's per-level working set (cell coordinates of two levels,
  /// sampling results) on top of the structure itself.
  std::size_t peak_working_bytes = 0;
};

/// Layout of a saved stream (§3.2).
enum class rho_grid_layout : std::uint32_t {
  nis = 0,  ///< no intermediate samples: codes in pre-order, then the leaf attributes
  is = 1,   ///< intermediate samples: per cell in pre-order, attribute then code (leaf: attribute)
  /// Beyond the paper: the codes and every cell's attribute (as IS holds them) entropy-coded
  /// with an adaptive binary range coder, contexts from the neighbourhood (G-PCC style) and
  /// attributes predicted from the parent cell's (detail/rho_grid_coder.hpp).
  compressed = 2,
};

/// Sizes of the compressed layout: the real byte counts of the streams the decoder reads.
struct rho_grid_coded_size {
  std::uint64_t geometry_bytes = 0;       ///< range-coded childhood codes
  std::uint64_t attribute_bytes = 0;      ///< range-coded attributes of every cell (inner + leaf)
  std::uint64_t file_bytes = 0;           ///< serialise(compressed).size(): + header + checksum
  double bits_per_sample_geometry = 0;    ///< geometry_bytes·8 / leaf samples
  double bits_per_sample_attributes = 0;  ///< attribute_bytes·8 / leaf samples
};

namespace detail {
/// The childhood code of a ρ-grid cell: ρ³ bits in the smallest unsigned words that hold them
/// (ρ=2: 8 bits, ρ=3: 32 bits for 27, ρ=4: 64, ρ=5: 2×64 for 125).
template <int Rho>
struct child_code {
  static constexpr int bits = Rho * Rho * Rho;
  using word = std::conditional_t<(bits <= 8), std::uint8_t,
                                  std::conditional_t<(bits <= 32), std::uint32_t, std::uint64_t>>;
  static constexpr int word_bits = 8 * sizeof(word);
  static constexpr int words = (bits + word_bits - 1) / word_bits;
  std::array<word, words> w{};

  [[nodiscard]] bool test(int j) const {
    return (w[std::size_t(j / word_bits)] >> (j % word_bits)) & 1u;
  }
  void set(int j) { w[std::size_t(j / word_bits)] |= word(word(1) << (j % word_bits)); }
  [[nodiscard]] int count() const {
    int n = 0;
    for (auto x : w) n += std::popcount(x);
    return n;
  }
  /// Number of set bits below bit j: the offset of child j in the cell's child table.
  [[nodiscard]] int rank(int j) const {
    int n = 0;
    const int full = j / word_bits;
    for (int i = 0; i < full; ++i) n += std::popcount(w[std::size_t(i)]);
    const int rem = j % word_bits;
    if (rem) n += std::popcount(word(w[std::size_t(full)] & word((word(1) << rem) - 1)));
    return n;
  }
  [[nodiscard]] bool empty() const { return count() == 0; }
  friend bool operator==(const child_code&, const child_code&) = default;
};
template <int Rho>
struct rho_grid_access;
}  // namespace detail

/// A ρ-grid over a triangle mesh or a point cloud (ρ ∈ {2,3,4,5}: octree, tri-grid, ...).
///
/// Levels and depths: level() is the paper's level of the leaves (rho_grid_options::level). A
/// cell's *depth* d counts the subdivisions of the bounding cube above it: the cube (the root)
/// has depth 0, the cells of the paper's level l have depth l + 1, the leaves leaf_depth() =
/// level() + 1. The per-cell accessors (depth_begin, cell_side) and rho_grid_node take depths.
///
/// Cells are numbered breadth first: depth 0 is the root (cell 0), and the cells of each depth
/// follow in path order, the children of a cell contiguous and in increasing digit order, digit
/// j = x + ρ·y + ρ²·z of the child's position in its parent. Cells [0, inner_count()) are inner
/// (every depth < leaf_depth()); the rest are the leaves (depth leaf_depth()). Inner cell i's
/// children are cells first_child(i) + rank, one per set bit of code(i) — the §3.3 child table is
/// the cell array itself, so the pointer is a 32-bit index.
///
/// Geometry: the bounding cube has its minimum corner at origin() (double) and side cube_side();
/// a cell at depth d with integer position (x, y, z) ∈ [0, ρ^d)³ has centre
/// origin + ((x, y, z) + ½)·cube_side/ρ^d. Attribute of a cell: normal code in the low
/// normal_bits() bits, material above it.
template <int Rho>
class rho_grid {
  static_assert(Rho >= 2 && Rho <= 5, "ρ-grids are built for ρ = 2, 3, 4, 5");

 public:
  static constexpr int rho = Rho;
  static constexpr int children_per_cell = Rho * Rho * Rho;
  using code_type = detail::child_code<Rho>;

  rho_grid() = default;

  /// The paper's level of the leaves (rho_grid_options::level); −1 for a single-cell grid.
  [[nodiscard]] int level() const { return leaf_depth_ - 1; }
  /// Depth of the leaves below the root cube: level() + 1, the k of Eq. 1–3.
  [[nodiscard]] int leaf_depth() const { return leaf_depth_; }
  [[nodiscard]] bool empty() const { return attrs_count_ == 0; }
  [[nodiscard]] vec3d origin() const { return origin_; }
  [[nodiscard]] double cube_side() const { return side_; }
  /// The input's bounding sphere in world coordinates: centre of the input points' bounding box,
  /// radius to the farthest point (core/bounds.hpp, bounding_sphere_about_box_centre) — what
  /// `pbrlod render` frames, so the same --view frames an input and its ρ-grid alike. The cube
  /// is larger (a power-of-ρ grid around the box) and would frame the model smaller.
  [[nodiscard]] vec3d input_centre() const { return input_centre_; }
  [[nodiscard]] double input_radius() const { return input_radius_; }
  [[nodiscard]] int normal_bits() const { return normal_bits_; }
  [[nodiscard]] int material_bits() const { return material_bits_; }
  /// Bits of the quantised colour (0 when the input had none).
  [[nodiscard]] int colour_bits() const { return colour_bits_; }
  /// σ: the bits of a sample's attributes, normal + material + colour.
  [[nodiscard]] int sigma() const { return normal_bits_ + material_bits_ + colour_bits_; }
  [[nodiscard]] bool has_normals() const { return normal_bits_ > 0; }
  [[nodiscard]] bool has_materials() const { return material_bits_ > 0; }
  [[nodiscard]] bool has_colours() const { return colour_bits_ > 0; }

  [[nodiscard]] std::size_t cell_count() const { return attrs_count_; }
  [[nodiscard]] std::size_t inner_count() const { return codes_.size(); }
  [[nodiscard]] std::size_t leaf_count() const { return attrs_count_ - codes_.size(); }
  /// First cell of depth d (0 ≤ d ≤ leaf_depth() + 1; depth_begin(leaf_depth() + 1) =
  /// cell_count()).
  [[nodiscard]] std::uint32_t depth_begin(int d) const { return depth_start_[std::size_t(d)]; }
  [[nodiscard]] bool is_leaf(std::uint32_t c) const { return c >= codes_.size(); }
  [[nodiscard]] const code_type& code(std::uint32_t c) const { return codes_[c]; }
  [[nodiscard]] std::uint32_t first_child(std::uint32_t c) const { return first_child_[c]; }
  /// Normal and material of cell c (normal code in the low normal_bits(), material above; 0
  /// when the grid stores neither).
  [[nodiscard]] std::uint32_t attribute(std::uint32_t c) const {
    return attrs_.empty() ? 0u : attrs_[c];
  }
  /// Colour code of cell c (rho_grid_encode_colour; 0 without colours).
  [[nodiscard]] std::uint32_t colour_code(std::uint32_t c) const {
    return colours_.empty() ? 0u : colours_[c];
  }
  [[nodiscard]] rgb8 colour(std::uint32_t c) const {
    return rho_grid_decode_colour(colour_code(c), colour_bits_);
  }
  /// The whole σ-bit sample of cell c as the streams store it: attribute(c) in the low
  /// normal + material bits, the colour code above.
  [[nodiscard]] std::uint32_t sample_bits(std::uint32_t c) const {
    return attribute(c) | (colour_code(c) << (normal_bits_ + material_bits_));
  }
  [[nodiscard]] std::uint32_t normal_code(std::uint32_t c) const {
    return attribute(c) & ((1u << normal_bits_) - 1u);
  }
  [[nodiscard]] std::uint32_t material(std::uint32_t c) const {
    return attribute(c) >> normal_bits_;
  }
  /// Side of a cell at depth d.
  [[nodiscard]] double cell_side(int d) const { return side_ / std::pow(double(Rho), d); }

  /// The sampled surface points (relative to origin(), one per cell), when the build kept them.
  [[nodiscard]] const std::vector<vec3f>& sample_points() const { return sample_points_; }
  [[nodiscard]] const rho_grid_stats& stats() const { return stats_; }

  /// Bytes of the §3.3 in-core structure: codes and 32-bit child indices of the inner cells,
  /// 16-bit attributes of every cell (none when normal + material bits = 0) and 16-bit colours
  /// of every cell (none without colours).
  [[nodiscard]] std::size_t memory_bytes() const {
    return codes_.size() * (sizeof(code_type) + sizeof(std::uint32_t)) +
           attrs_.size() * sizeof(std::uint16_t) + colours_.size() * sizeof(std::uint16_t);
  }
  /// Payload bits of a stream (§3.2), without the file header and checksum.
  [[nodiscard]] std::uint64_t payload_bits(rho_grid_layout layout) const {
    const std::uint64_t s = std::uint64_t(sigma()), n = leaf_count(), inner = inner_count();
    return inner * std::uint64_t(children_per_cell) + n * s +
           (layout == rho_grid_layout::is ? inner * s : 0);
  }

  // ---- storage (§3.2)
  /// The whole file (header, packed or coded payload, checksum) as bytes.
  [[nodiscard]] std::vector<unsigned char> serialise(rho_grid_layout layout) const;
  /// Parses and validates bytes written by serialise(); `what` names the data in messages.
  /// Throws FormatError for anything malformed: magic, version, ρ, every length, the tree shape
  /// against the counts, normal codes, trailing bits, checksum; for the compressed layout every
  /// decoded symbol against the counts and ranges, and the exact stream lengths. An NIS stream has
  /// no inner attributes: they are rebuilt bottom-up (mean of the children's normals, re-quantised;
  /// material of the first child), so load(NIS) equals the build in codes and leaf attributes.
  [[nodiscard]] static rho_grid parse(const std::vector<unsigned char>& bytes,
                                      const std::string& what = "rho-grid stream");
  /// Encodes the compressed layout and returns its sizes (costs one encode).
  [[nodiscard]] rho_grid_coded_size coded_size() const;
  /// Writes serialise(layout) to path; throws IoError.
  void save(const std::string& path, rho_grid_layout layout = rho_grid_layout::is) const;
  /// Reads a file written by save(); throws IoError / FormatError.
  [[nodiscard]] static rho_grid load(const std::string& path);

  /// Equal structure and attributes (sample points and stats are not compared).
  friend bool operator==(const rho_grid& a, const rho_grid& b) {
    return a.leaf_depth_ == b.leaf_depth_ && a.origin_ == b.origin_ && a.side_ == b.side_ &&
           a.input_centre_ == b.input_centre_ && a.input_radius_ == b.input_radius_ &&
           a.normal_bits_ == b.normal_bits_ && a.material_bits_ == b.material_bits_ &&
           a.colour_bits_ == b.colour_bits_ && a.colours_ == b.colours_ && a.codes_ == b.codes_ &&
           a.first_child_ == b.first_child_ && a.attrs_ == b.attrs_ &&
           a.depth_start_ == b.depth_start_ && a.attrs_count_ == b.attrs_count_;
  }

 private:
  friend struct detail::rho_grid_access<Rho>;
  int leaf_depth_ = 0;
  vec3d origin_ = vec3d::Zero();
  double side_ = 1;
  vec3d input_centre_ = vec3d::Zero();
  double input_radius_ = 0;
  int normal_bits_ = 0, material_bits_ = 0, colour_bits_ = 0;
  std::vector<code_type> codes_;            // inner cells
  std::vector<std::uint32_t> first_child_;  // inner cells
  std::vector<std::uint16_t> attrs_;        // every cell (empty when normal + material bits = 0)
  std::vector<std::uint16_t> colours_;      // every cell (empty without colours)
  std::vector<std::uint32_t> depth_start_;  // leaf_depth + 2 entries
  std::size_t attrs_count_ = 0;             // cells
  std::vector<vec3f> sample_points_;
  rho_grid_stats stats_;
};

/// Builds the ρ-grid of a triangle mesh (§3.1): a cell is non-empty when a triangle meets the
/// closed cell (exact CGAL triangle/box test); its sample is the closest surface point to the
/// centre. Exactly degenerate (zero-area) triangles are skipped; a mesh whose faces are all
/// degenerate (or that has none) is built from its vertices as a point cloud. Throws
/// InvalidArgument for an empty/invalid mesh, non-finite coordinates, bad options.
template <int Rho>
[[nodiscard]] rho_grid<Rho> build_rho_grid(const triangle_mesh& mesh,
                                           const rho_grid_options& options = {});

/// Builds the ρ-grid of a point cloud: a cell is non-empty when it holds an input point; its
/// sample is that cell's input point closest to the centre, with its normal (the cloud's, else
/// estimated from options.knn neighbours), material and colour (when the cloud has them).
template <int Rho>
[[nodiscard]] rho_grid<Rho> build_rho_grid(const point_cloud& points,
                                           const rho_grid_options& options = {});

/// Calls f(rho_grid<R>-typed tag) for the run-time ρ: f.template operator()<R>() with R ∈ 2..5.
/// Throws InvalidArgument for any other ρ. This is the CLI's entry point:
///   visit_rho(rho, [&]<int R>() { auto g = build_rho_grid<R>(mesh, opt); ... });
template <class F>
decltype(auto) visit_rho(int rho, F&& f) {
  switch (rho) {
    case 2:
      return f.template operator()<2>();
    case 3:
      return f.template operator()<3>();
    case 4:
      return f.template operator()<4>();
    case 5:
      return f.template operator()<5>();
    default:
      throw InvalidArgument("rho-grid: rho must be 2, 3, 4 or 5, got " + std::to_string(rho));
  }
}

/// The level rho_grid_options::level = nullopt builds (see there): for a mesh from ρ alone, for a
/// point cloud also from its occupancy (points per occupied leaf, counted from the sorted leaf
/// paths at the mesh level and each coarser one). Throws like build_rho_grid for an empty or
/// invalid input.
template <int Rho>
[[nodiscard]] int rho_grid_auto_level(const triangle_mesh& mesh);
template <int Rho>
[[nodiscard]] int rho_grid_auto_level(const point_cloud& points);

/// ρ of a saved rho-grid file (reads the header only); throws IoError / FormatError.
[[nodiscard]] int rho_grid_file_rho(const std::string& path);

extern template class rho_grid<2>;
extern template class rho_grid<3>;
extern template class rho_grid<4>;
extern template class rho_grid<5>;

}  // namespace pbr_lod
