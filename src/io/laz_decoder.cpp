// pbr_lod — LAZ decoding and encoding: LASzip's point-wise chunked compressor (point data record
// formats 0–5; the layered one of LAS 1.4 is laz_layered.cpp), the LASzip VLR and chunk table.
//
// This work is based on:
//  * M. Isenburg, "LASzip: lossless compression of LiDAR data", Photogrammetric Engineering and
//    Remote Sensing 79(2), 2013 — §"Compression": the items of a point record are predicted from
//    the previous record (x, y from the median of the last five differences in the same
//    return context, z from the last z of the same return level, GPS time from the last
//    difference and its multiples, RGB channel by channel from the red difference), and the
//    residuals are coded by an adaptive arithmetic coder.
//  * A. Said, "Introduction to arithmetic coding — theory and practice", HP Labs report
//    HPL-2004-76 (2004): the 32-bit range coder LASzip uses (its FastAC), with adaptive bit
//    models (13-bit probabilities) and adaptive symbol models (15-bit distributions, a lookup
//    table for alphabets above 16 symbols).
//  * ASPRS LAS 1.4 specification (R15, 2019), the point record layouts; and the LASzip VLR and
//    chunk table as LASzip writes them (laszip.hpp, lasreadpoint.cpp), which this code was
//    checked against by reading LASzip, laz-perf and laz-rs — not by copying them.
//
// Layout of a LAZ file (what read_laz_layout checks):
//   LAS header, format byte | 0x80 → VLRs, one of them "laszip encoded"/22204:
//     u16 compressor (2: point-wise chunked), u16 coder (0: arithmetic), u8 u8 u16 version,
//     u32 options, u32 chunk size (0xFFFFFFFF: variable), i64 i64 (special EVLRs, unused),
//     u16 item count, then per item u16 type, u16 size, u16 version
//   → at the point data offset: i64 offset of the chunk table (-1: in the file's last 8 bytes)
//   → the chunks, back to back
//   → the chunk table: u32 version (0), u32 chunk count, then an arithmetic-coded stream: per
//     chunk (its point count when chunks are variable, context 0, then) its byte size, context 1,
//     each an integer coded (32 bits, 2 contexts) against the previous chunk's value.
//
// A chunk: its first record stored raw (the items in order, as in the LAS record), then one
// arithmetic-coded stream for the others in which each record is its items, each coded against
// that item's previous value with models that start afresh in every chunk.
#include "laz_decoder.hpp"

#include <algorithm>
#include <array>
#include <memory>
#include <optional>

#include "laz_codec.hpp"
#include "laz_encoder.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod::detail {
namespace {

using namespace laz;  // NOLINT: the coder of laz_codec.hpp, used throughout

// LASzip's item types (laszip.hpp's LASitem::Type).
enum item_type : std::uint16_t {
  item_byte = 0,
  item_point10 = 6,
  item_gpstime11 = 7,
  item_rgb12 = 8,
  item_wavepacket13 = 9,
  item_point14 = 10,
  item_rgb14 = 11,
  item_rgbnir14 = 12,
  item_wavepacket14 = 13,
  item_byte14 = 14,
};

const char* item_name(std::uint16_t t) {
  switch (t) {
    case item_byte:
      return "BYTE";
    case item_point10:
      return "POINT10";
    case item_gpstime11:
      return "GPSTIME11";
    case item_rgb12:
      return "RGB12";
    case item_wavepacket13:
      return "WAVEPACKET13";
    case item_point14:
      return "POINT14";
    case item_rgb14:
      return "RGB14";
    case item_rgbnir14:
      return "RGBNIR14";
    case item_wavepacket14:
      return "WAVEPACKET14";
    case item_byte14:
      return "BYTE14";
    default:
      return "unknown";
  }
}

constexpr std::uint32_t variable_chunks = 0xFFFFFFFFu;

// Return number r and number of returns n (3 bits each) → one of 16 contexts for x, y and
// intensity, and the 8 "levels" (n − r, completed for files that number them oddly) for z.
constexpr std::uint8_t return_map[8][8] = {
    {15, 14, 13, 12, 11, 10, 9, 8},  {14, 0, 1, 3, 6, 10, 10, 9},
    {13, 1, 2, 4, 7, 11, 11, 10},    {12, 3, 4, 5, 8, 12, 12, 11},
    {11, 6, 7, 8, 9, 13, 13, 12},    {10, 10, 11, 12, 13, 14, 14, 13},
    {9, 10, 11, 12, 13, 14, 15, 14}, {8, 9, 10, 11, 12, 13, 14, 15}};
constexpr std::uint8_t return_level[8][8] = {{0, 1, 2, 3, 4, 5, 6, 7}, {1, 0, 1, 2, 3, 4, 5, 6},
                                             {2, 1, 0, 1, 2, 3, 4, 5}, {3, 2, 1, 0, 1, 2, 3, 4},
                                             {4, 3, 2, 1, 0, 1, 2, 3}, {5, 4, 3, 2, 1, 0, 1, 2},
                                             {6, 5, 4, 3, 2, 1, 0, 1}, {7, 6, 5, 4, 3, 2, 1, 0}};

/// POINT10 v2: the 20 bytes of formats 0–5 (x y z, intensity, return bits, classification,
/// scan angle, user data, point source). A 6-bit mask says which of the non-coordinate fields
/// changed; x and y are coded against the median of the last five differences in the same
/// return context, z against the last z of the same return level.
class point10_decoder {
 public:
  point10_decoder() : changed_(64), scan_angle_models_{symbol_model(256), symbol_model(256)} {}

  void first(const unsigned char* rec) {
    x_ = load_le<std::int32_t>(rec);
    y_ = load_le<std::int32_t>(rec + 4);
    z_ = load_le<std::int32_t>(rec + 8);
    intensity_ = 0;  // LASzip predicts intensity from last_intensity[m] only
    bits_ = rec[14];
    classification_ = rec[15];
    scan_angle_ = rec[16];
    user_data_ = rec[17];
    point_source_ = load_le<std::uint16_t>(rec + 18);
  }

  void next(range_decoder& dec, unsigned char* rec) {
    const std::uint32_t changed = dec.decode_symbol(changed_);
    unsigned r, n, m, l;
    if (changed != 0) {
      if (changed & 32)
        bits_ = static_cast<std::uint8_t>(dec.decode_symbol(bit_byte_[bits_].get(256)));
      r = bits_ & 7u;
      n = (bits_ >> 3) & 7u;
      m = return_map[n][r];
      l = return_level[n][r];
      if (changed & 16) {
        intensity_ = static_cast<std::uint16_t>(
            ic_intensity_.decode(dec, last_intensity_[m], m < 3 ? m : 3));
        last_intensity_[m] = intensity_;
      } else {
        intensity_ = last_intensity_[m];
      }
      if (changed & 8)
        classification_ = static_cast<std::uint8_t>(
            dec.decode_symbol(classification_m_[classification_].get(256)));
      if (changed & 4) {
        const unsigned dir = (bits_ >> 6) & 1u;
        scan_angle_ =
            static_cast<std::uint8_t>(dec.decode_symbol(scan_angle_models_[dir]) + scan_angle_);
      }
      if (changed & 2)
        user_data_ =
            static_cast<std::uint8_t>(dec.decode_symbol(user_data_m_[user_data_].get(256)));
      if (changed & 1)
        point_source_ = static_cast<std::uint16_t>(ic_point_source_.decode(dec, point_source_));
    } else {
      r = bits_ & 7u;
      n = (bits_ >> 3) & 7u;
      m = return_map[n][r];
      l = return_level[n][r];
    }
    const std::uint32_t single = n == 1 ? 1u : 0u;
    std::int32_t diff = ic_dx_.decode(dec, x_median_[m].get(), single);
    x_ = static_cast<std::int32_t>(static_cast<std::uint32_t>(x_) +
                                   static_cast<std::uint32_t>(diff));
    x_median_[m].add(diff);
    std::uint32_t k = ic_dx_.k();
    diff = ic_dy_.decode(dec, y_median_[m].get(), single + (k < 20 ? (k & ~1u) : 20u));
    y_ = static_cast<std::int32_t>(static_cast<std::uint32_t>(y_) +
                                   static_cast<std::uint32_t>(diff));
    y_median_[m].add(diff);
    k = (ic_dx_.k() + ic_dy_.k()) / 2;
    z_ = ic_z_.decode(dec, last_height_[l], single + (k < 18 ? (k & ~1u) : 18u));
    last_height_[l] = z_;

    store_le(rec, x_);
    store_le(rec + 4, y_);
    store_le(rec + 8, z_);
    store_le(rec + 12, intensity_);
    rec[14] = bits_;
    rec[15] = classification_;
    rec[16] = scan_angle_;
    rec[17] = user_data_;
    store_le(rec + 18, point_source_);
  }

 private:
  std::int32_t x_ = 0, y_ = 0, z_ = 0;
  std::uint16_t intensity_ = 0, point_source_ = 0;
  std::uint8_t bits_ = 0, classification_ = 0, scan_angle_ = 0, user_data_ = 0;
  std::array<std::uint16_t, 16> last_intensity_{};
  std::array<median5, 16> x_median_, y_median_;
  std::array<std::int32_t, 8> last_height_{};

  symbol_model changed_;
  symbol_model scan_angle_models_[2];
  std::array<lazy_model, 256> bit_byte_, classification_m_, user_data_m_;
  integer_codec ic_intensity_{16, 4};
  integer_codec ic_point_source_{16, 1};
  integer_codec ic_dx_{32, 2};
  integer_codec ic_dy_{32, 22};
  integer_codec ic_z_{32, 20};
};

/// GPSTIME11 v2: the 8-byte double as a 64-bit integer. Four sequences of times are tracked
/// (files interleave flight lines); each time is coded as a multiple (−10…500) of the sequence's
/// last difference plus a corrector, as a full new value, or as a switch to another sequence.
class gpstime11_decoder {
 public:
  static constexpr int multi_max = 500, multi_minus = -10;
  static constexpr std::uint32_t multi_unchanged = multi_max - multi_minus + 1;  // 511
  static constexpr std::uint32_t multi_code_full = multi_max - multi_minus + 2;  // 512
  static constexpr std::uint32_t multi_total = multi_max - multi_minus + 6;      // 516

  gpstime11_decoder() : multi_(multi_total), zero_diff_(6) {}

  void first(const unsigned char* rec) { time_[0] = load_le<std::uint64_t>(rec); }

  void next(range_decoder& dec, unsigned char* rec) {
    // A switch to another sequence is followed by that sequence's own code; a valid stream
    // switches once, a damaged one may not stop: the loop is bounded.
    for (int hops = 0;; ++hops) {
      if (hops > 8) break;
      if (diff_[last_] == 0) {
        const std::uint32_t multi = dec.decode_symbol(zero_diff_);
        if (multi == 1) {  // a 32-bit difference
          diff_[last_] = ic_.decode(dec, 0, 0);
          time_[last_] += static_cast<std::uint64_t>(static_cast<std::int64_t>(diff_[last_]));
          extreme_[last_] = 0;
        } else if (multi == 2) {  // a new full value starts a sequence
          full_value(dec);
        } else if (multi > 2) {
          last_ = (last_ + multi - 2) & 3u;
          continue;
        }
        break;
      }
      std::uint32_t multi = dec.decode_symbol(multi_);
      if (multi == 1) {
        time_[last_] +=
            static_cast<std::uint64_t>(static_cast<std::int64_t>(ic_.decode(dec, diff_[last_], 1)));
        extreme_[last_] = 0;
      } else if (multi < multi_unchanged) {
        std::int32_t d;
        const auto times = [&](std::int32_t f) {  // f · last difference, wrapping like LASzip
          return static_cast<std::int32_t>(static_cast<std::uint32_t>(f) *
                                           static_cast<std::uint32_t>(diff_[last_]));
        };
        if (multi == 0) {
          d = ic_.decode(dec, 0, 7);
          note_extreme(d);
        } else if (multi < static_cast<std::uint32_t>(multi_max)) {
          d = ic_.decode(dec, times(static_cast<std::int32_t>(multi)), multi < 10 ? 2 : 3);
        } else if (multi == static_cast<std::uint32_t>(multi_max)) {
          d = ic_.decode(dec, times(multi_max), 4);
          note_extreme(d);
        } else {
          const int f = multi_max - static_cast<int>(multi);  // −1 … −10
          if (f > multi_minus) {
            d = ic_.decode(dec, times(f), 5);
          } else {
            d = ic_.decode(dec, times(multi_minus), 6);
            note_extreme(d);
          }
        }
        time_[last_] += static_cast<std::uint64_t>(static_cast<std::int64_t>(d));
      } else if (multi == multi_code_full) {
        full_value(dec);
      } else if (multi > multi_code_full) {
        last_ = (last_ + multi - multi_code_full) & 3u;
        continue;
      }
      break;
    }
    store_le(rec, time_[last_]);
  }

 private:
  void full_value(range_decoder& dec) {
    next_ = (next_ + 1) & 3u;
    const auto high = static_cast<std::int32_t>(static_cast<std::uint32_t>(time_[last_] >> 32));
    time_[next_] = static_cast<std::uint64_t>(static_cast<std::uint32_t>(ic_.decode(dec, high, 8)))
                   << 32;
    time_[next_] |= dec.read_int();
    last_ = next_;
    diff_[last_] = 0;
    extreme_[last_] = 0;
  }
  // A difference far from the prediction replaces the sequence's difference after 4 in a row.
  void note_extreme(std::int32_t d) {
    if (++extreme_[last_] > 3) {
      diff_[last_] = d;
      extreme_[last_] = 0;
    }
  }

  std::array<std::uint64_t, 4> time_{};
  std::array<std::int32_t, 4> diff_{};
  std::array<std::int32_t, 4> extreme_{};
  std::uint32_t last_ = 0, next_ = 0;
  symbol_model multi_, zero_diff_;
  integer_codec ic_{32, 9};
};

/// RGB12 v2: a 7-bit mask says which of the six bytes changed (and bit 6 whether the colour is
/// not grey); red is coded against the last red, green and blue against the last value moved by
/// red's difference (blue by the mean of red's and green's), clamped to a byte.
class rgb12_decoder {
 public:
  rgb12_decoder()
      : used_(128), diff_{symbol_model(256), symbol_model(256), symbol_model(256),
                          symbol_model(256), symbol_model(256), symbol_model(256)} {}

  void first(const unsigned char* rec) {
    for (int c = 0; c < 3; ++c) last_[c] = load_le<std::uint16_t>(rec + 2 * c);
  }

  void next(range_decoder& dec, unsigned char* rec) {
    const std::uint32_t sym = dec.decode_symbol(used_);
    std::array<std::uint32_t, 3> v{};
    const auto lo = [](std::uint32_t c) { return c & 0xFFu; };
    const auto hi = [](std::uint32_t c) { return c >> 8; };
    const auto clamp8 = [](int x) { return static_cast<std::uint32_t>(std::clamp(x, 0, 255)); };
    const auto sym8 = [&](int i) { return dec.decode_symbol(diff_[i]); };

    v[0] = (sym & 1) ? ((sym8(0) + lo(last_[0])) & 0xFFu) : lo(last_[0]);
    v[0] |= (sym & 2) ? ((sym8(1) + hi(last_[0])) & 0xFFu) << 8 : (last_[0] & 0xFF00u);
    if (sym & 64) {
      int diff = static_cast<int>(lo(v[0])) - static_cast<int>(lo(last_[0]));
      v[1] = (sym & 4) ? ((sym8(2) + clamp8(diff + static_cast<int>(lo(last_[1])))) & 0xFFu)
                       : lo(last_[1]);
      if (sym & 16) {
        const std::uint32_t corr = sym8(4);
        diff = (diff + static_cast<int>(lo(v[1])) - static_cast<int>(lo(last_[1]))) / 2;
        v[2] = (corr + clamp8(diff + static_cast<int>(lo(last_[2])))) & 0xFFu;
      } else {
        v[2] = lo(last_[2]);
      }
      diff = static_cast<int>(hi(v[0])) - static_cast<int>(hi(last_[0]));
      if (sym & 8)
        v[1] |= ((sym8(3) + clamp8(diff + static_cast<int>(hi(last_[1])))) & 0xFFu) << 8;
      else
        v[1] |= last_[1] & 0xFF00u;
      if (sym & 32) {
        const std::uint32_t corr = sym8(5);
        diff = (diff + static_cast<int>(hi(v[1])) - static_cast<int>(hi(last_[1]))) / 2;
        v[2] |= ((corr + clamp8(diff + static_cast<int>(hi(last_[2])))) & 0xFFu) << 8;
      } else {
        v[2] |= last_[2] & 0xFF00u;
      }
    } else {
      v[1] = v[2] = v[0];
    }
    for (int c = 0; c < 3; ++c) {
      last_[c] = static_cast<std::uint16_t>(v[c]);
      store_le(rec + 2 * c, last_[c]);
    }
  }

 private:
  std::array<std::uint16_t, 3> last_{};
  symbol_model used_;
  symbol_model diff_[6];
};

/// BYTE v2 (extra bytes): each byte against the same byte of the last record, one model each.
class bytes_decoder {
 public:
  explicit bytes_decoder(std::size_t n) : last_(n) {
    models_.reserve(n);
    for (std::size_t i = 0; i < n; ++i) models_.push_back(std::make_unique<symbol_model>(256));
  }
  void first(const unsigned char* rec) { std::copy(rec, rec + last_.size(), last_.begin()); }
  void next(range_decoder& dec, unsigned char* rec) {
    for (std::size_t i = 0; i < last_.size(); ++i) {
      last_[i] = static_cast<unsigned char>(last_[i] + dec.decode_symbol(*models_[i]));
      rec[i] = last_[i];
    }
  }

 private:
  std::vector<unsigned char> last_;
  std::vector<std::unique_ptr<symbol_model>> models_;
};

/// One chunk of formats 0–5: POINT10, then GPSTIME11 when Gps, RGB12 when Rgb, WAVEPACKET13 when
/// Wave, then BYTE when the record has extra bytes. Returns the stream's overrun (bytes read past
/// its end).
template <bool Gps, bool Rgb, bool Wave = false>
std::uint64_t decode_pointwise(const unsigned char* bytes, std::size_t n_bytes, std::uint64_t count,
                               std::size_t record_length, unsigned char* out) {
  constexpr std::size_t gps_at = 20;
  constexpr std::size_t rgb_at = Gps ? 28 : 20;
  constexpr std::size_t wave_at = rgb_at + (Rgb ? 6 : 0);
  constexpr std::size_t extra_at = wave_at + (Wave ? 29 : 0);
  const std::size_t extra = record_length - extra_at;
  if (count == 0) return 0;
  // The first record is stored raw (read_laz_layout checked n_bytes ≥ record_length).
  std::memcpy(out, bytes, record_length);
  if (count == 1) return 0;
  byte_source in(bytes + record_length, n_bytes - record_length);
  range_decoder dec(in);
  auto point = std::make_unique<point10_decoder>();
  std::optional<gpstime11_decoder> gps;
  std::optional<rgb12_decoder> rgb;
  std::optional<wavepacket_state> wave;
  std::optional<bytes_decoder> tail;
  point->first(out);
  if constexpr (Gps) gps.emplace().first(out + gps_at);
  if constexpr (Rgb) rgb.emplace().first(out + rgb_at);
  if constexpr (Wave) wave.emplace();
  if (extra) tail.emplace(extra).first(out + extra_at);
  unsigned char* rec = out;
  for (std::uint64_t i = 1; i < count; ++i) {
    rec += record_length;
    point->next(dec, rec);
    if constexpr (Gps) gps->next(dec, rec + gps_at);
    if constexpr (Rgb) rgb->next(dec, rec + rgb_at);
    if constexpr (Wave) wave->decode(dec, rec - record_length + wave_at, rec + wave_at);
    if (extra) tail->next(dec, rec + extra_at);
    // A damaged chunk reads zeros past its end; stop once that is certain rather than decode
    // (up to) millions of records of garbage.
    if (in.overrun() > 16) break;
  }
  return in.overrun();
}

// --- encoding (formats 0–5): the same models and predictions, run forwards ---------------------

class point10_encoder {
 public:
  point10_encoder() : changed_(64), scan_angle_models_{symbol_model(256), symbol_model(256)} {}

  void first(const unsigned char* rec) { std::memcpy(last_, rec, 20); }

  void next(range_encoder& enc, const unsigned char* rec) {
    const std::uint8_t bits = rec[14];
    const unsigned r = bits & 7u, n = (bits >> 3) & 7u;
    const unsigned m = return_map[n][r], l = return_level[n][r];
    const auto intensity = load_le<std::uint16_t>(rec + 12);
    const auto source = load_le<std::uint16_t>(rec + 18);
    const auto last_source = load_le<std::uint16_t>(last_ + 18);
    const std::uint32_t changed =
        (bits != last_[14] ? 32u : 0u) | (intensity != last_intensity_[m] ? 16u : 0u) |
        (rec[15] != last_[15] ? 8u : 0u) | (rec[16] != last_[16] ? 4u : 0u) |
        (rec[17] != last_[17] ? 2u : 0u) | (source != last_source ? 1u : 0u);
    enc.encode_symbol(changed_, changed);
    if (changed & 32) enc.encode_symbol(bit_byte_[last_[14]].get(256), bits);
    if (changed & 16) {
      ic_intensity_.encode(enc, last_intensity_[m], intensity, m < 3 ? m : 3);
      last_intensity_[m] = intensity;
    }
    if (changed & 8) enc.encode_symbol(classification_m_[last_[15]].get(256), rec[15]);
    if (changed & 4)
      enc.encode_symbol(scan_angle_models_[(bits >> 6) & 1u],
                        static_cast<std::uint8_t>(rec[16] - last_[16]));
    if (changed & 2) enc.encode_symbol(user_data_m_[last_[17]].get(256), rec[17]);
    if (changed & 1) ic_point_source_.encode(enc, last_source, source);
    const std::uint32_t single = n == 1 ? 1u : 0u;
    const auto minus = [&](int at) {
      return static_cast<std::int32_t>(load_le<std::uint32_t>(rec + at) -
                                       load_le<std::uint32_t>(last_ + at));
    };
    std::int32_t diff = minus(0);
    ic_dx_.encode(enc, x_median_[m].get(), diff, single);
    x_median_[m].add(diff);
    std::uint32_t k = ic_dx_.k();
    diff = minus(4);
    ic_dy_.encode(enc, y_median_[m].get(), diff, single + (k < 20 ? (k & ~1u) : 20u));
    y_median_[m].add(diff);
    k = (ic_dx_.k() + ic_dy_.k()) / 2;
    const auto z = load_le<std::int32_t>(rec + 8);
    ic_z_.encode(enc, last_height_[l], z, single + (k < 18 ? (k & ~1u) : 18u));
    last_height_[l] = z;
    std::memcpy(last_, rec, 20);
  }

 private:
  unsigned char last_[20] = {};
  std::array<std::uint16_t, 16> last_intensity_{};
  std::array<median5, 16> x_median_, y_median_;
  std::array<std::int32_t, 8> last_height_{};
  symbol_model changed_;
  symbol_model scan_angle_models_[2];
  std::array<lazy_model, 256> bit_byte_, classification_m_, user_data_m_;
  integer_codec ic_intensity_{16, 4};
  integer_codec ic_point_source_{16, 1};
  integer_codec ic_dx_{32, 2};
  integer_codec ic_dy_{32, 22};
  integer_codec ic_z_{32, 20};
};

class gpstime11_encoder {
 public:
  static constexpr std::int32_t multi_max = 500, multi_minus = -10;
  static constexpr std::uint32_t multi_unchanged = 511, multi_code_full = 512;

  gpstime11_encoder() : multi_(516), zero_diff_(6) {}

  void first(const unsigned char* rec) { time_[0] = load_le<std::uint64_t>(rec); }

  void next(range_encoder& enc, const unsigned char* rec) {
    const auto t = load_le<std::uint64_t>(rec);
    const auto fits = [](std::uint64_t delta, std::int32_t& d) {
      const auto d64 = static_cast<std::int64_t>(delta);
      d = static_cast<std::int32_t>(d64);
      return d64 >= std::numeric_limits<std::int32_t>::min() &&
             d64 <= std::numeric_limits<std::int32_t>::max();
    };
    const auto times = [&](std::int32_t f) {
      return static_cast<std::int32_t>(static_cast<std::uint32_t>(f) *
                                       static_cast<std::uint32_t>(diff_[last_]));
    };
    const auto extreme = [&](std::int32_t d) {
      if (++extreme_[last_] > 3) {
        diff_[last_] = d;
        extreme_[last_] = 0;
      }
    };
    const auto full = [&](symbol_model& m, std::uint32_t code) {
      enc.encode_symbol(m, code);
      const auto high = [](std::uint64_t v) {
        return static_cast<std::int32_t>(static_cast<std::uint32_t>(v >> 32));
      };
      ic_.encode(enc, high(time_[last_]), high(t), 8);
      enc.write_bits(32, static_cast<std::uint32_t>(t));
      next_ = (next_ + 1) & 3u;
      last_ = next_;
      diff_[last_] = 0;
      extreme_[last_] = 0;
    };
    /// The other sequence t belongs to (1–3 ahead of last_), or 0.
    const auto other = [&]() -> unsigned {
      std::int32_t d;
      for (unsigned i = 1; i < 4; ++i)
        if (fits(t - time_[(last_ + i) & 3u], d)) return i;
      return 0;
    };
    for (;;) {  // at most one switch of sequence, then a code in it
      std::int32_t d = 0;
      if (diff_[last_] == 0) {
        if (t == time_[last_]) {
          enc.encode_symbol(zero_diff_, 0);
          return;
        }
        if (fits(t - time_[last_], d)) {
          enc.encode_symbol(zero_diff_, 1);
          ic_.encode(enc, 0, d, 0);
          diff_[last_] = d;
          extreme_[last_] = 0;
        } else if (const unsigned i = other(); i > 0) {
          enc.encode_symbol(zero_diff_, i + 2);
          last_ = (last_ + i) & 3u;
          continue;
        } else {
          full(zero_diff_, 2);
        }
        time_[last_] = t;
        return;
      }
      if (t == time_[last_]) {
        enc.encode_symbol(multi_, multi_unchanged);
        return;
      }
      if (fits(t - time_[last_], d)) {
        // LASzip's rounding (in float, half away from zero); any multiple decodes.
        const float ratio = static_cast<float>(d) / static_cast<float>(diff_[last_]);
        const auto multi = static_cast<std::int32_t>(ratio >= 0 ? ratio + 0.5f : ratio - 0.5f);
        if (multi == 1) {
          enc.encode_symbol(multi_, 1);
          ic_.encode(enc, diff_[last_], d, 1);
          extreme_[last_] = 0;
        } else if (multi > 0 && multi < multi_max) {
          enc.encode_symbol(multi_, static_cast<std::uint32_t>(multi));
          ic_.encode(enc, times(multi), d, multi < 10 ? 2 : 3);
        } else if (multi >= multi_max) {
          enc.encode_symbol(multi_, multi_max);
          ic_.encode(enc, times(multi_max), d, 4);
          extreme(d);
        } else if (multi < 0 && multi > multi_minus) {
          enc.encode_symbol(multi_, static_cast<std::uint32_t>(multi_max - multi));
          ic_.encode(enc, times(multi), d, 5);
        } else if (multi <= multi_minus) {
          enc.encode_symbol(multi_, static_cast<std::uint32_t>(multi_max - multi_minus));
          ic_.encode(enc, times(multi_minus), d, 6);
          extreme(d);
        } else {
          enc.encode_symbol(multi_, 0);
          ic_.encode(enc, 0, d, 7);
          extreme(d);
        }
      } else if (const unsigned i = other(); i > 0) {
        enc.encode_symbol(multi_, multi_code_full + i);
        last_ = (last_ + i) & 3u;
        continue;
      } else {
        full(multi_, multi_code_full);
      }
      time_[last_] = t;
      return;
    }
  }

 private:
  std::array<std::uint64_t, 4> time_{};
  std::array<std::int32_t, 4> diff_{};
  std::array<std::int32_t, 4> extreme_{};
  std::uint32_t last_ = 0, next_ = 0;
  symbol_model multi_, zero_diff_;
  integer_codec ic_{32, 9};
};

class rgb12_encoder {
 public:
  rgb12_encoder()
      : used_(128), diff_{symbol_model(256), symbol_model(256), symbol_model(256),
                          symbol_model(256), symbol_model(256), symbol_model(256)} {}
  void first(const unsigned char* rec) { std::memcpy(last_, rec, 6); }
  void next(range_encoder& enc, const unsigned char* rec) {
    std::array<std::uint32_t, 3> last{}, v{};
    for (int c = 0; c < 3; ++c) {
      last[c] = load_le<std::uint16_t>(last_ + 2 * c);
      v[c] = load_le<std::uint16_t>(rec + 2 * c);
    }
    const auto lo = [](std::uint32_t c) { return static_cast<int>(c & 0xFFu); };
    const auto hi = [](std::uint32_t c) { return static_cast<int>(c >> 8); };
    const auto clamp8 = [](int x) { return std::clamp(x, 0, 255); };
    const auto put = [&](int i, int x) {
      enc.encode_symbol(diff_[i], static_cast<std::uint8_t>(x));
    };
    const std::uint32_t sym =
        (lo(v[0]) != lo(last[0]) ? 1u : 0u) | (hi(v[0]) != hi(last[0]) ? 2u : 0u) |
        (lo(v[1]) != lo(last[1]) ? 4u : 0u) | (hi(v[1]) != hi(last[1]) ? 8u : 0u) |
        (lo(v[2]) != lo(last[2]) ? 16u : 0u) | (hi(v[2]) != hi(last[2]) ? 32u : 0u) |
        (v[0] != v[1] || v[0] != v[2] ? 64u : 0u);
    enc.encode_symbol(used_, sym);
    int diff_l = 0, diff_h = 0;
    if (sym & 1) put(0, diff_l = lo(v[0]) - lo(last[0]));
    if (sym & 2) put(1, diff_h = hi(v[0]) - hi(last[0]));
    if (sym & 64) {
      if (sym & 4) put(2, lo(v[1]) - clamp8(diff_l + lo(last[1])));
      if (sym & 16) {
        diff_l = (diff_l + lo(v[1]) - lo(last[1])) / 2;
        put(4, lo(v[2]) - clamp8(diff_l + lo(last[2])));
      }
      if (sym & 8) put(3, hi(v[1]) - clamp8(diff_h + hi(last[1])));
      if (sym & 32) {
        diff_h = (diff_h + hi(v[1]) - hi(last[1])) / 2;
        put(5, hi(v[2]) - clamp8(diff_h + hi(last[2])));
      }
    }
    std::memcpy(last_, rec, 6);
  }

 private:
  unsigned char last_[6] = {};
  symbol_model used_;
  symbol_model diff_[6];
};

class bytes_encoder {
 public:
  explicit bytes_encoder(std::size_t n) : last_(n) {
    for (std::size_t i = 0; i < n; ++i) models_.push_back(std::make_unique<symbol_model>(256));
  }
  void first(const unsigned char* rec) { std::copy(rec, rec + last_.size(), last_.begin()); }
  void next(range_encoder& enc, const unsigned char* rec) {
    for (std::size_t i = 0; i < last_.size(); ++i) {
      enc.encode_symbol(*models_[i], static_cast<std::uint8_t>(rec[i] - last_[i]));
      last_[i] = rec[i];
    }
  }

 private:
  std::vector<unsigned char> last_;
  std::vector<std::unique_ptr<symbol_model>> models_;
};

template <bool Gps, bool Rgb, bool Wave = false>
std::vector<unsigned char> encode_pointwise(const unsigned char* records, std::uint64_t count,
                                            std::size_t record_length) {
  constexpr std::size_t gps_at = 20;
  constexpr std::size_t rgb_at = Gps ? 28 : 20;
  constexpr std::size_t wave_at = rgb_at + (Rgb ? 6 : 0);
  constexpr std::size_t extra_at = wave_at + (Wave ? 29 : 0);
  const std::size_t extra = record_length - extra_at;
  std::vector<unsigned char> out;
  if (count == 0) return out;
  out.assign(records, records + record_length);  // the first record raw
  auto point = std::make_unique<point10_encoder>();
  std::optional<gpstime11_encoder> gps;
  std::optional<rgb12_encoder> rgb;
  std::optional<wavepacket_state> wave;
  std::optional<bytes_encoder> tail;
  point->first(records);
  if constexpr (Gps) gps.emplace().first(records + gps_at);
  if constexpr (Rgb) rgb.emplace().first(records + rgb_at);
  if constexpr (Wave) wave.emplace();
  if (extra) tail.emplace(extra).first(records + extra_at);
  range_encoder enc(out);
  for (std::uint64_t i = 1; i < count; ++i) {
    const unsigned char* rec = records + i * record_length;
    point->next(enc, rec);
    if constexpr (Gps) gps->next(enc, rec + gps_at);
    if constexpr (Rgb) rgb->next(enc, rec + rgb_at);
    if constexpr (Wave) wave->encode(enc, rec - record_length + wave_at, rec + wave_at);
    if (extra) tail->next(enc, rec + extra_at);
  }
  enc.done();
  return out;
}

// --- the layout: VLR and chunk table -----------------------------------------------------------

/// The items LASzip writes for LAS point format f (before any BYTE item for extra bytes).
std::vector<std::uint16_t> expected_items(unsigned f) {
  switch (f) {
    case 0:
      return {item_point10};
    case 1:
      return {item_point10, item_gpstime11};
    case 2:
      return {item_point10, item_rgb12};
    case 3:
      return {item_point10, item_gpstime11, item_rgb12};
    case 4:
      return {item_point10, item_gpstime11, item_wavepacket13};
    case 5:
      return {item_point10, item_gpstime11, item_rgb12, item_wavepacket13};
    case 6:
      return {item_point14};
    case 7:
      return {item_point14, item_rgb14};
    case 8:
      return {item_point14, item_rgbnir14};
    case 9:
      return {item_point14, item_wavepacket14};
    case 10:
      return {item_point14, item_rgbnir14, item_wavepacket14};
    default:
      return {};
  }
}

std::uint16_t item_size(std::uint16_t type) {
  switch (type) {
    case item_point10:
      return 20;
    case item_gpstime11:
      return 8;
    case item_rgb12:
      return 6;
    case item_wavepacket13:
      return 29;
    case item_point14:
      return 30;
    case item_rgb14:
      return 6;
    case item_rgbnir14:
      return 8;
    case item_wavepacket14:
      return 29;
    default:
      return 0;
  }
}

std::string items_text(const std::vector<laz_item>& items) {
  std::string s;
  for (const laz_item& it : items)
    s += cat(s.empty() ? "" : ", ", item_name(it.type), "(", it.size, ") v", it.version);
  return s;
}

/// Checks the VLR's item list against the LAS header: the items of the point format, in
/// order, each of its size, then at most one BYTE (BYTE14 for formats 6–10) item holding the extra
/// bytes; the sizes add up to the record length; the versions are those we decode (2 for the
/// point-wise items, 3 for the layered ones).
void check_items(const std::string& path, const laz_layout& L) {
  const std::vector<std::uint16_t> want = expected_items(L.format);
  const bool layered = L.format >= 6;
  const auto& items = L.items;
  bool ok = items.size() >= want.size() && items.size() <= want.size() + 1;
  std::uint32_t total = 0;
  for (std::size_t i = 0; ok && i < items.size(); ++i) {
    if (i < want.size())
      ok = items[i].type == want[i] && items[i].size == item_size(want[i]);
    else
      ok = items[i].type == (layered ? item_byte14 : item_byte) && items[i].size > 0;
    total += items[i].size;
  }
  if (!ok || total != L.record_length)
    format_error(path, "LASzip VLR",
                 cat("items [", items_text(items), "] do not describe point format ", L.format,
                     " with ", L.record_length, "-byte records"));
  // LASzip's item versions: 2 for the point-wise items but 1 for WAVEPACKET13, 3 for the
  // layered ones.
  for (const laz_item& it : items) {
    const std::uint16_t version = layered ? 3 : it.type == item_wavepacket13 ? 1 : 2;
    if (it.version != version)
      format_error(path, "LASzip VLR",
                   cat("item ", item_name(it.type), " has compressor version ", it.version,
                       "; our LAZ decoder reads version ", version,
                       layered ? "" : " (LASzip 2.0 and later)"));
  }
}

/// The LASzip VLR's payload.
laz_layout parse_laszip_vlr(const std::string& path, const las_header& h,
                            const std::vector<unsigned char>& d) {
  if (d.size() < 34)
    format_error(path, "LASzip VLR", cat("payload of ", d.size(), " bytes, at least 34 expected"));
  laz_layout L;
  L.compressor = load_le<std::uint16_t>(d.data());
  const std::uint16_t coder = load_le<std::uint16_t>(d.data() + 2);
  L.chunk_size = load_le<std::uint32_t>(d.data() + 12);
  const std::uint16_t n_items = load_le<std::uint16_t>(d.data() + 32);
  if (d.size() < 34 + 6 * std::size_t{n_items})
    format_error(path, "LASzip VLR",
                 cat(n_items, " items need ", 34 + 6 * n_items, " bytes, the VLR has ", d.size()));
  for (std::size_t i = 0; i < n_items; ++i) {
    const unsigned char* p = d.data() + 34 + 6 * i;
    L.items.push_back(
        {load_le<std::uint16_t>(p), load_le<std::uint16_t>(p + 2), load_le<std::uint16_t>(p + 4)});
  }
  L.format = h.format;
  L.record_length = h.record_length;
  if (coder != 0)
    format_error(path, "LASzip VLR", cat("coder ", coder, " (expected 0, arithmetic)"));
  if (L.compressor == 1)
    format_error(path, "LASzip VLR",
                 "point-wise compression without chunks (LASzip 1.x) is not supported by our LAZ "
                 "decoder: recompress it with a current laszip, or decompress it to LAS");
  const std::uint16_t want = L.format >= 6 ? 3 : 2;
  if (L.compressor != want)
    format_error(path, "LASzip VLR",
                 cat("compressor ", L.compressor, " for point format ", L.format, " (expected ",
                     want, want == 3 ? ", layered chunked)" : ", point-wise chunked)"));
  if (L.chunk_size == 0)
    format_error(path, "LASzip VLR", "chunk size 0 (expected a positive count of points)");
  check_items(path, L);
  return L;
}

/// Reads the chunk table at `table_at` and fills L.chunks (offsets, sizes, counts), checked.
void read_chunk_table(const std::string& path, const las_header& h, std::uint64_t file_size,
                      const laz_fetch& fetch, std::uint64_t table_at, laz_layout& L) {
  const std::uint64_t first_chunk = std::uint64_t{h.data_offset} + 8;
  if (table_at < first_chunk || table_at > file_size || file_size - table_at < 8)
    format_error(path, "chunk table",
                 cat("offset ", table_at, " is not inside the file (", file_size,
                     " bytes) after the point data offset ", h.data_offset));
  unsigned char head[8];
  fetch(table_at, 8, head);
  const std::uint32_t version = load_le<std::uint32_t>(head);
  const std::uint32_t n = load_le<std::uint32_t>(head + 4);
  if (version != 0) format_error(path, "chunk table", cat("version ", version, " (expected 0)"));
  const std::uint64_t chunk_bytes = table_at - first_chunk;  // the bytes the chunks may use
  const bool variable = L.chunk_size == variable_chunks;
  if (!variable) {
    const std::uint64_t want = h.count / L.chunk_size + (h.count % L.chunk_size ? 1 : 0);
    if (n != want)
      format_error(
          path, "chunk table",
          cat(n, " chunks, but ", h.count, " points in chunks of ", L.chunk_size, " make ", want));
  }
  // Every chunk starts with a raw record: a count beyond that is a damaged table (and is not
  // allowed to size an allocation).
  if (n > chunk_bytes / std::max<std::uint16_t>(L.record_length, 1))
    format_error(path, "chunk table",
                 cat(n, " chunks cannot fit in the ", chunk_bytes, " bytes of point data"));
  if (n == 0) {
    if (h.count != 0) format_error(path, "chunk table", cat("no chunks for ", h.count, " points"));
    return;
  }
  std::vector<unsigned char> table(static_cast<std::size_t>(file_size - table_at - 8));
  if (!table.empty()) fetch(table_at + 8, table.size(), table.data());
  byte_source in(table.data(), table.size());
  range_decoder dec(in);
  integer_codec ic(32, 2);
  L.chunks.resize(n);
  std::uint32_t prev_count = 0, prev_bytes = 0;
  std::uint64_t offset = first_chunk, first = 0;
  for (std::uint32_t i = 0; i < n; ++i) {
    laz_chunk& c = L.chunks[i];
    if (variable) {
      prev_count =
          static_cast<std::uint32_t>(ic.decode(dec, static_cast<std::int32_t>(prev_count), 0));
      c.count = prev_count;
    } else {
      c.count = std::min<std::uint64_t>(L.chunk_size, h.count - first);
    }
    prev_bytes =
        static_cast<std::uint32_t>(ic.decode(dec, static_cast<std::int32_t>(prev_bytes), 1));
    c.bytes = prev_bytes;
    c.offset = offset;
    c.first = first;
    if (in.overrun() > 4)
      format_error(path, "chunk table",
                   cat("truncated: its coded sizes end at chunk ", i, " of ", n));
    if (c.bytes > table_at - offset)
      format_error(path, "chunk table",
                   cat("chunk ", i, " of ", c.bytes, " bytes at offset ", offset,
                       " runs past the chunk table at ", table_at));
    if (c.count > 0 && c.bytes < L.record_length)
      format_error(path, "chunk table",
                   cat("chunk ", i, " has ", c.bytes, " bytes, less than one raw ", L.record_length,
                       "-byte record"));
    // Even a record predicted perfectly costs its change mask and the bit lengths of dx and dy
    // (and z, POINT10), symbols whose models never give the likeliest value more than
    // 1 − (symbols − 1)/2^15: at least 0.0075 bits (POINT10) or 0.0084 bits (POINT14). More
    // than 1100 records per byte is damage (and may not size an allocation).
    if (c.count > 1 + 1100 * (c.bytes - std::min<std::uint64_t>(c.bytes, L.record_length)))
      format_error(path, "chunk table",
                   cat("chunk ", i, " claims ", c.count, " points in ", c.bytes, " bytes"));
    offset += c.bytes;
    first += c.count;
    if (variable && first > h.count)
      format_error(path, "chunk table",
                   cat("the chunks hold more than the header's ", h.count, " points"));
  }
  if (first != h.count)
    format_error(path, "chunk table",
                 cat("the chunks hold ", first, " points, the header says ", h.count));
}

}  // namespace

std::uint64_t laz_layout::max_chunk_count() const {
  std::uint64_t m = 0;
  for (const laz_chunk& c : chunks) m = std::max(m, c.count);
  return m;
}

std::size_t laz_layout::chunk_of(std::uint64_t r) const {
  const auto it = std::upper_bound(chunks.begin(), chunks.end(), r,
                                   [](std::uint64_t v, const laz_chunk& c) { return v < c.first; });
  return static_cast<std::size_t>(it - chunks.begin()) - 1;
}

laz_layout read_laz_layout(const std::string& path, const las_header& h, std::uint64_t file_size,
                           const laz_fetch& fetch) {
  // The VLRs lie between the header and the point data.
  std::optional<laz_layout> L;
  std::uint64_t at = h.header_size;
  for (std::uint32_t i = 0; i < h.vlr_count; ++i) {
    if (at + 54 > h.data_offset)
      format_error(path, cat("VLR ", i),
                   cat("its 54-byte header at offset ", at, " runs past the point data at ",
                       h.data_offset, " (", h.vlr_count, " VLRs declared)"));
    unsigned char v[54];
    fetch(at, 54, v);
    const std::uint16_t record_id = load_le<std::uint16_t>(v + 18);
    const std::uint16_t length = load_le<std::uint16_t>(v + 20);
    if (at + 54 + length > h.data_offset)
      format_error(
          path, cat("VLR ", i),
          cat(length, " bytes at offset ", at + 54, " run past the point data at ", h.data_offset));
    const bool laszip =
        std::memcmp(v + 2, "laszip encoded", 14) == 0 && v[16] == 0 && record_id == 22204;
    if (laszip && !L) {
      std::vector<unsigned char> d(length);
      if (length) fetch(at + 54, length, d.data());
      L = parse_laszip_vlr(path, h, d);
    }
    at += 54 + length;
  }
  if (!L)
    format_error(path, "VLRs",
                 cat("the point data is compressed (format byte bit 7) but none of the ",
                     h.vlr_count, " VLRs is LASzip's (user id \"laszip encoded\", record 22204)"));
  if (h.count == 0) return *L;  // writers differ in what they put after no points
  if (std::uint64_t{h.data_offset} + 8 > file_size)
    format_error(path, "chunk table",
                 cat("truncated: no chunk table offset at the point data offset ", h.data_offset));
  unsigned char off[8];
  fetch(h.data_offset, 8, off);
  auto table_at = load_le<std::int64_t>(off);
  if (table_at == -1) {
    // Written by a streaming writer that could not seek back: the offset is the file's end.
    fetch(file_size - 8, 8, off);
    table_at = load_le<std::int64_t>(off);
  }
  read_chunk_table(path, h, file_size, fetch,
                   table_at < 0 ? ~std::uint64_t{0} : static_cast<std::uint64_t>(table_at), *L);
  return *L;
}

void decode_laz_chunk(const std::string& path, const laz_layout& L, std::size_t k,
                      const unsigned char* bytes, unsigned char* records) {
  const laz_chunk& c = L.chunks[k];
  const auto n = static_cast<std::size_t>(c.bytes);
  std::uint64_t overrun = 0;
  switch (L.format) {
    case 0:
      overrun = decode_pointwise<false, false>(bytes, n, c.count, L.record_length, records);
      break;
    case 1:
      overrun = decode_pointwise<true, false>(bytes, n, c.count, L.record_length, records);
      break;
    case 2:
      overrun = decode_pointwise<false, true>(bytes, n, c.count, L.record_length, records);
      break;
    case 3:
      overrun = decode_pointwise<true, true>(bytes, n, c.count, L.record_length, records);
      break;
    case 4:
      overrun = decode_pointwise<true, false, true>(bytes, n, c.count, L.record_length, records);
      break;
    case 5:
      overrun = decode_pointwise<true, true, true>(bytes, n, c.count, L.record_length, records);
      break;
    case 6:
    case 7:
    case 8:
    case 9:
    case 10:
      overrun = decode_layered_chunk(path, L, k, bytes, n, c.count, records);
      break;
    default:
      format_error(path, cat("chunk ", k), cat("point format ", L.format, " is not supported"));
  }
  // LASzip's encoder pads every stream so that its decoder never reads past the end.
  if (overrun > 0)
    format_error(path, cat("chunk ", k),
                 cat("damaged or truncated: decoding its ", c.count, " points needs more than its ",
                     c.bytes, " bytes at offset ", c.offset));
}

void decode_laz_chunks(const std::string& path, const laz_layout& L, std::size_t c0, std::size_t c1,
                       const laz_fetch& fetch, unsigned char* records, unsigned threads) {
  if (c1 <= c0) return;
  const std::uint64_t base = L.chunks[c0].first;
  parallel_tasks(c1 - c0, resolve_threads(threads), [&](std::size_t t, unsigned) {
    const std::size_t k = c0 + t;
    const laz_chunk& c = L.chunks[k];
    std::vector<unsigned char> bytes(static_cast<std::size_t>(c.bytes));
    if (!bytes.empty()) fetch(c.offset, bytes.size(), bytes.data());
    decode_laz_chunk(path, L, k, bytes.data(), records + (c.first - base) * L.record_length);
  });
}

laz_fetch laz_record_reader::fetch() const {
  return
      [this](std::uint64_t at, std::size_t n, unsigned char* out) { file_.read_exact(at, n, out); };
}

laz_record_reader::chunk_records laz_record_reader::cached(std::size_t k) const {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (const auto hit = cache_.find(k); hit != cache_.end()) return hit->second;
  }
  // Decoded outside the lock: two threads may decode the same chunk, which costs time only.
  const laz_chunk& c = layout_.chunks[k];
  auto records = std::make_shared<std::vector<unsigned char>>(
      static_cast<std::size_t>(c.count * layout_.record_length));
  decode_laz_chunks(file_.path(), layout_, k, k + 1, fetch(), records->data(), 1);
  const std::lock_guard<std::mutex> lock(mutex_);
  if (cache_.contains(k)) return records;
  // At least a few chunks, and as many small ones as hold a small read's neighbourhood: a file
  // of chunks of a few records each (COPC's nodes) would otherwise decode a chunk per record.
  while (order_.size() >= cache_min_chunks && cached_records_ + c.count > cache_records) {
    cached_records_ -= layout_.chunks[order_.front()].count;
    cache_.erase(order_.front());
    order_.pop_front();
  }
  cache_.emplace(k, records);
  order_.push_back(k);
  cached_records_ += c.count;
  return records;
}

void laz_record_reader::read(std::uint64_t first, std::uint64_t n, unsigned char* out) const {
  if (n == 0) return;
  const std::uint64_t end = first + n;
  const std::size_t k0 = layout_.chunk_of(first), k1 = layout_.chunk_of(end - 1) + 1;
  const std::size_t rl = layout_.record_length;
  // A large read: the chunks wholly inside [first, end) straight into out, in parallel. A small
  // one (reads of a few points, which come in runs over the same chunks) all through the cache.
  std::size_t full0 = k0, full1 = k0;
  if (n >= cache_records) {
    full1 = k1;
    if (layout_.chunks[k0].first < first) ++full0;
    const laz_chunk& last = layout_.chunks[k1 - 1];
    if (last.first + last.count > end) --full1;
    if (full0 < full1)
      decode_laz_chunks(file_.path(), layout_, full0, full1, fetch(),
                        out + (layout_.chunks[full0].first - first) * rl);
  }
  for (std::size_t k = k0; k < k1; ++k) {
    if (k >= full0 && k < full1) continue;
    const laz_chunk& c = layout_.chunks[k];
    const chunk_records records = cached(k);
    const std::uint64_t lo = std::max(first, c.first), hi = std::min(end, c.first + c.count);
    std::memcpy(out + (lo - first) * rl, records->data() + (lo - c.first) * rl,
                static_cast<std::size_t>((hi - lo) * rl));
  }
}

std::vector<unsigned char> encode_pointwise_chunk(unsigned format, std::uint16_t record_length,
                                                  const unsigned char* records,
                                                  std::uint64_t count) {
  switch (format) {
    case 0:
      return encode_pointwise<false, false>(records, count, record_length);
    case 1:
      return encode_pointwise<true, false>(records, count, record_length);
    case 2:
      return encode_pointwise<false, true>(records, count, record_length);
    case 3:
      return encode_pointwise<true, true>(records, count, record_length);
    case 4:
      return encode_pointwise<true, false, true>(records, count, record_length);
    case 5:
      return encode_pointwise<true, true, true>(records, count, record_length);
    default:
      throw InvalidArgument(cat("encode_pointwise_chunk: point format ", format));
  }
}

}  // namespace pbr_lod::detail
