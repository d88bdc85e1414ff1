// Opening a chunked point-octree, its lazily read chunks, and assemble(): see
// include/pbr_lod/builders/chunked_point_octree.hpp.
#include <filesystem>
#include <functional>

#include "builders/chunked/chunk_files.hpp"
#include "pbr_lod/builders/chunked_point_octree.hpp"
#include "pbr_lod/core/binary.hpp"

namespace pbr_lod {
bool is_chunked_point_octree(const std::string& dir) {
  return is_chunked_folder(dir, detail::chunked_top_format);
}

template <attributes A>
chunked_point_octree<A> chunked_point_octree<A>::open(const std::string& dir) {
  check_chunked_folder(dir);
  using io = detail::point_octree_io<A>;
  const std::string path = chunked_top_path(dir);
  const std::vector<unsigned char> bytes = detail::load_file_bytes(path);
  detail::byte_reader r{bytes, 0, path};
  detail::read_head(r, detail::chunked_top_format);
  const auto flags = r.get<std::uint32_t>("flags");
  detail::check_colour_flag((flags & 1u) != 0, A.colour, path, "chunked_point_octree");
  const auto bits = static_cast<int>(r.get<std::uint32_t>("normal bits"));
  if ((flags & ~3u) != 0 || ((flags & 2u) != 0) != (bits > 0) ||
      (bits > 0 && (bits < 6 || bits > 24)))
    throw FormatError(path + ": bad flags or normal bits");
  chunked_point_octree t;
  t.dir_ = dir;
  t.normal_bits_ = bits;
  t.origin_ = {r.get<double>("origin"), r.get<double>("origin"), r.get<double>("origin")};
  if (!all_finite(t.origin_)) throw FormatError(path + ": origin is not finite");
  t.input_points_ = r.get<std::uint64_t>("input points");
  t.input_sphere_.centre = r.get_vec("input sphere", 0);
  t.input_sphere_.radius = r.get_finite("input sphere", 0);
  if (t.input_sphere_.radius < 0) throw FormatError(path + ": negative input sphere radius");
  const auto n_nodes = r.get<std::uint64_t>("top node count");
  const auto n_chunks = r.get<std::uint64_t>("chunk count");
  const std::uint64_t nb = io::node_bytes(bits);
  const std::uint64_t header = 8 + 4 * 3 + 8 * 3 + 8 + 16 + 8 * 2;
  if (n_nodes == 0 || n_chunks == 0 || n_nodes > bytes.size() / nb ||
      n_chunks > bytes.size() / 20 ||
      header + n_nodes * (nb + 4) + n_chunks * 20 + 8 != bytes.size())
    throw FormatError(path + ": " + std::to_string(n_nodes) + " top nodes and " +
                      std::to_string(n_chunks) + " chunks do not fit the file's " +
                      std::to_string(bytes.size()) + " bytes");
  if (!detail::checksum_matches(bytes)) throw FormatError(path + ": checksum mismatch");
  std::shared_ptr<const normal_quantizer> q;
  if (bits > 0) q = normal_quantizer::shared(bits);
  t.top_nodes_.resize(n_nodes);
  t.top_colours_.resize(n_nodes);
  if (q) t.top_codes_.resize(n_nodes);
  for (std::size_t i = 0; i < n_nodes; ++i)
    io::get_node(r, q.get(), i, t.top_nodes_[i], q ? &t.top_codes_[i] : nullptr, t.top_colours_[i]);
  t.frontier_.resize(n_nodes);
  for (auto& f : t.frontier_) f = r.get<std::uint32_t>("chunk of a top node");
  t.chunk_top_.resize(n_chunks);
  t.chunk_samples_.resize(n_chunks);
  t.chunk_nodes_.resize(n_chunks);
  for (std::size_t c = 0; c < n_chunks; ++c) {
    t.chunk_top_[c] = r.get<std::uint32_t>("top node of a chunk");
    t.chunk_samples_[c] = r.get<std::uint64_t>("chunk samples");
    t.chunk_nodes_[c] = r.get<std::uint64_t>("chunk nodes");
  }
  t.validate(path);
  t.top_selection_.resize(n_nodes);
  for (std::size_t i = 0; i < n_nodes; ++i)
    t.top_selection_[i] = tree::make_selection(t.top_nodes_[i]);
  t.make_slots();
  return t;
}

template <attributes A>
void chunked_point_octree<A>::validate(const std::string& path) const {
  detail::validate_chunked_top(path, top_nodes_, frontier_, chunk_top_, chunk_samples_,
                               chunk_nodes_, input_points_);
}

template <attributes A>
const typename chunked_point_octree<A>::tree& chunked_point_octree<A>::chunk(
    std::uint32_t c) const {
  return this->load_chunk(c, [&](const std::string& path) {
    tree t = tree::load(path);
    bool same = t.origin() == origin_ && t.normal_bits() == normal_bits_ &&
                t.samples().size() == chunk_samples_[c] && t.nodes().size() == chunk_nodes_[c] &&
                t.at(0) == top_nodes_[chunk_top_[c]];
    if constexpr (A.colour) same = same && t.node_colour(0) == top_colours_[chunk_top_[c]];
    if (!same) throw FormatError(path + ": does not match its record in the top file");
    return t;
  });
}

/// build_point_octree's layout: a node's children are allocated together when it is built,
/// depth first in octant order, and the leaves' samples follow in the same order.
template <attributes A>
typename chunked_point_octree<A>::tree chunked_point_octree<A>::assemble() const {
  tree out;
  out.samples_.origin = origin_;
  out.normal_bits_ = normal_bits_;
  out.stats_.input_points = input_points_;
  const auto code_of = [&](node_id n) {
    const std::uint32_t i = in_top(n);
    return i != top ? top_codes_[i] : chunk(n.chunk).node_codes_[n.index];
  };
  const std::function<void(node_id, std::uint32_t)> place = [&](node_id n, std::uint32_t dst) {
    node nd = at(n);
    if constexpr (A.colour) out.node_colours_[dst] = node_colour(n);
    if (normal_bits_ > 0) out.node_codes_[dst] = code_of(n);
    if (nd.leaf) {
      const tree& t = chunk(n.chunk);
      const auto first = static_cast<std::uint32_t>(out.samples_.size());
      for (std::uint32_t k = nd.first; k < nd.first + nd.count; ++k) {
        out.samples_.positions.push_back(t.samples_.positions[k]);
        out.samples_.normals.push_back(t.samples_.normals[k]);
        out.samples_.axis_u.push_back(t.samples_.axis_u[k]);
        out.samples_.axis_v.push_back(t.samples_.axis_v[k]);
        if constexpr (A.colour) out.samples_.colours.push_back(t.samples_.colours[k]);
        if (normal_bits_ > 0) out.sample_codes_.push_back(t.sample_codes_[k]);
      }
      nd.first = first;
      out.nodes_[dst] = nd;
      return;
    }
    const auto first = static_cast<std::uint32_t>(out.nodes_.size());
    const auto kids = children(n);
    std::vector<node_id> list(kids.begin(), kids.end());
    out.nodes_.resize(out.nodes_.size() + list.size());
    if constexpr (A.colour) out.node_colours_.resize(out.nodes_.size());
    if (normal_bits_ > 0) out.node_codes_.resize(out.nodes_.size());
    nd.first = first;
    out.nodes_[dst] = nd;
    for (std::uint32_t j = 0; j < list.size(); ++j) place(list[j], first + j);
  };
  out.nodes_.resize(1);
  if constexpr (A.colour) out.node_colours_.resize(1);
  if (normal_bits_ > 0) out.node_codes_.resize(1);
  place(root(), 0);
  out.derive_selection();
  auto& st = out.stats_;
  st.nodes = out.nodes_.size();
  st.circle_fallbacks = out.count_circles();
  for (const auto& nd : out.nodes_) {
    st.leaves += nd.leaf;
    st.max_depth = std::max<std::size_t>(st.max_depth, nd.depth);
  }
  return out;
}

template class chunked_point_octree<point_octree_attributes(attributes{})>;
template class chunked_point_octree<point_octree_attributes(attributes{.colour = true})>;

}  // namespace pbr_lod
