// pbr_lod — the POP file format (Chen & Nguyen 2001 §3.5 storage): save, load with validation
// of every count and index, and the file's size accounting.

#include <cstring>
#include <memory>
#include <numeric>
#include <string>
#include <vector>

#include "pbr_lod/builders/pop.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/memory.hpp"
#include "pbr_lod/core/normal_quantization.hpp"
#include "pop_internal.hpp"

namespace pbr_lod::detail {

using namespace pop_internal;

// ---------------------------------------------------------------------------------------------
// Storage (§3.5). Little-endian file, version 3:
//   header   "PBRLODPP" | u32 version | u32 flags (1 = colour, 2 = quantised nodes, 4 = texture;
//            4 only with 1)
//            | u32 normal_bits | u32 sphere rule | u32 adjacency
//            | u64 vertices | u64 faces | u64 nodes | f64 origin[3] | f32 q_min[3] | f32 q_step[3]
//            | build stats: u64 isolated, non-manifold edges, degenerate, contained_inner
//            | quantised nodes only: f32 root centre[3], f32 root radius
//            | texture only: u32 texture width | u32 texture height
//   vertices u16 q[3] | normal code (u16 when normal_bits ≤ 16, else u32) | [u8 rgb[3]]
//   faces    u32 v[3]                          (in leaf order)
//   texture only: per face f32 uv[3][2]        (its corners' texture coordinates, leaf order)
//   nodes    quantised (QSplat-style, breadth first; first child / first face, parent and depth
//            are derived from the counts):
//              u16 sphere code (4 bits each: centre x, y, z offset, radius; levels 0..12;
//              relative to the parent) | normal code | u8 (bits 0–1 cone level, 2–3 count − 1,
//              4 leaf; 5–7 zero) | [u16 RGB 565]
//            float: f32 centre[3] | f32 radius | f32 cone | normal code | u32 first | u8 count
//              | u8 leaf | [u8 rgb[3]]
//   texture only: u8 rgb[3] per texel, width × height, rows top to bottom (embedded, so a file
//            is self-contained and its bytes depend on the texels only, not on where the
//            image was)
//   trailer  u64 FNV-1a of every byte before it
// Versions 1 (float nodes, fewer stats) and 2 (the build's timings, so no two builds compared
// equal) are rejected: rebuild the file.
// ---------------------------------------------------------------------------------------------
namespace {
constexpr file_format pop_format{"POP", {'P', 'B', 'R', 'L', 'O', 'D', 'P', 'P'}, 3};
constexpr std::size_t header_bytes = 8 + 4 * 5 + 8 * 3 + 8 * 3 + 4 * 6 + 8 * 4;
constexpr std::size_t root_bytes = 16;

std::size_t code_bytes(int bits) {
  return bits <= 16 ? 2 : 4;
}
std::size_t vertex_bytes(int bits, bool colour) {
  return 6 + code_bytes(bits) + (colour ? 3 : 0);
}
constexpr std::size_t face_bytes = 12;
constexpr std::size_t texcoord_bytes = 24;  // per face
constexpr std::size_t texture_head_bytes = 8;
/// What a textured file adds: the texture's size, the faces' texture coordinates, the texels.
std::size_t texture_file_bytes(const pop_data& d) {
  if (!d.texture) return 0;
  return texture_head_bytes + d.faces.size() * texcoord_bytes +
         static_cast<std::size_t>(d.texture->width) * static_cast<std::size_t>(d.texture->height) *
             3;
}
std::size_t node_bytes(int bits, bool colour, bool quantised) {
  if (quantised) return 2 + code_bytes(bits) + 1 + (colour ? 2 : 0);
  return 12 + 4 + 4 + code_bytes(bits) + 4 + 1 + 1 + (colour ? 3 : 0);
}

}  // namespace

std::size_t pop_file_bytes(const pop_data& d) {
  const bool colour = !d.node_colours.empty();
  return header_bytes + (d.quantised_nodes ? root_bytes : 0) +
         d.positions.size() * vertex_bytes(d.normal_bits, colour) + d.faces.size() * face_bytes +
         d.nodes.size() * node_bytes(d.normal_bits, colour, d.quantised_nodes) +
         texture_file_bytes(d) + 8;
}

void pop_internal::set_file_stats(pop_data& d, std::size_t size) {
  auto& st = d.stats;
  const bool colour = !d.node_colours.empty();
  st.file_bytes = size;
  st.vertex_file_bytes = d.positions.size() * vertex_bytes(d.normal_bits, colour);
  st.face_file_bytes = d.faces.size() * face_bytes;
  st.node_file_bytes = d.nodes.size() * node_bytes(d.normal_bits, colour, d.quantised_nodes);
  st.bytes_per_vertex = static_cast<double>(size) / static_cast<double>(d.positions.size());
  st.bytes_per_triangle = static_cast<double>(size) / static_cast<double>(d.faces.size());
}

void save_pop_data(const pop_data& d, const std::string& path) {
  const bool colour = !d.node_colours.empty();
  const bool qn = d.quantised_nodes;
  const bool textured = colour && d.texture != nullptr;
  const int bits = d.normal_bits;
  byte_writer w;
  w.bytes.reserve(pop_file_bytes(d));
  write_head(w, pop_format);
  w.put(static_cast<std::uint32_t>((colour ? 1u : 0u) | (qn ? 2u : 0u) | (textured ? 4u : 0u)));
  w.put(static_cast<std::uint32_t>(bits));
  w.put(static_cast<std::uint32_t>(d.spheres));
  w.put(static_cast<std::uint32_t>(d.adjacency));
  w.put(static_cast<std::uint64_t>(d.positions.size()));
  w.put(static_cast<std::uint64_t>(d.faces.size()));
  w.put(static_cast<std::uint64_t>(d.nodes.size()));
  for (int k = 0; k < 3; ++k) w.put(d.origin[k]);
  for (int k = 0; k < 3; ++k) w.put(d.q_min[k]);
  for (int k = 0; k < 3; ++k) w.put(d.q_step[k]);
  w.put(static_cast<std::uint64_t>(d.stats.isolated_faces));
  w.put(static_cast<std::uint64_t>(d.stats.nonmanifold_edges));
  w.put(static_cast<std::uint64_t>(d.stats.degenerate_faces));
  w.put(static_cast<std::uint64_t>(d.stats.contained_inner));
  if (qn) {
    for (int k = 0; k < 3; ++k) w.put(d.nodes[0].centre[k]);
    w.put(d.nodes[0].radius);
  }
  if (textured) {
    w.put(static_cast<std::uint32_t>(d.texture->width));
    w.put(static_cast<std::uint32_t>(d.texture->height));
  }
  for (std::size_t i = 0; i < d.positions.size(); ++i) {
    for (auto q : d.vertex_q[i]) w.put(q);
    w.put_code(d.vertex_normal_codes[i], bits);
    if (colour) w.put(d.colours[i]);
  }
  for (const auto& f : d.faces)
    for (auto v : f) w.put(v);
  if (textured)
    for (const auto& uv : d.face_texcoords)
      for (const auto& c : uv) {
        w.put(c.x());
        w.put(c.y());
      }
  for (std::size_t i = 0; i < d.nodes.size(); ++i) {
    const auto& nd = d.nodes[i];
    if (qn) {
      w.put(d.node_sphere_codes[i]);
      w.put_code(d.node_normal_codes[i], bits);
      w.put(static_cast<std::uint8_t>(cone_code(nd.cone_angle) | (nd.count - 1u) << 2 |
                                      (nd.leaf ? 16u : 0u)));
      if (colour) w.put(rgb565(d.node_colours[i]));
      continue;
    }
    for (int k = 0; k < 3; ++k) w.put(nd.centre[k]);
    w.put(nd.radius);
    w.put(nd.cone_angle);
    w.put_code(d.node_normal_codes[i], bits);
    w.put(nd.first);
    w.put(nd.count);
    w.put(nd.leaf);
    if (colour) w.put(d.node_colours[i]);
  }
  if (textured)
    for (const rgb8& t : d.texture->texels) w.put(t);
  append_checksum(w);
  save_file_bytes(path, w.bytes);
}

namespace {
/// What the header says about the rest of the file.
struct pop_file_head {
  bool colour = false, qn = false, textured = false;
  std::uint64_t tex_w = 0, tex_h = 0;  // textured only
  int bits = 0;
  std::uint64_t nv = 0, nf = 0, nn = 0, size = 0;
  vec3f root_centre = vec3f::Zero();  // quantised nodes only
  float root_radius = 0;
};

/// The header: magic, version, flags, counts against the file size, the checksum, then d's
/// scalar fields and stats. Throws FormatError on anything unexpected.
pop_file_head read_pop_head(byte_reader& r, const std::vector<unsigned char>& bytes,
                            const std::string& path, bool colour, pop_data& d) {
  pop_file_head h;
  h.colour = colour;
  read_head(r, pop_format, 2);  // 1: float node records; 2: timings in the file
  const auto flags = r.get<std::uint32_t>("flags");
  if (flags & ~7u) throw FormatError(path + ": unknown flags " + std::to_string(flags));
  check_colour_flag((flags & 1u) != 0, colour, path, "pop_tree");
  h.qn = (flags & 2u) != 0;
  h.textured = (flags & 4u) != 0;
  if (h.textured && !colour) throw FormatError(path + ": texture flag without the colour flag");
  h.bits = static_cast<int>(r.get<std::uint32_t>("normal bits"));
  if (h.bits < normal_quantizer::min_bits || h.bits > normal_quantizer::max_bits)
    throw FormatError(path + ": normal bits " + std::to_string(h.bits) + " outside 6..24");
  const auto rule = r.get<std::uint32_t>("sphere rule");
  if (rule > 1) throw FormatError(path + ": unknown sphere rule " + std::to_string(rule));
  const auto adjacency = r.get<std::uint32_t>("adjacency");
  if (adjacency > 1) throw FormatError(path + ": unknown adjacency " + std::to_string(adjacency));
  const auto nv = h.nv = r.get<std::uint64_t>("vertex count");
  const auto nf = h.nf = r.get<std::uint64_t>("face count");
  const auto nn = h.nn = r.get<std::uint64_t>("node count");
  const std::uint64_t vb = vertex_bytes(h.bits, colour), nb = node_bytes(h.bits, colour, h.qn);
  const std::uint64_t size = h.size = bytes.size();
  // The texture's size sits at the end of the header (read in order below): peeked here so
  // that the size check covers the whole file before anything is allocated.
  std::uint64_t texture_bytes = 0;
  if (h.textured) {
    const std::uint64_t at = header_bytes + (h.qn ? root_bytes : 0);
    if (at + texture_head_bytes > size) throw FormatError(path + ": truncated header");
    std::uint32_t wh[2];
    std::memcpy(wh, bytes.data() + at, sizeof wh);
    h.tex_w = wh[0];
    h.tex_h = wh[1];
    if (h.tex_w == 0 || h.tex_h == 0 || h.tex_w > 0x7fffffffu || h.tex_h > 0x7fffffffu ||
        h.tex_w > size / 3 || h.tex_h > size / 3 / h.tex_w || nf > size / texcoord_bytes)
      throw FormatError(path + ": texture of " + std::to_string(h.tex_w) + " × " +
                        std::to_string(h.tex_h) + " texels for " + std::to_string(nf) +
                        " faces does not fit in the file size " + std::to_string(size));
    texture_bytes = texture_head_bytes + nf * texcoord_bytes + h.tex_w * h.tex_h * 3;
  }
  if (nv == 0 || nf == 0 || nn == 0 || nv >= none || nf >= none || nn >= none || nv > size / vb ||
      nf > size / face_bytes || nn > size / nb ||
      header_bytes + (h.qn ? root_bytes : 0) + nv * vb + nf * face_bytes + nn * nb + texture_bytes +
              8 !=
          size)
    throw FormatError(path + ": " + std::to_string(nv) + " vertices, " + std::to_string(nf) +
                      " faces and " + std::to_string(nn) + " nodes do not match the file size " +
                      std::to_string(size));
  if (!checksum_matches(bytes)) throw FormatError(path + ": checksum mismatch (corrupt file)");

  d.normal_bits = h.bits;
  d.spheres = static_cast<pop_sphere_rule>(rule);
  d.adjacency = static_cast<pop_adjacency>(adjacency);
  d.quantised_nodes = h.qn;
  for (int k = 0; k < 3; ++k) d.origin[k] = r.get<double>("origin");
  if (!all_finite(d.origin)) throw FormatError(path + ": origin is not finite");
  for (int k = 0; k < 3; ++k) d.q_min[k] = r.get_finite("quantisation origin", 0);
  for (int k = 0; k < 3; ++k) d.q_step[k] = r.get_finite("quantisation step", 0);
  if ((d.q_step.array() < 0).any()) throw FormatError(path + ": negative quantisation step");
  d.stats.isolated_faces = r.get<std::uint64_t>("stats");
  d.stats.nonmanifold_edges = r.get<std::uint64_t>("stats");
  d.stats.degenerate_faces = r.get<std::uint64_t>("stats");
  d.stats.contained_inner = r.get<std::uint64_t>("stats");
  if (h.qn) {
    h.root_centre = r.get_vec("root centre", 0);
    h.root_radius = r.get_finite("root radius", 0);
    if (!(h.root_radius >= 0) || !std::isfinite(h.root_radius * 2))
      throw FormatError(path + ": root radius " + std::to_string(h.root_radius) +
                        " is negative or too large");
  }
  if (h.textured) {  // checked above
    (void)r.get<std::uint32_t>("texture width");
    (void)r.get<std::uint32_t>("texture height");
  }
  return h;
}

void check_code(const normal_quantizer& quant, const std::string& path, std::uint32_t c,
                const char* what, std::size_t i) {
  if (!quant.valid(c))
    throw FormatError(path + ": " + what + " " + std::to_string(i) + " has normal code " +
                      std::to_string(c) + " outside the " + std::to_string(quant.size()) +
                      "-entry table");
}

/// Vertices (dequantised, finite, valid normal codes) and faces (indices below the count).
void read_pop_mesh(byte_reader& r, const pop_file_head& h, const normal_quantizer& quant,
                   const std::string& path, pop_data& d) {
  const std::uint64_t nv = h.nv, nf = h.nf;
  resize_fresh(d.vertex_q, nv, 1);
  resize_fresh(d.positions, nv, 1);
  resize_fresh(d.vertex_normal_codes, nv, 1);
  resize_fresh(d.normals, nv, 1);
  if (h.colour) resize_fresh(d.colours, nv, 1);
  for (std::size_t i = 0; i < nv; ++i) {
    for (auto& q : d.vertex_q[i]) q = r.get<std::uint16_t>("vertex");
    d.positions[i] = dequantise(d.vertex_q[i], d.q_min, d.q_step);
    if (!all_finite(d.positions[i]))
      throw FormatError(path + ": vertex " + std::to_string(i) + " is not finite");
    d.vertex_normal_codes[i] = r.get_code(h.bits, "vertex normal");
    check_code(quant, path, d.vertex_normal_codes[i], "vertex", i);
    d.normals[i] = quant.decode(d.vertex_normal_codes[i]);
    if (h.colour) d.colours[i] = r.get<rgb8>("vertex colour");
  }
  resize_fresh(d.faces, nf, 1);
  for (std::size_t i = 0; i < nf; ++i)
    for (auto& v : d.faces[i]) {
      v = r.get<std::uint32_t>("face");
      if (v >= nv)
        throw FormatError(path + ": face " + std::to_string(i) + " references vertex " +
                          std::to_string(v) + ", but there are " + std::to_string(nv));
    }
  if (!h.textured) return;
  resize_fresh(d.face_texcoords, nf, 1);
  for (std::size_t i = 0; i < nf; ++i)
    for (auto& uv : d.face_texcoords[i]) {
      const float u = r.get_finite("face texture coordinate", i);
      uv = vec2f(u, r.get_finite("face texture coordinate", i));
    }
}

/// The embedded texture (any texel value is valid; its size was checked with the header).
void read_pop_texture(byte_reader& r, const pop_file_head& h, pop_data& d) {
  if (!h.textured) return;
  texture_image img;
  img.width = static_cast<int>(h.tex_w);
  img.height = static_cast<int>(h.tex_h);
  img.texels.resize(h.tex_w * h.tex_h);
  for (rgb8& t : img.texels) t = r.get<rgb8>("texel");
  d.texture = std::make_shared<const texture_image>(std::move(img));
}

/// The node records. Quantised records leave the spheres (relative to the parent) and `first`
/// (implied by the breadth-first order) to link_quantised_nodes() and check_pop_tree().
void read_pop_nodes(byte_reader& r, const pop_file_head& h, const normal_quantizer& quant,
                    const std::string& path, pop_data& d) {
  const std::uint64_t nn = h.nn;
  const bool qn = h.qn, colour = h.colour;
  resize_fresh(d.nodes, nn, 1);
  resize_fresh(d.node_normal_codes, nn, 1);
  if (qn) resize_fresh(d.node_sphere_codes, nn, 1);
  if (colour) resize_fresh(d.node_colours, nn, 1);
  for (std::size_t i = 0; i < nn; ++i) {
    auto& nd = d.nodes[i];
    if (qn) {
      const auto code = r.get<std::uint16_t>("node sphere");
      for (unsigned k = 0; k < 4; ++k)
        if (((code >> (4 * k)) & 15u) > 12u)
          throw FormatError(path + ": node " + std::to_string(i) + " has sphere code " +
                            std::to_string(code) + " with a level above 12");
      d.node_sphere_codes[i] = code;
      d.node_normal_codes[i] = r.get_code(h.bits, "node normal");
      check_code(quant, path, d.node_normal_codes[i], "node", i);
      nd.normal = quant.decode(d.node_normal_codes[i]);
      const auto packed = r.get<std::uint8_t>("node flags");
      if (packed & 0xe0u)
        throw FormatError(path + ": node " + std::to_string(i) + " has unknown flag bits " +
                          std::to_string(packed));
      nd.cone_angle = cone_level(packed & 3u);
      nd.count = static_cast<std::uint8_t>(((packed >> 2) & 3u) + 1u);
      nd.leaf = static_cast<std::uint8_t>((packed >> 4) & 1u);
      if (colour) d.node_colours[i] = from565(r.get<std::uint16_t>("node colour"));
      continue;
    }
    for (int k = 0; k < 3; ++k) nd.centre[k] = r.get_finite("node centre", i);
    nd.radius = r.get_finite("node radius", i);
    nd.cone_angle = r.get_finite("node cone", i);
    d.node_normal_codes[i] = r.get_code(h.bits, "node normal");
    check_code(quant, path, d.node_normal_codes[i], "node", i);
    nd.normal = quant.decode(d.node_normal_codes[i]);
    nd.first = r.get<std::uint32_t>("node first");
    nd.count = r.get<std::uint8_t>("node count");
    nd.leaf = r.get<std::uint8_t>("node leaf");
    if (colour) d.node_colours[i] = r.get<rgb8>("node colour");
    if (nd.radius < 0 || nd.cone_angle < 0 || nd.cone_angle > std::numbers::pi_v<float> ||
        nd.leaf > 1)
      throw FormatError(path + ": node " + std::to_string(i) +
                        " has a negative radius, a cone outside [0, π] or a bad leaf flag");
  }
}

/// Quantised records: breadth first with contiguous children, an inner node's first child
/// follows the children of the inner nodes before it, a leaf's first face the faces of the
/// leaves before it.
void link_quantised_nodes(const pop_file_head& h, const std::string& path, pop_data& d) {
  std::uint64_t next_child = 1, next_face = 0;
  for (std::size_t i = 0; i < h.nn; ++i) {
    auto& nd = d.nodes[i];
    if (nd.leaf) {
      nd.first = static_cast<std::uint32_t>(std::min<std::uint64_t>(next_face, none));
      next_face += nd.count;
    } else {
      nd.first = static_cast<std::uint32_t>(std::min<std::uint64_t>(next_child, none));
      next_child += nd.count;
    }
  }
  if (next_child != h.nn || next_face != h.nf)
    throw FormatError(path + ": the node counts give " + std::to_string(next_child) +
                      " nodes and " + std::to_string(next_face) + " faces, the file has " +
                      std::to_string(h.nn) + " and " + std::to_string(h.nf));
}

/// The tree: breadth first, children after their parent, every node reached once, leaves
/// partitioning the faces. Anything else is a corrupt file, not something to traverse. Sets
/// parents, depths, quantised spheres (a parent's before its children's) and the tree stats.
void check_pop_tree(const pop_file_head& h, const std::string& path, pop_data& d) {
  const std::uint64_t nn = h.nn, nf = h.nf;
  const bool qn = h.qn;
  std::vector<char> reached(nn, 0), face_seen(nf, 0);
  reached[0] = 1;
  auto& st = d.stats;
  if (qn) {
    d.nodes[0].centre = h.root_centre;
    d.nodes[0].radius = h.root_radius;
  }
  for (std::size_t i = 0; i < nn; ++i) {
    auto& nd = d.nodes[i];
    if (!reached[i])
      throw FormatError(path + ": node " + std::to_string(i) + " is not reachable from the root");
    if (qn && i > 0) {  // the parent (an earlier node) has its sphere
      const auto& pa = d.nodes[nd.parent];
      dequantise_sphere(pa.centre, pa.radius, d.node_sphere_codes[i], nd.centre, nd.radius);
      if (!all_finite(nd.centre))
        throw FormatError(path + ": node " + std::to_string(i) + " has a non-finite centre");
    }
    const std::uint64_t end = std::uint64_t{nd.first} + nd.count;
    if (nd.leaf) {
      if (nd.count < 1 || nd.count > 4 || end > nf)
        throw FormatError(path + ": leaf " + std::to_string(i) + " has faces [" +
                          std::to_string(nd.first) + ", " + std::to_string(end) +
                          "), expected 1..4 faces below " + std::to_string(nf));
      for (std::uint64_t k = nd.first; k < end; ++k) {
        if (face_seen[k])
          throw FormatError(path + ": face " + std::to_string(k) + " belongs to two leaves");
        face_seen[k] = 1;
      }
      ++st.leaves;
      ++st.leaves_by_size[nd.count - 1u];
    } else {
      if (nd.count < 2 || nd.count > 4 || nd.first <= i || end > nn)
        throw FormatError(path + ": node " + std::to_string(i) + " has children [" +
                          std::to_string(nd.first) + ", " + std::to_string(end) +
                          "), expected 2..4 children after it and below " + std::to_string(nn));
      if (nd.depth >= 65535) throw FormatError(path + ": tree deeper than 65535 levels");
      for (std::uint64_t k = nd.first; k < end; ++k) {
        if (reached[k])
          throw FormatError(path + ": node " + std::to_string(k) + " has two parents");
        reached[k] = 1;
        d.nodes[k].parent = static_cast<std::uint32_t>(i);
        d.nodes[k].depth = static_cast<std::uint16_t>(nd.depth + 1);
      }
    }
    st.max_depth = std::max<std::size_t>(st.max_depth, nd.depth);
  }
  for (std::size_t k = 0; k < nf; ++k)
    if (!face_seen[k]) throw FormatError(path + ": face " + std::to_string(k) + " is in no leaf");
}
}  // namespace

pop_data load_pop_data(const std::string& path, bool colour) {
  const std::vector<unsigned char> bytes = load_file_bytes(path);
  byte_reader r{bytes, 0, path};
  pop_data d;
  const pop_file_head h = read_pop_head(r, bytes, path, colour, d);
  const auto shared_quant = normal_quantizer::shared(h.bits);
  read_pop_mesh(r, h, *shared_quant, path, d);
  read_pop_nodes(r, h, *shared_quant, path, d);
  read_pop_texture(r, h, d);
  if (h.qn) link_quantised_nodes(h, path, d);
  check_pop_tree(h, path, d);
  d.stats.vertices = h.nv;
  d.stats.triangles = h.nf;
  d.stats.nodes = h.nn;
  set_file_stats(d, h.size);
  return d;
}

bool operator==(const pop_data& a, const pop_data& b) {
  // The build's timings and normals_filled are not part of the hierarchy (the file does not
  // hold them).
  const auto untimed = [](pop_build_stats s) {
    s.has_timings = false;
    s.build_seconds = s.prepare_seconds = s.adjacency_seconds = s.tree_seconds = 0;
    s.normals_filled = 0;
    return s;
  };
  return a.origin == b.origin && a.positions == b.positions && a.normals == b.normals &&
         a.colours == b.colours && a.faces == b.faces && a.nodes == b.nodes &&
         a.node_colours == b.node_colours && a.vertex_q == b.vertex_q && a.q_min == b.q_min &&
         a.q_step == b.q_step && a.vertex_normal_codes == b.vertex_normal_codes &&
         a.node_normal_codes == b.node_normal_codes && a.normal_bits == b.normal_bits &&
         a.spheres == b.spheres && a.adjacency == b.adjacency &&
         a.quantised_nodes == b.quantised_nodes && a.node_sphere_codes == b.node_sphere_codes &&
         untimed(a.stats) == untimed(b.stats) && a.face_texcoords == b.face_texcoords &&
         (a.texture == b.texture ||
          (a.texture && b.texture && a.texture->width == b.texture->width &&
           a.texture->height == b.texture->height && a.texture->texels == b.texture->texels));
}

}  // namespace pbr_lod::detail
