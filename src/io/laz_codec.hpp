// pbr_lod — the entropy coder of LAZ (LASzip): the 32-bit range coder, its adaptive bit and
// symbol models, and the integer compressor built on them. Decoding (laz_decoder.cpp) and
// encoding (the chunk tables the tests write, and later the LAZ writer) share these models, so
// both halves adapt identically. Not installed.
//
// Based on A. Said, "Introduction to arithmetic coding — theory and practice", HP Labs report
// HPL-2004-76 (2004), the FastAC coder LASzip uses, with LASzip's parameters: 13-bit bit-model
// probabilities, 15-bit symbol distributions, renormalisation below 2^24 (M. Isenburg,
// "LASzip: lossless compression of LiDAR data", PE&RS 79(2), 2013).
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "io_internal.hpp"  // byte_swapped

namespace pbr_lod::detail::laz {

// The coder's per-symbol steps are inlined into the item decoders (they are most of the
// decoding time); model updates and renormalisation, rarer, stay out of line.
#define PBR_LOD_LAZ_INLINE [[gnu::always_inline]] inline
#define PBR_LOD_LAZ_COLD [[gnu::noinline]]

constexpr std::uint32_t ac_min_length = 0x01000000u;  // renormalise below 2^24
constexpr std::uint32_t ac_max_length = 0xFFFFFFFFu;
constexpr std::uint32_t bm_length_shift = 13;  // bit models: 13-bit probability of a 0
constexpr std::uint32_t bm_max_count = 1u << bm_length_shift;
constexpr std::uint32_t dm_length_shift = 15;  // symbol models: 15-bit distributions
constexpr std::uint32_t dm_max_count = 1u << dm_length_shift;

/// The bytes of one arithmetic-coded stream. Past its end it gives zeros and counts them:
/// a stream is never read out of bounds, and a damaged one (overrun() > 0) is detected.
class byte_source {
 public:
  byte_source(const unsigned char* p, std::size_t n) : p_(p), end_(p + n) {}
  unsigned char get() {
    if (p_ < end_) return *p_++;
    ++overrun_;
    return 0;
  }
  [[nodiscard]] std::uint64_t overrun() const { return overrun_; }
  [[nodiscard]] const unsigned char* pos() const { return p_; }

 private:
  const unsigned char* p_;
  const unsigned char* end_;
  std::uint64_t overrun_ = 0;
};

/// An adaptive model of one binary decision: the probability of a 0, recomputed from counts
/// at growing intervals (4 decisions, then ×5/4 up to 64).
struct bit_model {
  std::uint32_t update_cycle = 4, until_update = 4;
  std::uint32_t bit_0_prob = 1u << (bm_length_shift - 1), bit_0_count = 1, bit_count = 2;

  PBR_LOD_LAZ_COLD void update() {
    if ((bit_count += update_cycle) > bm_max_count) {  // halve the counts
      bit_count = (bit_count + 1) >> 1;
      bit_0_count = (bit_0_count + 1) >> 1;
      if (bit_0_count == bit_count) ++bit_count;
    }
    const std::uint32_t scale = 0x80000000u / bit_count;
    bit_0_prob = (bit_0_count * scale) >> (31 - bm_length_shift);
    update_cycle = std::min<std::uint32_t>((5 * update_cycle) >> 2, 64);
    until_update = update_cycle;
  }
};

/// An adaptive model of an alphabet of 2–2048 symbols: counts, the cumulative distribution
/// they give (15 bits), recomputed at growing intervals, and for alphabets above 16 symbols a
/// table that narrows the search for a decoded value to a few distribution entries.
class symbol_model {
 public:
  explicit symbol_model(std::uint32_t symbols) : symbols_(symbols), last_symbol_(symbols - 1) {
    if (symbols > 16) {
      std::uint32_t table_bits = 3;
      while (symbols > (1u << (table_bits + 2))) ++table_bits;
      table_size_ = 1u << table_bits;
      table_shift_ = dm_length_shift - table_bits;
    }
    store_.assign(2 * std::size_t{symbols} + (table_size_ ? table_size_ + 2 : 0), 0);
    distribution_ = store_.data();
    count_ = distribution_ + symbols;
    table_ = table_size_ ? count_ + symbols : nullptr;
    std::fill(count_, count_ + symbols, 1u);
    update_cycle_ = symbols;
    update();
    until_update_ = update_cycle_ = (symbols + 6) >> 1;
  }
  symbol_model(const symbol_model&) = delete;
  symbol_model& operator=(const symbol_model&) = delete;

 private:
  friend class range_decoder;
  friend class range_encoder;

  PBR_LOD_LAZ_COLD void update() {
    if ((total_count_ += update_cycle_) > dm_max_count) {  // halve the counts
      total_count_ = 0;
      for (std::uint32_t n = 0; n < symbols_; ++n)
        total_count_ += (count_[n] = (count_[n] + 1) >> 1);
    }
    const std::uint32_t scale = 0x80000000u / total_count_;
    std::uint32_t sum = 0;
    if (table_size_ == 0) {
      for (std::uint32_t k = 0; k < symbols_; ++k) {
        distribution_[k] = (scale * sum) >> (31 - dm_length_shift);
        sum += count_[k];
      }
    } else {
      std::uint32_t s = 0;
      for (std::uint32_t k = 0; k < symbols_; ++k) {
        distribution_[k] = (scale * sum) >> (31 - dm_length_shift);
        sum += count_[k];
        const std::uint32_t w = distribution_[k] >> table_shift_;
        while (s < w) table_[++s] = k - 1;
      }
      table_[0] = 0;
      while (s <= table_size_) table_[++s] = symbols_ - 1;
    }
    update_cycle_ = std::min((5 * update_cycle_) >> 2, (symbols_ + 6) << 3);
    until_update_ = update_cycle_;
  }

  std::uint32_t symbols_, last_symbol_;
  std::uint32_t table_size_ = 0, table_shift_ = 0;
  std::uint32_t total_count_ = 0, update_cycle_ = 0, until_update_ = 0;
  std::vector<std::uint32_t> store_;
  std::uint32_t* distribution_ = nullptr;
  std::uint32_t* count_ = nullptr;
  std::uint32_t* table_ = nullptr;
};

/// The decoding half of the 32-bit range coder: `value` is the code's offset inside the current
/// interval of `length`; every decision narrows the interval and bytes shift in when it falls
/// below 2^24. Valid streams keep value < length; a damaged one may not, which decodes garbage
/// but never reads out of bounds (the symbol table index is clamped) nor loops (length > 0).
class range_decoder {
 public:
  explicit range_decoder(byte_source& in) : in_(in) {
    for (int i = 0; i < 4; ++i) value_ = (value_ << 8) | in_.get();
  }

  PBR_LOD_LAZ_INLINE std::uint32_t decode_bit(bit_model& m) {
    const std::uint32_t x = m.bit_0_prob * (length_ >> bm_length_shift);
    std::uint32_t sym;
    if (value_ < x) {
      sym = 0;
      length_ = x;
      ++m.bit_0_count;
    } else {
      sym = 1;
      value_ -= x;
      length_ -= x;
    }
    if (length_ < ac_min_length) renormalise();
    if (--m.until_update == 0) m.update();
    return sym;
  }

  PBR_LOD_LAZ_INLINE std::uint32_t decode_symbol(symbol_model& m) {
    std::uint32_t sym, x, y = length_;
    length_ >>= dm_length_shift;
    if (m.table_) {
      const std::uint32_t dv = value_ / length_;
      const std::uint32_t t = std::min(dv >> m.table_shift_, m.table_size_);
      sym = m.table_[t];
      std::uint32_t n = m.table_[t + 1] + 1;
      while (n > sym + 1) {  // bisection between the table's bounds
        const std::uint32_t k = (sym + n) >> 1;
        if (m.distribution_[k] > dv)
          n = k;
        else
          sym = k;
      }
      x = m.distribution_[sym] * length_;
      if (sym != m.last_symbol_) y = m.distribution_[sym + 1] * length_;
    } else {
      x = sym = 0;
      std::uint32_t n = m.symbols_, k = n >> 1;
      do {
        const std::uint32_t z = length_ * m.distribution_[k];
        if (z > value_) {
          n = k;
          y = z;
        } else {
          sym = k;
          x = z;
        }
      } while ((k = (sym + n) >> 1) != sym);
    }
    value_ -= x;
    length_ = y - x;
    if (length_ < ac_min_length) renormalise();
    ++m.count_[sym];
    if (--m.until_update_ == 0) m.update();
    return sym;
  }

  /// `bits` raw bits (1–32), equiprobable.
  PBR_LOD_LAZ_INLINE std::uint32_t read_bits(std::uint32_t bits) {
    if (bits > 19) {
      const std::uint32_t low = read_bits_short(16);
      return (read_bits_short(bits - 16) << 16) | low;
    }
    return read_bits_short(bits);
  }
  std::uint32_t read_int() {
    const std::uint32_t low = read_bits_short(16);
    return (read_bits_short(16) << 16) | low;
  }

 private:
  /// 1–19 raw bits.
  PBR_LOD_LAZ_INLINE std::uint32_t read_bits_short(std::uint32_t bits) {
    const std::uint32_t sym = value_ / (length_ >>= bits);
    value_ -= length_ * sym;
    if (length_ < ac_min_length) renormalise();
    return sym;
  }

  PBR_LOD_LAZ_INLINE void renormalise() {
    do {
      value_ = (value_ << 8) | in_.get();
    } while ((length_ <<= 8) < ac_min_length);
  }

  byte_source& in_;
  std::uint32_t value_ = 0;
  std::uint32_t length_ = ac_max_length;
};

/// The encoding half of the range coder, writing to a byte vector: `base` is the low end of
/// the interval, and a carry out of it is propagated into the bytes already written. done()
/// flushes and pads the stream so that range_decoder never reads past its end.
class range_encoder {
 public:
  explicit range_encoder(std::vector<unsigned char>& out) : out_(out) {}

  void encode_bit(bit_model& m, std::uint32_t bit) {
    const std::uint32_t x = m.bit_0_prob * (length_ >> bm_length_shift);
    if (bit == 0) {
      length_ = x;
      ++m.bit_0_count;
    } else {
      add_to_base(x);
      length_ -= x;
    }
    if (length_ < ac_min_length) renormalise();
    if (--m.until_update == 0) m.update();
  }

  void encode_symbol(symbol_model& m, std::uint32_t sym) {
    std::uint32_t x;
    if (sym == m.last_symbol_) {
      x = m.distribution_[sym] * (length_ >> dm_length_shift);
      add_to_base(x);
      length_ -= x;
    } else {
      x = m.distribution_[sym] * (length_ >>= dm_length_shift);
      add_to_base(x);
      length_ = m.distribution_[sym + 1] * length_ - x;
    }
    if (length_ < ac_min_length) renormalise();
    ++m.count_[sym];
    if (--m.until_update_ == 0) m.update();
  }

  /// The low `bits` bits (1–32) of sym, raw.
  void write_bits(std::uint32_t bits, std::uint32_t sym) {
    if (bits > 19) {
      write_bits(16, sym & 0xFFFFu);
      sym >>= 16;
      bits -= 16;
    }
    add_to_base(sym * (length_ >>= bits));
    if (length_ < ac_min_length) renormalise();
  }

  /// Ends the stream: the bytes that pin the code inside the final interval, then two or three
  /// zeros for the decoder's look-ahead.
  void done() {
    bool another_byte = true;
    if (length_ > 2 * ac_min_length) {
      add_to_base(ac_min_length);
      length_ = ac_min_length >> 1;
    } else {
      add_to_base(ac_min_length >> 1);
      length_ = ac_min_length >> 9;
      another_byte = false;
    }
    renormalise();
    out_.push_back(0);
    out_.push_back(0);
    if (another_byte) out_.push_back(0);
  }

 private:
  void add_to_base(std::uint32_t x) {
    const std::uint32_t before = base_;
    base_ += x;
    if (before > base_) {  // carry into the bytes written
      for (std::size_t i = out_.size(); i-- > start_;)
        if (++out_[i] != 0) break;
    }
  }
  void renormalise() {
    do {
      out_.push_back(static_cast<unsigned char>(base_ >> 24));
      base_ <<= 8;
    } while ((length_ <<= 8) < ac_min_length);
  }

  std::vector<unsigned char>& out_;
  std::size_t start_ = out_.size();  // a carry never reaches bytes before the stream
  std::uint32_t base_ = 0;
  std::uint32_t length_ = ac_max_length;
};

/// LASzip's integer compressor: an integer is coded as a corrector to a
/// prediction. The corrector's bit length k (0–32) is a symbol of a per-context model; its
/// value, for k ≤ bits_high, a symbol of a per-k model, else the top bits_high bits a symbol and
/// the rest raw. The result wraps into the integer's range (2^bits, or `range`).
class integer_codec {
 public:
  integer_codec(std::uint32_t bits, std::uint32_t contexts, std::uint32_t bits_high = 8,
                std::uint32_t range = 0)
      : bits_high_(bits_high) {
    if (range) {
      corr_range_ = range;
      while (range) {
        range >>= 1;
        ++corr_bits_;
      }
      if (corr_range_ == (1u << (corr_bits_ - 1))) --corr_bits_;
      corr_min_ = static_cast<std::int32_t>(0u - corr_range_ / 2);
    } else if (bits && bits < 32) {
      corr_bits_ = bits;
      corr_range_ = 1u << bits;
      corr_min_ = static_cast<std::int32_t>(0u - corr_range_ / 2);
    } else {
      corr_bits_ = 32;
      corr_range_ = 0;
      corr_min_ = std::numeric_limits<std::int32_t>::min();
    }
    // Models are made on first use: a model's first state is fixed, so making it later changes
    // nothing, and most of LASzip's contexts and corrector lengths never occur in a chunk
    // (each chunk starts afresh, so setup is paid per chunk).
    k_models_.resize(contexts);
    corrector_.resize(corr_bits_);
  }

  /// Codes `real` predicted as `pred` in `context` (the encoder's half).
  void encode(range_encoder& enc, std::int32_t pred, std::int32_t real, std::uint32_t context = 0) {
    // The corrector folded into [corr_min, corr_min + corr_range), in 32-bit wrapping arithmetic.
    std::uint32_t c = static_cast<std::uint32_t>(real) - static_cast<std::uint32_t>(pred);
    const auto ci = static_cast<std::int64_t>(static_cast<std::int32_t>(c));
    if (corr_range_ != 0) {
      if (ci < corr_min_)
        c += corr_range_;
      else if (ci > std::int64_t{corr_min_} + corr_range_ - 1)
        c -= corr_range_;
    }
    const auto cs = static_cast<std::int32_t>(c);
    // k: the bit length of |c| (of c − 1 for positive c): c lies in [−(2^k − 1), 2^k].
    std::uint32_t c1 = cs <= 0 ? 0u - c : c - 1;
    std::uint32_t k = 0;
    while (c1) {
      c1 >>= 1;
      ++k;
    }
    k_ = k;
    enc.encode_symbol(k_model(context), k);
    if (k == 0) {
      enc.encode_bit(corrector0_, c);
      return;
    }
    if (k == 32) return;
    c = cs < 0 ? c + ((1u << k) - 1) : c - 1;
    if (k <= bits_high_) {
      enc.encode_symbol(corrector_model(k), c);
    } else {
      const std::uint32_t low_bits = k - bits_high_;
      enc.encode_symbol(corrector_model(k), c >> low_bits);
      enc.write_bits(low_bits, c & ((1u << low_bits) - 1));
    }
  }

  /// The integer predicted as `pred` in `context`.
  std::int32_t decode(range_decoder& dec, std::int32_t pred, std::uint32_t context = 0) {
    std::uint32_t real = static_cast<std::uint32_t>(pred) + corrector(dec, context);
    if (static_cast<std::int32_t>(real) < 0)
      real += corr_range_;
    else if (real >= corr_range_)
      real -= corr_range_;
    return static_cast<std::int32_t>(real);
  }
  /// The bit length of the last corrector (LASzip uses it as a context for the next integer).
  [[nodiscard]] std::uint32_t k() const { return k_; }

 private:
  PBR_LOD_LAZ_INLINE std::uint32_t corrector(range_decoder& dec, std::uint32_t context) {
    k_ = dec.decode_symbol(k_model(context));
    if (k_ == 0) return dec.decode_bit(corrector0_);  // 0 or 1
    if (k_ >= 32) return static_cast<std::uint32_t>(corr_min_);
    std::uint32_t c;
    if (k_ <= bits_high_) {
      c = dec.decode_symbol(corrector_model(k_));
    } else {
      const std::uint32_t low_bits = k_ - bits_high_;
      c = dec.decode_symbol(corrector_model(k_));
      c = (c << low_bits) | dec.read_bits(low_bits);
    }
    // [0, 2^(k-1)) holds -(2^k - 1) … -2^(k-1); [2^(k-1), 2^k) holds 2^(k-1) + 1 … 2^k.
    if (c >= (1u << (k_ - 1)))
      c += 1;
    else
      c -= (1u << k_) - 1;
    return c;
  }

  symbol_model& k_model(std::uint32_t context) {
    auto& m = k_models_[context];
    if (!m) m = std::make_unique<symbol_model>(corr_bits_ + 1);
    return *m;
  }
  /// The model of correctors of bit length k (1 ≤ k ≤ corr_bits): 2^min(k, bits_high) symbols.
  symbol_model& corrector_model(std::uint32_t k) {
    auto& m = corrector_[k - 1];
    if (!m) m = std::make_unique<symbol_model>(1u << std::min(k, bits_high_));
    return *m;
  }

  std::uint32_t bits_high_;
  std::uint32_t corr_bits_ = 0, corr_range_ = 0;
  std::int32_t corr_min_ = 0;
  std::uint32_t k_ = 0;
  std::vector<std::unique_ptr<symbol_model>> k_models_;
  bit_model corrector0_;
  std::vector<std::unique_ptr<symbol_model>> corrector_;
};

// --- shared by the item decoders --------------------------------------------------------------

/// A symbol model made on first use (LASzip's per-value contexts: most of 256 are never used).
class lazy_model {
 public:
  symbol_model& get(std::uint32_t symbols) {
    if (!m_) m_ = std::make_unique<symbol_model>(symbols);
    return *m_;
  }

 private:
  std::unique_ptr<symbol_model> m_;
};

/// The median of the last five values, kept sorted with a flag that says which end the next
/// insertion replaces (LASzip's StreamingMedian5).
class median5 {
 public:
  void add(std::int32_t v) {
    auto& a = v_;
    if (high_) {
      if (v < a[2]) {
        a[4] = a[3];
        a[3] = a[2];
        if (v < a[0]) {
          a[2] = a[1];
          a[1] = a[0];
          a[0] = v;
        } else if (v < a[1]) {
          a[2] = a[1];
          a[1] = v;
        } else {
          a[2] = v;
        }
      } else {
        if (v < a[3]) {
          a[4] = a[3];
          a[3] = v;
        } else {
          a[4] = v;
        }
        high_ = false;
      }
    } else {
      if (a[2] < v) {
        a[0] = a[1];
        a[1] = a[2];
        if (a[4] < v) {
          a[2] = a[3];
          a[3] = a[4];
          a[4] = v;
        } else if (a[3] < v) {
          a[2] = a[3];
          a[3] = v;
        } else {
          a[2] = v;
        }
      } else {
        if (a[1] < v) {
          a[0] = a[1];
          a[1] = v;
        } else {
          a[0] = v;
        }
        high_ = true;
      }
    }
  }
  [[nodiscard]] std::int32_t get() const { return v_[2]; }

 private:
  std::array<std::int32_t, 5> v_{};
  bool high_ = true;
};

/// Stores v little-endian at p.
template <class T>
inline void store_le(unsigned char* p, T v) {
  if constexpr (std::endian::native == std::endian::big) v = byte_swapped(v);
  std::memcpy(p, &v, sizeof(T));
}

/// Appends v little-endian to s (the writers' file assembly).
template <class T>
inline void append_le(std::string& s, T v) {
  unsigned char b[sizeof(T)];
  store_le(b, v);
  s.append(reinterpret_cast<const char*>(b), sizeof(T));
}

/// WAVEPACKET13 v1 / WAVEPACKET14 v3 (formats 4, 5, 9, 10): the 29 bytes that point into the
/// waveform data — descriptor index (a symbol), offset (unchanged, the last packet's end, a
/// 32-bit difference or raw), packet size, return point and dx dy dz (floats coded by their
/// bits as integers), each against the last packet. One state per scanner channel in v3.
class wavepacket_state {
 public:
  wavepacket_state()
      : index_(256),
        offset_sym_{symbol_model(4), symbol_model(4), symbol_model(4), symbol_model(4)} {}

  /// Decodes the packet after `last` (29 bytes) into out (29 bytes; may alias last).
  void decode(range_decoder& dec, const unsigned char* last, unsigned char* out) {
    const auto last_offset = load_le<std::uint64_t>(last + 1);
    const auto last_size = load_le<std::uint32_t>(last + 9);
    std::uint32_t v[4];
    for (int i = 0; i < 4; ++i) v[i] = load_le<std::uint32_t>(last + 13 + 4 * i);
    const auto descriptor = static_cast<unsigned char>(dec.decode_symbol(index_));
    last_sym_ = dec.decode_symbol(offset_sym_[last_sym_]);
    std::uint64_t offset;
    if (last_sym_ == 0) {
      offset = last_offset;
    } else if (last_sym_ == 1) {
      offset = last_offset + last_size;
    } else if (last_sym_ == 2) {
      last_offset_diff_ = ic_offset_diff_.decode(dec, last_offset_diff_, 0);
      offset =
          last_offset + static_cast<std::uint64_t>(static_cast<std::int64_t>(last_offset_diff_));
    } else {
      offset = dec.read_int();
      offset |= std::uint64_t{dec.read_int()} << 32;
    }
    const auto size =
        static_cast<std::uint32_t>(ic_size_.decode(dec, static_cast<std::int32_t>(last_size), 0));
    v[0] = static_cast<std::uint32_t>(
        ic_return_point_.decode(dec, static_cast<std::int32_t>(v[0]), 0));
    for (std::uint32_t a = 0; a < 3; ++a)
      v[1 + a] =
          static_cast<std::uint32_t>(ic_xyz_.decode(dec, static_cast<std::int32_t>(v[1 + a]), a));
    out[0] = descriptor;
    store_le(out + 1, offset);
    store_le(out + 9, size);
    for (int i = 0; i < 4; ++i) store_le(out + 13 + 4 * i, v[i]);
  }

  /// Encodes the packet `cur` after `last` (29 bytes each).
  void encode(range_encoder& enc, const unsigned char* last, const unsigned char* cur) {
    const auto last_offset = load_le<std::uint64_t>(last + 1);
    const auto last_size = load_le<std::uint32_t>(last + 9);
    const auto offset = load_le<std::uint64_t>(cur + 1);
    enc.encode_symbol(index_, cur[0]);
    const auto d64 = static_cast<std::int64_t>(offset - last_offset);
    std::uint32_t sym = 3;
    if (d64 == 0)
      sym = 0;
    else if (offset == last_offset + last_size)
      sym = 1;
    else if (d64 >= std::numeric_limits<std::int32_t>::min() &&
             d64 <= std::numeric_limits<std::int32_t>::max())
      sym = 2;
    enc.encode_symbol(offset_sym_[last_sym_], sym);
    last_sym_ = sym;
    if (sym == 2) {
      ic_offset_diff_.encode(enc, last_offset_diff_, static_cast<std::int32_t>(d64), 0);
      last_offset_diff_ = static_cast<std::int32_t>(d64);
    } else if (sym == 3) {
      enc.write_bits(32, static_cast<std::uint32_t>(offset));
      enc.write_bits(32, static_cast<std::uint32_t>(offset >> 32));
    }
    ic_size_.encode(enc, load_le<std::int32_t>(last + 9), load_le<std::int32_t>(cur + 9), 0);
    ic_return_point_.encode(enc, load_le<std::int32_t>(last + 13), load_le<std::int32_t>(cur + 13),
                            0);
    for (std::uint32_t a = 0; a < 3; ++a)
      ic_xyz_.encode(enc, load_le<std::int32_t>(last + 17 + 4 * a),
                     load_le<std::int32_t>(cur + 17 + 4 * a), a);
  }

 private:
  symbol_model index_;
  symbol_model offset_sym_[4];
  std::uint32_t last_sym_ = 0;
  std::int32_t last_offset_diff_ = 0;
  integer_codec ic_offset_diff_{32, 1}, ic_size_{32, 1}, ic_return_point_{32, 1}, ic_xyz_{32, 3};
};

}  // namespace pbr_lod::detail::laz
