// The chunked (out-of-core) point-octree build: see
// include/pbr_lod/builders/chunked_point_octree.hpp for the steps and why the result equals
// build_point_octree's.
#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>

#include "builders/chunked/chunk_files.hpp"
#include "pbr_lod/builders/chunked_point_octree.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/core/normal_repair.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod {
namespace detail {
namespace {

namespace fs = std::filesystem;

int octant_of(const vec3d& p, const vec3d& m) {
  return (p.x() >= m.x() ? 1 : 0) | (p.y() >= m.y() ? 2 : 0) | (p.z() >= m.z() ? 4 : 0);
}

}  // namespace

/// Per-octant sums of one node, streamed: the in-memory octant pass (point_octree_builder::
/// octant_pass) sums each block of 2^16 of the node's samples from zero and adds the blocks'
/// sums in order; a sample's block is its rank among the node's samples in input order, which
/// the stable scatter of the in-memory build preserves. 64-bit counts: a top node may hold more
/// samples than an in-memory build may.
struct stream_sums {
  std::array<std::uint64_t, 8> cnt{};
  std::array<vec3d, 8> psum, nsum, csum;
  stream_sums() {
    psum.fill(vec3d::Zero());
    nsum.fill(vec3d::Zero());
    csum.fill(vec3d::Zero());
  }
  void add(const stream_sums& o) {
    for (std::size_t u = 0; u < 8; ++u) {
      cnt[u] += o.cnt[u];
      psum[u] += o.psum[u];
      nsum[u] += o.nsum[u];
      csum[u] += o.csum[u];
    }
  }
};

struct stream_acc {
  std::uint64_t seen = 0;
  stream_sums total, part;
  void add(int o, const vec3d& p, const vec3f* n, const rgb8* c, std::uint64_t block) {
    const auto u = static_cast<std::size_t>(o);
    ++part.cnt[u];
    part.psum[u] += p;
    if (n) part.nsum[u] += n->cast<double>();
    if (c) part.csum[u] += vec3d(c->r, c->g, c->b);
    if (++seen % block == 0) {
      total.add(part);
      part = {};
    }
  }
  void finish(std::uint64_t block) {
    if (seen % block != 0) total.add(part);
    part = {};
  }
};

template <attributes In>
struct chunked_point_octree_builder : chunked_pass_base {
  static constexpr attributes A = point_octree_attributes(In);
  using tree = point_octree<A>;
  using node = typename tree::node;
  using B = point_octree_builder<A>;
  using code_t = typename tree::orientation_code;
  using summary = typename B::summary;
  static constexpr std::uint32_t none = 0xffffffffu;
  static constexpr std::uint64_t block = B::block;

  /// A node above the chunks: its split point (the mean, §3) and what the passes sum for it.
  struct mean_cell {
    vec3d mean = vec3d::Zero(), normal_sum = vec3d::Zero(), colour_sum = vec3d::Zero();
    std::uint32_t depth = 0;
    double r2 = 0;
    float min_dot = 1;
    stream_acc acc;
  };
  using top_node = typename top_tree<mean_cell>::node;
  struct chunk_info {
    std::uint32_t top;
    std::uint64_t count = 0;
    vec3f lo = vec3f::Constant(std::numeric_limits<float>::infinity());
    vec3f hi = vec3f::Constant(-std::numeric_limits<float>::infinity());
  };

  const chunked_point_octree_options& opt;
  point_octree_options oo;  // the octree options without the progress callback
  unsigned threads;
  std::uint64_t n;
  std::uint64_t chunk_points;
  std::shared_ptr<const normal_quantizer> quant;
  top_tree<mean_cell> upper;  // the tree above the chunks
  std::vector<top_node>& nodes = upper.nodes;
  std::vector<chunk_info> chunks;
  chunked_build_report rep;
  box3 box;              // of the input's positions (the root pass)
  double sphere_r2 = 0;  // about box.centre() (the distribution pass)
  std::vector<std::uint64_t> chunk_nodes;
  std::uint64_t missing = 0;  // input normals zero or not finite (the structure pass counts)

  chunked_point_octree_builder(const point_source& s, const std::string& d,
                               const chunked_point_octree_options& o)
      : chunked_pass_base(s, d, o.block_points, o.distributed, "build_point_octree_chunked"),
        opt(o),
        oo(o.builder),
        n(s.size()) {
    oo.progress = {};
    threads = resolve_threads(oo.threads);
    chunk_points = chunk_points_for(opt.memory_bytes, opt.chunk_points,
                                    {chunk_bytes_per_point, 1, oo.leaf_size});
    if (oo.normal_bits > 0) quant = normal_quantizer::shared(oo.normal_bits);
  }

  void progress(double f) const {
    if (opt.builder.progress && !opt.builder.progress(f))
      throw Cancelled("build_point_octree_chunked: cancelled");
  }

  [[nodiscard]] std::uint32_t descend(const vec3d& p) const {
    return upper.descend(p, [](const top_node& x, const vec3d& q) { return octant(x, q); });
  }

  // ---- Pajarola's split (§3), as top_tree's rule: a node splits at the mean of its samples
  // while it holds more than a chunk, the octants' sums summed block by block exactly as the
  // in-memory octant pass sums them (same order, same doubles).
  static vec3d local(const vec3f& p) { return p.cast<double>(); }
  [[nodiscard]] bool split(const top_node& x) const {
    return x.count > chunk_points && x.depth < oo.max_depth;
  }
  static int octant(const top_node& x, const vec3d& p) { return octant_of(p, x.mean); }
  static void add(top_node& x, int o, const vec3d& p) {
    x.r2 = std::max(x.r2, (p - x.mean).squaredNorm());
    x.acc.add(o, p, nullptr, nullptr, block);
  }
  /// Samples all at one position (one octant about their mean): the chunk's build makes it a
  /// leaf, as build() does.
  static bool keep_whole(top_node& x) {
    x.acc.finish(block);
    int nonempty = 0;
    for (auto c : x.acc.total.cnt) nonempty += c > 0;
    return nonempty < 2;
  }
  static mean_cell child(const top_node& x, int o) {
    const auto u = static_cast<std::size_t>(o);
    mean_cell c;
    c.mean = x.acc.total.psum[u] / static_cast<double>(x.acc.total.cnt[u]);
    c.depth = x.depth + 1;
    return c;
  }

  /// Step 1: the root's mean, then one pass per level splitting every node above chunk size.
  void structure() {
    stream_acc root;
    stream([&](std::uint64_t first, const point_block& b) {
      for (std::size_t k = 0; k < b.size(); ++k) {
        if (!all_finite(b.positions[k]))
          throw InvalidArgument("build_point_octree_chunked: " + src.name() + ": position " +
                                std::to_string(first + k) + " is not finite");
        if constexpr (In.normal) missing += missing_normal(b.normals[k]) ? 1 : 0;
        root.add(0, b.positions[k].cast<double>(), nullptr, nullptr, block);
        box.extend(b.positions[k]);
      }
    });
    root.finish(block);
    mean_cell top;
    top.mean = root.total.psum[0] / static_cast<double>(n);
    upper.grow(*this, top, n, *this);
  }

  /// Step 2: every point into its chunk's file (rank 0; the others learn the chunks' sizes from
  /// the files once it is done).
  void distribute() {
    for (const std::uint32_t i : upper.chunk_top) chunks.push_back({.top = i});
    const std::vector<chunk_extent> ext = chunked_pass_base::distribute(
        chunks.size(), chunks.size(),
        [&](const point_block& b, std::size_t k) {
          sphere_r2 =
              std::max(sphere_r2, (b.positions[k] - box.centre()).cast<double>().squaredNorm());
          return nodes[descend(b.positions[k].cast<double>())].chunk;
        },
        [](const point_record&, std::uint32_t) {}, [] {});
    for (std::size_t c = 0; c < chunks.size(); ++c) {
      chunks[c].lo = ext[c].lo;
      chunks[c].hi = ext[c].hi;
      chunks[c].count = ext[c].count;
      rep.largest_chunk = std::max(rep.largest_chunk, chunks[c].count);
    }
  }

  /// Neighbours the estimation reads: the ellipses', and the normals' where any is missing
  /// (none given, or some zero or not finite: fill_missing_normals).
  [[nodiscard]] int knn_needed() const {
    return In.normal && missing == 0 ? oo.knn_ellipses : std::max(oo.knn, oo.knn_ellipses);
  }

  /// The chunks in octree order (depth first, octants in order): neighbours follow each other.
  [[nodiscard]] std::vector<std::uint32_t> chunks_in_order() const {
    return upper.chunks_in_order();
  }

  /// Step 3: the halos (chunked_pass_base::halos); when input normals are missing, those
  /// estimated chunk after chunk (fill_normals_in_turn), so that one orientation spreads over
  /// the chunks (step 4 then finds none missing among a chunk's own points).
  void halos() {
    std::vector<chunk_extent> ext(chunks.size());
    for (std::size_t c = 0; c < chunks.size(); ++c)
      ext[c] = {chunks[c].lo, chunks[c].hi, chunks[c].count};
    const auto chunk_of = [&](const vec3f& p) { return nodes[descend(p.cast<double>())].chunk; };
    rep.halo_points = chunked_pass_base::halos(ext, knn_needed(), threads, chunk_of);
    if (In.normal && missing > 0) {
      if (rank == 0)
        fill_normals_in_turn(chunks_in_order(), chunks.size(), oo.knn, threads, chunk_of);
      barrier();
    }
  }

  /// Step 4: per chunk (by its rank), the estimation over the chunk and its halo, the
  /// quantisation, and the prepared samples saved for step 6.
  void estimate() {
    for (std::size_t c = 0; c < chunks.size(); ++c) {
      if (!mine(c)) continue;
      const auto recs = read_records(temp_path("chunk", c));
      std::vector<point_record> halo;
      if (chunks.size() > 1) halo = read_records(temp_path("halo", c));
      point_set<In> set;
      set.origin = src.origin();
      set.resize(recs.size() + halo.size());
      std::size_t i = 0;
      for (const std::vector<point_record>* part :
           {&recs, static_cast<const std::vector<point_record>*>(&halo)})
        for (const point_record& r : *part) {
          set.positions[i] = r.position;
          if constexpr (In.normal) set.normals[i] = r.normal;
          if constexpr (In.colour) set.colours[i] = r.colour;
          ++i;
        }
      point_octree_build_stats st;
      point_set<A> work = prepare_samples<A>(set, oo, threads, st, recs.size());
      std::vector<code_t> codes;
      if (quant) quantize_samples(work, *quant, codes, threads);
      save_prepared(temp_path("prep", c), work, codes);
      progress(0.2 + 0.3 * static_cast<double>(c + 1) / static_cast<double>(chunks.size()));
    }
  }

  /// The quantised normals of every chunk into `normals`, in input order (rank 0).
  void gather_normals(index_file& normals) const {
    for (std::size_t c = 0; c < chunks.size(); ++c) {
      const auto recs = read_records(temp_path("chunk", c));
      // The prepared file starts with the positions, then the normals (save_prepared).
      std::ifstream f(temp_path("prep", c), std::ios::binary);
      f.seekg(static_cast<std::streamoff>(recs.size() * sizeof(vec3f)));
      std::vector<vec3f> nrm;
      get_vector(f, nrm, recs.size());
      if (!f) throw IoError(temp_path("prep", c) + ": read failed");
      normals.scatter(recs, nrm);
    }
  }

  template <class T>
  static void put_vector(std::ofstream& f, const std::vector<T>& v) {
    f.write(reinterpret_cast<const char*>(v.data()),
            static_cast<std::streamsize>(v.size() * sizeof(T)));
  }
  template <class T>
  static void get_vector(std::ifstream& f, std::vector<T>& v, std::size_t n) {
    v.resize(n);
    f.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(n * sizeof(T)));
  }
  void save_prepared(const std::string& path, const point_set<A>& w,
                     const std::vector<code_t>& codes) const {
    std::ofstream f(path, std::ios::binary | std::ios::trunc);
    put_vector(f, w.positions);
    put_vector(f, w.normals);
    put_vector(f, w.axis_u);
    put_vector(f, w.axis_v);
    if constexpr (A.colour) put_vector(f, w.colours);
    put_vector(f, codes);
    if (!f) throw IoError(path + ": write failed");
  }
  void load_prepared(const std::string& path, std::size_t m, point_set<A>& w,
                     std::vector<code_t>& codes) const {
    std::ifstream f(path, std::ios::binary);
    w.origin = src.origin();
    get_vector(f, w.positions, m);
    get_vector(f, w.normals, m);
    get_vector(f, w.axis_u, m);
    get_vector(f, w.axis_v, m);
    if constexpr (A.colour) get_vector(f, w.colours, m);
    get_vector(f, codes, quant ? m : 0);
    if (!f) throw IoError(path + ": read failed");
  }

  /// Step 5: the top nodes' normal and colour sums (the root's over the whole input, every split
  /// node's per octant, in the in-memory block order), then their normal cones.
  void attribute_passes(const index_file& normals) {
    stream_acc root;
    for (auto& x : nodes) x.acc = {};
    std::vector<vec3f> nb;
    stream([&](std::uint64_t first, const point_block& b) {
      normals.read(first, b.size(), nb);
      for (std::size_t k = 0; k < b.size(); ++k) {
        const vec3d p = b.positions[k].cast<double>();
        const rgb8* c = In.colour ? &b.colours[k] : nullptr;
        root.add(0, p, &nb[k], c, block);
        for (std::uint32_t x = 0; nodes[x].st == top_node::state::split;) {
          const int o = octant_of(p, nodes[x].mean);
          nodes[x].acc.add(o, p, &nb[k], c, block);
          x = nodes[x].child[static_cast<std::size_t>(o)];
        }
      }
    });
    root.finish(block);
    nodes[0].normal_sum = root.total.nsum[0];
    nodes[0].colour_sum = root.total.csum[0];
    bool any_split = false;
    for (auto& x : nodes) {
      if (x.st != top_node::state::split) continue;
      any_split = true;
      x.acc.finish(block);
      for (std::size_t o = 0; o < 8; ++o) {
        if (x.child[o] == none) continue;
        top_node& c = nodes[x.child[o]];
        c.normal_sum = x.acc.total.nsum[o];
        c.colour_sum = x.acc.total.csum[o];
        if (x.acc.total.cnt[o] != c.count ||
            x.acc.total.psum[o] / static_cast<double>(c.count) != c.mean)
          throw IoError(src.name() + ": the source gave different points on a second pass");
      }
    }
    if (!any_split) return;
    stream([&](std::uint64_t first, const point_block& b) {
      normals.read(first, b.size(), nb);
      for (std::size_t k = 0; k < b.size(); ++k) {
        const vec3d p = b.positions[k].cast<double>();
        for (std::uint32_t x = 0; nodes[x].st == top_node::state::split;) {
          top_node& t = nodes[x];
          t.min_dot = std::min(t.min_dot, mean_normal(t).dot(nb[k]));
          x = t.child[static_cast<std::size_t>(octant_of(p, t.mean))];
        }
      }
    });
  }

  /// n̄_c as build() derives it from the node's input (and whether the normals cancel).
  static bool normal_valid(const top_node& x) {
    return x.normal_sum.norm() > 1e-6 * static_cast<double>(x.count);
  }
  static vec3f mean_normal(const top_node& x) {
    const double nlen = x.normal_sum.norm();
    return normal_valid(x) ? vec3f((x.normal_sum / nlen).template cast<float>()) : vec3f::UnitZ();
  }

  /// What step 6 keeps of a chunk for the top: its root's record and summary.
  struct chunk_root {
    node record;
    rgb8 colour{};
    code_t code{};
    summary sum;
  };

  /// Step 6: chunk c's subtree from its input, as build() makes that node's subtree; saved.
  chunk_root build_chunk(std::size_t c) {
    const top_node& x = nodes[chunks[c].top];
    const auto m = static_cast<std::uint32_t>(chunks[c].count);
    tree t;
    std::vector<code_t> codes;
    load_prepared(temp_path("prep", c), m, t.samples_, codes);
    B b(t.samples_, quant ? &codes : nullptr, oo, quant.get(), threads);
    typename B::local L;
    b.reserve(L, b.node_estimate(m));
    L.nodes.resize(1);
    if constexpr (A.colour) L.colours.resize(1);
    if (quant) L.codes.resize(1);
    const typename B::input inp{0, m, x.mean, x.normal_sum, x.colour_sum, x.depth};
    chunk_root out;
    out.sum = b.build(L, 0, inp, threads > 1 && m > 20000);
    t.nodes_ = std::move(L.nodes);
    if constexpr (A.colour) t.node_colours_ = std::move(L.colours);
    t.node_codes_ = std::move(L.codes);
    t.sample_codes_ = std::move(codes);
    t.normal_bits_ = oo.normal_bits;
    t.stats_.input_points = m;
    t.save((dir / chunk_file_name(static_cast<std::uint32_t>(c))).string());
    chunk_nodes[c] = t.nodes_.size();
    out.record = t.nodes_[0];
    if constexpr (A.colour) out.colour = t.node_colours_[0];
    if (quant) out.code = t.node_codes_[0];
    return out;
  }

  /// A chunk's root for the top (rank 0), through a file: the chunk may be built elsewhere.
  void save_root(std::size_t c, const chunk_root& r) const {
    byte_writer w;
    point_octree_io<A>::put_node(w, oo.normal_bits, r.record, quant ? &r.code : nullptr, r.colour);
    w.put(chunk_nodes[c]);
    const auto put = [&](const auto& m) {
      for (Eigen::Index i = 0; i < m.size(); ++i) w.put(m.data()[i]);
    };
    w.put(r.sum.scatter.n);
    put(r.sum.scatter.mean);
    put(r.sum.scatter.scatter);
    put(r.sum.gd.sum);
    put(r.sum.gf.sum);
    put(r.sum.disk);
    w.put(r.sum.n);
    save_file_bytes(temp_path("root", c), w.bytes);
  }
  chunk_root load_root(std::size_t c) {
    const std::string path = temp_path("root", c);
    const std::vector<unsigned char> bytes = load_file_bytes(path);
    byte_reader r{bytes, 0, path};
    chunk_root out;
    point_octree_io<A>::get_node(r, quant.get(), c, out.record, quant ? &out.code : nullptr,
                                 out.colour);
    chunk_nodes[c] = r.get<std::uint64_t>("nodes");
    const auto get = [&](auto& m) {
      using T = std::remove_reference_t<decltype(m.data()[0])>;
      for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = r.get<T>("summary");
    };
    out.sum.scatter.n = r.get<double>("summary");
    get(out.sum.scatter.mean);
    get(out.sum.scatter.scatter);
    get(out.sum.gd.sum);
    get(out.sum.gf.sum);
    get(out.sum.disk);
    out.sum.n = r.get<double>("summary");
    return out;
  }

  /// Step 7: the top nodes bottom up (children come after their parent), as build() finishes
  /// an inner node: centre and cone, then EQ 4 and EQ 5–6 over the children.
  typename B::local finish_top(const std::vector<chunk_root>& roots) {
    typename B::local T;
    T.nodes.resize(nodes.size());
    if constexpr (A.colour) T.colours.resize(nodes.size());
    if (quant) T.codes.resize(nodes.size());
    point_set<A> none_set;
    B tb(none_set, nullptr, oo, quant.get(), 1);
    std::vector<summary> sums(nodes.size());
    for (std::size_t i = nodes.size(); i-- > 0;) {
      const top_node& x = nodes[i];
      if (x.st == top_node::state::chunk) {
        const chunk_root& r = roots[x.chunk];
        T.nodes[i] = r.record;
        if constexpr (A.colour) T.colours[i] = r.colour;
        if (quant) T.codes[i] = r.code;
        sums[i] = r.sum;
        continue;
      }
      node nd =
          B::node_centre_and_cone(T, static_cast<std::uint32_t>(i), x.mean, x.colour_sum, x.count,
                                  x.depth, mean_normal(x), normal_valid(x), x.min_dot);
      nd.leaf = 0;
      nd.first = x.first_child;
      nd.count = x.children;
      const std::vector<summary> kids(sums.begin() + x.first_child,
                                      sums.begin() + x.first_child + x.children);
      sums[i] = tb.finish_inner(T, static_cast<std::uint32_t>(i), nd, x.first_child, kids,
                                static_cast<float>(std::sqrt(x.r2)), normal_valid(x));
    }
    return T;
  }

  void write_top(const typename B::local& T) const {
    using io = point_octree_io<A>;
    byte_writer w;
    write_head(w, chunked_top_format);
    w.put(static_cast<std::uint32_t>((A.colour ? 1u : 0u) | (quant ? 2u : 0u)));
    w.put(static_cast<std::uint32_t>(oo.normal_bits));
    const vec3d o = src.origin();
    w.put(o.x());
    w.put(o.y());
    w.put(o.z());
    w.put(n);
    // The input's bounding sphere about its box centre (bounding_sphere_about_box_centre): a
    // view frames the directory as it frames the input, without reading the chunks.
    w.put_vec(box.centre());
    w.put(static_cast<float>(std::sqrt(sphere_r2)));
    w.put(static_cast<std::uint64_t>(nodes.size()));
    w.put(static_cast<std::uint64_t>(chunks.size()));
    for (std::size_t i = 0; i < nodes.size(); ++i) {
      rgb8 colour{};
      if constexpr (A.colour) colour = T.colours[i];
      io::put_node(w, oo.normal_bits, T.nodes[i], quant ? &T.codes[i] : nullptr, colour);
    }
    for (const auto& x : nodes) w.put(x.chunk);
    for (std::size_t c = 0; c < chunks.size(); ++c) {
      w.put(chunks[c].top);
      w.put(chunks[c].count);
      w.put(chunk_nodes[c]);
    }
    append_checksum(w);
    save_file_bytes((dir / chunked_top_file).string(), w.bytes);
  }

  /// An input that fits one chunk is that chunk: build_point_octree of the whole input, which is
  /// what the chunk's build would make (the same folder, byte for byte), without the passes and
  /// temporary files that would double its time.
  chunked_build_report build_whole(std::chrono::steady_clock::time_point t0) {
    using clock = std::chrono::steady_clock;
    const point_cloud all = read_all(src);
    ++passes;
    point_octree_options whole = oo;
    whole.threads = threads;
    tree t = build_point_octree(point_set<In>::from(all), whole);
    for (const vec3f& p : all.positions)
      sphere_r2 = std::max(sphere_r2, (p - box.centre()).cast<double>().squaredNorm());
    chunks.push_back({.top = 0, .count = n});
    nodes[0].chunk = 0;
    chunk_nodes.assign(1, t.nodes_.size());
    t.save((dir / chunk_file_name(0)).string());
    chunk_root r;
    r.record = t.nodes_[0];
    if constexpr (A.colour) r.colour = t.node_colours_[0];
    if (quant) r.code = t.node_codes_[0];
    write_top(finish_top({r}));
    finish();
    progress(1);
    rep.passes = passes;
    rep.chunks = 1;
    rep.top_nodes = 1;
    rep.largest_chunk = n;
    rep.chunk_build_seconds = rep.seconds =
        std::chrono::duration<double>(clock::now() - t0).count();
    return rep;
  }

  chunked_build_report run() {
    using clock = std::chrono::steady_clock;
    const auto t0 = clock::now();
    start();
    rep.input_points = n;
    rep.chunk_points = chunk_points;
    rep.estimated_normals = !In.normal;
    progress(0);
    structure();
    rep.normals_filled = missing;
    rep.estimated_normals = rep.estimated_normals || (n > 0 && missing == n);
    if (nodes.size() == 1 && ranks == 1) return build_whole(t0);
    distribute();
    halos();
    progress(0.2);
    double pass_s = std::chrono::duration<double>(clock::now() - t0).count();
    const auto t1 = clock::now();
    estimate();
    barrier();
    rep.estimation_seconds = std::chrono::duration<double>(clock::now() - t1).count();
    const auto t2 = clock::now();
    {
      std::optional<index_file> normals;
      share_normals(normals, n, [&](index_file& file) { gather_normals(file); });
      attribute_passes(*normals);  // every rank: each needs its chunks' inputs
    }
    pass_s += std::chrono::duration<double>(clock::now() - t2).count();
    rep.pass_seconds = pass_s;
    const auto t3 = clock::now();
    chunk_nodes.assign(chunks.size(), 0);
    for (std::size_t c = 0; c < chunks.size(); ++c) {
      if (mine(c)) save_root(c, build_chunk(c));
      progress(0.5 + 0.5 * static_cast<double>(c + 1) / static_cast<double>(chunks.size()));
    }
    barrier();
    rep.chunk_build_seconds = std::chrono::duration<double>(clock::now() - t3).count();
    if (rank == 0) {
      std::vector<chunk_root> roots;
      roots.reserve(chunks.size());
      for (std::size_t c = 0; c < chunks.size(); ++c) roots.push_back(load_root(c));
      write_top(finish_top(roots));
    }
    finish();  // the folder is whole when any rank returns
    rep.passes = passes;
    rep.chunks = chunks.size();
    rep.top_nodes = nodes.size();
    rep.seconds = std::chrono::duration<double>(clock::now() - t0).count();
    return rep;
  }
};

}  // namespace detail

chunked_build_report build_point_octree_chunked(const point_source& src, const std::string& dir,
                                                const chunked_point_octree_options& options) {
  const attributes a = src.attrs();
  return detail::build_or_keep(dir, "build_point_octree_chunked", [&] {
    if (a.normal && a.colour)
      return detail::chunked_point_octree_builder<attributes{.normal = true, .colour = true}>(
                 src, dir, options)
          .run();
    if (a.normal)
      return detail::chunked_point_octree_builder<attributes{.normal = true}>(src, dir, options)
          .run();
    if (a.colour)
      return detail::chunked_point_octree_builder<attributes{.colour = true}>(src, dir, options)
          .run();
    return detail::chunked_point_octree_builder<attributes{}>(src, dir, options).run();
  });
}

}  // namespace pbr_lod
