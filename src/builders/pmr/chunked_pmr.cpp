// Opening a chunked PMR, its lazily read chunks, and assemble(): see
// include/pbr_lod/builders/chunked_pmr.hpp.
#include <algorithm>
#include <filesystem>

#include "builders/chunked/chunk_files.hpp"
#include "pbr_lod/builders/chunked_pmr.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pmr_internal.hpp"

namespace pbr_lod {

namespace detail {
struct chunked_pmr_access {
  static pmr_hierarchy make(pmr_data&& d) {
    pmr_hierarchy h;
    h.d_ = std::move(d);
    return h;
  }
  static const pmr_data& data(const pmr_hierarchy& h) { return h.d_; }
};
}  // namespace detail

namespace {

namespace fs = std::filesystem;

/// Origin, bounds, options and build counts: the head of the top file after its flags.
void read_settings(detail::byte_reader& r, vec3d& origin, vec3d& lo, vec3d& hi,
                   std::uint32_t& leaf_points, float& margin, std::vector<float>& rho,
                   pmr_build_stats& stats) {
  for (vec3d* v : {&origin, &lo, &hi})
    for (int k = 0; k < 3; ++k) (*v)[k] = r.get<double>("origin or bounds");
  if (!all_finite(origin) || !all_finite(lo) || !all_finite(hi))
    throw FormatError(r.path + ": origin or input bounds not finite");
  leaf_points = r.get<std::uint32_t>("max_leaf_points");
  margin = r.get_finite("neighbour_margin", 0);
  const auto nrho = r.get<std::uint32_t>("threshold count");
  if (nrho > 31) throw FormatError(r.path + ": more than 31 thresholds");
  for (std::uint32_t i = 0; i < nrho; ++i) {
    rho.push_back(r.get_finite("rho", i));
    if (!(rho[i] > 0) || (i > 0 && !(rho[i] > rho[i - 1])))
      throw FormatError(r.path + ": rho[" + std::to_string(i) + "] is not positive and increasing");
  }
  for (std::size_t* s : detail::stat_fields(stats))
    *s = static_cast<std::size_t>(r.get<std::uint64_t>("build counts"));
}

}  // namespace

bool is_chunked_pmr(const std::string& dir) {
  return is_chunked_folder(dir, detail::chunked_pmr_format);
}

template <attributes A>
chunked_pmr<A> chunked_pmr<A>::open(const std::string& dir) {
  check_chunked_folder(dir);
  const std::string path = chunked_top_path(dir);
  const std::vector<unsigned char> bytes = detail::load_file_bytes(path);
  detail::byte_reader r{bytes, 0, path};
  detail::read_head(r, detail::chunked_pmr_format);
  const auto flags = r.get<std::uint32_t>("flags");
  if ((flags & ~1u) != 0) throw FormatError(path + ": unknown flags");
  detail::check_colour_flag((flags & 1u) != 0, A.colour, path, "chunked_pmr");
  chunked_pmr t;
  t.dir_ = dir;
  std::uint32_t leaf_points = 0;
  float margin = 0;
  read_settings(r, t.origin_, t.input_min_, t.input_max_, leaf_points, margin, t.rho_, t.stats_);
  t.input_sphere_.centre = r.get_vec("input sphere", 0);
  t.input_sphere_.radius = r.get_finite("input sphere", 0);
  if (t.input_sphere_.radius < 0) throw FormatError(path + ": negative input sphere radius");
  const auto n_nodes = r.get<std::uint64_t>("top node count");
  const auto n_chunks = r.get<std::uint64_t>("chunk count");
  const std::uint64_t rest = bytes.size() - r.pos;
  if (n_nodes == 0 || n_chunks == 0 || n_nodes > rest / 52 || n_chunks > rest / 28 ||
      n_nodes * 52 + n_chunks * 28 + 8 != rest)
    throw FormatError(path + ": " + std::to_string(n_nodes) + " top nodes and " +
                      std::to_string(n_chunks) + " chunks do not fit the file's " +
                      std::to_string(bytes.size()) + " bytes");
  if (!detail::checksum_matches(bytes)) throw FormatError(path + ": checksum mismatch");
  t.top_nodes_.resize(n_nodes);
  for (std::size_t i = 0; i < n_nodes; ++i) t.top_nodes_[i] = detail::get_node(r, i);
  t.frontier_.resize(n_nodes);
  for (auto& f : t.frontier_) f = r.get<std::uint32_t>("chunk of a top node");
  t.chunk_top_.resize(n_chunks);
  t.chunk_samples_.resize(n_chunks);
  t.chunk_nodes_.resize(n_chunks);
  t.leaf_offset_.assign(1, 0);
  for (std::size_t c = 0; c < n_chunks; ++c) {
    t.chunk_top_[c] = r.get<std::uint32_t>("top node of a chunk");
    t.chunk_samples_[c] = r.get<std::uint64_t>("chunk samples");
    const auto leaves = r.get<std::uint64_t>("chunk leaves");
    t.chunk_nodes_[c] = r.get<std::uint64_t>("chunk nodes");
    if (leaves == 0 || leaves > t.chunk_samples_[c] ||
        t.leaf_offset_.back() + leaves >= std::uint64_t{0xffffffffu})
      throw FormatError(path + ": chunk " + std::to_string(c) + ": bad leaf count");
    t.leaf_offset_.push_back(static_cast<std::uint32_t>(t.leaf_offset_.back() + leaves));
  }
  detail::validate_chunked_top(path, t.top_nodes_, t.frontier_, t.chunk_top_, t.chunk_samples_,
                               t.chunk_nodes_, t.stats_.input_points);
  t.make_slots();
  return t;
}

template <attributes A>
const pmr_hierarchy& chunked_pmr<A>::chunk(std::uint32_t c) const {
  return load_chunk(c, [&](const std::string& path) {
    pmr_hierarchy h = pmr_hierarchy::load(path);
    const bool same = h.origin() == origin_ && h.rho() == rho_ &&
                      h.input_total() == stats_.input_points &&
                      h.positions().size() - h.foreign() == chunk_samples_[c] &&
                      h.nodes().size() == chunk_nodes_[c] &&
                      h.leaf_count() == leaf_offset_[c + 1] - leaf_offset_[c] &&
                      h.nodes()[0] == top_nodes_[chunk_top_[c]] && h.has_colours() == A.colour;
    if (!same) throw FormatError(path + ": does not match its record in the top file");
    return h;
  });
}

template <attributes A>
std::uint32_t chunked_pmr<A>::chunk_of_leaf(std::uint32_t leaf) const {
  const auto it = std::upper_bound(leaf_offset_.begin(), leaf_offset_.end(), leaf);
  return static_cast<std::uint32_t>(it - leaf_offset_.begin() - 1);
}

/// build_pmr's layout: nodes breadth first (children together, in octant order), leaves and
/// their samples in node order, each level's triangles as sorted triples of global sample
/// indices, sorted and wound about the normals.
template <attributes A>
pmr_hierarchy chunked_pmr<A>::assemble() const {
  using detail::chunked_pmr_access;
  detail::pmr_data d;
  d.origin = origin_;
  d.input_min = input_min_;
  d.input_max = input_max_;
  d.rho = rho_;
  d.stats = stats_;
  std::vector<node_id> order{root()};
  std::vector<std::pair<std::uint32_t, std::uint32_t>> leaves;  // (chunk, local leaf)
  for (std::size_t k = 0; k < order.size(); ++k) {
    detail::pmr_node nd = at(order[k]);
    if (nd.leaf) {
      nd.first = static_cast<std::uint32_t>(leaves.size());
      leaves.emplace_back(order[k].chunk, chunk(order[k].chunk).leaf_of(order[k].index));
    } else {
      nd.first = static_cast<std::uint32_t>(order.size());
      for (const node_id c : children(order[k])) order.push_back(c);
    }
    d.nodes.push_back(nd);
  }
  const auto& first = chunked_pmr_access::data(chunk(0));
  d.max_leaf_points = first.max_leaf_points;
  d.neighbour_margin = first.neighbour_margin;
  // Samples leaf by leaf; where each input point went.
  std::vector<std::uint32_t> global(stats_.input_points);
  d.leaf_list.resize(leaves.size());
  for (std::size_t l = 0; l < leaves.size(); ++l) {
    const auto& c = chunked_pmr_access::data(chunk(leaves[l].first));
    const detail::pmr_leaf& L = c.leaf_list[leaves[l].second];
    d.leaf_list[l] = {static_cast<std::uint32_t>(d.positions.size()), L.point_count, 0};
    for (std::uint32_t g = L.first_point; g < L.first_point + L.point_count; ++g) {
      global[c.source[g]] = static_cast<std::uint32_t>(d.positions.size());
      d.positions.push_back(c.positions[g]);
      d.normals.push_back(c.normals[g]);
      if (A.colour || !c.colours.empty()) d.colours.push_back(c.colours[g]);
      d.source.push_back(c.source[g]);
    }
  }
  for (std::uint32_t k = 0; k < d.nodes.size(); ++k)
    if (d.nodes[k].leaf) d.leaf_list[d.nodes[k].first].node = k;
  for (std::size_t l = 0; l < leaves.size(); ++l) assemble_levels(d, leaves[l], global);
  detail::pmr_wind_triangles(d);
  return chunked_pmr_access::make(std::move(d));
}

/// One leaf's levels into d: its triangles in global indices, sorted, its umbrellas renumbered.
template <attributes A>
void chunked_pmr<A>::assemble_levels(detail::pmr_data& d,
                                     std::pair<std::uint32_t, std::uint32_t> leaf,
                                     const std::vector<std::uint32_t>& global) const {
  const auto& c = detail::chunked_pmr_access::data(chunk(leaf.first));
  using tri = std::array<std::uint32_t, 3>;
  std::vector<std::pair<tri, std::uint32_t>> tris;  // (global triple, index in the chunk's level)
  std::vector<std::uint32_t> renumber;
  for (std::uint32_t li = 0; li < levels(); ++li) {
    const detail::pmr_level& L = c.levels[static_cast<std::size_t>(leaf.second) * levels() + li];
    tris.clear();
    for (std::uint32_t t = 0; t < L.tris; ++t) {
      tri g;
      for (int k = 0; k < 3; ++k) g[k] = global[c.source[c.triangles[L.first_tri + t][k]]];
      std::sort(g.begin(), g.end());
      tris.emplace_back(g, t);
    }
    std::sort(tris.begin(), tris.end());
    renumber.assign(L.tris, 0);
    detail::pmr_level out = L;
    out.first_tri = static_cast<std::uint32_t>(d.triangles.size());
    out.first_entry = static_cast<std::uint32_t>(d.umbrellas.size());
    for (std::uint32_t t = 0; t < L.tris; ++t) {
      renumber[tris[t].second] = t;
      d.triangles.push_back(tris[t].first);
    }
    for (std::uint32_t k = 0; k < L.points; ++k) {
      detail::pmr_umbrella u = c.umbrellas[L.first_entry + k];
      const std::uint32_t from = u.first;
      u.first = static_cast<std::uint32_t>(d.umbrella_index.size());
      for (std::uint32_t j = from; j < from + u.count; ++j)
        d.umbrella_index.push_back(renumber[c.umbrella_index[j]]);
      d.umbrellas.push_back(u);
    }
    d.levels.push_back(out);
  }
}

template class chunked_pmr<with_normals>;
template class chunked_pmr<with_normals_colours>;

}  // namespace pbr_lod
