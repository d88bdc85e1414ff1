// ρ-grid compressed layout — beyond the paper (Duguet & Drettakis 2004 store raw bits, §3.2).
//
// This work is based on:
//   M. Botsch, A. Wiratanaya, L. Kobbelt. Efficient High Quality Rendering of Point Sampled
//   Geometry. EGWR 2002 (childhood codes of an octree entropy-coded: ~2 bits per point);
//   the MPEG G-PCC octree geometry coder (ISO/IEC 23090-9): occupancy bits coded one at a time
//   with adaptive binary contexts chosen by the parent's face-neighbour occupancy and by the
//   already-coded neighbours at the child level.
// "Level" in this file is a cell's depth below the cube (rho_grid::depth_begin), not the
// option's (the paper's) level.
//
// Geometry: level by level, cell by cell in breadth-first (= path) order, each of the ρ³ child
// bits of a cell's code is range-coded with a context (level, child index j, n6, c3):
//   n6 = occupied face neighbours of the cell at its level (0..6),
//   c3 = occupancy of the child's −x, −y, −z neighbours at the child level. Decreasing one
//        coordinate with the others fixed decreases the path number, so these are always coded
//        before (in this cell or in an earlier cell of the level).
// The last bit of a code whose other bits are all 0 is 1 (codes are never empty) and not coded.
//
// Attributes: every cell in breadth-first order; the prediction is the parent cell's attribute
// (code 0 for the root; the previous sibling was tried and costs ~1 bit more per sample). The
// normal code is split in the quantiser's parameterisation (octant, latitude row i, longitude
// column j of the one-octant table on |x|, |y|, |z|, normal_quantization.hpp). Coded: a flag
// "equal to the prediction" (context: level); else the octant XOR the predicted octant (3-bit
// tree), i − i_pred, and j minus the predicted column rescaled to row i (adaptive Exp-Golomb
// residuals). A normal just across an octant boundary keeps (i, j) near the prediction's, since
// the table is on absolute values. Materials: a bit tree conditioned on the predicted material.
// Colours (when the grid has them): each channel's quantised level minus the parent's, an
// adaptive Exp-Golomb residual per channel (closest-point colours of a cell and its parent are
// usually equal or near on a smoothly coloured surface).
#include <algorithm>
#include <array>
#include <memory>
#include <optional>

#include "pbr_lod/builders/detail/rho_grid_coder.hpp"
#include "pbr_lod/builders/detail/rho_grid_impl.hpp"
#include "pbr_lod/core/normal_quantization.hpp"

namespace pbr_lod::detail {
namespace {

template <int Rho>
struct geometry_model {
  static constexpr int R3 = Rho * Rho * Rho;
  rho_geometry_context kind;
  std::vector<range_prob> probs;
  explicit geometry_model(int depth, rho_geometry_context k)
      : kind(k), probs(std::size_t(std::max(depth, 1)) * R3 * 7 * 8, range_prob_init) {}
  range_prob& at(int level, int j, int n6, int c3) {
    return probs[((std::size_t(level) * R3 + std::size_t(j)) * 7 + std::size_t(n6)) * 8 +
                 std::size_t(c3)];
  }
};

using pos3 = std::array<std::uint32_t, 3>;

/// The walk shared by the encoder and the decoder: per level, the cells' positions and
/// occupancy; `bit(level, j, n6, c3, known)` codes or decodes child bit j (known = -1, or the
/// value the bit must have), returns it.
template <int Rho, class Code>
void walk_geometry(int depth, rho_geometry_context kind, const std::vector<std::uint64_t>* limits,
                   const std::string& what, Code&& code_cell) {
  constexpr int R3 = Rho * Rho * Rho;
  const bool need_sets = kind != rho_geometry_context::level_child;
  std::vector<pos3> cur{{0, 0, 0}}, next;
  cell_set cur_set, next_set;
  cur_set.clear();
  cur_set.insert(cell_set::key(0, 0, 0));
  std::uint64_t side = 1;  // cells per axis at the current level
  for (int l = 0; l < depth; ++l) {
    next.clear();
    next_set.clear();
    for (std::size_t ci = 0; ci < cur.size(); ++ci) {
      const pos3 p = cur[ci];
      int n6 = 0;
      if (need_sets)
        for (int a = 0; a < 3; ++a) {
          pos3 q = p;
          if (p[a] > 0) {
            --q[a];
            n6 += cur_set.contains(cell_set::key(q[0], q[1], q[2]));
            ++q[a];
          }
          if (p[a] + 1 < side) {
            ++q[a];
            n6 += cur_set.contains(cell_set::key(q[0], q[1], q[2]));
          }
        }
      bool any = false;
      for (int j = 0; j < R3; ++j) {
        const pos3 q = {p[0] * Rho + std::uint32_t(j % Rho),
                        p[1] * Rho + std::uint32_t((j / Rho) % Rho),
                        p[2] * Rho + std::uint32_t(j / (Rho * Rho))};
        int c3 = 0;
        if (kind == rho_geometry_context::parent_and_child_neighbours)
          for (int a = 0; a < 3; ++a)
            if (q[a] > 0) {
              pos3 r = q;
              --r[a];
              c3 |= int(next_set.contains(cell_set::key(r[0], r[1], r[2]))) << a;
            }
        const bool forced = j == R3 - 1 && !any;
        if (code_cell(l, ci, j, n6, c3, forced)) {
          any = true;
          next.push_back(q);
          if (need_sets) next_set.insert(cell_set::key(q[0], q[1], q[2]));
          if (limits && next.size() > (*limits)[std::size_t(l) + 1])
            throw FormatError(what + ": level " + std::to_string(l + 1) +
                              " has more cells than the " +
                              std::to_string((*limits)[std::size_t(l) + 1]) + " declared");
        }
      }
    }
    if (limits && next.size() != (*limits)[std::size_t(l) + 1])
      throw FormatError(what + ": level " + std::to_string(l + 1) + " holds " +
                        std::to_string(next.size()) + " cells, " +
                        std::to_string((*limits)[std::size_t(l) + 1]) + " declared");
    cur.swap(next);
    std::swap(cur_set, next_set);
    side *= Rho;
  }
}

/// Split of a normal code into (octant, row i, column j) and back.
struct normal_split {
  int bits = 0;
  std::uint32_t mask = 0;
  std::uint32_t rows = 0;               // k
  std::vector<std::uint16_t> row_of_t;  // t → i
  explicit normal_split(const normal_quantizer& q)
      : bits(q.bits()), mask((1u << (q.bits() - 3)) - 1u), rows(std::uint32_t(q.latitude_steps())) {
    for (std::uint32_t i = 0; i < rows; ++i)
      for (std::uint32_t j = 0; j <= i; ++j) row_of_t.push_back(std::uint16_t(i));
  }
  void split(std::uint32_t code, std::uint32_t& oct, std::int32_t& i, std::int32_t& j) const {
    oct = code >> (bits - 3);
    const std::uint32_t t = code & mask;
    i = row_of_t[t];
    j = std::int32_t(t) - i * (i + 1) / 2;
  }
  /// Column of row i nearest to the longitude of column jp of row ip.
  static std::int32_t predict_column(std::int32_t ip, std::int32_t jp, std::int32_t i) {
    const auto c = std::int32_t(((2 * jp + 1) * (i + 1)) / (2 * (ip + 1)));
    return std::clamp(c, 0, i);
  }
};

struct attribute_model {
  std::array<range_prob, 32> equal;
  std::array<range_prob, 8> octant;  // bit tree, nodes 1..7
  adaptive_int row, column_same, column_moved;
  std::vector<range_prob> material;    // (predicted material, bit-tree node)
  std::array<adaptive_int, 3> colour;  // residual per channel (red, green, blue)
  attribute_model(int material_bits) {
    equal.fill(range_prob_init);
    octant.fill(range_prob_init);
    material.assign(std::size_t(1) << (2 * material_bits), range_prob_init);
  }
};

/// Codes (or decodes) the attribute of one cell against a prediction.
template <bool Encode, class Coder>
std::uint32_t code_attribute(Coder& rc, attribute_model& m, const std::optional<normal_split>& ns,
                             int nb, int mb, int level, std::uint32_t pred, std::uint32_t value,
                             const std::string& what) {
  std::uint32_t nc = 0;
  if (ns) {
    const std::uint32_t nmask = (1u << nb) - 1u;
    const std::uint32_t pn = pred & nmask;
    auto& eq = m.equal[std::size_t(std::min(level, 31))];
    const std::uint32_t vn = value & nmask;
    unsigned same;
    if constexpr (Encode) {
      same = vn == pn;
      rc.encode(eq, same);
    } else {
      same = rc.decode(eq);
    }
    if (same) {
      nc = pn;
    } else {
      std::uint32_t po, o = 0;
      std::int32_t pi, pj, i = 0, j = 0;
      ns->split(pn, po, pi, pj);
      if constexpr (Encode) ns->split(vn, o, i, j);
      std::uint32_t x = o ^ po, node = 1;
      for (int b = 2; b >= 0; --b) {
        unsigned bit;
        if constexpr (Encode) {
          bit = (x >> b) & 1u;
          rc.encode(m.octant[node], bit);
        } else {
          bit = rc.decode(m.octant[node]);
        }
        node = (node << 1) | bit;
      }
      x = node & 7u;
      if constexpr (Encode) {
        m.row.encode(rc, i - pi);
      } else {
        i = pi + m.row.decode(rc, what);
        if (i < 0 || std::uint32_t(i) >= ns->rows)
          throw FormatError(what + ": decoded normal row " + std::to_string(i) + " out of range");
      }
      const std::int32_t jp = normal_split::predict_column(pi, pj, i);
      // Same octant and row as the prediction: the column must differ (the flag said so).
      auto& col = (x == 0 && i == pi) ? m.column_same : m.column_moved;
      if constexpr (Encode) {
        col.encode(rc, j - jp);
      } else {
        j = jp + col.decode(rc, what);
        if (j < 0 || j > i)
          throw FormatError(what + ": decoded normal column " + std::to_string(j) +
                            " out of range");
        o = po ^ x;
      }
      nc = (o << (nb - 3)) | std::uint32_t(i * (i + 1) / 2 + j);
      if constexpr (!Encode)
        if (nc == pn) throw FormatError(what + ": normal residual of zero after a miss");
    }
  }
  std::uint32_t mat = 0;
  if (mb > 0) {
    const std::uint32_t pm = pred >> nb;
    range_prob* probs = m.material.data() + (std::size_t(pm) << mb);
    std::uint32_t node = 1;
    for (int b = mb - 1; b >= 0; --b) {
      unsigned bit;
      if constexpr (Encode) {
        bit = ((value >> nb) >> b) & 1u;
        rc.encode(probs[node], bit);
      } else {
        bit = rc.decode(probs[node]);
      }
      node = (node << 1) | bit;
    }
    mat = node & ((1u << mb) - 1u);
  }
  return nc | (mat << nb);
}

/// Codes (or decodes) a colour code of `cb` bits against the predicted code: per channel the
/// level minus the predicted level. Decoding checks each level against its channel's range.
template <bool Encode, class Coder>
std::uint32_t code_colour(Coder& rc, attribute_model& m, int cb, std::uint32_t pred,
                          std::uint32_t value, const std::string& what) {
  const auto split = rho_grid_colour_split(cb);
  std::uint32_t out = 0;
  int shift = 0;
  for (std::size_t ch = 0; ch < 3; ++ch) {
    const int bits = split[ch];
    const std::uint32_t mask = (1u << bits) - 1u;
    const auto p = std::int32_t((pred >> shift) & mask);
    std::int32_t v;
    if constexpr (Encode) {
      v = std::int32_t((value >> shift) & mask);
      m.colour[ch].encode(rc, v - p);
    } else {
      v = p + m.colour[ch].decode(rc, what);
      if (v < 0 || std::uint32_t(v) > mask)
        throw FormatError(what + ": decoded colour level " + std::to_string(v) + " out of range");
    }
    out |= std::uint32_t(v) << shift;
    shift += bits;
  }
  return out;
}

/// The attribute stream, shared by the encoder and the decoder: the root's attribute, then each
/// inner cell's children in breadth-first order, each coded against its parent's attribute (or,
/// with sibling_or_parent, its previous sibling's). get(i) is cell i's attribute (already decoded
/// when decoding); put(i, v) receives what code_attribute returns for cell i; likewise
/// get_colour, put_colour for its colour code when the grid has colours (coded after the
/// attribute, against the same cell's colour).
template <bool Encode, int Rho, class Coder, class Get, class Put, class GetC, class PutC>
void walk_attributes(Coder& rc, const rho_grid<Rho>& g, const rho_coder_options& options, Get&& get,
                     Put&& put, GetC&& get_colour, PutC&& put_colour, const std::string& what) {
  const int nb = g.normal_bits(), mb = g.material_bits(), cb = g.colour_bits();
  std::shared_ptr<const normal_quantizer> q;  // the process-wide table, not one per call
  std::optional<normal_split> ns;
  if (nb > 0) {
    q = normal_quantizer::shared(nb);
    ns.emplace(*q);
  }
  attribute_model m(mb);
  const auto code = [&](std::uint32_t i, int level, std::uint32_t pred, std::uint32_t pred_colour) {
    if (nb + mb > 0)
      put(i, code_attribute<Encode>(rc, m, ns, nb, mb, level, pred, Encode ? get(i) : 0u, what));
    if (cb > 0)
      put_colour(i, code_colour<Encode>(rc, m, cb, pred_colour, Encode ? get_colour(i) : 0u, what));
  };
  code(0, 0, 0, 0);
  int level = 0;
  for (std::uint32_t c = 0; c < g.inner_count(); ++c) {
    while (c >= g.depth_begin(level + 1)) ++level;
    const std::uint32_t first = g.first_child(c), n = std::uint32_t(g.code(c).count());
    for (std::uint32_t k = 0; k < n; ++k) {
      const bool sibling =
          options.attributes == rho_attribute_predictor::sibling_or_parent && k > 0;
      const std::uint32_t from = sibling ? first + k - 1 : c;
      code(first + k, level + 1, nb + mb > 0 ? std::uint32_t(get(from)) : 0u,
           cb > 0 ? std::uint32_t(get_colour(from)) : 0u);
    }
  }
}

}  // namespace

template <int Rho>
rho_coded_streams rho_grid_encode(const rho_grid<Rho>& g, const rho_coder_options& options) {
  rho_coded_streams out;
  const int depth = g.leaf_depth();
  if (depth > 0) {
    range_encoder rc;
    geometry_model<Rho> m(depth, options.geometry);
    std::uint32_t cell = 0;  // breadth-first index of the cell being coded
    std::size_t last_ci = ~std::size_t(0);
    int last_level = -1;
    walk_geometry<Rho>(depth, options.geometry, nullptr, "",
                       [&](int l, std::size_t ci, int j, int n6, int c3, bool forced) {
                         if (l != last_level || ci != last_ci) {
                           cell = g.depth_begin(l) + std::uint32_t(ci);
                           last_level = l;
                           last_ci = ci;
                         }
                         const bool bit = g.code(cell).test(j);
                         if (!forced) rc.encode(m.at(l, j, n6, c3), bit);
                         return bit;
                       });
    out.geometry = rc.finish();
  }
  if (g.sigma() > 0) {
    range_encoder rc;
    walk_attributes<true>(
        rc, g, options, [&](std::uint32_t i) { return g.attribute(i); },
        [](std::uint32_t, std::uint32_t) {}, [&](std::uint32_t i) { return g.colour_code(i); },
        [](std::uint32_t, std::uint32_t) {}, "");
    out.attributes = rc.finish();
  }
  return out;
}

template <int Rho>
void rho_grid_decode(rho_grid<Rho>& g, const unsigned char* geometry, std::size_t geometry_size,
                     const unsigned char* attributes, std::size_t attributes_size,
                     const std::vector<std::uint64_t>& per_level, const rho_coder_options& options,
                     const std::string& what) {
  using access = rho_grid_access<Rho>;
  const int depth = g.leaf_depth();
  auto& codes = access::codes(g);
  std::uint64_t total = 0;
  for (auto n : per_level) total += n;
  if (depth == 0) {
    if (geometry_size != 0) throw FormatError(what + ": geometry stream of a depth-0 grid");
  } else {
    range_decoder rc(geometry, geometry_size, what + " (geometry)");
    geometry_model<Rho> m(depth, options.geometry);
    std::size_t last_ci = ~std::size_t(0);
    int last_level = -1;
    walk_geometry<Rho>(depth, options.geometry, &per_level, what,
                       [&](int l, std::size_t ci, int j, int n6, int c3, bool forced) {
                         if (l != last_level || ci != last_ci) {
                           codes.emplace_back();
                           last_level = l;
                           last_ci = ci;
                         }
                         const bool bit = forced || rc.decode(m.at(l, j, n6, c3));
                         if (bit) codes.back().set(j);
                         return bit;
                       });
    rc.finish();
  }
  // The walk matched every level's decoded cells to the declared counts, so `total` is the real
  // cell count; the attributes are sized before finish() so its in-core statistics count them.
  auto& attrs = access::attrs(g);
  auto& colours = access::colours(g);
  if (g.normal_bits() + g.material_bits() > 0) attrs.assign(total, 0);
  if (g.has_colours()) colours.assign(total, 0);
  access::finish(g, total, what);
  if (g.sigma() == 0) {
    if (attributes_size != 0) throw FormatError(what + ": attribute stream of a grid with σ = 0");
    return;
  }
  range_decoder rc(attributes, attributes_size, what + " (attributes)");
  walk_attributes<false>(
      rc, g, options, [&](std::uint32_t i) { return attrs[i]; },
      [&](std::uint32_t i, std::uint32_t v) { attrs[i] = std::uint16_t(v); },
      [&](std::uint32_t i) { return colours[i]; },
      [&](std::uint32_t i, std::uint32_t v) { colours[i] = std::uint16_t(v); }, what);
  rc.finish();
}

#define PBR_LOD_RHO_CODEC(R)                                                                   \
  template rho_coded_streams rho_grid_encode<R>(const rho_grid<R>&, const rho_coder_options&); \
  template void rho_grid_decode<R>(                                                            \
      rho_grid<R>&, const unsigned char*, std::size_t, const unsigned char*, std::size_t,      \
      const std::vector<std::uint64_t>&, const rho_coder_options&, const std::string&);
PBR_LOD_RHO_CODEC(2)
PBR_LOD_RHO_CODEC(3)
PBR_LOD_RHO_CODEC(4)
PBR_LOD_RHO_CODEC(5)
#undef PBR_LOD_RHO_CODEC

}  // namespace pbr_lod::detail
