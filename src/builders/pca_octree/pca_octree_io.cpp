// pbr_lod — the PCA octree's file: save() and the validating load().
//
// This work is based on:
//   A. Kalaiah, A. Varshney. Statistical Point Geometry. SGP 2003, §3.1 and Fig. 5: the node
//   records of 13 bytes (17 with colour) and the k-means codebooks they index.
//
// Little-endian file, version 2 (version 1 had classes of σ only, without the extents):
//   header   "PBRLODSG" | u32 version | u32 flags (1 = colour, 2 = quantised)
//            | u32 leaf_size | u32 max_depth | f32 γ | f32 curvature c | f32 λ_max
//            | u64 input points | u64 nodes | u32 codebook sizes p, n, c (0 when not quantised;
//            c is 0 without colour) | f64 origin[3] | f64 root cube min[3] (relative to origin)
//            | f64 root cube edge | f64 input radius (origin = centre of the input's box)
//   codebooks f32[6] × p (log₂ of σ_p¹..³ and of the extents, over the cell edge)
//            | f32[3] × n (σ_n¹, σ_n², normal extent; radians) | f32[4] × c (σ_c¹..³, extent)
//   tree     u8 child mask per node, breadth first (first child and depth follow from them)
//   records  quantised: 13 bytes per node [+ u32 colour record] (layout: pca_octree_internal.hpp)
//            float: f32 μ_p[3] f_p[9] σ_p[3] f_n[9] σ_n[2] extent[3] normal extent
//                   [+ μ_c[3] f_c[9] σ_c[3] colour extent]
//   trailer  u64 FNV-1a of every byte before it
// No timings: the same input and options give the same bytes.

#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numbers>

#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/normal_quantization.hpp"
#include "pca_octree_internal.hpp"

namespace pbr_lod::detail {

namespace {
constexpr file_format pca_format{"PCA octree", {'P', 'B', 'R', 'L', 'O', 'D', 'S', 'G'}, 2};
constexpr std::size_t header_bytes = 8 + 4 * 2 + 4 * 2 + 4 * 3 + 8 * 2 + 4 * 3 + 8 * 8;
constexpr std::size_t float_node_floats = 30, float_colour_floats = 16;

std::size_t record_bytes(bool quantised, bool colour) {  // without the child mask
  if (quantised) return 13 + (colour ? 4 : 0);
  return 4 * (float_node_floats + (colour ? float_colour_floats : 0));
}
void put_mat(byte_writer& w, const mat3f& m) {
  for (int c = 0; c < 3; ++c) w.put_vec(m.col(c));
}
}  // namespace

std::size_t pca_record_bytes(bool quantised, bool colour) {
  return record_bytes(quantised, colour);
}

std::uint64_t pca_codebook_bytes(std::uint64_t kp, std::uint64_t kn, std::uint64_t kc) {
  return 4 * (kp * pca_feature_dims[0] + kn * pca_feature_dims[1] + kc * pca_feature_dims[2]);
}

std::size_t pca_file_bytes(const pca_data& d) {
  const bool colour = !d.colours.empty();
  return header_bytes +
         pca_codebook_bytes(d.codebook_p.size(), d.codebook_n.size(), d.codebook_c.size()) +
         d.nodes.size() * (1 + record_bytes(d.quantised, colour)) + 8;
}

void put_pca_codebooks(byte_writer& w, const pca_data& d) {
  const std::vector<pca_feature>* books[3] = {&d.codebook_p, &d.codebook_n, &d.codebook_c};
  for (int b = 0; b < 3; ++b)
    for (const pca_feature& v : *books[b])
      for (int k = 0; k < pca_feature_dims[b]; ++k) w.put(v[k]);
}

void get_pca_codebooks(byte_reader& r, pca_data& d, std::uint32_t kp, std::uint32_t kn,
                       std::uint32_t kc, const std::string& path) {
  const auto bad = [&](const std::string& what) { throw FormatError(path + ": " + what); };
  const auto get = [&](int b, const char* what, std::uint32_t i) {
    pca_feature v = pca_feature::Zero();
    for (int k = 0; k < pca_feature_dims[b]; ++k) v[k] = r.get_finite(what, i);
    return v;
  };
  d.codebook_p.resize(kp);
  for (std::uint32_t i = 0; i < kp; ++i) {
    d.codebook_p[i] = get(0, "position codebook entry", i);
    if ((d.codebook_p[i].array().abs() > 128).any())
      bad("position codebook entry " + std::to_string(i) + " out of range");
  }
  d.codebook_n.resize(kn);
  for (std::uint32_t i = 0; i < kn; ++i) {
    d.codebook_n[i] = get(1, "normal codebook entry", i);
    if (!((d.codebook_n[i].array() >= 0).all() && (d.codebook_n[i].array() <= 4).all()))
      bad("normal codebook entry " + std::to_string(i) + " outside [0, 4] radians");
  }
  d.codebook_c.resize(kc);
  for (std::uint32_t i = 0; i < kc; ++i) {
    d.codebook_c[i] = get(2, "colour codebook entry", i);
    if ((d.codebook_c[i].array() < 0).any() || (d.codebook_c[i].array() > 2).any())
      bad("colour codebook entry " + std::to_string(i) + " outside [0, 2]");
  }
}

void put_pca_nodes(byte_writer& w, const pca_data& d) {
  const bool colour = !d.colours.empty();
  for (const auto& nd : d.nodes) w.put(nd.mask);
  for (std::size_t i = 0; i < d.nodes.size(); ++i) {
    if (d.quantised) {
      for (auto b : d.records[i]) w.put(b);
      if (colour) w.put(d.colour_records[i]);
      continue;
    }
    const pca_node& nd = d.nodes[i];
    w.put_vec(nd.mean);
    put_mat(w, nd.frame);
    w.put_vec(nd.sigma);
    put_mat(w, nd.normal_frame);
    w.put(nd.normal_sigma.x());
    w.put(nd.normal_sigma.y());
    w.put_vec(nd.extent);
    w.put(nd.normal_extent);
    if (colour) {
      const pca_colour& c = d.colours[i];
      w.put_vec(c.mean);
      put_mat(w, c.frame);
      w.put_vec(c.sigma);
      w.put(c.extent);
    }
  }
}

void save_pca_data(const pca_data& d, const std::string& path) {
  const bool colour = !d.colours.empty();
  byte_writer w;
  w.bytes.reserve(pca_file_bytes(d));
  write_head(w, pca_format);
  w.put(static_cast<std::uint32_t>((colour ? 1u : 0u) | (d.quantised ? 2u : 0u)));
  w.put(d.leaf_size);
  w.put(d.max_depth);
  w.put(d.gamma);
  w.put(d.curvature_c);
  w.put(d.lambda_max);
  w.put(static_cast<std::uint64_t>(d.stats.input_points));
  w.put(static_cast<std::uint64_t>(d.nodes.size()));
  w.put(static_cast<std::uint32_t>(d.codebook_p.size()));
  w.put(static_cast<std::uint32_t>(d.codebook_n.size()));
  w.put(static_cast<std::uint32_t>(d.codebook_c.size()));
  for (int k = 0; k < 3; ++k) w.put(d.origin[k]);
  for (int k = 0; k < 3; ++k) w.put(d.cube_min[k]);
  w.put(d.cube_size);
  w.put(d.input_radius);
  put_pca_codebooks(w, d);
  put_pca_nodes(w, d);
  append_checksum(w);
  save_file_bytes(path, w.bytes);
}

namespace {

mat3f get_frame(byte_reader& r, const std::string& path, const char* what, std::size_t i) {
  mat3f m;
  for (int c = 0; c < 3; ++c) m.col(c) = r.get_vec(what, i);
  for (int c = 0; c < 3; ++c) {
    if (std::abs(m.col(c).norm() - 1) > 1e-3f)
      throw FormatError(path + ": " + what + " of node " + std::to_string(i) +
                        " has a column that is not unit length");
    if (std::abs(m.col(c).dot(m.col((c + 1) % 3))) > 1e-3f)
      throw FormatError(path + ": " + what + " of node " + std::to_string(i) +
                        " is not orthogonal");
  }
  return m;
}

}  // namespace

void get_pca_nodes(byte_reader& r, pca_data& d, std::uint64_t nn, bool colour,
                   std::uint8_t root_depth, const std::string& path) {
  const auto bad = [&](const std::string& what) { throw FormatError(path + ": " + what); };
  const auto kp = d.codebook_p.size(), kn = d.codebook_n.size(), kc = d.codebook_c.size();
  // The tree: breadth first, children contiguous after their parent.
  d.nodes.assign(nn, pca_node{});
  d.nodes[0].depth = root_depth;
  std::uint64_t next = 1;
  for (std::uint64_t i = 0; i < nn; ++i) {
    pca_node& nd = d.nodes[i];
    nd.mask = r.get<std::uint8_t>("child mask");
    if (i > 0 && i >= next) bad("node " + std::to_string(i) + " is not reachable from the root");
    nd.count = static_cast<std::uint8_t>(std::popcount(nd.mask));
    nd.first = nd.count ? static_cast<std::uint32_t>(next) : 0;
    next += nd.count;
    if (next > nn)
      bad("node " + std::to_string(i) + " has children beyond the node count " +
          std::to_string(nn));
    for (std::uint32_t c = nd.first; c < nd.first + nd.count; ++c)
      d.nodes[c].depth = static_cast<std::uint8_t>(nd.depth + 1);
    if (nd.count && nd.depth + 1u > d.max_depth)
      bad("node " + std::to_string(i) + " has children below the depth limit " +
          std::to_string(d.max_depth));
  }
  if (next != nn) bad(std::to_string(nn - next) + " nodes are not reachable from the root");
  pca_derive_cells(d);

  if (colour) d.colours.resize(nn);
  if (d.quantised) {
    const auto q16 = normal_quantizer::shared(pca_layout::axis_bits);
    const auto q7 = normal_quantizer::shared(pca_layout::colour_axis_bits);
    d.records.resize(nn);
    if (colour) d.colour_records.resize(nn);
    for (std::uint64_t i = 0; i < nn; ++i) {
      auto& rec = d.records[i];
      for (auto& b : rec) b = r.get<std::uint8_t>("node record");
      using L = pca_layout;
      const std::string node = "node " + std::to_string(i);
      if (get_bits(rec, L::sp, 12) >= kp) bad(node + " has a position class beyond the codebook");
      if (get_bits(rec, L::sn, 12) >= kn) bad(node + " has a normal class beyond the codebook");
      if (!q16->valid(get_bits(rec, L::fp_axis, L::axis_bits)))
        bad(node + " has an invalid f_p axis code");
      if (!q16->valid(get_bits(rec, L::fn_axis, L::axis_bits)))
        bad(node + " has an invalid mean normal code");
      if (colour) {
        const auto c = r.get<std::uint32_t>("colour record");
        d.colour_records[i] = c;
        if ((c >> L::sc & 63u) >= kc) bad(node + " has a colour class beyond the codebook");
        if (!q7->valid(c >> L::fc_axis & 127u)) bad(node + " has an invalid f_c axis code");
      }
      pca_decode_node(d, static_cast<std::uint32_t>(i), d.nodes[i],
                      colour ? &d.colours[i] : nullptr);
    }
  } else {
    for (std::uint64_t i = 0; i < nn; ++i) {
      pca_node& nd = d.nodes[i];
      nd.mean = r.get_vec("mean", i);
      nd.frame = get_frame(r, path, "position frame", i);
      nd.sigma = r.get_vec("position sigma", i);
      nd.normal_frame = get_frame(r, path, "normal frame", i);
      nd.normal_sigma.x() = r.get_finite("normal sigma", i);
      nd.normal_sigma.y() = r.get_finite("normal sigma", i);
      nd.extent = r.get_vec("extent", i);
      nd.normal_extent = r.get_finite("normal extent", i);
      if ((nd.sigma.array() < 0).any() || (nd.normal_sigma.array() < 0).any())
        bad("node " + std::to_string(i) + " has a negative sigma");
      if ((nd.extent.array() < 0).any() || !(nd.normal_extent >= 0))
        bad("node " + std::to_string(i) + " has a negative extent");
      if (colour) {
        pca_colour& c = d.colours[i];
        c.mean = r.get_vec("colour mean", i);
        c.frame = get_frame(r, path, "colour frame", i);
        c.sigma = r.get_vec("colour sigma", i);
        c.extent = r.get_finite("colour extent", i);
        if ((c.sigma.array() < 0).any() || !(c.extent >= 0))
          bad("node " + std::to_string(i) + " has a negative colour sigma or extent");
      }
    }
  }
}

void get_pca_options(byte_reader& r, pca_data& d) {
  d.leaf_size = r.get<std::uint32_t>("leaf size");
  d.max_depth = r.get<std::uint32_t>("max depth");
  d.gamma = r.get_finite("gamma", 0);
  d.curvature_c = r.get_finite("curvature c", 0);
  d.lambda_max = r.get_finite("lambda max", 0);
  const auto bad = [&](const std::string& what) { throw FormatError(r.path + ": " + what); };
  if (d.leaf_size < 1) bad("leaf size 0");
  if (d.max_depth < 1 || d.max_depth > 30)
    bad("max depth " + std::to_string(d.max_depth) + " outside 1..30");
  if (!(d.gamma > 0 && d.gamma <= 10)) bad("gamma " + std::to_string(d.gamma) + " outside (0, 10]");
  if (!(d.curvature_c >= 0)) bad("negative curvature c");
  if (!(d.lambda_max >= 1 && d.lambda_max <= 16)) bad("lambda max outside [1, 16]");
}

pca_data load_pca_data(const std::string& path, bool colour) {
  const std::vector<unsigned char> bytes = load_file_bytes(path);
  byte_reader r{bytes, 0, path};
  read_head(r, pca_format);
  const auto flags = r.get<std::uint32_t>("flags");
  if (flags & ~3u) throw FormatError(path + ": unknown flags " + std::to_string(flags));
  check_colour_flag((flags & 1u) != 0, colour, path, "pca_octree");
  pca_data d;
  d.quantised = (flags & 2u) != 0;
  get_pca_options(r, d);
  const auto bad = [&](const std::string& what) { throw FormatError(path + ": " + what); };
  const auto input_points = r.get<std::uint64_t>("input point count");
  const auto nn = r.get<std::uint64_t>("node count");
  const auto kp = r.get<std::uint32_t>("position codebook size");
  const auto kn = r.get<std::uint32_t>("normal codebook size");
  const auto kc = r.get<std::uint32_t>("colour codebook size");
  if (nn == 0 || nn >= (1ull << 32) - 1) bad("node count " + std::to_string(nn));
  if (d.quantised) {
    if (kp < 1 || kp > 4096)
      bad("position codebook size " + std::to_string(kp) + " outside 1..4096");
    if (kn < 1 || kn > 4096) bad("normal codebook size " + std::to_string(kn) + " outside 1..4096");
    if (colour ? (kc < 1 || kc > 64) : kc != 0)
      bad("colour codebook size " + std::to_string(kc) +
          (colour ? " outside 1..64" : ", expected 0"));
  } else if (kp != 0 || kn != 0 || kc != 0) {
    bad("codebooks in a file without quantisation");
  }
  for (int k = 0; k < 3; ++k) d.origin[k] = r.get<double>("origin");
  for (int k = 0; k < 3; ++k) d.cube_min[k] = r.get<double>("root cube");
  d.cube_size = r.get<double>("root cube edge");
  d.input_radius = r.get<double>("input radius");
  if (!std::isfinite(d.input_radius) || d.input_radius < 0) bad("input radius is not finite");
  if (!all_finite(d.origin)) bad("origin is not finite");
  if (!all_finite(d.cube_min) || !std::isfinite(d.cube_size) || !(d.cube_size > 0))
    bad("root cube is not finite or has no extent");
  const std::uint64_t size = bytes.size();
  const std::uint64_t rb = 1 + record_bytes(d.quantised, colour);
  if (nn > size / rb || header_bytes + pca_codebook_bytes(kp, kn, kc) + nn * rb + 8 != size)
    bad(std::to_string(nn) + " nodes and codebooks of " + std::to_string(kp) + ", " +
        std::to_string(kn) + ", " + std::to_string(kc) + " entries do not match the file size " +
        std::to_string(size));
  if (!checksum_matches(bytes)) bad("checksum mismatch (corrupt file)");

  get_pca_codebooks(r, d, kp, kn, kc, path);
  get_pca_nodes(r, d, nn, colour, 0, path);
  pca_derive_bounds(d);
  auto& st = d.stats;
  st.input_points = input_points;
  st.nodes = nn;
  for (const auto& nd : d.nodes) {
    st.leaves += nd.count == 0 ? 1 : 0;
    st.max_depth = std::max<std::size_t>(st.max_depth, nd.depth);
  }
  return d;
}

}  // namespace pbr_lod::detail
