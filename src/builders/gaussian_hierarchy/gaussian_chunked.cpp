// The Gaussian hierarchy built out of core (builders/chunked_gaussian_hierarchy.hpp says how and
// why it equals the in-memory build) and its lazy reader.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>

#include "builders/chunked/chunk_files.hpp"
#include "gaussian_build.hpp"
#include "gaussian_cuts.hpp"
#include "pbr_lod/builders/chunked_gaussian_hierarchy.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod {
namespace {

namespace fs = std::filesystem;
using key = detail::gaussian_split_key;
constexpr std::uint32_t none = 0xffffffffu;

/// Floats of one Gaussian's record (the hierarchy file's and the temporary files'): position,
/// scale, rotation, opacity, SH.
std::size_t record_floats(int degree) {
  return 11 + 3 * static_cast<std::size_t>(sh_coefficients(degree));
}

void put_record(const gaussian_cloud& g, std::size_t i, float* out) {
  std::memcpy(out, g.positions[i].data(), 12);
  std::memcpy(out + 3, g.scales[i].data(), 12);
  std::memcpy(out + 6, g.rotations[i].data(), 16);
  out[10] = g.opacities[i];
  std::memcpy(out + 11, g.sh.data() + i * g.sh_stride(), g.sh_stride() * sizeof(float));
}

void get_record(const float* in, gaussian_cloud& g, std::size_t i) {
  std::memcpy(g.positions[i].data(), in, 12);
  std::memcpy(g.scales[i].data(), in + 3, 12);
  std::memcpy(g.rotations[i].data(), in + 6, 16);
  g.opacities[i] = in[10];
  std::memcpy(g.sh.data() + i * g.sh_stride(), in + 11, g.sh_stride() * sizeof(float));
}

void resize_cloud(gaussian_cloud& g, std::size_t n) {
  g.positions.resize(n);
  g.scales.resize(n);
  g.rotations.resize(n);
  g.opacities.resize(n);
  g.sh.resize(n * g.sh_stride());
}

void copy_gaussian(const gaussian_cloud& from, std::size_t i, gaussian_cloud& to, std::size_t j) {
  to.positions[j] = from.positions[i];
  to.scales[j] = from.scales[i];
  to.rotations[j] = from.rotations[i];
  to.opacities[j] = from.opacities[i];
  std::copy_n(from.sh.begin() + static_cast<std::ptrdiff_t>(i * from.sh_stride()), from.sh_stride(),
              to.sh.begin() + static_cast<std::ptrdiff_t>(j * to.sh_stride()));
}

/// What a chunk's build leaves for the top: its root's Gaussians and node, its counts.
struct chunk_root {
  gaussian_cloud g;  // the root's Gaussians: its merged one, or a leaf's
  float size = 0;
  sphere bounds;
  std::uint64_t nodes = 0, leaves = 0, count = 0;
};

void save_root(const std::string& path, const chunk_root& r) {
  detail::byte_writer w;
  w.put(static_cast<std::uint64_t>(r.g.size()));
  std::vector<float> rec(record_floats(r.g.sh_degree));
  for (std::size_t i = 0; i < r.g.size(); ++i) {
    put_record(r.g, i, rec.data());
    for (const float f : rec) w.put(f);
  }
  w.put(r.size);
  w.put_vec(r.bounds.centre);
  w.put(r.bounds.radius);
  w.put(r.nodes);
  w.put(r.leaves);
  w.put(r.count);
  detail::save_file_bytes(path, w.bytes);
}

chunk_root load_root(const std::string& path, int degree, const vec3d& origin) {
  const std::vector<unsigned char> bytes = detail::load_file_bytes(path);
  detail::byte_reader r{bytes, 0, path};
  chunk_root out;
  out.g.sh_degree = degree;
  out.g.origin = origin;
  const auto n = r.get<std::uint64_t>("root Gaussians");
  const std::size_t per = record_floats(degree);
  r.need(n, per * sizeof(float), "root Gaussians");
  resize_cloud(out.g, n);
  std::vector<float> rec(per);
  for (std::size_t i = 0; i < n; ++i) {
    for (float& f : rec) f = r.get<float>("root Gaussian");
    get_record(rec.data(), out.g, i);
  }
  out.size = r.get<float>("root size");
  out.bounds.centre = r.get_vec("root sphere", 0);
  out.bounds.radius = r.get<float>("root sphere");
  out.nodes = r.get<std::uint64_t>("nodes");
  out.leaves = r.get<std::uint64_t>("leaves");
  out.count = r.get<std::uint64_t>("count");
  return out;
}

}  // namespace

/// The build: chunked_folder_build's ranks and staging folder, the steps of the header.
struct gaussian_chunked_build : detail::chunked_folder_build {
  /// A top node while building: Gaussians [lo, hi) of the keys; its first child, or its chunk.
  struct part {
    std::uint32_t lo, hi;
    std::uint32_t first = 0, chunk = none;
  };

  const gaussian_source& src;
  const chunked_gaussian_hierarchy_options& o;
  chunked_build_report rep;
  std::vector<part> parts;               // breadth-first
  std::vector<std::uint32_t> chunk_top;  // per chunk: its part
  sphere input_sphere;
  unsigned threads = 1;

  gaussian_chunked_build(const gaussian_source& s, const std::string& target,
                         const chunked_gaussian_hierarchy_options& opt)
      : chunked_folder_build(target, opt.block_points, opt.distributed,
                             "chunked Gaussian hierarchy"),
        src(s),
        o(opt) {}

  [[nodiscard]] double since(std::chrono::steady_clock::time_point t) const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
  }

  /// f(first index, block) over the whole source; one full pass.
  template <class F>
  void stream(F&& f) {
    ++passes;
    gaussian_cloud b;
    for (std::uint64_t first = 0; first < src.size(); first += block_points) {
      const auto count =
          static_cast<std::size_t>(std::min<std::uint64_t>(block_points, src.size() - first));
      src.read(first, count, b);
      if (b.size() != count || b.sh_degree != src.sh_degree())
        throw IoError(src.name() + ": a block came back with the wrong size or SH degree");
      b.validate(src.name() + ", Gaussians from " + std::to_string(first));
      f(first, b);
    }
  }

  /// Steps 1–2: the keys, and the top split from them exactly as build_gaussian_hierarchy splits
  /// its top (each level's splits side by side); then each Gaussian's chunk.
  std::vector<std::uint32_t> split_top(std::uint64_t chunk_points) {
    const auto n = static_cast<std::uint32_t>(src.size());
    std::vector<key> keys(n);
    stream([&](std::uint64_t first, const gaussian_cloud& b) {
      for (std::size_t k = 0; k < b.size(); ++k)
        keys[first + k] = {b.positions[k], 3 * b.scales[k].maxCoeff(),
                           static_cast<std::uint32_t>(first + k)};
    });
    // The input's sphere as bounding_sphere_about_box_centre gives it (the tool frames views by
    // it).
    box3 box;
    for (const key& k : keys) box.extend(k.p);
    const vec3f centre = box.centre();
    double r2 = 0;
    for (const key& k : keys) r2 = std::max(r2, (k.p - centre).cast<double>().squaredNorm());
    input_sphere = {centre, static_cast<float>(std::sqrt(r2))};
    parts.push_back({0, n});
    for (std::size_t begin = 0; begin < parts.size();) {
      const std::size_t end = parts.size();
      std::vector<std::size_t> split;
      for (std::size_t i = begin; i < end; ++i)
        if (parts[i].hi - parts[i].lo > chunk_points) split.push_back(i);
      detail::parallel_tasks(split.size(), threads, [&](std::size_t k, unsigned) {
        const part& p = parts[split[k]];
        detail::split_at_median(std::span<key>(keys).subspan(p.lo, p.hi - p.lo));
      });
      for (std::size_t i = begin; i < end; ++i) {
        const part p = parts[i];
        if (p.hi - p.lo > chunk_points) {
          const std::uint32_t mid = p.lo + (p.hi - p.lo) / 2;
          parts[i].first = static_cast<std::uint32_t>(parts.size());
          parts.push_back({p.lo, mid});
          parts.push_back({mid, p.hi});
        } else {
          parts[i].chunk = static_cast<std::uint32_t>(chunk_top.size());
          chunk_top.push_back(static_cast<std::uint32_t>(i));
        }
      }
      begin = end;
    }
    std::vector<std::uint32_t> owner(n);
    for (const std::uint32_t t : chunk_top)
      for (std::uint32_t i = parts[t].lo; i < parts[t].hi; ++i) owner[keys[i].g] = parts[t].chunk;
    return owner;
  }

  /// Step 3 (rank 0): every Gaussian's record appended to its chunk's temporary file.
  void distribute(const std::vector<std::uint32_t>& owner) {
    const std::size_t chunks = chunk_top.size();
    std::vector<detail::append_file> out;
    out.reserve(chunks);
    for (std::size_t c = 0; c < chunks; ++c)
      out.emplace_back(temp_path("chunk", c), buffer_bytes(chunks));
    std::vector<float> rec(record_floats(src.sh_degree()));
    stream([&](std::uint64_t first, const gaussian_cloud& b) {
      for (std::size_t k = 0; k < b.size(); ++k) {
        put_record(b, k, rec.data());
        out[owner[first + k]].put_bytes(rec.data(), rec.size() * sizeof(float));
      }
    });
    for (auto& f : out) f.flush();
  }

  /// Step 4: chunk c built in memory from its file, saved; its root kept for the top.
  void build_chunk(std::uint32_t c) {
    const std::string path = temp_path("chunk", c);
    const part& p = parts[chunk_top[c]];
    const std::size_t per = record_floats(src.sh_degree());
    gaussian_cloud g;
    g.origin = src.origin();
    g.sh_degree = src.sh_degree();
    resize_cloud(g, p.hi - p.lo);
    // Read in pieces straight into the cloud (the chunk's file is as large as the cloud).
    std::ifstream f(path, std::ios::binary);
    std::vector<float> rec(per * 4096);
    for (std::size_t i = 0; i < g.size();) {
      const std::size_t n = std::min<std::size_t>(4096, g.size() - i);
      if (!f.read(reinterpret_cast<char*>(rec.data()),
                  static_cast<std::streamsize>(n * per * sizeof(float))))
        throw IoError(path + ": cut short");
      for (std::size_t k = 0; k < n; ++k, ++i) get_record(rec.data() + k * per, g, i);
    }
    if (f.peek() != std::char_traits<char>::eof()) throw IoError(path + ": longer than its chunk");
    gaussian_hierarchy_options bo = o.builder;
    bo.threads = threads;
    const gaussian_hierarchy h = build_gaussian_hierarchy(g, bo);
    g = gaussian_cloud{};
    h.save((dir / chunk_file(c, chunked_gaussian_hierarchy::chunk_extension)).string());
    chunk_root r;
    const detail::gaussian_range root = h.gaussians(0);
    r.g.origin = h.origin();
    r.g.sh_degree = h.sh_degree();
    resize_cloud(r.g, root.count);
    for (std::uint32_t i = 0; i < root.count; ++i) copy_gaussian(h.store(), root.first + i, r.g, i);
    r.size = h.nodes()[0].size;
    r.bounds = h.nodes()[0].bounds;
    r.nodes = h.nodes().size();
    r.leaves = (r.nodes + 1) / 2;
    r.count = h.input_gaussians();
    save_root(temp_path("root", c), r);
  }

  /// Step 5 (rank 0): the top nodes from the chunks' roots, merged bottom up, and the top file.
  void write_top() {
    chunked_gaussian_hierarchy t;
    t.top_g_.origin = src.origin();
    t.top_g_.sh_degree = src.sh_degree();
    t.input_ = src.size();
    t.input_sphere_ = input_sphere;
    std::vector<chunk_root> roots;
    std::uint32_t total = 0;
    for (std::size_t c = 0; c < chunk_top.size(); ++c) {
      roots.push_back(load_root(temp_path("root", c), src.sh_degree(), src.origin()));
      t.chunk_samples_.push_back(roots.back().count);
      t.chunk_nodes_.push_back(roots.back().nodes);
      t.leaves_ += roots.back().leaves;
    }
    t.top_nodes_.resize(parts.size());
    for (std::size_t i = 0; i < parts.size(); ++i) {
      const std::uint32_t c = parts[i].chunk;
      const std::uint32_t count =
          c == none || roots[c].leaves > 1 ? 0 : static_cast<std::uint32_t>(roots[c].g.size());
      t.top_nodes_[i].gaussian = total;
      t.top_nodes_[i].count = count;
      t.top_nodes_[i].first = c == none ? parts[i].first : 0;
      total += count == 0 ? 1 : count;
      t.frontier_.push_back(c == none ? chunked_gaussian_hierarchy::top : c);
    }
    t.chunk_top_ = chunk_top;
    resize_cloud(t.top_g_, total);
    for (std::size_t i = parts.size(); i-- > 0;) {
      auto& n = t.top_nodes_[i];
      if (const std::uint32_t c = parts[i].chunk; c != none) {
        for (std::size_t k = 0; k < roots[c].g.size(); ++k)
          copy_gaussian(roots[c].g, k, t.top_g_, n.gaussian + k);
        n.size = roots[c].size;
        n.bounds = roots[c].bounds;
        continue;
      }
      // The merge of build_gaussian_hierarchy: the children's representatives, left then right.
      const auto &l = t.top_nodes_[n.first], &r = t.top_nodes_[n.first + 1];
      std::vector<std::uint32_t> reps;
      for (const auto* k : {&l, &r})
        for (std::uint32_t j = 0; j < (k->count == 0 ? 1 : k->count); ++j)
          reps.push_back(k->gaussian + j);
      detail::merge_gaussians(t.top_g_, reps, n.gaussian, o.builder.opacity);
      n.size = std::max({t.top_g_.scales[n.gaussian].maxCoeff(), l.size, r.size});
      n.bounds = detail::enclose(detail::enclose(l.bounds, r.bounds),
                                 detail::gaussian_reach(t.top_g_, n.gaussian));
    }
    detail::save_file_bytes(chunked_top_path(dir.string()), t.serialize_top());
    rep.top_nodes = parts.size();
  }

  chunked_build_report run() {
    const auto t0 = std::chrono::steady_clock::now();
    const auto& b = o.builder;
    if (b.leaf_size < 1 || b.leaf_size > 64)
      throw InvalidArgument(std::string(who) + ": leaf_size must be 1–64, got " +
                            std::to_string(b.leaf_size));
    if (src.size() > (std::uint64_t{1} << 31))
      throw InvalidArgument(std::string(who) + ": more than 2^31 Gaussians (" +
                            std::to_string(src.size()) + ")");
    start(src.name(), src.size(), src.origin(), "Gaussians");
    threads = resolve_threads(b.threads);
    // Every chunk split from a larger node is then an inner node (more than leaf_size).
    const chunk_cost cost{gaussian_chunk_bytes(src.sh_degree()), 1,
                          2 * static_cast<std::uint64_t>(b.leaf_size) + 1};
    const std::uint64_t chunk_points = chunk_points_for(o.memory_bytes, o.chunk_points, cost);
    {
      const std::vector<std::uint32_t> owner = split_top(chunk_points);
      if (rank == 0) distribute(owner);
    }
    barrier();
    rep.pass_seconds = since(t0);
    const auto t1 = std::chrono::steady_clock::now();
    for (std::uint32_t c = 0; c < chunk_top.size(); ++c)
      if (mine(c)) build_chunk(c);
    barrier();
    rep.chunk_build_seconds = since(t1);
    const auto t2 = std::chrono::steady_clock::now();
    if (rank == 0) write_top();
    finish();
    rep.pass_seconds += since(t2);
    rep.input_points = src.size();
    rep.chunks = chunk_top.size();
    rep.top_nodes = parts.size();
    rep.chunk_points = chunk_points;
    for (const std::uint32_t t : chunk_top)
      rep.largest_chunk = std::max<std::uint64_t>(rep.largest_chunk, parts[t].hi - parts[t].lo);
    rep.passes = passes;
    rep.seconds = since(t0);
    return rep;
  }
};

chunked_build_report build_gaussian_hierarchy_chunked(
    const gaussian_source& src, const std::string& dir,
    const chunked_gaussian_hierarchy_options& options) {
  return detail::build_or_keep(dir, "chunked Gaussian hierarchy", [&] {
    gaussian_chunked_build b(src, dir, options);
    return b.run();
  });
}

bool is_chunked_gaussian_hierarchy(const std::string& dir) {
  return is_chunked_folder(dir, detail::chunked_gaussian_top_format);
}

// --- the reader ----------------------------------------------------------------------------------

std::vector<unsigned char> chunked_gaussian_hierarchy::serialize_top() const {
  detail::byte_writer w;
  detail::write_head(w, detail::chunked_gaussian_top_format);
  w.put(static_cast<std::uint32_t>(top_g_.sh_degree));
  for (int a = 0; a < 3; ++a) w.put(top_g_.origin[a]);
  w.put(input_);
  w.put(leaves_);
  w.put_vec(input_sphere_.centre);
  w.put(input_sphere_.radius);
  w.put(static_cast<std::uint64_t>(top_nodes_.size()));
  w.put(static_cast<std::uint64_t>(chunk_top_.size()));
  w.put(static_cast<std::uint64_t>(top_g_.size()));
  std::vector<float> rec(record_floats(top_g_.sh_degree));
  for (std::size_t i = 0; i < top_g_.size(); ++i) {
    put_record(top_g_, i, rec.data());
    for (const float f : rec) w.put(f);
  }
  for (const top_node& n : top_nodes_) {
    w.put(n.gaussian);
    w.put(n.count);
    w.put(n.first);
    w.put(n.size);
    w.put_vec(n.bounds.centre);
    w.put(n.bounds.radius);
  }
  for (const std::uint32_t f : frontier_) w.put(f);
  for (std::size_t c = 0; c < chunk_top_.size(); ++c) {
    w.put(chunk_top_[c]);
    w.put(chunk_samples_[c]);
    w.put(chunk_nodes_[c]);
  }
  detail::append_checksum(w);
  return std::move(w.bytes);
}

chunked_gaussian_hierarchy chunked_gaussian_hierarchy::open(const std::string& dir) {
  check_chunked_folder(dir);
  const std::string path = chunked_top_path(dir);
  const std::vector<unsigned char> bytes = detail::load_file_bytes(path);
  detail::byte_reader r{bytes, 0, path};
  detail::read_head(r, detail::chunked_gaussian_top_format);
  if (!detail::checksum_matches(bytes)) r.fail("checksum mismatch (the file is damaged)");
  chunked_gaussian_hierarchy h;
  h.dir_ = dir;
  const auto degree = r.get<std::uint32_t>("SH degree");
  if (degree > static_cast<std::uint32_t>(max_sh_degree))
    r.fail("SH degree " + std::to_string(degree) + " is not 0–3");
  h.top_g_.sh_degree = static_cast<int>(degree);
  for (int a = 0; a < 3; ++a) h.top_g_.origin[a] = r.get<double>("origin");
  if (!all_finite(h.top_g_.origin)) r.fail("the origin is not finite");
  h.input_ = r.get<std::uint64_t>("input Gaussians");
  h.leaves_ = r.get<std::uint64_t>("leaves");
  h.input_sphere_.centre = r.get_vec("input sphere", 0);
  h.input_sphere_.radius = r.get<float>("input sphere");
  if (!all_finite(h.input_sphere_.centre) || !(h.input_sphere_.radius >= 0) ||
      !std::isfinite(h.input_sphere_.radius))
    r.fail("the input sphere is not finite");
  const auto nodes = r.get<std::uint64_t>("top nodes");
  const auto chunks = r.get<std::uint64_t>("chunks");
  const auto stored = r.get<std::uint64_t>("top Gaussians");
  if (h.input_ == 0 || h.input_ > (std::uint64_t{1} << 31) || h.leaves_ == 0 ||
      h.leaves_ > h.input_ || nodes == 0 || chunks == 0 || chunks > nodes || stored < nodes ||
      stored > nodes + 64)
    r.fail("counts do not fit: " + std::to_string(h.input_) + " input Gaussians, " +
           std::to_string(h.leaves_) + " leaves, " + std::to_string(nodes) + " top nodes, " +
           std::to_string(chunks) + " chunks, " + std::to_string(stored) + " top Gaussians");
  const std::size_t per = record_floats(h.top_g_.sh_degree);
  r.need(stored, per * sizeof(float), "top Gaussians");
  r.need(nodes, 32 + 4, "top nodes");
  r.need(chunks, 20, "chunks");
  resize_cloud(h.top_g_, stored);
  std::vector<float> rec(per);
  for (std::size_t i = 0; i < stored; ++i) {
    for (float& f : rec) f = r.get<float>("top Gaussian");
    get_record(rec.data(), h.top_g_, i);
  }
  try {
    h.top_g_.validate(path, std::numeric_limits<float>::infinity());
  } catch (const InvalidArgument& e) {
    throw FormatError(e.what());
  }
  h.top_nodes_.resize(nodes);
  for (top_node& n : h.top_nodes_) {
    n.gaussian = r.get<std::uint32_t>("top node Gaussian");
    n.count = r.get<std::uint32_t>("top node count");
    n.first = r.get<std::uint32_t>("top node children");
    n.size = r.get<float>("top node size");
    n.bounds.centre = r.get_vec("top node sphere", 0);
    n.bounds.radius = r.get<float>("top node sphere");
  }
  h.frontier_.resize(nodes);
  for (std::uint32_t& f : h.frontier_) f = r.get<std::uint32_t>("top node chunk");
  h.chunk_top_.resize(chunks);
  h.chunk_samples_.resize(chunks);
  h.chunk_nodes_.resize(chunks);
  for (std::size_t c = 0; c < chunks; ++c) {
    h.chunk_top_[c] = r.get<std::uint32_t>("chunk top node");
    h.chunk_samples_[c] = r.get<std::uint64_t>("chunk Gaussians");
    h.chunk_nodes_[c] = r.get<std::uint64_t>("chunk nodes");
  }
  if (bytes.size() - r.pos != 8) r.fail("unexpected bytes before the checksum");
  h.validate(path);
  h.make_slots();
  return h;
}

void chunked_gaussian_hierarchy::validate(const std::string& path) const {
  const auto fail = [&](const std::string& m) { throw FormatError(path + ": " + m); };
  // Inner top nodes have two children after them (validate_chunked_top checks the tree).
  struct shape {
    bool leaf;
    std::uint32_t first, count;
  };
  std::vector<shape> shapes;
  std::uint64_t next = 0;
  for (std::size_t i = 0; i < top_nodes_.size(); ++i) {
    const top_node& n = top_nodes_[i];
    const bool chunk_root = frontier_[i] != top;
    if (n.gaussian != next || n.count > 64 || (n.count != 0 && !chunk_root))
      fail("top node " + std::to_string(i) + " has the wrong Gaussians");
    next += n.count == 0 ? 1 : n.count;
    if (!(std::isfinite(n.size) && n.size >= 0 && all_finite(n.bounds.centre) &&
          std::isfinite(n.bounds.radius) && n.bounds.radius >= 0))
      fail("top node " + std::to_string(i) + " has a non-finite or negative size or sphere");
    shapes.push_back({false, n.first, chunk_root ? 0u : 2u});
  }
  if (next != top_g_.size()) fail("the top nodes do not hold the top Gaussians");
  detail::validate_chunked_top(path, shapes, frontier_, chunk_top_, chunk_samples_, chunk_nodes_,
                               input_);
  std::uint64_t leaves = 0;
  for (std::size_t c = 0; c < chunk_top_.size(); ++c) {
    if (chunk_nodes_[c] % 2 == 0 || chunk_nodes_[c] > 2 * chunk_samples_[c] ||
        (chunk_nodes_[c] == 1) != (top_nodes_[chunk_top_[c]].count != 0))
      fail("chunk " + std::to_string(c) +
           " has a node count that no binary tree over its Gaussians has");
    leaves += (chunk_nodes_[c] + 1) / 2;
  }
  if (leaves != leaves_) fail("the chunks' leaves do not add up");
}

const gaussian_hierarchy& chunked_gaussian_hierarchy::chunk(std::uint32_t c) const {
  return load_chunk(c, [&](const std::string& path) {
    gaussian_hierarchy h = gaussian_hierarchy::load(path);
    const top_node& t = top_nodes_[chunk_top_[c]];
    const detail::gaussian_range root = h.gaussians(0);
    const auto differs = [&] {
      if (h.input_gaussians() != chunk_samples_[c] || h.nodes().size() != chunk_nodes_[c] ||
          h.sh_degree() != sh_degree() || h.origin() != origin() ||
          root.count != (t.count == 0 ? 1 : t.count) || h.nodes()[0].size != t.size)
        return true;
      std::vector<float> a(record_floats(sh_degree())), b(a.size());
      for (std::uint32_t k = 0; k < root.count; ++k) {
        put_record(h.store(), root.first + k, a.data());
        put_record(top_g_, t.gaussian + k, b.data());
        if (std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) != 0) return true;
      }
      return false;
    };
    if (differs())
      throw FormatError(path + ": does not match the top file (chunk " + std::to_string(c) +
                        " of " + chunked_top_path(dir_) + ")");
    return h;
  });
}

gaussian_cloud chunked_gaussian_hierarchy::cut(const view& v, const traverse_options& o,
                                               const gaussian_policy& p) const {
  return detail::gaussian_cut(*this, v, o, p);
}
gaussian_cloud chunked_gaussian_hierarchy::cut(const view& v, const traverse_options& o) const {
  return cut(v, o, gaussian_policy{});
}

gaussian_cloud chunked_gaussian_hierarchy::level(std::size_t level) const {
  return detail::gaussian_level(*this, level);
}

std::size_t chunked_gaussian_hierarchy::depth() const {
  return detail::gaussian_depth(*this);
}

gaussian_hierarchy chunked_gaussian_hierarchy::assemble() const {
  gaussian_hierarchy h;
  h.g_.origin = origin();
  h.g_.sh_degree = sh_degree();
  h.input_ = input_;
  resize_cloud(h.g_, input_ + leaves_ - 1);
  h.nodes_.resize(2 * leaves_ - 1);
  // Preorder, left before right: leaves take the next input slots, inner nodes the next inner
  // ones, as build_gaussian_hierarchy numbers them.
  struct visit {
    node_id n;
    std::uint32_t parent;  // the global node whose right child this is, or none
  };
  std::vector<visit> stack{{root(), none}};
  std::uint32_t next_node = 0, next_leaf = 0;
  auto next_inner = static_cast<std::uint32_t>(input_);
  while (!stack.empty()) {
    const visit at = stack.back();
    stack.pop_back();
    const std::uint32_t me = next_node++;
    if (at.parent != none) h.nodes_[at.parent].right = me;
    gaussian_hierarchy::node& d = h.nodes_[me];
    const detail::gaussian_range r = gaussians(at.n);
    d.size = size_sphere(at.n).radius;
    d.bounds = bounding_sphere(at.n);
    if (is_leaf(at.n)) {
      d.gaussian = next_leaf;
      d.count = r.count;
      for (std::uint32_t k = 0; k < r.count; ++k)
        copy_gaussian(*r.cloud, r.first + k, h.g_, next_leaf++);
      continue;
    }
    d.gaussian = next_inner;
    d.count = 0;
    copy_gaussian(*r.cloud, r.first, h.g_, next_inner++);
    const child_range kids = children(at.n);
    stack.push_back({kids.ids[1], me});
    stack.push_back({kids.ids[0], none});
  }
  return h;
}

}  // namespace pbr_lod
