// Opening a chunked PCA octree, its lazily read chunks, and assemble(): see
// include/pbr_lod/builders/chunked_pca_octree.hpp.
#include <algorithm>
#include <bit>
#include <filesystem>

#include "pbr_lod/builders/chunked_pca_octree.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pca_octree_internal.hpp"

namespace pbr_lod {

namespace detail {
struct chunked_pca_access {
  template <attributes A>
  static pca_octree<A> make(pca_data&& d) {
    pca_octree<A> t;
    t.d_ = std::move(d);
    return t;
  }
};

std::uint64_t pca_chunk::global_id(std::uint32_t i) const {
  const auto l = static_cast<std::size_t>(
      std::upper_bound(level_first.begin(), level_first.end(), i) - level_first.begin() - 1);
  return std::uint64_t{level_global[l]} + (i - level_first[l]);
}

namespace {
constexpr std::uint32_t none = 0xffffffffu;

/// The codebooks after their sizes (as the PCA octree file), checked as its load checks them.
void read_codebooks(byte_reader& r, pca_data& d, std::uint32_t kp, std::uint32_t kn,
                    std::uint32_t kc, bool colour) {
  const auto bad = [&](const std::string& what) { throw FormatError(r.path + ": " + what); };
  if (d.quantised) {
    if (kp < 1 || kp > 4096 || kn < 1 || kn > 4096 || (colour ? (kc < 1 || kc > 64) : kc != 0))
      bad("codebook sizes " + std::to_string(kp) + ", " + std::to_string(kn) + ", " +
          std::to_string(kc) + " out of range");
  } else if (kp != 0 || kn != 0 || kc != 0) {
    bad("codebooks in a file without quantisation");
  }
  get_pca_codebooks(r, d, kp, kn, kc, r.path);
}
}  // namespace

pca_chunk load_pca_chunk(const std::string& path, const pca_data& top, std::uint32_t chunk,
                         bool colour) {
  const std::vector<unsigned char> bytes = load_file_bytes(path);
  byte_reader r{bytes, 0, path};
  read_head(r, pca_chunk_format);
  const auto bad = [&](const std::string& what) { throw FormatError(path + ": " + what); };
  const auto flags = r.get<std::uint32_t>("flags");
  if (flags != ((colour ? 1u : 0u) | (top.quantised ? 2u : 0u)))
    bad("flags " + std::to_string(flags) + " differ from the top file's");
  if (r.get<std::uint32_t>("chunk") != chunk) bad("is not chunk " + std::to_string(chunk));
  const auto depth = r.get<std::uint32_t>("root depth");
  pca_chunk c;
  c.points = r.get<std::uint64_t>("points");
  const auto nn = r.get<std::uint64_t>("nodes");
  pca_data& d = c.d;
  for (int k = 0; k < 3; ++k) d.cube_min[k] = r.get<double>("cell");
  d.cube_size = r.get<double>("cell edge");
  const auto levels = r.get<std::uint32_t>("levels");
  const std::uint64_t rb = 1 + pca_record_bytes(top.quantised, colour);
  const std::uint64_t rest = bytes.size() - r.pos;
  if (depth > top.max_depth || nn == 0 || levels == 0 || levels > 31 || nn > rest / rb ||
      4ull * levels + nn * rb + 8 != rest)
    bad("depth " + std::to_string(depth) + ", " + std::to_string(nn) + " nodes and " +
        std::to_string(levels) + " levels do not fit the file's " + std::to_string(bytes.size()) +
        " bytes");
  if (!checksum_matches(bytes)) bad("checksum mismatch (corrupt file)");
  c.level_global.resize(levels);
  for (auto& g : c.level_global) g = r.get<std::uint32_t>("level number");
  d.origin = top.origin;
  d.leaf_size = top.leaf_size;
  d.max_depth = top.max_depth;
  d.gamma = top.gamma;
  d.curvature_c = top.curvature_c;
  d.lambda_max = top.lambda_max;
  d.quantised = top.quantised;
  d.codebook_p = top.codebook_p;
  d.codebook_n = top.codebook_n;
  d.codebook_c = top.codebook_c;
  d.input_radius = top.input_radius;
  get_pca_nodes(r, d, nn, colour, static_cast<std::uint8_t>(depth), path);
  pca_derive_bounds_with(d, top.lambda_norm, 1);
  // Level starts from the depths (breadth first: levels contiguous).
  for (std::uint32_t i = 0; i < nn; ++i)
    if (i == 0 || d.nodes[i].depth != d.nodes[i - 1].depth) c.level_first.push_back(i);
  if (c.level_first.size() != levels) bad("level count differs from its tree's");
  return c;
}

}  // namespace detail

bool is_chunked_pca_octree(const std::string& dir) {
  return is_chunked_folder(dir, detail::chunked_pca_format);
}

template <attributes A>
chunked_pca_octree<A> chunked_pca_octree<A>::open(const std::string& dir) {
  check_chunked_folder(dir);
  using namespace detail;
  const std::string path = chunked_top_path(dir);
  const std::vector<unsigned char> bytes = load_file_bytes(path);
  byte_reader r{bytes, 0, path};
  read_head(r, chunked_pca_format);
  const auto bad = [&](const std::string& what) { throw FormatError(path + ": " + what); };
  const auto flags = r.get<std::uint32_t>("flags");
  if ((flags & ~3u) != 0) bad("unknown flags " + std::to_string(flags));
  check_colour_flag((flags & 1u) != 0, A.colour, path, "chunked_pca_octree");
  chunked_pca_octree t;
  t.dir_ = dir;
  pca_data& d = t.top_;
  d.quantised = (flags & 2u) != 0;
  get_pca_options(r, d);
  d.lambda_norm = r.get_finite("lambda unit", 0);
  if (!(d.lambda_norm > 0)) bad("lambda unit not positive");
  d.stats.input_points = r.get<std::uint64_t>("input points");
  for (int k = 0; k < 3; ++k) d.origin[k] = r.get<double>("origin");
  for (int k = 0; k < 3; ++k) d.cube_min[k] = r.get<double>("root cube");
  d.cube_size = r.get<double>("root cube edge");
  d.input_radius = r.get<double>("input radius");
  if (!all_finite(d.origin) || !all_finite(d.cube_min) || !std::isfinite(d.cube_size) ||
      !(d.cube_size > 0) || !std::isfinite(d.input_radius) || d.input_radius < 0)
    bad("origin, root cube or input radius not finite");
  const auto kp = r.get<std::uint32_t>("codebook size"), kn = r.get<std::uint32_t>("codebook size"),
             kc = r.get<std::uint32_t>("codebook size");
  if (pca_codebook_bytes(kp, kn, kc) > bytes.size() - r.pos) bad("codebooks cut short");
  read_codebooks(r, d, kp, kn, kc, A.colour);
  const auto nt = r.get<std::uint64_t>("top node count");
  const auto nc = r.get<std::uint64_t>("chunk count");
  const std::uint64_t rb = 1 + pca_record_bytes(d.quantised, A.colour) + 8,
                      cb = 4 + 8 + 8 + 1 + 4 + 4;
  const std::uint64_t rest = bytes.size() - r.pos;
  if (nt == 0 || nc == 0 || nt > rest / rb || nc > rest / cb || nt * rb + nc * cb + 8 != rest)
    bad(std::to_string(nt) + " top nodes and " + std::to_string(nc) +
        " chunks do not fit the file's " + std::to_string(bytes.size()) + " bytes");
  if (!checksum_matches(bytes)) bad("checksum mismatch (corrupt file)");
  get_pca_nodes(r, d, nt, A.colour, 0, path);
  t.frontier_.resize(nt);
  t.top_global_.resize(nt);
  for (std::uint64_t i = 0; i < nt; ++i) {
    t.frontier_[i] = r.get<std::uint32_t>("chunk of a top node");
    t.top_global_[i] = r.get<std::uint32_t>("node number");
  }
  t.chunk_top_.resize(nc);
  t.chunk_samples_.resize(nc);
  t.chunk_nodes_.resize(nc);
  std::vector<std::uint8_t> root_mask(nc);
  std::vector<std::array<float, 2>> root_bounds(nc);
  std::vector<char> fixed(nt, 0);
  std::uint64_t points = 0, total = 0;
  for (std::uint64_t c = 0; c < nc; ++c) {
    t.chunk_top_[c] = r.get<std::uint32_t>("top node of a chunk");
    t.chunk_samples_[c] = r.get<std::uint64_t>("chunk points");
    t.chunk_nodes_[c] = r.get<std::uint64_t>("chunk nodes");
    root_mask[c] = r.get<std::uint8_t>("chunk root mask");
    root_bounds[c] = {r.get_finite("chunk root radius", c), r.get_finite("chunk root cone", c)};
    const std::uint32_t x = t.chunk_top_[c];
    if (x >= nt || t.frontier_[x] != c || fixed[x] || d.nodes[x].count != 0 ||
        t.chunk_samples_[c] == 0 || t.chunk_nodes_[c] == 0 ||
        (root_mask[c] == 0) != (t.chunk_nodes_[c] == 1))
      bad("chunk " + std::to_string(c) + " and its top node disagree");
    fixed[x] = 1;
    points += t.chunk_samples_[c];
    total += t.chunk_nodes_[c];
  }
  for (std::uint64_t i = 0; i < nt; ++i) {
    if (!fixed[i] && (t.frontier_[i] != none || d.nodes[i].count == 0))
      bad("top node " + std::to_string(i) + " is a leaf that is not a chunk");
    total += fixed[i] ? 0 : 1;
  }
  if (points != d.stats.input_points)
    bad("the chunks hold " + std::to_string(points) + " points, the input " +
        std::to_string(d.stats.input_points));
  for (std::uint64_t i = 0; i < nt; ++i)
    if (t.top_global_[i] >= total) bad("top node " + std::to_string(i) + " has a bad number");
  // The chunks' roots are leaves of the top tree; their bounds come from the chunks, so the top
  // is bounded without reading them: with a chunk's root taken as a leaf, and then its own.
  pca_derive_bounds_with(d, d.lambda_norm, 1);
  for (std::uint64_t c = 0; c < nc; ++c) {
    pca_node& nd = d.nodes[t.chunk_top_[c]];
    nd.radius = root_bounds[c][0];
    nd.cone_angle = root_bounds[c][1];
  }
  pca_derive_bounds_with(d, d.lambda_norm, 1, &fixed);
  for (std::uint64_t c = 0; c < nc; ++c) {  // then the roots take their chunk's children
    pca_node& nd = d.nodes[t.chunk_top_[c]];
    nd.mask = root_mask[c];
    nd.count = static_cast<std::uint8_t>(std::popcount(nd.mask));
    nd.first = nd.count ? 1 : 0;
  }
  d.stats.nodes = total;
  t.make_slots();
  return t;
}

template <attributes A>
const detail::pca_chunk& chunked_pca_octree<A>::chunk(std::uint32_t c) const {
  return load_chunk(c, [&](const std::string& path) {
    detail::pca_chunk k = detail::load_pca_chunk(path, top_, c, A.colour);
    // The chunk's root is the top's copy of it (statistics, cell, bounds, children).
    const pca_node& root = top_.nodes[chunk_top_[c]];
    const bool same = k.points == chunk_samples_[c] && k.d.nodes.size() == chunk_nodes_[c] &&
                      k.d.nodes[0] == root &&
                      (!A.colour || k.d.colours[0] == top_.colours[chunk_top_[c]]) &&
                      k.global_id(0) == top_global_[chunk_top_[c]];
    if (!same) throw FormatError(path + ": does not match its record in the top file");
    // Every node's whole-tree number lies in the tree (assemble() places the node there).
    for (std::size_t l = 0; l < k.level_first.size(); ++l) {
      const std::uint64_t end =
          l + 1 < k.level_first.size() ? k.level_first[l + 1] : k.d.nodes.size();
      if (std::uint64_t{k.level_global[l]} + (end - k.level_first[l]) > node_count())
        throw FormatError(path + ": level " + std::to_string(l) +
                          " numbers nodes beyond the tree's " + std::to_string(node_count()));
    }
    return k;
  });
}

/// build_pca_octree's layout: every node at its whole-tree number, its first child's number as
/// `first` (a node's children are consecutive there as in its chunk or the top).
template <attributes A>
pca_octree<A> chunked_pca_octree<A>::assemble() const {
  detail::pca_data d = top_;
  const std::uint64_t n = node_count();
  d.nodes.assign(n, pca_node{});
  if (A.colour) d.colours.assign(n, pca_colour{});
  if (d.quantised) d.records.assign(n, {});
  if (d.quantised && A.colour) d.colour_records.assign(n, 0);
  const auto place = [&](const detail::pca_data& from, std::uint32_t i, std::uint64_t g,
                         std::uint64_t first) {
    d.nodes[g] = from.nodes[i];
    d.nodes[g].first = static_cast<std::uint32_t>(first);
    if (A.colour) d.colours[g] = from.colours[i];
    if (d.quantised) d.records[g] = from.records[i];
    if (d.quantised && A.colour) d.colour_records[g] = from.colour_records[i];
  };
  for (std::uint32_t i = 0; i < top_.nodes.size(); ++i) {
    if (frontier_[i] != top) continue;
    const pca_node& nd = top_.nodes[i];
    place(top_, i, top_global_[i], top_global_[nd.first]);
  }
  for (std::uint32_t c = 0; c < chunk_top_.size(); ++c) {
    const detail::pca_chunk& k = chunk(c);
    for (std::uint32_t i = 0; i < k.d.nodes.size(); ++i) {
      const pca_node& nd = k.d.nodes[i];
      place(k.d, i, k.global_id(i), nd.count ? k.global_id(nd.first) : 0);
    }
  }
  auto& st = d.stats;
  st = {};
  st.input_points = top_.stats.input_points;
  st.nodes = n;
  for (const auto& nd : d.nodes) {
    st.leaves += nd.count == 0 ? 1 : 0;
    st.max_depth = std::max<std::size_t>(st.max_depth, nd.depth);
  }
  return detail::chunked_pca_access::make<A>(std::move(d));
}

template class chunked_pca_octree<with_normals>;
template class chunked_pca_octree<with_normals_colours>;

}  // namespace pbr_lod
