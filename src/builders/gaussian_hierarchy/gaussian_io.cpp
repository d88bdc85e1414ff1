// The Gaussian hierarchy's file ("PBRLODGH" version 1) and its cuts as plain Gaussian clouds.
//
// Layout (little-endian): magic, u32 version, u32 SH degree, u64 input Gaussians, u64 inner
// Gaussians, u64 nodes, f64×3 origin; per stored Gaussian (input ones in leaf order, then the
// inner nodes' in preorder) position f32×3, scale f32×3, rotation f32×4 (w x y z), opacity f32,
// SH f32 × (degree+1)²·3; per node (preorder) u32 gaussian, u32 count, u32 right, f32 size,
// f32×4 bounding sphere; the FNV-1a checksum of everything before it.
#include <cstring>
#include <functional>
#include <limits>

#include "gaussian_cuts.hpp"
#include "pbr_lod/builders/gaussian_hierarchy.hpp"
#include "pbr_lod/core/atomic_file.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/error.hpp"

namespace pbr_lod {
namespace {

constexpr detail::file_format gaussian_format{
    "Gaussian hierarchy", {'P', 'B', 'R', 'L', 'O', 'D', 'G', 'H'}, 1};
constexpr std::size_t node_bytes = 32;

void put_floats(detail::byte_writer& w, const float* p, std::size_t n) {
  const auto* b = reinterpret_cast<const unsigned char*>(p);
  w.bytes.insert(w.bytes.end(), b, b + n * sizeof(float));
}

template <class V>
void get_floats(detail::byte_reader& r, std::vector<V>& out, std::size_t count, int per,
                const char* what) {
  r.need(count, per * sizeof(float), what);
  out.resize(count);
  for (std::size_t i = 0; i < count; ++i)
    for (int k = 0; k < per; ++k) out[i][k] = r.get<float>(what);
}

/// Walks the tree in preorder and checks that it is one: node numbers in preorder, children in
/// range, leaves tiling the input Gaussians in order, inner Gaussians in preorder after them.
void check_tree(const std::vector<gaussian_hierarchy::node>& nodes, std::size_t input,
                const detail::byte_reader& r) {
  if (nodes.empty()) return;
  std::vector<std::uint32_t> stack{0};
  std::size_t expected = 0, next_leaf = 0, next_inner = input;
  while (!stack.empty()) {
    const std::uint32_t n = stack.back();
    stack.pop_back();
    if (n != expected) r.fail("node " + std::to_string(n) + " is not in preorder");
    ++expected;
    const auto& d = nodes[n];
    if (!(std::isfinite(d.size) && d.size >= 0 && all_finite(d.bounds.centre) &&
          std::isfinite(d.bounds.radius) && d.bounds.radius >= 0))
      r.fail("node " + std::to_string(n) + " has a non-finite or negative size or sphere");
    if (d.count != 0) {
      if (d.gaussian != next_leaf || d.count > input - next_leaf)
        r.fail("leaf " + std::to_string(n) + " does not hold the next input Gaussians");
      next_leaf += d.count;
      continue;
    }
    if (d.gaussian != next_inner)
      r.fail("inner node " + std::to_string(n) + " does not hold the next inner Gaussian");
    ++next_inner;
    if (d.right <= n + 1 || d.right >= nodes.size())
      r.fail("inner node " + std::to_string(n) + " has its right child out of range");
    stack.push_back(d.right);
    stack.push_back(n + 1);
  }
  if (expected != nodes.size() || next_leaf != input)
    r.fail("the tree does not reach every node and input Gaussian");
}

}  // namespace

void gaussian_hierarchy::serialize_into(detail::byte_writer& w,
                                        const std::function<void()>& flush) const {
  detail::write_head(w, gaussian_format);
  w.put(static_cast<std::uint32_t>(g_.sh_degree));
  w.put(static_cast<std::uint64_t>(input_));
  w.put(static_cast<std::uint64_t>(g_.size() - input_));
  w.put(static_cast<std::uint64_t>(nodes_.size()));
  for (int a = 0; a < 3; ++a) w.put(g_.origin[a]);
  constexpr std::size_t piece = std::size_t{1} << 20;
  for (std::size_t i = 0; i < g_.size(); ++i) {
    put_floats(w, g_.positions[i].data(), 3);
    put_floats(w, g_.scales[i].data(), 3);
    put_floats(w, g_.rotations[i].data(), 4);
    w.put(g_.opacities[i]);
    put_floats(w, g_.sh.data() + i * g_.sh_stride(), g_.sh_stride());
    if (w.bytes.size() >= piece) flush();
  }
  for (const node& d : nodes_) {
    w.put(d.gaussian);
    w.put(d.count);
    w.put(d.right);
    w.put(d.size);
    w.put_vec(d.bounds.centre);
    w.put(d.bounds.radius);
    if (w.bytes.size() >= piece) flush();
  }
}

std::vector<unsigned char> gaussian_hierarchy::serialize() const {
  detail::byte_writer w;
  w.bytes.reserve(file_bytes());
  serialize_into(w, [] {});
  detail::append_checksum(w);
  return std::move(w.bytes);
}

gaussian_hierarchy gaussian_hierarchy::parse(const std::vector<unsigned char>& bytes,
                                             const std::string& path) {
  detail::byte_reader r{bytes, 0, path};
  detail::read_head(r, gaussian_format);
  if (!detail::checksum_matches(bytes)) r.fail("checksum mismatch (the file is damaged)");
  gaussian_hierarchy h;
  const auto degree = r.get<std::uint32_t>("SH degree");
  if (degree > static_cast<std::uint32_t>(max_sh_degree))
    r.fail("SH degree " + std::to_string(degree) + " is not 0–3");
  h.g_.sh_degree = static_cast<int>(degree);
  const auto input = r.get<std::uint64_t>("input count");
  const auto inner = r.get<std::uint64_t>("inner count");
  const auto node_count = r.get<std::uint64_t>("node count");
  if (input == 0 || input > (std::uint64_t{1} << 31) || inner >= input ||
      node_count != 2 * inner + 1)
    r.fail("counts do not form a binary tree: " + std::to_string(input) + " input, " +
           std::to_string(inner) + " inner Gaussians, " + std::to_string(node_count) + " nodes");
  for (int a = 0; a < 3; ++a) h.g_.origin[a] = r.get<double>("origin");
  const std::size_t total = input + inner, stride = h.g_.sh_stride();
  r.need(total, (11 + stride) * sizeof(float), "Gaussians");
  r.need(total * (11 + stride) * sizeof(float) + node_count * node_bytes, 1, "bytes");
  h.g_.positions.resize(total);
  h.g_.scales.resize(total);
  h.g_.rotations.resize(total);
  h.g_.opacities.resize(total);
  h.g_.sh.resize(total * stride);
  for (std::size_t i = 0; i < total; ++i) {
    for (int k = 0; k < 3; ++k) h.g_.positions[i][k] = r.get<float>("position");
    for (int k = 0; k < 3; ++k) h.g_.scales[i][k] = r.get<float>("scale");
    for (int k = 0; k < 4; ++k) h.g_.rotations[i][k] = r.get<float>("rotation");
    h.g_.opacities[i] = r.get<float>("opacity");
    std::memcpy(h.g_.sh.data() + i * stride, bytes.data() + r.pos, stride * sizeof(float));
    r.pos += stride * sizeof(float);
  }
  try {
    h.g_.validate(path, std::numeric_limits<float>::infinity());
  } catch (const InvalidArgument& e) {
    throw FormatError(e.what());
  }
  h.input_ = input;
  h.nodes_.resize(node_count);
  for (node& d : h.nodes_) {
    d.gaussian = r.get<std::uint32_t>("node Gaussian");
    d.count = r.get<std::uint32_t>("node count");
    d.right = r.get<std::uint32_t>("node right child");
    d.size = r.get<float>("node size");
    for (int k = 0; k < 3; ++k) d.bounds.centre[k] = r.get<float>("node sphere");
    d.bounds.radius = r.get<float>("node sphere");
  }
  if (bytes.size() - r.pos != 8) r.fail("unexpected bytes before the checksum");
  check_tree(h.nodes_, input, r);
  return h;
}

std::size_t gaussian_hierarchy::file_bytes() const {
  return 8 + 4 + 4 + 3 * 8 + 3 * 8 + g_.size() * (11 + g_.sh_stride()) * sizeof(float) +
         nodes_.size() * node_bytes + 8;
}

void gaussian_hierarchy::save(const std::string& path) const {
  // In pieces of about 1 MiB, hashed as they go: a 10⁷-Gaussian scene's 5 GB file is never in
  // memory (serialize() gives the same bytes).
  write_file_atomically(path, [&](const auto& write) {
    detail::byte_writer w;
    std::uint64_t hash = detail::fnv1a(nullptr, 0);
    const auto flush = [&] {
      hash = detail::fnv1a(w.bytes.data(), w.bytes.size(), hash);
      write(w.bytes.data(), w.bytes.size());
      w.bytes.clear();
    };
    serialize_into(w, flush);
    flush();
    unsigned char tail[8];  // as byte_writer::put writes it
    std::memcpy(tail, &hash, 8);
    write(tail, 8);
  });
}

gaussian_hierarchy gaussian_hierarchy::load(const std::string& path) {
  return parse(detail::load_file_bytes(path), path);
}

gaussian_cloud gaussian_hierarchy::cut(const view& v, const traverse_options& o,
                                       const gaussian_policy& p) const {
  return detail::gaussian_cut(*this, v, o, p);
}
gaussian_cloud gaussian_hierarchy::cut(const view& v, const traverse_options& o) const {
  return cut(v, o, gaussian_policy{});
}

gaussian_cloud gaussian_hierarchy::level(std::size_t level) const {
  return detail::gaussian_level(*this, level);
}

std::size_t gaussian_hierarchy::depth() const {
  return detail::gaussian_depth(*this);
}

}  // namespace pbr_lod
