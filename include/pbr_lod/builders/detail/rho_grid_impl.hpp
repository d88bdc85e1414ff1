// pbr_lod — internals of the ρ-grid: packed bit streams (§3.2) and the assembly of the in-core
// structure (§3.3) from the codes of a breadth-first build or a pre-order stream.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/core/error.hpp"

namespace pbr_lod::detail {

/// Appends bit fields LSB first into bytes (bit i of the stream is bit i%8 of byte i/8).
class bit_writer {
 public:
  /// Writes the low `n` bits of v (0 ≤ n ≤ 64).
  void put(std::uint64_t v, int n) {
    for (int i = 0; i < n;) {
      const int used = int(bits_ % 8);
      if (used == 0) bytes_.push_back(0);
      const int take = std::min(8 - used, n - i);
      const auto chunk = static_cast<unsigned>((v >> i) & ((1u << take) - 1u));
      bytes_.back() = static_cast<unsigned char>(bytes_.back() | (chunk << used));
      bits_ += std::uint64_t(take);
      i += take;
    }
  }
  [[nodiscard]] std::uint64_t bits() const { return bits_; }
  [[nodiscard]] std::vector<unsigned char>& bytes() { return bytes_; }

 private:
  std::vector<unsigned char> bytes_;
  std::uint64_t bits_ = 0;
};

/// Reads bit fields written by bit_writer from bytes [begin, begin + bit_count/8⌉); reading past
/// bit_count throws FormatError naming `what`.
class bit_reader {
 public:
  bit_reader(const unsigned char* data, std::uint64_t bit_count, const std::string& what)
      : data_(data), bit_count_(bit_count), what_(what) {}
  std::uint64_t get(int n, const char* element) {
    if (bit_count_ - pos_ < std::uint64_t(n))
      throw FormatError(what_ + ": truncated payload while reading " + element + " at bit " +
                        std::to_string(pos_) + " of " + std::to_string(bit_count_));
    std::uint64_t v = 0;
    for (int i = 0; i < n;) {
      const int used = int(pos_ % 8);
      const int take = std::min(8 - used, n - i);
      const std::uint64_t chunk = (data_[pos_ / 8] >> used) & ((1u << take) - 1u);
      v |= chunk << i;
      pos_ += std::uint64_t(take);
      i += take;
    }
    return v;
  }
  [[nodiscard]] std::uint64_t position() const { return pos_; }

 private:
  const unsigned char* data_;
  std::uint64_t bit_count_;
  std::uint64_t pos_ = 0;
  const std::string& what_;
};

template <int Rho>
struct rho_grid_access {
  using grid = rho_grid<Rho>;
  static auto& codes(grid& g) { return g.codes_; }
  static auto& attrs(grid& g) { return g.attrs_; }
  static auto& colours(grid& g) { return g.colours_; }
  static void set_colour_bits(grid& g, int cb) { g.colour_bits_ = cb; }
  static auto& samples(grid& g) { return g.sample_points_; }
  static auto& stats(grid& g) { return g.stats_; }
  static void set_input_bounds(grid& g, const vec3d& centre, double radius) {
    g.input_centre_ = centre;
    g.input_radius_ = radius;
  }
  static void set_frame(grid& g, int leaf_depth, const vec3d& origin, double side, int nb, int mb) {
    g.leaf_depth_ = leaf_depth;
    g.origin_ = origin;
    g.side_ = side;
    g.normal_bits_ = nb;
    g.material_bits_ = mb;
  }
  /// Derives child indices and depth starts from the codes (breadth-first), checking that the
  /// shape is a complete depth-k tree: every inner cell has a child, every cell above depth k is
  /// inner, and the cells add up to `cells`. Throws FormatError naming `what` otherwise.
  static void finish(grid& g, std::size_t cells, const std::string& what) {
    g.attrs_count_ = cells;
    g.first_child_.assign(g.codes_.size(), 0);
    g.depth_start_.assign(std::size_t(g.leaf_depth_) + 2, 0);
    std::uint64_t begin = 0, end = 1;  // cells of the current depth
    for (int l = 0; l < g.leaf_depth_; ++l) {
      if (end > g.codes_.size())
        throw FormatError(what + ": depth " + std::to_string(l) + " needs " + std::to_string(end) +
                          " childhood codes, the stream has " + std::to_string(g.codes_.size()));
      std::uint64_t next = end;
      for (std::uint64_t i = begin; i < end; ++i) {
        const int n = g.codes_[i].count();
        if (n == 0)
          throw FormatError(what + ": inner cell " + std::to_string(i) + " has an empty code");
        g.first_child_[i] = std::uint32_t(next);
        next += std::uint64_t(n);
        if (next > 0xffffffffull)
          throw FormatError(what + ": more cells than 32-bit child indices address");
      }
      g.depth_start_[std::size_t(l) + 1] = std::uint32_t(end);
      begin = end;
      end = next;
    }
    g.depth_start_[std::size_t(g.leaf_depth_)] = std::uint32_t(begin);
    g.depth_start_[std::size_t(g.leaf_depth_) + 1] = std::uint32_t(end);
    if (g.codes_.size() != begin)
      throw FormatError(what + ": " + std::to_string(g.codes_.size()) +
                        " childhood codes, but the tree has " + std::to_string(begin) +
                        " inner cells");
    if (end != cells)
      throw FormatError(what + ": the codes describe " + std::to_string(end) + " cells, " +
                        std::to_string(cells) + " were stored");
    auto& s = g.stats_;
    s.rho = Rho;
    s.level = g.level();
    s.sigma = g.sigma();
    s.samples = g.leaf_count();
    s.inner_cells = g.inner_count();
    const double n = std::max<double>(1, double(s.samples));
    s.bits_per_sample_nis = double(g.payload_bits(rho_grid_layout::nis)) / n;
    s.bits_per_sample_is = double(g.payload_bits(rho_grid_layout::is)) / n;
    s.bits_per_sample_incore = double(g.memory_bytes()) * 8 / n;
  }
};

}  // namespace pbr_lod::detail
