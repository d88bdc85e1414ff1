// pbr_lod — unit normals quantised to q bits through a table of directions.
//
// This work is based on:
//   R. Pajarola, "Efficient Level-of-Details for Point Based Rendering", CGIM 2003:
//   §5 and Fig. 9 (3 octant bits + a triangular latitude/longitude table over one octant),
//   Fig. 13 (q = 12: 31 latitude steps, 496 directions per octant).
//
// Layout (ours; the paper fixes only the triangular shape, see docs/normal-quantization.md):
//   code = octant << (q − 3) | t,   octant bit 0 = (x < 0), bit 1 = (y < 0), bit 2 = (z < 0),
//   t = i·(i + 1)/2 + j  for latitude row i ∈ [0, k) and longitude column j ∈ [0, i],
//   k the largest integer with k(k + 1)/2 ≤ 2^(q − 3)   (q = 12 → 31, q = 16 → 127).
//   Row i owns the band of polar angles [b(i−1), b(i)] with 1 − cos b(i) = (i+1)(i+2)/(k(k+1)),
//   i.e. the band's area is proportional to its i + 1 samples (equal area per direction); the
//   row sits at the band's middle angle θ_i = (b(i−1) + b(i))/2 (b(−1) = 0), and its samples at
//   the cell centres φ_ij = (π/2)·(j + ½)/(i + 1). No table direction lies on an octant
//   boundary, so no two codes decode to the same direction and negating a direction only flips
//   the three octant bits (negate()).
//
// Measured against the paper's literal layout (rows at (π/2)·i/(k−1), samples on both octant
// edges) this lowers the worst error at q = 12 from 2.63° to 2.38° and the mean from 1.31° to
// 1.23° (numbers and method in docs/normal-quantization.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "pbr_lod/core/math.hpp"
#include "pbr_lod/core/memory.hpp"

namespace pbr_lod {

/// Encodes unit normals as q-bit codes and back. Immutable after construction: const member
/// functions are safe for concurrent readers. The table holds k(k+1)/2 float directions
/// (q = 16: 8128 entries, 95 kB; q = 24: 2.1 M entries, 25 MB); up to q = 16 a candidate grid
/// for encode() adds 8 B per cell (q = 16: 256², 512 kB, ≈ 3 ms to build; q = 12: 64², 32 kB).
/// Construct once and share (shared()) rather than per call.
class normal_quantizer {
 public:
  static constexpr int min_bits = 6;   ///< k = 3: 6 directions per octant, worst error ≈ 24°
  static constexpr int max_bits = 24;  ///< k = 2047: worst error ≈ 0.04°, 25 MB table

  /// Throws InvalidArgument unless min_bits ≤ q_bits ≤ max_bits.
  explicit normal_quantizer(int q_bits);

  /// A quantizer for q_bits shared by every caller: built once per q ≤ max_shared_bits and kept
  /// for the life of the program (at most 1.5 MB each), built afresh above that (its table is
  /// up to 25 MB). Building the q = 16 table and its candidate grid takes ≈ 3 ms, a fifth of a
  /// 69 k-triangle POP build.
  /// Thread-safe. Throws InvalidArgument as the constructor does.
  [[nodiscard]] static std::shared_ptr<const normal_quantizer> shared(int q_bits);
  static constexpr int max_shared_bits = 20;

  /// The code of the table direction nearest to n (largest dot product, evaluated in double
  /// against the float table entries that decode() returns; ties go to the first candidate in a
  /// fixed order, so the result is deterministic). n need not be unit length. A zero-length or
  /// non-finite n (NaN, ±Inf component) encodes as +z does: code 0. −0.0 counts as positive.
  [[nodiscard]] std::uint32_t encode(const vec3f& n) const;

  /// encode() of every in[i] into out[i], the same codes. Faster over many normals: the
  /// candidate grid's cells (512 kB at q = 16, so often not in cache) are loaded for a run of
  /// normals before any of them is searched, so their cache misses overlap (bench_core:
  /// BM_EncodeMany). Throws InvalidArgument when the sizes differ.
  void encode(std::span<const vec3f> in, std::span<std::uint32_t> out) const;

  /// The unit direction of a code; throws InvalidArgument when !valid(code).
  [[nodiscard]] vec3f decode(std::uint32_t code) const {
    if (!valid(code)) throw_invalid_code(code);
    const vec3f& d = dirs_[code & index_mask_];
    const std::uint32_t o = code >> (bits_ - 3);
    return {(o & 1u) ? -d.x() : d.x(), (o & 2u) ? -d.y() : d.y(), (o & 4u) ? -d.z() : d.z()};
  }

  /// The code of −decode(code) (exactly: the table is symmetric under sign flips and has no
  /// direction on an octant boundary). Throws InvalidArgument when !valid(code).
  [[nodiscard]] std::uint32_t negate(std::uint32_t code) const {
    if (!valid(code)) throw_invalid_code(code);
    return code ^ (7u << (bits_ - 3));
  }

  /// True for the codes decode() accepts: q bits with index t < k(k+1)/2 in its octant.
  [[nodiscard]] bool valid(std::uint32_t code) const {
    return (code >> bits_) == 0 && (code & index_mask_) < per_octant_;
  }

  /// Number of distinct directions, 8·k(k+1)/2 (≤ 2^q; the remaining codes are invalid).
  [[nodiscard]] std::size_t size() const { return 8 * std::size_t(per_octant_); }
  /// q, the number of bits of a code.
  [[nodiscard]] int bits() const { return bits_; }
  /// k, the number of latitude rows per octant.
  [[nodiscard]] int latitude_steps() const { return k_; }
  /// Cells per side of encode()'s candidate grid over the octant's octahedral coordinates
  /// (|x|, |y|)/(|x| + |y| + |z|), the smallest power of two ≥ 2k; 0 above q = 16, where
  /// encode() searches the latitude rows instead (docs/normal-quantization.md).
  [[nodiscard]] std::uint32_t candidate_grid() const { return grid_; }

  /// A guaranteed upper bound on the angle between a unit n and decode(encode(n)), in degrees
  /// (from the band geometry: the worst point of row i's band is on a band edge, half a
  /// longitude cell away; plus 1e-6 rad for the float rounding of the table). About 13 % above
  /// the worst error measured over 10⁶ random normals. A normal cone built from decoded normals
  /// must be widened by this much to bound the original normals.
  [[nodiscard]] double max_error_degrees() const { return max_error_deg_; }

 private:
  [[noreturn]] void throw_invalid_code(std::uint32_t code) const;
  void search_row(int row, double ax, double ay, double az, double phi_cells, double& best_dot,
                  std::uint32_t& best) const;
  void build_cells();
  static constexpr std::uint64_t no_cell = ~std::uint64_t{0};
  std::uint64_t cell_of(const vec3f& n) const;
  std::uint32_t encode_in(const vec3f& n, std::uint64_t cell) const;

  int bits_ = 0;
  int k_ = 0;
  std::uint32_t per_octant_ = 0;    // k(k+1)/2
  std::uint32_t index_mask_ = 0;    // 2^(q−3) − 1
  std::vector<vec3f> dirs_;         // first octant, index t
  std::vector<double> row_cos_;     // cos θ_i
  std::vector<double> row_sin_;     // sin θ_i
  std::vector<double> row_margin_;  // search_row(): how near a cell edge both neighbours compete
  // Candidate grid (q ≤ 16): the folded normal's octahedral coordinates (|x|, |y|)/‖n‖₁ pick one
  // of grid_ × grid_ cells; each holds up to four entries, every one whose region can meet the
  // cell, in ascending index (16 bits each, 0xFFFF = none). A cell whose first slot is 0xFFFF
  // has more than four (or lies outside the octant): the row search decides there.
  std::uint32_t grid_ = 0;
  std::vector<std::uint64_t, detail::mapped_allocator<std::uint64_t>> cells_;
  double max_error_deg_ = 0;
};

}  // namespace pbr_lod
