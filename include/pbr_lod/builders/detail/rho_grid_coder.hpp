// pbr_lod — internals of the ρ-grid's compressed layout (beyond the paper): an adaptive binary
// range coder and the context models that code childhood codes and attributes with it.
//
// The coder is the classic carry-propagating binary range coder (32-bit range, 64-bit low with
// a one-byte cache, as in LZMA's rc), written here from its description, with 12-bit adaptive
// probabilities updated by p += (4096 − p) >> 5 / p −= p >> 5 (a ~32-symbol memory; p stays in
// [31, 4065], so no symbol ever costs more than ~7 bits). The decoder reads exactly the bytes
// the encoder wrote: 5 at start, one per renormalisation shift, the encoder's 5 flush bytes
// matching; so a stream read to its end with bytes left over, or read past its end, is corrupt.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/core/error.hpp"

namespace pbr_lod::detail {

/// An adaptive probability that the next bit is 0, in units of 2^-12.
using range_prob = std::uint16_t;
inline constexpr int range_prob_bits = 12;
inline constexpr range_prob range_prob_init = 1u << (range_prob_bits - 1);
inline constexpr int range_prob_shift = 5;

class range_encoder {
 public:
  void encode(range_prob& p, unsigned bit) {
    const std::uint32_t bound = (range_ >> range_prob_bits) * p;
    if (bit == 0) {
      range_ = bound;
      p = range_prob(p + (((1u << range_prob_bits) - p) >> range_prob_shift));
    } else {
      low_ += bound;
      range_ -= bound;
      p = range_prob(p - (p >> range_prob_shift));
    }
    while (range_ < (1u << 24)) {
      range_ <<= 8;
      shift_low();
    }
  }
  /// Flushes and returns the stream (the encoder is spent afterwards).
  [[nodiscard]] std::vector<unsigned char> finish() {
    for (int i = 0; i < 5; ++i) shift_low();
    return std::move(out_);
  }

 private:
  void shift_low() {
    // The byte leaving `low` is final unless a later carry can still reach it: bytes of 0xFF are
    // held back (cache_size_) until the carry is known.
    if (std::uint32_t(low_) < 0xFF000000u || (low_ >> 32) != 0) {
      const auto carry = static_cast<unsigned char>(low_ >> 32);
      unsigned char b = cache_;
      do {
        out_.push_back(static_cast<unsigned char>(b + carry));
        b = 0xFF;
      } while (--cache_size_ != 0);
      cache_ = static_cast<unsigned char>(low_ >> 24);
    }
    ++cache_size_;
    low_ = (low_ & 0x00FFFFFFu) << 8;
  }
  std::uint64_t low_ = 0;
  std::uint32_t range_ = 0xFFFFFFFFu;
  unsigned char cache_ = 0;
  std::uint64_t cache_size_ = 1;
  std::vector<unsigned char> out_;
};

/// Decodes a range_encoder stream from [data, data + size); every failure (reading past the
/// end, a non-zero first byte, bytes left at finish()) is a FormatError naming `what`.
class range_decoder {
 public:
  range_decoder(const unsigned char* data, std::size_t size, std::string what)
      : data_(data), size_(size), what_(std::move(what)) {
    if (next() != 0) throw FormatError(what_ + ": range-coded stream does not start with 0");
    for (int i = 0; i < 4; ++i) code_ = (code_ << 8) | next();
  }
  unsigned decode(range_prob& p) {
    const std::uint32_t bound = (range_ >> range_prob_bits) * p;
    unsigned bit;
    if (code_ < bound) {
      range_ = bound;
      p = range_prob(p + (((1u << range_prob_bits) - p) >> range_prob_shift));
      bit = 0;
    } else {
      code_ -= bound;
      range_ -= bound;
      p = range_prob(p - (p >> range_prob_shift));
      bit = 1;
    }
    while (range_ < (1u << 24)) {
      range_ <<= 8;
      code_ = (code_ << 8) | next();
    }
    return bit;
  }
  /// Throws unless every byte was consumed.
  void finish() const {
    if (pos_ != size_)
      throw FormatError(what_ + ": " + std::to_string(size_ - pos_) +
                        " bytes left over after the range-coded stream");
  }

 private:
  std::uint32_t next() {
    if (pos_ >= size_)
      throw FormatError(what_ + ": range-coded stream truncated at byte " + std::to_string(pos_));
    return data_[pos_++];
  }
  const unsigned char* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
  std::uint32_t code_ = 0;
  std::uint32_t range_ = 0xFFFFFFFFu;
  std::string what_;  // owned: callers pass composed names
};

/// Adaptive Exp-Golomb code of an unsigned integer: the bit length of v + 1 in unary (one
/// context per position), then the bits under its leading one (one context per (length,
/// position)). Small values, the common residuals, cost a few adaptive bits.
struct adaptive_uint {
  static constexpr int max_prefix = 24;  // values < 2^24; a longer prefix is corrupt data
  range_prob prefix[max_prefix + 1];
  range_prob suffix[max_prefix + 1][max_prefix];
  adaptive_uint() {
    for (auto& p : prefix) p = range_prob_init;
    for (auto& row : suffix)
      for (auto& p : row) p = range_prob_init;
  }
  void encode(range_encoder& e, std::uint32_t v) {
    const std::uint32_t m = v + 1;
    const int n = std::bit_width(m) - 1;  // bits under the leading one
    for (int t = 0; t < n; ++t) e.encode(prefix[t], 1);
    e.encode(prefix[n], 0);
    for (int t = n - 1; t >= 0; --t) e.encode(suffix[n][t], (m >> t) & 1u);
  }
  std::uint32_t decode(range_decoder& d, const std::string& what) {
    int n = 0;
    while (d.decode(prefix[n])) {
      if (++n > max_prefix - 1) throw FormatError(what + ": residual out of range");
    }
    std::uint32_t m = 1;
    for (int t = n - 1; t >= 0; --t) m = (m << 1) | d.decode(suffix[n][t]);
    return m - 1;
  }
};

/// Signed integer: zero flag, sign, then |v| − 1 as an adaptive_uint.
struct adaptive_int {
  range_prob zero = range_prob_init, sign = range_prob_init;
  adaptive_uint magnitude;
  void encode(range_encoder& e, std::int32_t v) {
    e.encode(zero, v != 0);
    if (v == 0) return;
    e.encode(sign, v < 0);
    magnitude.encode(e, std::uint32_t(v < 0 ? -v : v) - 1);
  }
  std::int32_t decode(range_decoder& d, const std::string& what) {
    if (!d.decode(zero)) return 0;
    const bool neg = d.decode(sign);
    const auto m = std::int32_t(magnitude.decode(d, what)) + 1;
    return neg ? -m : m;
  }
};

/// Open-addressing set of packed cell positions (x | y << 21 | z << 42, each < 2^21, which
/// rho_grid_max_leaf_depth guarantees), for the neighbourhood contexts.
class cell_set {
 public:
  static constexpr std::uint64_t empty_key = ~std::uint64_t(0);
  static std::uint64_t key(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
    return std::uint64_t(x) | (std::uint64_t(y) << 21) | (std::uint64_t(z) << 42);
  }
  void clear() {
    slots_.assign(64, empty_key);
    count_ = 0;
  }
  void insert(std::uint64_t k) {
    if (slots_.empty()) clear();
    if (2 * (count_ + 1) > slots_.size()) grow();
    std::size_t i = slot(k);
    while (slots_[i] != empty_key) {
      if (slots_[i] == k) return;
      i = (i + 1) & (slots_.size() - 1);
    }
    slots_[i] = k;
    ++count_;
  }
  [[nodiscard]] bool contains(std::uint64_t k) const {
    if (slots_.empty()) return false;
    for (std::size_t i = slot(k);; i = (i + 1) & (slots_.size() - 1)) {
      if (slots_[i] == k) return true;
      if (slots_[i] == empty_key) return false;
    }
  }

 private:
  [[nodiscard]] std::size_t slot(std::uint64_t k) const {
    return std::size_t((k * 0x9E3779B97F4A7C15ull) >> (64 - std::countr_zero(slots_.size())));
  }
  void grow() {
    std::vector<std::uint64_t> old(slots_.size() * 2, empty_key);
    old.swap(slots_);
    count_ = 0;
    for (auto k : old)
      if (k != empty_key) insert(k);
  }
  std::vector<std::uint64_t> slots_;
  std::size_t count_ = 0;
};

/// Context choice for the childhood-code bits (docs/rho-grid.md compares them).
enum class rho_geometry_context : std::uint32_t {
  level_child = 0,        ///< (level, child index j)
  parent_neighbours = 1,  ///< + number of the parent's 6 face neighbours that are occupied
  /// + occupancy of the child's −x, −y, −z neighbours at the child level (already coded: path
  /// order puts a cell after every cell with one coordinate smaller and the others equal)
  parent_and_child_neighbours = 2,
};
/// Prediction of a cell's attribute (docs/rho-grid.md compares them).
enum class rho_attribute_predictor : std::uint32_t {
  parent = 0,             ///< the parent cell's attribute
  sibling_or_parent = 1,  ///< the previous sibling's, the parent's for a first child
};
struct rho_coder_options {
  rho_geometry_context geometry = rho_geometry_context::parent_and_child_neighbours;
  rho_attribute_predictor attributes = rho_attribute_predictor::parent;
};

/// The two range-coded streams of a ρ-grid: the childhood codes (breadth first) and the
/// attributes of every cell (breadth first). A stream with no symbols (depth 0; σ = 0) is empty.
struct rho_coded_streams {
  std::vector<unsigned char> geometry, attributes;
};

template <int Rho>
[[nodiscard]] rho_coded_streams rho_grid_encode(const rho_grid<Rho>& g,
                                                const rho_coder_options& options);

/// Decodes into g, whose frame (depth, bits) is set and whose codes/attributes are empty:
/// per_level[l] = declared cells of level l. Leaves g complete (rho_grid_access::finish).
/// Throws FormatError naming `what` on any inconsistency.
template <int Rho>
void rho_grid_decode(rho_grid<Rho>& g, const unsigned char* geometry, std::size_t geometry_size,
                     const unsigned char* attributes, std::size_t attributes_size,
                     const std::vector<std::uint64_t>& per_level, const rho_coder_options& options,
                     const std::string& what);

/// serialise(rho_grid_layout::compressed) with a chosen context model (tests, benchmarks).
template <int Rho>
[[nodiscard]] std::vector<unsigned char> rho_grid_serialise_compressed(
    const rho_grid<Rho>& g, const rho_coder_options& options);

}  // namespace pbr_lod::detail
