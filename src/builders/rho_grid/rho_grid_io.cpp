// ρ-grid packed streams (Duguet & Drettakis 2004, §3.2): NIS and IS layouts, save/load with
// validation of every length.
//
// File layout (little endian):
//   magic "PBRLODRG", u32 version, u32 ρ, u32 leaf depth k = level + 1
//   (rho_grid::leaf_depth), u32 layout (0 NIS, 1 IS),
//   u32 normal bits, u32 material bits, [version 5 only: u32 colour bits], f64 origin[3],
//   f64 cube side,
//   f64 input centre[3] (world), f64 input radius (rho_grid::input_centre), u64 cells per level [k
//   + 1], u64 payload bits, payload bytes ⌈bits/8⌉, u64 FNV-1a of all bytes before it.
// Payload, pre-order from the root (children in increasing digit order):
//   NIS  ρ³-bit code of every inner cell, then the σ-bit attribute of every leaf
//   IS   per cell: σ-bit attribute, then (inner cells) the ρ³-bit code
// A σ-bit attribute is rho_grid::sample_bits: normal code, material, colour code from the low
// bits up.
// The cells of one level appear in pre-order in path order, which is the breadth-first order of
// the in-core structure, so reading appends to per-level arrays and needs no reordering.
//
// Version 4 for every layout of a grid without colours, version 5 (the colour bits in the header)
// for a grid with colours: a grid without colours writes exactly the bytes it always did, and a
// reader of version 4 alone refuses a coloured file by its version instead of misreading it.
// Versions 1 (NIS, IS) and 2 (compressed) had no input bounds, and 1–3 held the build's time (no
// two builds compared equal): they are rejected with a message to rebuild.
// Compressed layout (2, beyond the paper): the same
// header up to the cells per level, then u32 geometry context model, u32 attribute predictor,
// u64 geometry bytes G, u64 attribute bytes A, G + A bytes of the two range-coded streams
// (rho_grid_codec.cpp), u64 FNV-1a.
#include <algorithm>
#include <cstring>
#include <fstream>
#include <iterator>
#include <memory>
#include <optional>

#include "pbr_lod/builders/detail/rho_grid_coder.hpp"
#include "pbr_lod/builders/detail/rho_grid_impl.hpp"
#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/normal_quantization.hpp"

namespace pbr_lod {
namespace {

constexpr detail::file_format rho_format{"rho-grid", {'P', 'B', 'R', 'L', 'O', 'D', 'R', 'G'}, 4};
/// The version a grid with colours is written in (rho_format.version without).
constexpr std::uint32_t coloured_version = 5;
/// Bytes before the cells per level: magic, 6 u32, 8 f64 (origin, side, input bounds); version 5
/// one u32 more (the colour bits).
constexpr std::size_t fixed_header_bytes(bool coloured) {
  return 8 + (coloured ? 7 : 6) * 4 + 8 * 8;
}

/// Reads and checks the magic and the version (4, or 5 with colours): read_head's messages, two
/// versions.
std::uint32_t read_rho_head(detail::byte_reader& r) {
  for (const char c : rho_format.magic)
    if (r.get<char>("magic") != c)
      throw FormatError(r.path + ": not a pbr_lod " + rho_format.name +
                        " file (bad magic, expected " + std::string(rho_format.magic, 8) + ")");
  const auto v = r.get<std::uint32_t>("version");
  if (v >= 1 && v <= 3)
    throw FormatError(r.path + ": " + rho_format.name + " file version " + std::to_string(v) +
                      " is no longer read; this library reads version " +
                      std::to_string(rho_format.version) + " (" + std::to_string(coloured_version) +
                      " with colours): rebuild the file with pbrlod build");
  if (v != rho_format.version && v != coloured_version)
    throw FormatError(r.path + ": version " + std::to_string(v) + ", this library reads version " +
                      std::to_string(rho_format.version) + " (" + std::to_string(coloured_version) +
                      " with colours)");
  return v;
}

struct header_writer {
  std::vector<unsigned char>& b;
  template <class T>
  void put(const T& v) {
    const auto* p = reinterpret_cast<const unsigned char*>(&v);
    b.insert(b.end(), p, p + sizeof(T));
  }
};

template <class Code>
void put_code(detail::bit_writer& w, const Code& c, int bits) {
  int left = bits;
  for (auto word : c.w) {
    const int n = std::min<int>(left, Code::word_bits);
    w.put(std::uint64_t(word), n);
    left -= n;
  }
}
template <class Code>
Code get_code(detail::bit_reader& r, int bits) {
  Code c;
  int left = bits;
  for (auto& word : c.w) {
    const int n = std::min<int>(left, Code::word_bits);
    word = static_cast<typename Code::word>(r.get(n, "childhood code"));
    left -= n;
  }
  return c;
}

/// The header common to every layout, up to the cells per level.
template <int Rho>
void put_header(std::vector<unsigned char>& out, const rho_grid<Rho>& g, rho_grid_layout layout) {
  header_writer h{out};
  for (char c : rho_format.magic) h.put(c);
  h.put(g.has_colours() ? coloured_version : rho_format.version);
  h.put(std::uint32_t(Rho));
  h.put(std::uint32_t(g.leaf_depth()));
  h.put(std::uint32_t(layout));
  h.put(std::uint32_t(g.normal_bits()));
  h.put(std::uint32_t(g.material_bits()));
  if (g.has_colours()) h.put(std::uint32_t(g.colour_bits()));
  h.put(g.origin().x());
  h.put(g.origin().y());
  h.put(g.origin().z());
  h.put(g.cube_side());
  h.put(g.input_centre().x());
  h.put(g.input_centre().y());
  h.put(g.input_centre().z());
  h.put(g.input_radius());
  for (int l = 0; l <= g.leaf_depth(); ++l)
    h.put(std::uint64_t(g.depth_begin(l + 1) - g.depth_begin(l)));
}

/// What every layout's header holds after the magic and version (put_header's fields), read and
/// checked: the grid's frame, its attribute layout, the input's bounds and the cells per level.
struct rho_file_head {
  std::uint32_t depth, layout, nb, mb, cb;
  vec3d origin, in_centre;
  double side, in_radius;
  std::vector<std::uint64_t> per_level;  ///< cells at levels 0..depth
  std::uint64_t total;                   ///< cells in all
};

template <int Rho>
rho_file_head read_header(detail::byte_reader& r, const std::string& what) {
  // Versions 1 (NIS, IS) and 2 (compressed) did not record the input's bounds, 1–3 stored the
  // build's time.
  const std::uint32_t version = read_rho_head(r);
  const auto rho_in = r.get<std::uint32_t>("rho");
  if (rho_in != std::uint32_t(Rho))
    throw FormatError(what + ": the stream holds a rho=" + std::to_string(rho_in) +
                      " grid, a rho=" + std::to_string(Rho) + " grid was expected");
  const auto depth = r.get<std::uint32_t>("leaf depth");
  if (depth > std::uint32_t(rho_grid_max_leaf_depth(Rho)))
    throw FormatError(what + ": leaf depth " + std::to_string(depth) + " exceeds the maximum " +
                      std::to_string(rho_grid_max_leaf_depth(Rho)));
  const auto layout = r.get<std::uint32_t>("layout");
  if (layout > 2) throw FormatError(what + ": unknown layout " + std::to_string(layout));
  const auto nb = r.get<std::uint32_t>("normal bits");
  const auto mb = r.get<std::uint32_t>("material bits");
  if ((nb != 0 && (nb < std::uint32_t(normal_quantizer::min_bits) || nb > 16)) || mb > 8 ||
      nb + mb > 16)
    throw FormatError(what + ": unsupported attribute layout (" + std::to_string(nb) +
                      " normal bits, " + std::to_string(mb) + " material bits)");
  const auto cb = version == coloured_version ? r.get<std::uint32_t>("colour bits") : 0u;
  if (version == coloured_version && (cb < 3 || cb > 16))
    throw FormatError(what + ": version " + std::to_string(coloured_version) + " with " +
                      std::to_string(cb) + " colour bits (expected 3 to 16)");
  vec3d origin;
  origin.x() = r.get<double>("origin");
  origin.y() = r.get<double>("origin");
  origin.z() = r.get<double>("origin");
  const double side = r.get<double>("cube side");
  if (!all_finite(origin) || !std::isfinite(side) || !(side > 0))
    throw FormatError(what + ": origin or cube side is not finite and positive");
  vec3d in_centre;
  in_centre.x() = r.get<double>("input centre");
  in_centre.y() = r.get<double>("input centre");
  in_centre.z() = r.get<double>("input centre");
  const double in_radius = r.get<double>("input radius");
  if (!all_finite(in_centre) || !std::isfinite(in_radius) || !(in_radius >= 0))
    throw FormatError(what + ": input bounds are not finite (radius ≥ 0)");
  constexpr std::uint64_t R3 = std::uint64_t(Rho) * Rho * Rho;
  std::vector<std::uint64_t> per_level(depth + 1);
  std::uint64_t total = 0;
  for (std::uint32_t l = 0; l <= depth; ++l) {
    per_level[l] = r.get<std::uint64_t>("cells per level");
    const std::uint64_t prev = l == 0 ? 1 : per_level[l - 1];
    if ((l == 0 && per_level[l] != 1) ||
        (l > 0 && (per_level[l] < prev || per_level[l] > prev * R3)))
      throw FormatError(what + ": level " + std::to_string(l) + " has " +
                        std::to_string(per_level[l]) + " cells, impossible below " +
                        std::to_string(prev) + " cells");
    total += per_level[l];
    if (total > 0xffffffffull)
      throw FormatError(what + ": more cells than 32-bit child indices address");
  }
  return {depth, layout, nb, mb, cb, origin, in_centre, side, in_radius, std::move(per_level),
          total};
}

/// The compressed layout (2): the coded geometry and attribute streams after their lengths.
template <int Rho>
rho_grid<Rho> parse_compressed(const rho_file_head& h, detail::byte_reader& r,
                               const std::vector<unsigned char>& bytes, const std::string& what) {
  using access = detail::rho_grid_access<Rho>;
  const auto& [depth, layout, nb, mb, cb, origin, in_centre, side, in_radius, per_level, total] = h;
  rho_grid<Rho> g;
  access::set_frame(g, int(depth), origin, side, int(nb), int(mb));
  access::set_colour_bits(g, int(cb));
  access::set_input_bounds(g, in_centre, in_radius);
  const auto gm = r.get<std::uint32_t>("geometry context model");
  const auto am = r.get<std::uint32_t>("attribute predictor");
  if (gm > 2 || am > 1)
    throw FormatError(what + ": unknown context model " + std::to_string(gm) + "/" +
                      std::to_string(am));
  const auto gbytes = r.get<std::uint64_t>("geometry bytes");
  const auto abytes = r.get<std::uint64_t>("attribute bytes");
  const std::uint64_t left = bytes.size() - r.pos;
  if (left < 8 || gbytes > left - 8 || abytes != left - 8 - gbytes)
    throw FormatError(what + ": " + std::to_string(bytes.size()) + " bytes, the header declares " +
                      std::to_string(gbytes) + " + " + std::to_string(abytes) +
                      " coded bytes (truncated or padded)");
  if (!detail::checksum_matches(bytes))
    throw FormatError(what + ": checksum mismatch (corrupt stream)");
  const detail::rho_coder_options opt{.geometry = detail::rho_geometry_context(gm),
                                      .attributes = detail::rho_attribute_predictor(am)};
  detail::rho_grid_decode(g, bytes.data() + r.pos, std::size_t(gbytes),
                          bytes.data() + r.pos + gbytes, std::size_t(abytes), per_level, opt, what);
  return g;
}

/// NIS (layout 0) without inner samples: each inner cell's sample from its children, bottom up —
/// the mean normal re-quantised, the first child's material, the mean colour re-quantised.
template <int Rho>
void rebuild_inner_samples(rho_grid<Rho>& g, const rho_file_head& h, const normal_quantizer* q,
                           std::uint64_t inner) {
  using access = detail::rho_grid_access<Rho>;
  const auto [nb, mb, cb] = std::array{h.nb, h.mb, h.cb};
  auto& attrs = access::attrs(g);
  auto& colours = access::colours(g);
  // Rebuild the intermediate samples bottom-up: mean normal of the children, re-quantised;
  // the first child's material; the mean colour of the children, re-quantised.
  for (std::size_t c = inner; c-- > 0;) {
    const auto cc = std::uint32_t(c);
    const std::uint32_t first = g.first_child(cc);
    const int n = g.code(cc).count();
    if (nb + mb > 0) {
      std::uint32_t nc = 0;
      if (q) {
        vec3f sum = vec3f::Zero();
        for (int i = 0; i < n; ++i) sum += q->decode(g.normal_code(first + std::uint32_t(i)));
        nc = q->encode(sum.squaredNorm() > 0 ? vec3f(sum) : q->decode(g.normal_code(first)));
      }
      const std::uint32_t mat = g.material(first);
      attrs[c] = std::uint16_t(nc | (mat << nb));
    }
    if (cb > 0) {
      std::array<int, 3> sum{};
      for (int i = 0; i < n; ++i) {
        const rgb8 k = g.colour(first + std::uint32_t(i));
        sum[0] += k.r;
        sum[1] += k.g;
        sum[2] += k.b;
      }
      const auto mean = [n](int v) { return std::uint8_t((v + n / 2) / n); };
      colours[c] = std::uint16_t(
          rho_grid_encode_colour(rgb8{mean(sum[0]), mean(sum[1]), mean(sum[2])}, int(cb)));
    }
  }
}

/// The NIS (0) and IS (1) layouts: the childhood codes depth first, the samples after them (NIS,
/// leaves only) or with each cell (IS).
template <int Rho>
rho_grid<Rho> parse_bitstream(const rho_file_head& h, detail::byte_reader& r,
                              const std::vector<unsigned char>& bytes, const std::string& what) {
  using access = detail::rho_grid_access<Rho>;
  using code_type = typename rho_grid<Rho>::code_type;
  constexpr std::uint64_t R3 = std::uint64_t(Rho) * Rho * Rho;
  const auto& [depth, layout, nb, mb, cb, origin, in_centre, side, in_radius, per_level, total] = h;
  const std::uint64_t sigma = nb + mb + cb, leaves = per_level[depth], inner = total - leaves;
  const std::uint64_t expect = inner * R3 + leaves * sigma + (layout == 1 ? inner * sigma : 0);
  const auto bits = r.get<std::uint64_t>("payload bits");
  if (bits != expect)
    throw FormatError(what + ": payload of " + std::to_string(bits) + " bits, the counts need " +
                      std::to_string(expect));
  const std::uint64_t payload_bytes = (bits + 7) / 8;
  if (bytes.size() - r.pos < 8 || bytes.size() - r.pos - 8 != payload_bytes)
    throw FormatError(what + ": " + std::to_string(bytes.size()) + " bytes, expected " +
                      std::to_string(r.pos + payload_bytes + 8) + " (truncated or padded)");
  if (!detail::checksum_matches(bytes))
    throw FormatError(what + ": checksum mismatch (corrupt stream)");
  if (bits % 8 != 0 && (bytes[r.pos + payload_bytes - 1] >> (bits % 8)) != 0)
    throw FormatError(what + ": non-zero padding bits after the payload");

  rho_grid<Rho> g;
  access::set_frame(g, int(depth), origin, side, int(nb), int(mb));
  access::set_colour_bits(g, int(cb));
  access::set_input_bounds(g, in_centre, in_radius);
  auto& codes = access::codes(g);
  auto& attrs = access::attrs(g);
  auto& colours = access::colours(g);
  std::vector<std::vector<code_type>> lcodes(depth);
  std::vector<std::vector<std::uint16_t>> lattrs(depth + 1), lcolours(depth + 1);
  detail::bit_reader br(bytes.data() + r.pos, bits, what);
  // The process-wide table: building one per parse was most of the cost of loading a small grid.
  std::shared_ptr<const normal_quantizer> q;
  if (nb > 0) q = normal_quantizer::shared(int(nb));
  const auto read_attr = [&](std::uint32_t l) {
    const auto a = std::uint32_t(br.get(int(sigma), "attribute"));
    if (q && !q->valid(a & ((1u << nb) - 1u)))
      throw FormatError(what + ": invalid normal code " + std::to_string(a & ((1u << nb) - 1u)) +
                        " at bit " + std::to_string(br.position()));
    if (nb + mb > 0) lattrs[l].push_back(std::uint16_t(a & ((1u << (nb + mb)) - 1u)));
    if (cb > 0) lcolours[l].push_back(std::uint16_t(a >> (nb + mb)));  // every cb-bit code valid
  };
  std::vector<std::uint32_t> stack{0};  // levels of the cells still to read
  while (!stack.empty()) {
    const std::uint32_t l = stack.back();
    stack.pop_back();
    if (layout == 1) read_attr(l);
    if (l == depth) {
      if (layout == 1 && std::max(lattrs[l].size(), lcolours[l].size()) > leaves && sigma > 0)
        throw FormatError(what + ": more leaves than the " + std::to_string(leaves) + " declared");
      continue;
    }
    const auto c = get_code<code_type>(br, int(R3));
    const int n = c.count();
    if (n == 0)
      throw FormatError(what + ": empty childhood code at level " + std::to_string(l) + ", bit " +
                        std::to_string(br.position()));
    lcodes[l].push_back(c);
    if (lcodes[l].size() > per_level[l])
      throw FormatError(what + ": level " + std::to_string(l) + " has more cells than the " +
                        std::to_string(per_level[l]) + " declared");
    for (int i = 0; i < n; ++i) stack.push_back(l + 1);
  }
  std::uint64_t leaf_seen = 0;
  for (std::uint32_t l = 0; l < depth; ++l) {
    if (lcodes[l].size() != per_level[l])
      throw FormatError(what + ": level " + std::to_string(l) + " holds " +
                        std::to_string(lcodes[l].size()) + " cells, " +
                        std::to_string(per_level[l]) + " declared");
    leaf_seen = 0;
    for (const auto& c : lcodes[l]) leaf_seen += std::uint64_t(c.count());
    if (leaf_seen != per_level[l + 1])
      throw FormatError(what + ": level " + std::to_string(l + 1) + " holds " +
                        std::to_string(leaf_seen) + " cells, " + std::to_string(per_level[l + 1]) +
                        " declared");
    codes.insert(codes.end(), lcodes[l].begin(), lcodes[l].end());
  }
  if (layout == 0) {
    for (std::uint64_t i = 0; i < leaves; ++i) read_attr(depth);
  }
  if (br.position() != bits)
    throw FormatError(what + ": payload has " + std::to_string(bits - br.position()) +
                      " bits left over");
  const auto gather = [&](std::vector<std::uint16_t>& dst,
                          const std::vector<std::vector<std::uint16_t>>& per) {
    if (layout == 1)
      for (const auto& la : per) dst.insert(dst.end(), la.begin(), la.end());
    else {
      dst.assign(inner, 0);
      dst.insert(dst.end(), per[depth].begin(), per[depth].end());
    }
  };
  if (nb + mb > 0) gather(attrs, lattrs);
  if (cb > 0) gather(colours, lcolours);
  access::finish(g, total, what);
  if (layout == 0 && sigma > 0 && inner > 0) rebuild_inner_samples(g, h, q.get(), inner);
  return g;
}

}  // namespace

namespace detail {
template <int Rho>
std::vector<unsigned char> rho_grid_serialise_compressed(const rho_grid<Rho>& g,
                                                         const rho_coder_options& options) {
  std::vector<unsigned char> out;
  put_header(out, g, rho_grid_layout::compressed);
  const rho_coded_streams s = rho_grid_encode(g, options);
  header_writer h{out};
  h.put(std::uint32_t(options.geometry));
  h.put(std::uint32_t(options.attributes));
  h.put(std::uint64_t(s.geometry.size()));
  h.put(std::uint64_t(s.attributes.size()));
  out.insert(out.end(), s.geometry.begin(), s.geometry.end());
  out.insert(out.end(), s.attributes.begin(), s.attributes.end());
  h.put(fnv1a(out.data(), out.size()));
  return out;
}
}  // namespace detail

template <int Rho>
rho_grid_coded_size rho_grid<Rho>::coded_size() const {
  const auto bytes = detail::rho_grid_serialise_compressed(*this, {});
  // Read the two stream lengths back from the file just written: the sizes are those of the
  // bytes the decoder reads, never an estimate.
  std::uint64_t gb = 0, ab = 0;
  const std::size_t lengths =
      fixed_header_bytes(has_colours()) + std::size_t(leaf_depth_ + 1) * 8 + 2 * 4;
  std::memcpy(&gb, bytes.data() + lengths, 8);
  std::memcpy(&ab, bytes.data() + lengths + 8, 8);
  rho_grid_coded_size s;
  s.geometry_bytes = gb;
  s.attribute_bytes = ab;
  s.file_bytes = bytes.size();
  const double n = std::max<double>(1, double(leaf_count()));
  s.bits_per_sample_geometry = double(gb) * 8 / n;
  s.bits_per_sample_attributes = double(ab) * 8 / n;
  return s;
}

template <int Rho>
std::vector<unsigned char> rho_grid<Rho>::serialise(rho_grid_layout layout) const {
  if (layout == rho_grid_layout::compressed)
    return detail::rho_grid_serialise_compressed(*this, {});
  if (layout != rho_grid_layout::nis && layout != rho_grid_layout::is)
    throw InvalidArgument("rho-grid: unknown layout " + std::to_string(std::uint32_t(layout)));
  std::vector<unsigned char> out;
  put_header(out, *this, layout);
  header_writer h{out};
  const std::uint64_t bits = payload_bits(layout);
  h.put(bits);

  detail::bit_writer w;
  const int s = sigma();
  const bool is = layout == rho_grid_layout::is;
  std::vector<std::uint32_t> stack{0};
  while (!stack.empty()) {
    const std::uint32_t c = stack.back();
    stack.pop_back();
    if (is) w.put(sample_bits(c), s);
    if (is_leaf(c)) continue;
    put_code(w, codes_[c], children_per_cell);
    for (std::uint32_t i = std::uint32_t(codes_[c].count()); i-- > 0;)
      stack.push_back(first_child_[c] + i);
  }
  if (!is)
    for (std::size_t c = codes_.size(); c < attrs_count_; ++c)
      w.put(sample_bits(std::uint32_t(c)), s);
  if (w.bits() != bits)
    throw Error("rho-grid: internal error, wrote " + std::to_string(w.bits()) +
                " payload bits, expected " + std::to_string(bits));
  out.insert(out.end(), w.bytes().begin(), w.bytes().end());
  h.put(detail::fnv1a(out.data(), out.size()));
  return out;
}

template <int Rho>
rho_grid<Rho> rho_grid<Rho>::parse(const std::vector<unsigned char>& bytes,
                                   const std::string& what) {
  detail::byte_reader r{bytes, 0, what};
  const rho_file_head h = read_header<Rho>(r, what);
  return h.layout == 2 ? parse_compressed<Rho>(h, r, bytes, what)
                       : parse_bitstream<Rho>(h, r, bytes, what);
}

template <int Rho>
void rho_grid<Rho>::save(const std::string& path, rho_grid_layout layout) const {
  detail::save_file_bytes(path, serialise(layout));
}

template <int Rho>
rho_grid<Rho> rho_grid<Rho>::load(const std::string& path) {
  return parse(detail::load_file_bytes(path), path);
}

int rho_grid_file_rho(const std::string& path) {
  const auto bytes = detail::load_file_bytes(path);
  detail::byte_reader r{bytes, 0, path};
  (void)read_rho_head(r);
  const auto rho = r.get<std::uint32_t>("rho");
  if (rho < 2 || rho > 5) throw FormatError(path + ": rho " + std::to_string(rho) + " unsupported");
  return int(rho);
}

template std::vector<unsigned char> detail::rho_grid_serialise_compressed<2>(
    const rho_grid<2>&, const detail::rho_coder_options&);
template std::vector<unsigned char> detail::rho_grid_serialise_compressed<3>(
    const rho_grid<3>&, const detail::rho_coder_options&);
template std::vector<unsigned char> detail::rho_grid_serialise_compressed<4>(
    const rho_grid<4>&, const detail::rho_coder_options&);
template std::vector<unsigned char> detail::rho_grid_serialise_compressed<5>(
    const rho_grid<5>&, const detail::rho_coder_options&);
template class rho_grid<2>;
template class rho_grid<3>;
template class rho_grid<4>;
template class rho_grid<5>;

}  // namespace pbr_lod
