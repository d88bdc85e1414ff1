// pbr_lod — the point-octree file format (Pajarola 2003 §5, Table 2: what a node stores):
// serialise, load with validation of every count and index, file size. Included by
// builders/point_octree.hpp after the builder.
#pragma once

#include <cstring>
#include <string>
#include <vector>

#include "pbr_lod/builders/detail/point_octree_impl.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/normal_quantization.hpp"

namespace pbr_lod {

// ---------------------------------------------------------------------------------------------
// Storage (§5, Table 2). Little-endian file:
//   header  "PBRLODPO" | u32 version | u32 flags (1 colour, 2 quantised) | u32 normal_bits
//           | u64 nodes | u64 samples | f64 origin[3] | u64 input points
//           (version 1 also held the build's timings: no two builds compared equal)
//   nodes   f32 centre[3], f32 radius, f32 cone, u32 first, u32 count, u8 leaf, u8 depth,
//           then quantised: u16/u32 normal code, u16/u32 axis code, f32 a, f32 b
//                  or float: f32 normal[3], f32 axis_u[3], f32 axis_v[3]
//           [u8 rgb[3]]
//   samples f32 position[3], then the same normal/axis block as nodes, [u8 rgb[3]]
//   trailer u64 FNV-1a of every byte before it
// ---------------------------------------------------------------------------------------------
namespace detail {

inline constexpr file_format point_octree_format{
    "point-octree", {'P', 'B', 'R', 'L', 'O', 'D', 'P', 'O'}, 2};

template <attributes A>
struct point_octree_io {
  using tree = point_octree<A>;

  static std::size_t orientation_bytes(int bits) {
    return bits > 0 ? 2 * (bits <= 16 ? 2u : 4u) + 8 : 36;
  }
  static std::size_t node_bytes(int bits) {
    return 12 + 4 + 4 + 4 + 4 + 1 + 1 + orientation_bytes(bits) + (A.colour ? 3 : 0);
  }
  static std::size_t sample_bytes(int bits) {
    return 12 + orientation_bytes(bits) + (A.colour ? 3 : 0);
  }
  static constexpr std::size_t header_bytes = 8 + 4 * 3 + 8 * 2 + 8 * 3 + 8;

  using code_t = typename tree::orientation_code;
  static void put_orientation(byte_writer& w, int bits, const code_t* code, const vec3f& n,
                              const vec3f& u, const vec3f& v) {
    if (bits > 0) {
      w.put_code(code->normal, bits);
      w.put_code(code->axis, bits);
      w.put(code->a);
      w.put(code->b);
    } else {
      w.put_vec(n);
      w.put_vec(u);
      w.put_vec(v);
    }
  }

  /// One node record (also the chunked hierarchy's top file, builders/chunked_point_octree.hpp).
  static void put_node(byte_writer& w, int bits, const typename tree::node& nd, const code_t* code,
                       rgb8 colour) {
    w.put_vec(nd.centre);
    w.put(nd.radius);
    w.put(nd.cone_angle);
    w.put(nd.first);
    w.put(nd.count);
    w.put(nd.leaf);
    w.put(nd.depth);
    put_orientation(w, bits, code, nd.normal, nd.axis_u, nd.axis_v);
    if constexpr (A.colour) w.put(colour);
  }
  /// Reads what put_node wrote, validating it; `i` names the node in messages.
  static void get_node(byte_reader& r, const normal_quantizer* q, std::size_t i,
                       typename tree::node& nd, code_t* code, rgb8& colour) {
    nd.centre = r.get_vec("node centre", i);
    nd.radius = r.get_finite("node radius", i);
    nd.cone_angle = r.get_finite("node cone", i);
    nd.first = r.get<std::uint32_t>("node first");
    nd.count = r.get<std::uint32_t>("node count");
    nd.leaf = r.get<std::uint8_t>("node leaf");
    nd.depth = r.get<std::uint8_t>("node depth");
    get_orientation(r, q, code, nd.normal, nd.axis_u, nd.axis_v, i);
    if constexpr (A.colour) colour = r.get<rgb8>("node colour");
    if (nd.radius < 0 || nd.cone_angle < 0 || nd.leaf > 1)
      throw FormatError(r.path + ": node " + std::to_string(i) +
                        " has a negative radius/cone or a bad leaf flag");
  }

  static std::vector<unsigned char> serialise(const tree& t) {
    byte_writer w;
    w.bytes.reserve(t.file_bytes());
    write_head(w, point_octree_format);
    w.put(static_cast<std::uint32_t>((A.colour ? 1u : 0u) | (t.normal_bits_ > 0 ? 2u : 0u)));
    w.put(static_cast<std::uint32_t>(t.normal_bits_));
    w.put(static_cast<std::uint64_t>(t.nodes_.size()));
    w.put(static_cast<std::uint64_t>(t.samples_.size()));
    w.put(t.samples_.origin.x());
    w.put(t.samples_.origin.y());
    w.put(t.samples_.origin.z());
    w.put(static_cast<std::uint64_t>(t.stats_.input_points));
    const int bits = t.normal_bits_;
    for (std::size_t i = 0; i < t.nodes_.size(); ++i) {
      rgb8 colour{};
      if constexpr (A.colour) colour = t.node_colours_[i];
      put_node(w, bits, t.nodes_[i], bits ? &t.node_codes_[i] : nullptr, colour);
    }
    const auto& s = t.samples_;
    for (std::size_t i = 0; i < s.size(); ++i) {
      w.put_vec(s.positions[i]);
      put_orientation(w, bits, bits ? &t.sample_codes_[i] : nullptr, s.normals[i], s.axis_u[i],
                      s.axis_v[i]);
      if constexpr (A.colour) w.put(s.colours[i]);
    }
    append_checksum(w);
    return w.bytes;
  }

  static void get_orientation(byte_reader& r, const normal_quantizer* q, code_t* code, vec3f& n,
                              vec3f& u, vec3f& v, std::size_t element) {
    if (q) {
      code->normal = r.get_code(q->bits(), "normal code");
      code->axis = r.get_code(q->bits(), "axis code");
      if (!q->valid(code->normal) || !q->valid(code->axis))
        throw FormatError(r.path + ": element " + std::to_string(element) +
                          " has a normal code beyond the " + std::to_string(q->size()) +
                          "-entry table");
      const float a = r.get_finite("axis length", element),
                  b = r.get_finite("axis length", element);
      if (a < 0 || b < 0)
        throw FormatError(r.path + ": negative axis length in element " + std::to_string(element));
      code->a = a;
      code->b = b;
      vec3f e1, e2;
      axes_from_codes(*q, code->normal, code->axis, n, e1, e2);
      u = e1 * a;
      v = e2 * b;
    } else {
      n = r.get_vec("normal", element);
      u = r.get_vec("axis_u", element);
      v = r.get_vec("axis_v", element);
    }
  }

  static tree load(const std::string& path) {
    const std::vector<unsigned char> bytes = load_file_bytes(path);
    byte_reader r{bytes, 0, path};
    read_head(r, point_octree_format, 1);  // version 1 stored the build's timings
    const auto flags = r.get<std::uint32_t>("flags");
    check_colour_flag((flags & 1u) != 0, A.colour, path, "point_octree");
    if (flags & ~3u) throw FormatError(path + ": unknown flags " + std::to_string(flags));
    const auto bits = static_cast<int>(r.get<std::uint32_t>("normal bits"));
    if (((flags & 2u) != 0) != (bits > 0) || bits < 0 || (bits > 0 && (bits < 6 || bits > 24)))
      throw FormatError(path + ": inconsistent normal quantisation (" + std::to_string(bits) +
                        " bits)");
    const auto n_nodes = r.get<std::uint64_t>("node count");
    const auto n_samples = r.get<std::uint64_t>("sample count");
    const std::size_t expect = header_bytes;
    // Validate the counts against the file size before allocating anything.
    const std::uint64_t nb = node_bytes(bits), sb = sample_bytes(bits);
    if (n_nodes == 0 || n_samples == 0 || n_nodes > bytes.size() / nb ||
        n_samples > bytes.size() / sb || expect + n_nodes * nb + n_samples * sb + 8 != bytes.size())
      throw FormatError(path + ": " + std::to_string(n_nodes) + " nodes and " +
                        std::to_string(n_samples) + " samples need " +
                        std::to_string(expect + n_nodes * nb + n_samples * sb + 8) +
                        " bytes, the file has " + std::to_string(bytes.size()));
    if (!checksum_matches(bytes)) throw FormatError(path + ": checksum mismatch (corrupt file)");

    tree t;
    t.normal_bits_ = bits;
    std::shared_ptr<const normal_quantizer> q;  // one table per process, not one per load
    if (bits > 0) q = normal_quantizer::shared(bits);
    auto& s = t.samples_;
    s.origin.x() = r.get<double>("origin");
    s.origin.y() = r.get<double>("origin");
    s.origin.z() = r.get<double>("origin");
    if (!all_finite(s.origin)) throw FormatError(path + ": origin is not finite");
    t.stats_.input_points = r.get<std::uint64_t>("stats");
    t.nodes_.resize(n_nodes);
    if constexpr (A.colour) t.node_colours_.resize(n_nodes);
    if (q) t.node_codes_.resize(n_nodes);
    for (std::size_t i = 0; i < n_nodes; ++i) {
      rgb8 colour{};
      get_node(r, q.get(), i, t.nodes_[i], q ? &t.node_codes_[i] : nullptr, colour);
      if constexpr (A.colour) t.node_colours_[i] = colour;
    }
    s.resize(n_samples);
    if (q) t.sample_codes_.resize(n_samples);
    for (std::size_t i = 0; i < n_samples; ++i) {
      s.positions[i] = r.get_vec("sample position", i);
      get_orientation(r, q.get(), q ? &t.sample_codes_[i] : nullptr, s.normals[i], s.axis_u[i],
                      s.axis_v[i], i);
      if constexpr (A.colour) s.colours[i] = r.get<rgb8>("sample colour");
    }
    validate_tree(t, path);
    t.derive_selection();
    t.stats_.nodes = n_nodes;
    t.stats_.circle_fallbacks = t.count_circles();
    for (const auto& nd : t.nodes_) {
      t.stats_.leaves += nd.leaf;
      t.stats_.max_depth = std::max<std::size_t>(t.stats_.max_depth, nd.depth);
    }
    return t;
  }

  /// Children come after their parent and every node is reached once; leaves partition the
  /// samples. Anything else is a corrupt file, not something to traverse.
  static void validate_tree(const tree& t, const std::string& path) {
    const std::size_t n = t.nodes_.size();
    std::vector<char> reached(n, 0);
    std::vector<char> sample_seen(t.samples_.size(), 0);
    reached[0] = 1;
    for (std::size_t i = 0; i < n; ++i) {
      const auto& nd = t.nodes_[i];
      if (!reached[i])
        throw FormatError(path + ": node " + std::to_string(i) + " is not reachable from the root");
      const std::uint64_t end = static_cast<std::uint64_t>(nd.first) + nd.count;
      if (nd.leaf) {
        if (nd.count == 0 || end > t.samples_.size())
          throw FormatError(path + ": leaf " + std::to_string(i) +
                            " references samples beyond the file's " +
                            std::to_string(t.samples_.size()));
        for (std::uint64_t k = nd.first; k < end; ++k) {
          if (sample_seen[k])
            throw FormatError(path + ": sample " + std::to_string(k) + " belongs to two leaves");
          sample_seen[k] = 1;
        }
      } else {
        if (nd.count == 0 || nd.count > 8 || nd.first <= i || end > n)
          throw FormatError(path + ": node " + std::to_string(i) + " has children [" +
                            std::to_string(nd.first) + ", " + std::to_string(end) +
                            "), expected 1..8 children after it and below " + std::to_string(n));
        for (std::uint64_t k = nd.first; k < end; ++k) {
          if (reached[k])
            throw FormatError(path + ": node " + std::to_string(k) + " has two parents");
          reached[k] = 1;
        }
      }
    }
    for (std::size_t k = 0; k < sample_seen.size(); ++k)
      if (!sample_seen[k])
        throw FormatError(path + ": sample " + std::to_string(k) + " is in no leaf");
  }
};

}  // namespace detail

template <attributes A>
std::size_t point_octree<A>::file_bytes() const {
  using io = detail::point_octree_io<A>;
  return io::header_bytes + nodes_.size() * io::node_bytes(normal_bits_) +
         samples_.size() * io::sample_bytes(normal_bits_) + 8;
}

template <attributes A>
void point_octree<A>::save(const std::string& path) const {
  detail::save_file_bytes(path, detail::point_octree_io<A>::serialise(*this));
}

template <attributes A>
point_octree<A> point_octree<A>::load(const std::string& path) {
  return detail::point_octree_io<A>::load(path);
}

}  // namespace pbr_lod
