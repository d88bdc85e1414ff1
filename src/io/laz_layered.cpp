// pbr_lod — LAZ decoding and encoding of LAS 1.4 point formats 6–10: LASzip's layered chunked
// compressor (compressor 3) with the items POINT14, RGB14, RGBNIR14, WAVEPACKET14 and BYTE14, v3.
//
// Based on the LASzip paper (M. Isenburg, PE&RS 79(2), 2013) for the predictions, which are
// those of the point-wise items (laz_decoder.cpp), and on LASzip's LAS 1.4 compressor as read in
// LASzip, laz-perf and laz-rs (not copied): instead of one arithmetic-coded stream per chunk,
// every field group is a layer of its own, so a reader may skip the layers it does not need
// (we decode them all), and the contexts are kept per scanner channel (0–3) so that
// interleaved channels do not disturb each other's predictions.
//
// A chunk: the first record raw; u32 point count; the byte size (u32) of every layer — POINT14:
// xy (with the change mask and the returns), z, classification, flags, intensity, scan angle,
// user data, point source, GPS time; RGB14: rgb; RGBNIR14: rgb, nir; WAVEPACKET14: one; BYTE14:
// one per extra byte
// — then the layers, each an arithmetic-coded stream. An empty layer means the field never
// changes in the chunk: it keeps the first record's value.
#include <algorithm>
#include <array>
#include <memory>
#include <optional>

#include "laz_codec.hpp"
#include "laz_decoder.hpp"
#include "laz_encoder.hpp"

namespace pbr_lod::detail {
namespace {

using namespace laz;  // NOLINT: the coder of laz_codec.hpp, used throughout

/// One layer: its bytes and, when it has any, a decoder on them.
class layer {
 public:
  void open(const unsigned char* p, std::size_t n) {
    src_.emplace(p, n);
    if (n > 0) dec_.emplace(*src_);
  }
  [[nodiscard]] bool present() const { return dec_.has_value(); }
  range_decoder& dec() { return *dec_; }
  [[nodiscard]] std::uint64_t overrun() const { return src_ ? src_->overrun() : 0; }
  /// The decoder, or a decoder on no bytes (zeros, counted as overrun) when the layer is empty
  /// but a change bit asks for it — a damaged chunk.
  range_decoder& dec_or_empty() {
    if (!dec_) dec_.emplace(*src_);
    return *dec_;
  }

 private:
  std::optional<byte_source> src_;
  std::optional<range_decoder> dec_;
};

// Return number r and number of returns n (4 bits each) → 6 contexts for x and y (LASzip's
// table; it completes the regular cases for files that number returns oddly).
constexpr std::uint8_t return_map_6[16][16] = {{0, 1, 2, 3, 4, 5, 3, 4, 4, 5, 5, 5, 5, 5, 5, 5},
                                               {1, 0, 1, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3},
                                               {2, 1, 2, 4, 4, 4, 4, 4, 4, 4, 4, 3, 3, 3, 3, 3},
                                               {3, 3, 4, 5, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4},
                                               {4, 3, 4, 4, 5, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4},
                                               {5, 3, 4, 4, 4, 5, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4},
                                               {3, 3, 4, 4, 4, 4, 5, 4, 4, 4, 4, 4, 4, 4, 4, 4},
                                               {4, 3, 4, 4, 4, 4, 4, 5, 4, 4, 4, 4, 4, 4, 4, 4},
                                               {4, 3, 4, 4, 4, 4, 4, 4, 5, 4, 4, 4, 4, 4, 4, 4},
                                               {5, 3, 4, 4, 4, 4, 4, 4, 4, 5, 4, 4, 4, 4, 4, 4},
                                               {5, 3, 4, 4, 4, 4, 4, 4, 4, 4, 5, 4, 4, 4, 4, 4},
                                               {5, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5, 4, 4, 4},
                                               {5, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5, 5, 4, 4},
                                               {5, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5, 5, 4},
                                               {5, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5, 5},
                                               {5, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5}};

/// The z context: how far the return is from the last, |n − r|, at most 7.
constexpr unsigned return_level_8(unsigned n, unsigned r) {
  return std::min(n > r ? n - r : r - n, 7u);
}

/// A LAS 1.4 format 6 record (30 bytes) as fields.
struct point14 {
  std::int32_t x = 0, y = 0, z = 0;
  std::uint16_t intensity = 0;
  std::uint8_t r = 0, n = 0;  // return number, number of returns (4 bits each)
  std::uint8_t class_flags = 0, channel = 0, scan_dir = 0, edge = 0;
  std::uint8_t classification = 0, user_data = 0;
  std::uint16_t scan_angle = 0, point_source = 0;
  std::uint64_t gps = 0;  // the double's bits

  void load(const unsigned char* p) {
    x = load_le<std::int32_t>(p);
    y = load_le<std::int32_t>(p + 4);
    z = load_le<std::int32_t>(p + 8);
    intensity = load_le<std::uint16_t>(p + 12);
    r = p[14] & 15u;
    n = p[14] >> 4;
    class_flags = p[15] & 15u;
    channel = (p[15] >> 4) & 3u;
    scan_dir = (p[15] >> 6) & 1u;
    edge = p[15] >> 7;
    classification = p[16];
    user_data = p[17];
    scan_angle = load_le<std::uint16_t>(p + 18);
    point_source = load_le<std::uint16_t>(p + 20);
    gps = load_le<std::uint64_t>(p + 22);
  }
  void store(unsigned char* p) const {
    store_le(p, x);
    store_le(p + 4, y);
    store_le(p + 8, z);
    store_le(p + 12, intensity);
    p[14] = static_cast<unsigned char>(r | (n << 4));
    p[15] =
        static_cast<unsigned char>(class_flags | (channel << 4) | (scan_dir << 6) | (edge << 7));
    p[16] = classification;
    p[17] = user_data;
    store_le(p + 18, scan_angle);
    store_le(p + 20, point_source);
    store_le(p + 22, gps);
  }
  /// The 6 bits the flags layer codes: classification flags, scan direction, edge of line.
  [[nodiscard]] unsigned flags() const { return class_flags | (scan_dir << 4u) | (edge << 5u); }
};

enum point14_layer : std::size_t {
  l_xy,
  l_z,
  l_class,
  l_flags,
  l_intensity,
  l_scan_angle,
  l_user_data,
  l_point_source,
  l_gps,
  point14_layers
};

/// The state of POINT14 for one scanner channel, the same on both sides of the coder: the last
/// record, the predictions' state and the models.
struct point14_channel {
  point14 p;
  bool gps_changed = false;
  std::array<std::uint16_t, 8> last_intensity{};
  std::array<std::int32_t, 8> last_z{};
  std::array<median5, 12> x_median, y_median;
  // GPS time: four sequences, as GPSTIME11 (laz_decoder.cpp), with v3's codes.
  std::array<std::uint64_t, 4> time{};
  std::array<std::int32_t, 4> diff{};
  std::array<std::int32_t, 4> extreme{};
  std::uint32_t last = 0, next = 0;

  std::array<lazy_model, 8> changed;
  symbol_model scanner{3};
  symbol_model rn_gps_same{13};
  std::array<lazy_model, 16> nr, rn;
  std::array<lazy_model, 64> classification, flags, user_data;
  symbol_model gps_multi{515};
  symbol_model gps_zero_diff{5};
  integer_codec dx{32, 2}, dy{32, 22}, dz{32, 20}, intensity{16, 4}, scan_angle{16, 2},
      point_source{16, 1}, gps{32, 9};
};

/// A channel's first state, from the record `seed` (the chunk's first record, or the last
/// record of the channel before).
void start_channel(std::array<std::unique_ptr<point14_channel>, 4>& ch, unsigned sc,
                   const point14& seed) {
  ch[sc] = std::make_unique<point14_channel>();
  point14_channel& c = *ch[sc];
  c.p = seed;
  c.last_z.fill(seed.z);
  c.last_intensity.fill(seed.intensity);
  c.time[0] = seed.gps;
}

/// POINT14 v3. Per scanner channel: the last record, the predictions' state and the models,
/// made when the channel first occurs (from the record of the channel before it).
class point14_decoder {
 public:
  void first(const unsigned char* rec) {
    point14 p;
    p.load(rec);
    current_ = p.channel;
    start_channel(ch_, current_, p);
  }

  /// Decodes the next record into rec; returns its scanner channel (the other items' context).
  unsigned next(std::array<layer, point14_layers>& L, unsigned char* rec) {
    point14_channel& prev = *ch_[current_];
    range_decoder& xy = L[l_xy].dec();
    const unsigned lpr =
        (prev.p.r == 1 ? 1u : 0u) | (prev.p.r >= prev.p.n ? 2u : 0u) | (prev.gps_changed ? 4u : 0u);
    const std::uint32_t changed = xy.decode_symbol(prev.changed[lpr].get(128));
    unsigned sc = current_;
    if (changed & 64) {  // the scanner channel changed
      sc = (prev.p.channel + xy.decode_symbol(prev.scanner) + 1) % 4;
      if (!ch_[sc]) start_channel(ch_, sc, prev.p);
      current_ = sc;
    }
    point14_channel& c = *ch_[sc];
    point14& p = c.p;
    p.channel = static_cast<std::uint8_t>(sc);
    const bool gps_changed = (changed & 16) != 0;

    // Returns: n coded when bit 2 says so; r stepped by ±1 (bits 0, 1) or coded (both).
    unsigned n = p.n, r = p.r;
    if (changed & 4) n = xy.decode_symbol(c.nr[p.n].get(16));
    p.n = static_cast<std::uint8_t>(n);
    const bool plus = changed & 1, minus = changed & 2;
    if (plus && !minus)
      r = (r + 1) % 16;
    else if (minus && !plus)
      r = (r + 15) % 16;
    else if (plus && minus)
      r = gps_changed ? xy.decode_symbol(c.rn[r].get(16))
                      : (r + xy.decode_symbol(c.rn_gps_same) + 2) % 16;
    p.r = static_cast<std::uint8_t>(r);

    // x and y against the median of the last five differences of the context.
    const unsigned ctx = (return_map_6[n][r] << 1u) | (gps_changed ? 1u : 0u);
    const std::uint32_t single = n == 1 ? 1u : 0u;
    std::int32_t diff = c.dx.decode(xy, c.x_median[ctx].get(), single);
    p.x = static_cast<std::int32_t>(static_cast<std::uint32_t>(p.x) +
                                    static_cast<std::uint32_t>(diff));
    c.x_median[ctx].add(diff);
    std::uint32_t k = std::min(c.dx.k(), 20u) & ~1u;
    diff = c.dy.decode(xy, c.y_median[ctx].get(), single | k);
    p.y = static_cast<std::int32_t>(static_cast<std::uint32_t>(p.y) +
                                    static_cast<std::uint32_t>(diff));
    c.y_median[ctx].add(diff);
    if (L[l_z].present()) {
      k = std::min((c.dx.k() + c.dy.k()) / 2, 18u) & ~1u;
      const unsigned level = return_level_8(n, r);
      p.z = c.dz.decode(L[l_z].dec(), c.last_z[level], single | k);
      c.last_z[level] = p.z;
    }
    if (L[l_class].present()) {
      const unsigned cc = ((r == 1 && r >= n) ? 1u : 0u) | ((p.classification & 0x1Fu) << 1);
      p.classification =
          static_cast<std::uint8_t>(L[l_class].dec().decode_symbol(c.classification[cc].get(256)));
    }
    if (L[l_flags].present()) {
      const std::uint32_t f = L[l_flags].dec().decode_symbol(c.flags[p.flags()].get(64));
      p.edge = (f >> 5) & 1u;
      p.scan_dir = (f >> 4) & 1u;
      p.class_flags = f & 15u;
    }
    if (L[l_intensity].present()) {
      const unsigned ic = (gps_changed ? 1u : 0u) | (r >= n ? 2u : 0u) | (r == 1 ? 4u : 0u);
      p.intensity = static_cast<std::uint16_t>(
          c.intensity.decode(L[l_intensity].dec(), c.last_intensity[ic], ic >> 1));
      c.last_intensity[ic] = p.intensity;
    }
    if (changed & 8)
      p.scan_angle = static_cast<std::uint16_t>(
          c.scan_angle.decode(L[l_scan_angle].dec_or_empty(), p.scan_angle, gps_changed ? 1 : 0));
    if (L[l_user_data].present())
      p.user_data = static_cast<std::uint8_t>(
          L[l_user_data].dec().decode_symbol(c.user_data[p.user_data / 4].get(256)));
    if (changed & 32)
      p.point_source = static_cast<std::uint16_t>(
          c.point_source.decode(L[l_point_source].dec_or_empty(), p.point_source, 0));
    if (gps_changed) decode_gps(c, L[l_gps].dec_or_empty());
    c.gps_changed = gps_changed;
    p.store(rec);
    return sc;
  }

  [[nodiscard]] unsigned current() const { return current_; }

 private:
  static constexpr std::uint32_t multi_max = 500, code_full = 511;

  void decode_gps(point14_channel& c, range_decoder& dec) {
    const auto times = [&](std::int32_t f) {  // f · last difference, wrapping like LASzip
      return static_cast<std::int32_t>(static_cast<std::uint32_t>(f) *
                                       static_cast<std::uint32_t>(c.diff[c.last]));
    };
    const auto add = [&](std::int32_t d) {
      c.time[c.last] += static_cast<std::uint64_t>(static_cast<std::int64_t>(d));
    };
    const auto extreme = [&](std::int32_t d) {
      if (++c.extreme[c.last] > 3) {
        c.diff[c.last] = d;
        c.extreme[c.last] = 0;
      }
    };
    const auto full = [&] {
      c.next = (c.next + 1) & 3u;
      const auto high = static_cast<std::int32_t>(static_cast<std::uint32_t>(c.time[c.last] >> 32));
      c.time[c.next] =
          static_cast<std::uint64_t>(static_cast<std::uint32_t>(c.gps.decode(dec, high, 8))) << 32;
      c.time[c.next] |= dec.read_int();
      c.last = c.next;
      c.diff[c.last] = 0;
      c.extreme[c.last] = 0;
    };
    // A switch of sequence is followed by that sequence's own code; bounded for damaged data.
    for (int hops = 0; hops < 8; ++hops) {
      if (c.diff[c.last] == 0) {
        const std::uint32_t multi = dec.decode_symbol(c.gps_zero_diff);
        if (multi == 0) {
          c.diff[c.last] = c.gps.decode(dec, 0, 0);
          add(c.diff[c.last]);
          c.extreme[c.last] = 0;
        } else if (multi == 1) {
          full();
        } else {
          c.last = (c.last + multi - 1) & 3u;
          continue;
        }
        break;
      }
      const std::uint32_t multi = dec.decode_symbol(c.gps_multi);
      if (multi == 1) {
        add(c.gps.decode(dec, c.diff[c.last], 1));
        c.extreme[c.last] = 0;
      } else if (multi < code_full) {
        std::int32_t d;
        if (multi == 0) {
          d = c.gps.decode(dec, 0, 7);
          extreme(d);
        } else if (multi < multi_max) {
          d = c.gps.decode(dec, times(static_cast<std::int32_t>(multi)), multi < 10 ? 2 : 3);
        } else if (multi == multi_max) {
          d = c.gps.decode(dec, times(500), 4);
          extreme(d);
        } else {
          const int f = 500 - static_cast<int>(multi);  // −1 … −10
          if (f > -10) {
            d = c.gps.decode(dec, times(f), 5);
          } else {
            d = c.gps.decode(dec, times(-10), 6);
            extreme(d);
          }
        }
        add(d);
      } else if (multi == code_full) {
        full();
      } else {
        c.last = (c.last + multi - code_full) & 3u;
        continue;
      }
      break;
    }
    c.p.gps = c.time[c.last];
  }

  std::array<std::unique_ptr<point14_channel>, 4> ch_;
  unsigned current_ = 0;
};

/// RGB14 v3 (and the rgb layer of RGBNIR14): RGB12's prediction, contexts per channel. Like
/// LASzip, a switch to a channel seen before predicts from the previous channel's last colour
/// (and updates it); a new channel starts from that colour.
template <int Bytes>
class channel_items {
 public:
  /// Where the last value of the current channel is, for the first record.
  void first(const unsigned char* rec, unsigned sc) {
    last_ch_ = sc;
    slot(sc).used = true;
    std::copy(rec, rec + Bytes, slot(sc).last.begin());
  }

 protected:
  struct ctx {
    bool used = false;
    std::array<unsigned char, Bytes> last{};
  };
  /// The last value to predict from after a switch to channel sc (see the class comment).
  unsigned char* switch_to(unsigned sc) {
    unsigned char* last = slot(last_ch_).last.data();
    if (sc != last_ch_) {
      last_ch_ = sc;
      if (!slot(sc).used) {
        slot(sc).used = true;
        std::copy(last, last + Bytes, slot(sc).last.begin());
        last = slot(sc).last.data();
      }
    }
    return last;
  }
  ctx& slot(unsigned sc) { return slots_[sc]; }
  unsigned last_ch_ = 0;
  std::array<ctx, 4> slots_;
};

class rgb14_decoder : public channel_items<6> {
 public:
  void next(layer& rgb, unsigned sc, unsigned char* rec) {
    if (!rgb.present()) {
      std::copy(slot(last_ch_).last.begin(), slot(last_ch_).last.end(), rec);
      return;
    }
    unsigned char* lastp = switch_to(sc);
    models& m = model(sc);
    range_decoder& dec = rgb.dec();
    std::array<std::uint32_t, 3> last{}, v{};
    for (int c = 0; c < 3; ++c) last[c] = load_le<std::uint16_t>(lastp + 2 * c);
    const std::uint32_t sym = dec.decode_symbol(m.used);
    const auto lo = [](std::uint32_t c) { return c & 0xFFu; };
    const auto hi = [](std::uint32_t c) { return c >> 8; };
    const auto clamp8 = [](int x) { return static_cast<std::uint32_t>(std::clamp(x, 0, 255)); };
    const auto sym8 = [&](int i) { return dec.decode_symbol(m.diff[i]); };
    v[0] = (sym & 1) ? ((sym8(0) + lo(last[0])) & 0xFFu) : lo(last[0]);
    v[0] |= (sym & 2) ? ((sym8(1) + hi(last[0])) & 0xFFu) << 8 : (last[0] & 0xFF00u);
    if (sym & 64) {
      int diff = static_cast<int>(lo(v[0])) - static_cast<int>(lo(last[0]));
      v[1] = (sym & 4) ? ((sym8(2) + clamp8(diff + static_cast<int>(lo(last[1])))) & 0xFFu)
                       : lo(last[1]);
      if (sym & 16) {
        const std::uint32_t corr = sym8(4);
        diff = (diff + static_cast<int>(lo(v[1])) - static_cast<int>(lo(last[1]))) / 2;
        v[2] = (corr + clamp8(diff + static_cast<int>(lo(last[2])))) & 0xFFu;
      } else {
        v[2] = lo(last[2]);
      }
      diff = static_cast<int>(hi(v[0])) - static_cast<int>(hi(last[0]));
      if (sym & 8)
        v[1] |= ((sym8(3) + clamp8(diff + static_cast<int>(hi(last[1])))) & 0xFFu) << 8;
      else
        v[1] |= last[1] & 0xFF00u;
      if (sym & 32) {
        const std::uint32_t corr = sym8(5);
        diff = (diff + static_cast<int>(hi(v[1])) - static_cast<int>(hi(last[1]))) / 2;
        v[2] |= ((corr + clamp8(diff + static_cast<int>(hi(last[2])))) & 0xFFu) << 8;
      } else {
        v[2] |= last[2] & 0xFF00u;
      }
    } else {
      v[1] = v[2] = v[0];
    }
    for (int c = 0; c < 3; ++c) store_le(lastp + 2 * c, static_cast<std::uint16_t>(v[c]));
    std::copy(lastp, lastp + 6, rec);
  }

 private:
  struct models {
    symbol_model used{128};
    symbol_model diff[6] = {symbol_model(256), symbol_model(256), symbol_model(256),
                            symbol_model(256), symbol_model(256), symbol_model(256)};
  };
  models& model(unsigned sc) {
    if (!models_[sc]) models_[sc] = std::make_unique<models>();
    return *models_[sc];
  }
  std::array<std::unique_ptr<models>, 4> models_;
};

/// The nir layer of RGBNIR14 v3: the low and high byte, each against the last.
class nir14_decoder : public channel_items<2> {
 public:
  void next(layer& nir, unsigned sc, unsigned char* rec) {
    if (!nir.present()) {
      std::copy(slot(last_ch_).last.begin(), slot(last_ch_).last.end(), rec);
      return;
    }
    unsigned char* lastp = switch_to(sc);
    models& m = model(sc);
    range_decoder& dec = nir.dec();
    const std::uint32_t sym = dec.decode_symbol(m.used);
    if (sym & 1) lastp[0] = static_cast<unsigned char>(lastp[0] + dec.decode_symbol(m.diff[0]));
    if (sym & 2) lastp[1] = static_cast<unsigned char>(lastp[1] + dec.decode_symbol(m.diff[1]));
    rec[0] = lastp[0];
    rec[1] = lastp[1];
  }

 private:
  struct models {
    symbol_model used{4};
    symbol_model diff[2] = {symbol_model(256), symbol_model(256)};
  };
  models& model(unsigned sc) {
    if (!models_[sc]) models_[sc] = std::make_unique<models>();
    return *models_[sc];
  }
  std::array<std::unique_ptr<models>, 4> models_;
};

/// BYTE14 v3: every extra byte a layer of its own, against the same byte of the last record.
class byte14_decoder {
 public:
  explicit byte14_decoder(std::size_t n) : n_(n) {}
  void first(const unsigned char* rec, unsigned sc) {
    last_ch_ = sc;
    slot(sc).used = true;
    slot(sc).last.assign(rec, rec + n_);
  }
  void next(std::vector<layer>& layers, unsigned sc, unsigned char* rec) {
    std::vector<unsigned char>* last = &slot(last_ch_).last;
    if (sc != last_ch_) {
      last_ch_ = sc;
      if (!slot(sc).used) {
        slot(sc).used = true;
        slot(sc).last = *last;
        last = &slot(sc).last;
      }
    }
    ctx& c = slot(sc);
    for (std::size_t i = 0; i < n_; ++i) {
      if (layers[i].present()) {
        if (c.models.empty()) c.models.resize(n_);
        (*last)[i] = static_cast<unsigned char>(
            (*last)[i] + layers[i].dec().decode_symbol(c.models[i].get(256)));
      }
      rec[i] = (*last)[i];
    }
  }

 private:
  struct ctx {
    bool used = false;
    std::vector<unsigned char> last;
    std::vector<lazy_model> models;
  };
  ctx& slot(unsigned sc) { return slots_[sc]; }
  std::size_t n_;
  unsigned last_ch_ = 0;
  std::array<ctx, 4> slots_;
};

// --- encoding: the same models and predictions, run forwards -----------------------------------

/// A layer being written: its bytes, an encoder on them, and whether any record changed the
/// field (an unchanged layer is not written: the decoder keeps the first record's value).
struct out_layer {
  std::vector<unsigned char> bytes;
  range_encoder enc{bytes};
  bool changed = false;
};

class point14_encoder {
 public:
  void first(const unsigned char* rec) {
    point14 p;
    p.load(rec);
    current_ = p.channel;
    start_channel(ch_, current_, p);
  }

  /// Encodes rec; returns its scanner channel (the other items' context).
  unsigned next(std::array<std::unique_ptr<out_layer>, point14_layers>& L,
                const unsigned char* rec) {
    point14 q;
    q.load(rec);
    const unsigned sc = q.channel;
    point14_channel& prev = *ch_[current_];
    // The changes are judged against this channel's last record, or for a channel new in the
    // chunk against the record it will start from (the previous channel's).
    const point14& old = ch_[sc] ? ch_[sc]->p : prev.p;
    // Bits, not doubles: LAZ must give back every time exactly (−0.0, NaNs included).
    const bool gps_change = q.gps != old.gps;
    const bool source_change = q.point_source != old.point_source;
    const bool angle_change = q.scan_angle != old.scan_angle;
    const unsigned last_n = old.n, last_r = old.r, n = q.n, r = q.r;
    const bool inc = r == (last_r + 1) % 16, dec = r == (last_r + 15) % 16;
    const bool misc = r != last_r && !inc && !dec;
    const std::uint32_t changed = ((inc || misc) ? 1u : 0u) | ((dec || misc) ? 2u : 0u) |
                                  (n != last_n ? 4u : 0u) | (angle_change ? 8u : 0u) |
                                  (gps_change ? 16u : 0u) | (source_change ? 32u : 0u) |
                                  (sc != current_ ? 64u : 0u);
    range_encoder& xy = L[l_xy]->enc;
    const unsigned lpr =
        (prev.p.r == 1 ? 1u : 0u) | (prev.p.r >= prev.p.n ? 2u : 0u) | (prev.gps_changed ? 4u : 0u);
    xy.encode_symbol(prev.changed[lpr].get(128), changed);
    if (sc != current_) {
      xy.encode_symbol(prev.scanner, (sc + 4 - current_ - 1) % 4);
      if (!ch_[sc]) start_channel(ch_, sc, prev.p);
      current_ = sc;
    }
    point14_channel& c = *ch_[sc];
    point14& p = c.p;
    if (n != last_n) xy.encode_symbol(c.nr[last_n].get(16), n);
    if (misc) {
      if (gps_change)
        xy.encode_symbol(c.rn[last_r].get(16), r);
      else
        xy.encode_symbol(c.rn_gps_same, (r + 32 - last_r - 2) % 16);
    }
    const unsigned ctx = (return_map_6[n][r] << 1u) | (gps_change ? 1u : 0u);
    const std::uint32_t single = n == 1 ? 1u : 0u;
    const auto minus = [](std::int32_t a, std::int32_t b) {
      return static_cast<std::int32_t>(static_cast<std::uint32_t>(a) -
                                       static_cast<std::uint32_t>(b));
    };
    std::int32_t diff = minus(q.x, p.x);
    c.dx.encode(xy, c.x_median[ctx].get(), diff, single);
    c.x_median[ctx].add(diff);
    std::uint32_t k = std::min(c.dx.k(), 20u) & ~1u;
    diff = minus(q.y, p.y);
    c.dy.encode(xy, c.y_median[ctx].get(), diff, single | k);
    c.y_median[ctx].add(diff);
    {
      k = std::min((c.dx.k() + c.dy.k()) / 2, 18u) & ~1u;
      const unsigned level = return_level_8(n, r);
      L[l_z]->changed = true;  // LASzip always writes the z layer
      c.dz.encode(L[l_z]->enc, c.last_z[level], q.z, single | k);
      c.last_z[level] = q.z;
    }
    {
      const unsigned cc = ((r == 1 && r >= n) ? 1u : 0u) | ((p.classification & 0x1Fu) << 1);
      L[l_class]->changed |= q.classification != p.classification;
      L[l_class]->enc.encode_symbol(c.classification[cc].get(256), q.classification);
    }
    {
      L[l_flags]->changed |= q.flags() != p.flags();
      L[l_flags]->enc.encode_symbol(c.flags[p.flags()].get(64), q.flags());
    }
    {
      const unsigned ic = (gps_change ? 1u : 0u) | (r >= n ? 2u : 0u) | (r == 1 ? 4u : 0u);
      L[l_intensity]->changed |= q.intensity != p.intensity;
      c.intensity.encode(L[l_intensity]->enc, c.last_intensity[ic], q.intensity, ic >> 1);
      c.last_intensity[ic] = q.intensity;
    }
    if (angle_change) {
      L[l_scan_angle]->changed = true;
      c.scan_angle.encode(L[l_scan_angle]->enc, p.scan_angle, q.scan_angle, gps_change ? 1 : 0);
    }
    {
      L[l_user_data]->changed |= q.user_data != p.user_data;
      L[l_user_data]->enc.encode_symbol(c.user_data[p.user_data / 4].get(256), q.user_data);
    }
    if (source_change) {
      L[l_point_source]->changed = true;
      c.point_source.encode(L[l_point_source]->enc, p.point_source, q.point_source, 0);
    }
    if (gps_change) {
      L[l_gps]->changed = true;
      encode_gps(c, L[l_gps]->enc, q.gps);
    }
    c.gps_changed = gps_change;
    p = q;
    return sc;
  }

 private:
  static constexpr std::int32_t multi_max = 500, multi_minus = -10, code_full = 511;

  /// The first of sequences last + start … last + 3 from which t is a 32-bit difference (and
  /// that difference), or −1.
  static int find_sequence(const point14_channel& c, std::uint64_t t, int start, std::int32_t& d) {
    for (int i = start; i < 4; ++i) {
      const std::uint64_t delta = t - c.time[(c.last + static_cast<unsigned>(i)) & 3u];
      const auto d64 = static_cast<std::int64_t>(delta);
      if (d64 >= std::numeric_limits<std::int32_t>::min() &&
          d64 <= std::numeric_limits<std::int32_t>::max()) {
        d = static_cast<std::int32_t>(d64);
        return i;
      }
    }
    return -1;
  }

  void encode_gps(point14_channel& c, range_encoder& enc, std::uint64_t t) {
    const auto times = [&](std::int32_t f) {
      return static_cast<std::int32_t>(static_cast<std::uint32_t>(f) *
                                       static_cast<std::uint32_t>(c.diff[c.last]));
    };
    const auto extreme = [&](std::int32_t d) {
      if (++c.extreme[c.last] > 3) {
        c.diff[c.last] = d;
        c.extreme[c.last] = 0;
      }
    };
    const auto full = [&] {
      const auto high = [](std::uint64_t v) {
        return static_cast<std::int32_t>(static_cast<std::uint32_t>(v >> 32));
      };
      c.gps.encode(enc, high(c.time[c.last]), high(t), 8);
      enc.write_bits(32, static_cast<std::uint32_t>(t));
      c.next = (c.next + 1) & 3u;
      c.last = c.next;
      c.diff[c.last] = 0;
      c.extreme[c.last] = 0;
    };
    for (;;) {  // at most one switch of sequence, then a code in it
      std::int32_t d = 0;
      if (c.diff[c.last] == 0) {
        const int i = find_sequence(c, t, 0, d);
        if (i == 0) {
          enc.encode_symbol(c.gps_zero_diff, 0);
          c.gps.encode(enc, 0, d, 0);
          c.diff[c.last] = d;
          c.extreme[c.last] = 0;
        } else if (i > 0) {
          enc.encode_symbol(c.gps_zero_diff, static_cast<std::uint32_t>(i) + 1);
          c.last = (c.last + static_cast<unsigned>(i)) & 3u;
          continue;
        } else {
          enc.encode_symbol(c.gps_zero_diff, 1);
          full();
        }
        c.time[c.last] = t;
        return;
      }
      const auto d64 = static_cast<std::int64_t>(t - c.time[c.last]);
      if (d64 >= std::numeric_limits<std::int32_t>::min() &&
          d64 <= std::numeric_limits<std::int32_t>::max()) {
        d = static_cast<std::int32_t>(d64);
        // The multiple of the last difference, rounded as LASzip does (in float, half away
        // from zero); any choice decodes, this one gives LASzip's bytes.
        const float ratio = static_cast<float>(d) / static_cast<float>(c.diff[c.last]);
        const auto multi = static_cast<std::int32_t>(ratio >= 0 ? ratio + 0.5f : ratio - 0.5f);
        if (multi > 0 && multi < multi_max) {
          enc.encode_symbol(c.gps_multi, static_cast<std::uint32_t>(multi));
          c.gps.encode(enc, times(multi), d, multi == 1 ? 1 : multi < 10 ? 2 : 3);
          if (multi == 1) c.extreme[c.last] = 0;
        } else if (multi >= multi_max) {
          enc.encode_symbol(c.gps_multi, multi_max);
          c.gps.encode(enc, times(multi_max), d, 4);
          extreme(d);
        } else if (multi < 0 && multi > multi_minus) {
          enc.encode_symbol(c.gps_multi, static_cast<std::uint32_t>(multi_max - multi));
          c.gps.encode(enc, times(multi), d, 5);
        } else if (multi <= multi_minus) {
          enc.encode_symbol(c.gps_multi, static_cast<std::uint32_t>(multi_max - multi_minus));
          c.gps.encode(enc, times(multi_minus), d, 6);
          extreme(d);
        } else {  // 0
          enc.encode_symbol(c.gps_multi, 0);
          c.gps.encode(enc, 0, d, 7);
          extreme(d);
        }
      } else {
        const int i = find_sequence(c, t, 1, d);
        if (i > 0) {
          enc.encode_symbol(c.gps_multi, static_cast<std::uint32_t>(code_full + i));
          c.last = (c.last + static_cast<unsigned>(i)) & 3u;
          continue;
        }
        enc.encode_symbol(c.gps_multi, code_full);
        full();
      }
      c.time[c.last] = t;
      return;
    }
  }

  std::array<std::unique_ptr<point14_channel>, 4> ch_;
  unsigned current_ = 0;
};

struct rgb14_models {
  symbol_model used{128};
  symbol_model diff[6] = {symbol_model(256), symbol_model(256), symbol_model(256),
                          symbol_model(256), symbol_model(256), symbol_model(256)};
};

class rgb14_encoder : public channel_items<6> {
 public:
  void next(out_layer& L, unsigned sc, const unsigned char* rec) {
    unsigned char* lastp = switch_to(sc);
    if (!models_[sc]) models_[sc] = std::make_unique<rgb14_models>();
    rgb14_models& m = *models_[sc];
    std::array<std::uint32_t, 3> last{}, v{};
    for (int c = 0; c < 3; ++c) {
      last[c] = load_le<std::uint16_t>(lastp + 2 * c);
      v[c] = load_le<std::uint16_t>(rec + 2 * c);
    }
    const auto lo = [](std::uint32_t c) { return static_cast<int>(c & 0xFFu); };
    const auto hi = [](std::uint32_t c) { return static_cast<int>(c >> 8); };
    const auto clamp8 = [](int x) { return std::clamp(x, 0, 255); };
    const auto put = [&](int i, int x) {
      L.enc.encode_symbol(m.diff[i], static_cast<std::uint8_t>(x));
    };
    const std::uint32_t sym =
        (lo(v[0]) != lo(last[0]) ? 1u : 0u) | (hi(v[0]) != hi(last[0]) ? 2u : 0u) |
        (lo(v[1]) != lo(last[1]) ? 4u : 0u) | (hi(v[1]) != hi(last[1]) ? 8u : 0u) |
        (lo(v[2]) != lo(last[2]) ? 16u : 0u) | (hi(v[2]) != hi(last[2]) ? 32u : 0u) |
        (v[0] != v[1] || v[0] != v[2] ? 64u : 0u);
    L.changed |= v != last;
    L.enc.encode_symbol(m.used, sym);
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
    std::copy(rec, rec + 6, lastp);
  }

 private:
  std::array<std::unique_ptr<rgb14_models>, 4> models_;
};

class nir14_encoder : public channel_items<2> {
 public:
  void next(out_layer& L, unsigned sc, const unsigned char* rec) {
    unsigned char* lastp = switch_to(sc);
    if (!models_[sc]) models_[sc] = std::make_unique<models>();
    models& m = *models_[sc];
    const std::uint32_t sym = (rec[0] != lastp[0] ? 1u : 0u) | (rec[1] != lastp[1] ? 2u : 0u);
    L.changed |= sym != 0;
    L.enc.encode_symbol(m.used, sym);
    if (sym & 1) L.enc.encode_symbol(m.diff[0], static_cast<std::uint8_t>(rec[0] - lastp[0]));
    if (sym & 2) L.enc.encode_symbol(m.diff[1], static_cast<std::uint8_t>(rec[1] - lastp[1]));
    lastp[0] = rec[0];
    lastp[1] = rec[1];
  }

 private:
  struct models {
    symbol_model used{4};
    symbol_model diff[2] = {symbol_model(256), symbol_model(256)};
  };
  std::array<std::unique_ptr<models>, 4> models_;
};

class byte14_encoder {
 public:
  explicit byte14_encoder(std::size_t n) : n_(n) {}
  void first(const unsigned char* rec, unsigned sc) {
    last_ch_ = sc;
    slots_[sc].used = true;
    slots_[sc].last.assign(rec, rec + n_);
  }
  void next(std::vector<std::unique_ptr<out_layer>>& layers, unsigned sc,
            const unsigned char* rec) {
    std::vector<unsigned char>* last = &slots_[last_ch_].last;
    if (sc != last_ch_) {
      last_ch_ = sc;
      if (!slots_[sc].used) {
        slots_[sc].used = true;
        slots_[sc].last = *last;
        last = &slots_[sc].last;
      }
    }
    auto& c = slots_[sc];
    if (c.models.empty()) c.models.resize(n_);
    for (std::size_t i = 0; i < n_; ++i) {
      layers[i]->changed |= rec[i] != (*last)[i];
      layers[i]->enc.encode_symbol(c.models[i].get(256),
                                   static_cast<std::uint8_t>(rec[i] - (*last)[i]));
      (*last)[i] = rec[i];
    }
  }

 private:
  struct ctx {
    bool used = false;
    std::vector<unsigned char> last;
    std::vector<lazy_model> models;
  };
  std::size_t n_;
  unsigned last_ch_ = 0;
  std::array<ctx, 4> slots_;
};

/// WAVEPACKET14 v3: WAVEPACKET13's coding (laz_codec.hpp's wavepacket_state), one state per
/// channel, the last packet switched between channels as RGB14's colour is.
class wave14_decoder : public channel_items<29> {
 public:
  void next(layer& L, unsigned sc, unsigned char* rec) {
    unsigned char* lastp = switch_to(sc);
    if (L.present()) {
      if (!states_[sc]) states_[sc] = std::make_unique<wavepacket_state>();
      states_[sc]->decode(L.dec(), lastp, lastp);
    }
    std::copy(lastp, lastp + 29, rec);
  }

 private:
  std::array<std::unique_ptr<wavepacket_state>, 4> states_;
};

class wave14_encoder : public channel_items<29> {
 public:
  void next(out_layer& L, unsigned sc, const unsigned char* rec) {
    unsigned char* lastp = switch_to(sc);
    if (!states_[sc]) states_[sc] = std::make_unique<wavepacket_state>();
    L.changed |= !std::equal(rec, rec + 29, lastp);
    states_[sc]->encode(L.enc, lastp, rec);
    std::copy(rec, rec + 29, lastp);
  }

 private:
  std::array<std::unique_ptr<wavepacket_state>, 4> states_;
};

}  // namespace

std::uint64_t decode_layered_chunk(const std::string& path, const laz_layout& L, std::size_t k,
                                   const unsigned char* bytes, std::size_t n_bytes,
                                   std::uint64_t count, unsigned char* out) {
  const std::size_t rl = L.record_length;
  if (count == 0) return 0;
  std::memcpy(out, bytes, rl);  // read_laz_layout checked n_bytes ≥ rl
  if (count == 1) return 0;
  const bool rgb = L.format == 7 || L.format == 8 || L.format == 10;
  const bool nir = L.format == 8 || L.format == 10, wave = L.format >= 9;
  const std::size_t at_wave = 30 + (rgb ? 6 : 0) + (nir ? 2 : 0);
  const std::size_t at_extra = at_wave + (wave ? 29 : 0);
  const std::size_t extra = rl - at_extra;

  // The point count and the layer sizes, checked against the chunk.
  const std::size_t n_layers =
      point14_layers + (rgb ? 1 : 0) + (nir ? 1 : 0) + (wave ? 1 : 0) + extra;
  std::size_t at = rl;
  if (n_bytes - at < 4 + 4 * n_layers)
    format_error(path, cat("chunk ", k),
                 cat("truncated: ", n_bytes,
                     " bytes cannot hold the first record, the point count "
                     "and ",
                     n_layers, " layer sizes"));
  const std::uint32_t stored_count = load_le<std::uint32_t>(bytes + at);
  at += 4;
  if (stored_count != count)
    format_error(path, cat("chunk ", k),
                 cat("holds ", stored_count, " points, the chunk table says ", count));
  std::vector<std::uint32_t> sizes(n_layers);
  std::uint64_t total = 0;
  for (std::size_t i = 0; i < n_layers; ++i, at += 4) {
    sizes[i] = load_le<std::uint32_t>(bytes + at);
    total += sizes[i];
  }
  if (total > n_bytes - at)
    format_error(path, cat("chunk ", k),
                 cat("its layers need ", total, " bytes, ", n_bytes - at, " remain"));

  std::array<layer, point14_layers> p_layers;
  layer rgb_layer, nir_layer, wave_layer;
  std::vector<layer> byte_layers(extra);
  std::size_t li = 0;
  const auto open = [&](layer& l) {
    l.open(bytes + at, sizes[li]);
    at += sizes[li++];
  };
  for (layer& l : p_layers) open(l);
  if (rgb) open(rgb_layer);
  if (nir) open(nir_layer);
  if (wave) open(wave_layer);
  for (layer& l : byte_layers) open(l);
  if (!p_layers[l_xy].present())
    format_error(path, cat("chunk ", k), "its xy layer is empty (every record has one)");

  auto point = std::make_unique<point14_decoder>();
  std::optional<rgb14_decoder> rgb_dec;
  std::optional<nir14_decoder> nir_dec;
  std::optional<wave14_decoder> wave_dec;
  std::optional<byte14_decoder> byte_dec;
  point->first(out);
  const unsigned sc0 = point->current();
  if (rgb) rgb_dec.emplace().first(out + 30, sc0);
  if (nir) nir_dec.emplace().first(out + 36, sc0);
  if (wave) wave_dec.emplace().first(out + at_wave, sc0);
  if (extra) byte_dec.emplace(extra).first(out + at_extra, sc0);
  const auto overrun = [&] {
    std::uint64_t o = rgb_layer.overrun() + nir_layer.overrun() + wave_layer.overrun();
    for (const layer& l : p_layers) o += l.overrun();
    for (const layer& l : byte_layers) o += l.overrun();
    return o;
  };
  unsigned char* rec = out;
  for (std::uint64_t i = 1; i < count; ++i) {
    rec += rl;
    const unsigned sc = point->next(p_layers, rec);
    if (rgb) rgb_dec->next(rgb_layer, sc, rec + 30);
    if (nir) nir_dec->next(nir_layer, sc, rec + 36);
    if (wave) wave_dec->next(wave_layer, sc, rec + at_wave);
    if (extra) byte_dec->next(byte_layers, sc, rec + at_extra);
    if ((i & 1023) == 0 && overrun() > 64) break;  // damaged: stop decoding garbage
  }
  return overrun();
}

std::vector<unsigned char> encode_layered_chunk(unsigned format, std::uint16_t record_length,
                                                const unsigned char* records, std::uint64_t count) {
  std::vector<unsigned char> out;
  if (count == 0) return out;
  const std::size_t rl = record_length;
  const bool rgb = format == 7 || format == 8 || format == 10;
  const bool nir = format == 8 || format == 10, wave = format >= 9;
  const std::size_t at_wave = 30 + (rgb ? 6 : 0) + (nir ? 2 : 0);
  const std::size_t at_extra = at_wave + (wave ? 29 : 0);
  const std::size_t extra = rl - at_extra;
  out.assign(records, records + rl);  // the first record raw

  std::array<std::unique_ptr<out_layer>, point14_layers> p_layers;
  for (auto& l : p_layers) l = std::make_unique<out_layer>();
  auto rgb_layer = std::make_unique<out_layer>(), nir_layer = std::make_unique<out_layer>();
  auto wave_layer = std::make_unique<out_layer>();
  std::vector<std::unique_ptr<out_layer>> byte_layers(extra);
  for (auto& l : byte_layers) l = std::make_unique<out_layer>();
  p_layers[l_xy]->changed = true;  // LASzip always writes the xy and z layers
  p_layers[l_z]->changed = true;

  auto point = std::make_unique<point14_encoder>();
  std::optional<rgb14_encoder> rgb_enc;
  std::optional<nir14_encoder> nir_enc;
  std::optional<byte14_encoder> byte_enc;
  point->first(records);
  const unsigned sc0 = (records[15] >> 4) & 3u;
  if (rgb) rgb_enc.emplace().first(records + 30, sc0);
  if (nir) nir_enc.emplace().first(records + 36, sc0);
  std::optional<wave14_encoder> wave_enc;
  if (wave) wave_enc.emplace().first(records + at_wave, sc0);
  if (extra) byte_enc.emplace(extra).first(records + at_extra, sc0);
  for (std::uint64_t i = 1; i < count; ++i) {
    const unsigned char* rec = records + i * rl;
    const unsigned sc = point->next(p_layers, rec);
    if (rgb) rgb_enc->next(*rgb_layer, sc, rec + 30);
    if (nir) nir_enc->next(*nir_layer, sc, rec + 36);
    if (wave) wave_enc->next(*wave_layer, sc, rec + at_wave);
    if (extra) byte_enc->next(byte_layers, sc, rec + at_extra);
  }

  // The point count, the layer sizes (0 for a layer no record changed), the layers.
  std::vector<out_layer*> all;
  for (auto& l : p_layers) all.push_back(l.get());
  if (rgb) all.push_back(rgb_layer.get());
  if (nir) all.push_back(nir_layer.get());
  if (wave) all.push_back(wave_layer.get());
  for (auto& l : byte_layers) all.push_back(l.get());
  const auto put32 = [&](std::uint32_t v) {
    unsigned char b[4];
    store_le(b, v);
    out.insert(out.end(), b, b + 4);
  };
  put32(static_cast<std::uint32_t>(count));
  for (out_layer* l : all) {
    l->enc.done();
    put32(l->changed ? static_cast<std::uint32_t>(l->bytes.size()) : 0u);
  }
  for (out_layer* l : all)
    if (l->changed) out.insert(out.end(), l->bytes.begin(), l->bytes.end());
  return out;
}

}  // namespace pbr_lod::detail
