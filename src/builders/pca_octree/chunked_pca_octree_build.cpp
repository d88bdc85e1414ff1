// The chunked (out-of-core) PCA octree build: see include/pbr_lod/builders/chunked_pca_octree.hpp
// for the steps and why the result equals build_pca_octree's.
#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <thread>
#include <unordered_map>

#include "builders/chunked/chunk_files.hpp"
#include "pbr_lod/builders/chunked_pca_octree.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/normal_repair.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pca_octree_internal.hpp"

namespace pbr_lod {
namespace detail {
namespace {

namespace fs = std::filesystem;
constexpr std::uint32_t none = 0xffffffffu;

/// A cell of the octree above the chunks, and the box of its points (a pass gathers it: a cell
/// whose points are all at one position is never split).
struct pca_cell {
  vec3d cell_min = vec3d::Zero();
  std::uint8_t depth = 0;
  vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
};
using top_cell = top_tree<pca_cell>::node;

inline std::size_t octant_of(const vec3d& q, const vec3d& mid) {
  return (q.x() >= mid.x() ? 1u : 0u) | (q.y() >= mid.y() ? 2u : 0u) | (q.z() >= mid.z() ? 4u : 0u);
}

// ---- the statistics a chunk keeps between its steps (temporary files, exact doubles/floats)
void put_acc(byte_writer& w, const scatter_accumulator& a) {
  w.put(a.n);
  for (int k = 0; k < 3; ++k) w.put(a.mean[k]);
  for (int k = 0; k < 9; ++k) w.put(a.scatter(k));
}
scatter_accumulator get_acc(byte_reader& r) {
  scatter_accumulator a;
  a.n = r.get<double>("moments");
  for (int k = 0; k < 3; ++k) a.mean[k] = r.get<double>("moments");
  for (int k = 0; k < 9; ++k) a.scatter(k) = r.get<double>("moments");
  return a;
}
template <class M>
void put_m(byte_writer& w, const M& m) {
  for (Eigen::Index k = 0; k < m.size(); ++k) w.put(m(k));
}
template <class M>
void get_m(byte_reader& r, M& m) {
  for (Eigen::Index k = 0; k < m.size(); ++k) m(k) = r.get<typename M::Scalar>("statistics");
}
/// A chunk's nodes with their undecoded statistics and cells.
void put_raw(byte_writer& w, const pca_data& d) {
  w.put(static_cast<std::uint64_t>(d.nodes.size()));
  w.put(static_cast<std::uint8_t>(d.colours.empty() ? 0 : 1));
  for (const pca_node& nd : d.nodes) {
    put_m(w, nd.mean);
    put_m(w, nd.frame);
    put_m(w, nd.sigma);
    put_m(w, nd.normal_frame);
    put_m(w, nd.normal_sigma);
    put_m(w, nd.extent);
    w.put(nd.normal_extent);
    w.put(nd.first);
    w.put(nd.count);
    w.put(nd.mask);
    w.put(nd.depth);
    put_m(w, nd.cell_min);
    w.put(nd.cell_size);
  }
  for (const pca_colour& c : d.colours) {
    put_m(w, c.mean);
    put_m(w, c.frame);
    put_m(w, c.sigma);
    w.put(c.extent);
  }
}
void get_raw(byte_reader& r, pca_data& d) {
  d.nodes.resize(r.get<std::uint64_t>("nodes"));
  const bool colour = r.get<std::uint8_t>("colour") != 0;
  for (pca_node& nd : d.nodes) {
    get_m(r, nd.mean);
    get_m(r, nd.frame);
    get_m(r, nd.sigma);
    get_m(r, nd.normal_frame);
    get_m(r, nd.normal_sigma);
    get_m(r, nd.extent);
    nd.normal_extent = r.get<float>("normal extent");
    nd.first = r.get<std::uint32_t>("first");
    nd.count = r.get<std::uint8_t>("count");
    nd.mask = r.get<std::uint8_t>("mask");
    nd.depth = r.get<std::uint8_t>("depth");
    get_m(r, nd.cell_min);
    nd.cell_size = r.get<double>("cell");
  }
  d.colours.resize(colour ? d.nodes.size() : 0);
  for (pca_colour& c : d.colours) {
    get_m(r, c.mean);
    get_m(r, c.frame);
    get_m(r, c.sigma);
    c.extent = r.get<float>("colour extent");
  }
}

/// Node counts per level of a breadth-first tree (depths absolute, levels contiguous).
std::vector<std::uint32_t> level_counts(const pca_data& d) {
  std::vector<std::uint32_t> c;
  for (const pca_node& nd : d.nodes) {
    const std::size_t l = nd.depth - d.nodes[0].depth;
    if (l >= c.size()) c.resize(l + 1, 0);
    ++c[l];
  }
  return c;
}

struct chunked_pca_builder : chunked_pass_base {
  const chunked_pca_octree_options& opt;
  pca_octree_options po;  // without the progress callback
  std::uint64_t n;
  std::uint64_t chunk_points;
  unsigned workers = 1;
  attributes in;
  vec3d centre_rel = vec3d::Zero();  // the origin relative to the source's
  double size = 0, input_radius = 0;
  top_tree<pca_cell> upper;  // the tree above the chunks
  std::vector<top_cell>& nodes = upper.nodes;
  std::vector<std::uint32_t>& chunk_top = upper.chunk_top;  // per chunk: its top cell
  std::vector<std::uint64_t> chunk_count;
  std::vector<std::vector<std::uint32_t>> chunk_levels;  // per chunk: nodes per local level
  // per chunk whose root is a leaf below a surface: widened by its spacing in its parent's plane
  // (pca_widen_leaf, as node_statistics does for every other leaf)
  std::vector<double> root_leaf_h;
  std::vector<std::uint8_t> root_widen;
  std::vector<mat3f> root_parent_frame;
  std::vector<std::vector<std::uint32_t>> chunk_global;  // per chunk: whole-tree number per level
  std::vector<std::uint32_t> top_global;                 // per top cell
  std::uint64_t total_nodes = 0;
  std::uint64_t missing = 0;          // input normals absent, zero or not finite
  std::vector<chunk_extent> extents;  // per chunk: its box (rank 0) and points
  pca_data top;                       // the top cells as nodes (a chunk's root: a leaf here)
  chunked_build_report rep;

  chunked_pca_builder(const point_source& s, const std::string& d,
                      const chunked_pca_octree_options& o)
      : chunked_pass_base(s, d, o.block_points, o.distributed, "build_pca_octree_chunked"),
        opt(o),
        po(o.builder),
        n(s.size()),
        in(s.attrs()) {
    po.progress = {};
    pca_validate_options(po, true);
    if (n >= std::numeric_limits<std::uint32_t>::max() - 1)
      throw InvalidArgument("build_pca_octree_chunked: more than 2^32 - 2 points");
    workers = pca_threads(po.threads);
    // Chunks are built `workers` at a time (over_my_chunks).
    chunk_points = chunk_points_for(opt.memory_bytes, opt.chunk_points,
                                    {chunked_pca_bytes_per_point, workers, po.leaf_size});
  }

  void progress(double f) const {
    if (opt.builder.progress && !opt.builder.progress(f))
      throw Cancelled("build_pca_octree_chunked: cancelled");
  }
  [[nodiscard]] vec3d local(const vec3f& p) const { return p.cast<double>() - centre_rel; }
  [[nodiscard]] double half_of(const top_cell& x) const {
    return size / std::ldexp(1.0, x.depth + 1);
  }
  [[nodiscard]] std::uint32_t descend(const vec3d& p) const {
    return upper.descend(p, [&](const top_cell& x, const vec3d& q) { return octant(x, q); });
  }

  // ---- build_pca_data's split, as top_tree's rule: a cell splits at its centre while it holds
  // more than a chunk and its points are not all at one position.
  [[nodiscard]] bool split(const top_cell& x) const {
    return x.count > chunk_points && x.depth < po.max_depth;
  }
  [[nodiscard]] int octant(const top_cell& x, const vec3d& p) const {
    return static_cast<int>(octant_of(p, x.cell_min + vec3d::Constant(half_of(x))));
  }
  static void add(top_cell& x, int, const vec3d& p) {
    x.lo = x.lo.cwiseMin(p);
    x.hi = x.hi.cwiseMax(p);
  }
  static bool keep_whole(const top_cell& x) { return x.lo == x.hi; }
  [[nodiscard]] pca_cell child(const top_cell& x, int o) const {
    const double half = half_of(x);
    pca_cell c;
    c.cell_min = x.cell_min + vec3d((o & 1) ? half : 0, (o & 2) ? half : 0, (o & 4) ? half : 0);
    c.depth = static_cast<std::uint8_t>(x.depth + 1);
    return c;
  }

  /// Steps 1–2: the box (build_pca_data's origin and root cube) and the checks of every point,
  /// then one pass per level splitting every cell above chunk size that build_pca_data splits.
  void structure() {
    vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    stream([&](std::uint64_t first, const point_block& b) {
      for (std::size_t k = 0; k < b.size(); ++k) {
        if (!all_finite(b.positions[k]))
          throw InvalidArgument("build_pca_octree_chunked: " + src.name() + ": position " +
                                std::to_string(first + k) + " is not finite");
        missing += !in.normal || missing_normal(b.normals[k]) ? 1 : 0;
        lo = lo.cwiseMin(b.positions[k].cast<double>());
        hi = hi.cwiseMax(b.positions[k].cast<double>());
      }
    });
    centre_rel = 0.5 * (lo + hi);
    size = (hi - lo).maxCoeff();
    size = size > 0 ? size * (1 + 1e-9) : 1e-9 * std::max(1.0, src.origin().cwiseAbs().maxCoeff());
    pca_cell root;
    root.cell_min = vec3d::Constant(-0.5 * size);
    upper.grow(*this, root, n, *this);
    rep.chunks = chunk_top.size();
    rep.top_nodes = nodes.size();
  }

  /// Step 3 (rank 0): every point into its chunk's file, input order kept.
  void distribute() {
    const std::size_t m = chunk_top.size();
    extents = chunked_pass_base::distribute(
        m, m,
        [&](const point_block& b, std::size_t k) {
          const vec3d p = local(b.positions[k]);
          input_radius = std::max(input_radius, p.norm());
          return nodes[descend(p)].chunk;
        },
        [](const point_record&, std::uint32_t) {}, [] {});
    chunk_count.resize(m);
    for (std::size_t c = 0; c < m; ++c) {
      chunk_count[c] = extents[c].count;
      rep.largest_chunk = std::max(rep.largest_chunk, chunk_count[c]);
    }
  }

  /// Step 3b, when normals are missing (none given, or some zero or not finite): the k-NN halos
  /// (chunked_pass_base::halos, as the chunked point-octree's), then (rank 0) chunk after chunk
  /// in octree order fill_missing_normals over the chunk and its halo, the halo's points of
  /// chunks already done carrying their estimates: those orient the chunk's, so that one
  /// orientation spreads from chunk to chunk as the in-memory build's spreads over the whole
  /// input. The chunk's file is rewritten with its normals.
  void fill_normals() {
    const std::size_t m = chunk_top.size();
    rep.halo_points = halos(extents, po.knn, workers,
                            [&](const vec3f& p) { return nodes[descend(local(p))].chunk; });
    if (rank == 0)
      fill_normals_in_turn(chunks_in_order(), m, po.knn, workers,
                           [&](const vec3f& p) { return nodes[descend(local(p))].chunk; });
    barrier();
  }

  /// f(chunk, threads) over this rank's chunks (chunked_pass_base::over_my_chunks), progress
  /// from p0 to p1.
  template <class F>
  void over_my_chunks(double p0, double p1, F&& f) {
    chunked_pass_base::over_my_chunks(chunk_top.size(), workers, f,
                                      [&](double done) { progress(p0 + (p1 - p0) * done); });
  }

  /// Step 4 for chunk c: its subtree and statistics (build_pca_data's code) kept in "raw", its
  /// normals in octree order in "nrm", its root's moments and level sizes in "sum".
  void build_chunk(std::size_t c, unsigned threads) const {
    const std::vector<point_record> recs = read_records(temp_path("chunk", c));
    if (recs.size() != chunk_count[c]) throw IoError(temp_path("chunk", c) + ": cut short");
    pca_points pts;
    pts.pos.resize(recs.size());
    pts.normals.resize(recs.size());
    if (in.colour) pts.colours.resize(recs.size());
    for (std::size_t i = 0; i < recs.size(); ++i) {
      pts.pos[i] = local(recs[i].position);
      pts.normals[i] = recs[i].normal.normalized();
      if (in.colour) pts.colours[i] = recs[i].colour;
    }
    const top_cell& x = nodes[chunk_top[c]];
    // A leaf of one or two points takes its parent's spacing (build_pca_data's rule): the
    // chunk root's parent is a top cell.
    double parent_spacing = 0;
    for (const top_cell& y : nodes)
      if (y.st == top_cell::state::split && chunk_top[c] >= y.first_child &&
          chunk_top[c] < y.first_child + y.children)
        parent_spacing = size / std::ldexp(1.0, y.depth) / std::sqrt(static_cast<double>(y.count));
    pca_data d;
    const pca_subtree_moments m =
        pca_build_subtree(d, pts, x.cell_min, x.depth, size, po, threads, parent_spacing);
    byte_writer w;
    put_raw(w, d);
    save_file_bytes(temp_path("raw", c), w.bytes);
    byte_writer nw;
    for (const vec3f& v : pts.normals) nw.put_vec(v);
    save_file_bytes(temp_path("nrm", c), nw.bytes);
    byte_writer sw;
    put_acc(sw, m.positions);
    put_acc(sw, m.colours);
    sw.put(m.root_leaf_h);
    const std::vector<std::uint32_t> lc = level_counts(d);
    sw.put(static_cast<std::uint32_t>(lc.size()));
    for (const std::uint32_t v : lc) sw.put(v);
    save_file_bytes(temp_path("sum", c), sw.bytes);
  }

  [[nodiscard]] pca_data load_raw(std::size_t c) const {
    const std::string path = temp_path("raw", c);
    const std::vector<unsigned char> bytes = load_file_bytes(path);
    byte_reader r{bytes, 0, path};
    pca_data d;
    get_raw(r, d);
    // Once the top's pass has widened the root (top_statistics), every later reader sees it so.
    if (c < root_widen.size() && root_widen[c] != 0)
      pca_widen_leaf(d.nodes[0], root_leaf_h[c], root_parent_frame[c]);
    return d;
  }

  /// The chunks from left to right (the in-memory order of their points).
  [[nodiscard]] std::vector<std::uint32_t> chunks_in_order() const {
    return upper.chunks_in_order();
  }

  /// Step 5 (rank 0): the top cells' statistics.
  void top_statistics(std::vector<scatter_accumulator>& pos_acc,
                      std::vector<scatter_accumulator>& col_acc) {
    const std::size_t t = nodes.size();
    top.nodes.assign(t, pca_node{});
    if (in.colour) top.colours.assign(t, pca_colour{});
    pos_acc.assign(t, {});
    col_acc.assign(t, {});
    chunk_levels.resize(chunk_top.size());
    root_leaf_h.assign(chunk_top.size(), 0);
    root_widen.assign(chunk_top.size(), 0);
    root_parent_frame.assign(chunk_top.size(), mat3f::Identity());
    std::vector<std::vector<std::uint32_t>> above(chunk_top.size());  // split ancestors
    std::vector<std::uint32_t> parent(t, none);
    for (std::uint32_t x = 0; x < t; ++x)
      for (std::uint32_t k = 0; k < nodes[x].children; ++k) parent[nodes[x].first_child + k] = x;
    for (std::uint32_t c = 0; c < chunk_top.size(); ++c) {
      for (std::uint32_t a = parent[chunk_top[c]]; a != none; a = parent[a]) above[c].push_back(a);
      // The chunk's root node, its moments and its level sizes.
      const pca_data d = load_raw(c);
      top.nodes[chunk_top[c]] = d.nodes[0];
      top.nodes[chunk_top[c]].first = 0;
      top.nodes[chunk_top[c]].count = 0;
      top.nodes[chunk_top[c]].mask = 0;
      if (in.colour) top.colours[chunk_top[c]] = d.colours[0];
      const std::string path = temp_path("sum", c);
      const std::vector<unsigned char> bytes = load_file_bytes(path);
      byte_reader r{bytes, 0, path};
      pos_acc[chunk_top[c]] = get_acc(r);
      col_acc[chunk_top[c]] = get_acc(r);
      root_leaf_h[c] = r.get<double>("leaf spacing");
      chunk_levels[c].resize(r.get<std::uint32_t>("levels"));
      for (auto& v : chunk_levels[c]) v = r.get<std::uint32_t>("level");
    }
    // The normals: two passes over the chunks' normals in octree order, every split cell's sums
    // in the order pca_normals adds them.
    const std::vector<std::uint32_t> order = chunks_in_order();
    std::vector<vec3d> sum(t, vec3d::Zero()), fallback(t, vec3d::Zero());
    std::vector<char> seen(t, 0);
    std::vector<vec3f> nrm;
    const auto read_normals = [&](std::uint32_t c) {
      const std::string path = temp_path("nrm", c);
      const std::vector<unsigned char> bytes = load_file_bytes(path);
      byte_reader r{bytes, 0, path};
      nrm.resize(chunk_count[c]);
      for (std::size_t i = 0; i < nrm.size(); ++i) nrm[i] = r.get_vec("normal", i);
    };
    for (const std::uint32_t c : order) {
      read_normals(c);
      for (const std::uint32_t a : above[c]) {
        if (!seen[a]) fallback[a] = nrm[0].cast<double>();
        seen[a] = 1;
        for (const vec3f& v : nrm) sum[a] += v.cast<double>();
      }
    }
    std::vector<mat3d> frame(t, mat3d::Identity()), frame_t(t, mat3d::Identity());
    std::vector<Eigen::Matrix2d> m(t, Eigen::Matrix2d::Zero());
    for (std::uint32_t x = 0; x < t; ++x)
      if (nodes[x].st == top_cell::state::split) {
        frame[x] = pca_normal_pole(sum[x], nodes[x].count, fallback[x]);
        frame_t[x] = frame[x].transpose();
      }
    for (const std::uint32_t c : order) {
      read_normals(c);
      for (const std::uint32_t a : above[c])
        for (const vec3f& v : nrm) pca_normal_unwrap_add(frame_t[a], v, m[a]);
    }
    // Positions and colours: the children's moments merged in octant order, bottom up.
    for (std::uint32_t x = static_cast<std::uint32_t>(t); x-- > 0;) {
      const top_cell& cell = nodes[x];
      if (cell.st != top_cell::state::split) continue;
      for (std::uint32_t k = 0; k < cell.children; ++k) {
        pos_acc[x] += pos_acc[cell.first_child + k];
        col_acc[x] += col_acc[cell.first_child + k];
      }
      pca_node& nd = top.nodes[x];
      pca_set_statistics(nd, pos_acc[x], pca_normal_finish(frame[x], m[x], cell.count));
      if (in.colour) top.colours[x] = pca_colours_from(col_acc[x].mean, col_acc[x].covariance());
      nd.first = cell.first_child;
      nd.count = static_cast<std::uint8_t>(cell.children);
      for (std::size_t o = 0; o < 8; ++o)
        if (cell.child[o] != none) nd.mask = static_cast<std::uint8_t>(nd.mask | (1u << o));
      nd.depth = cell.depth;
      nd.cell_min = cell.cell_min;
      nd.cell_size = size / std::ldexp(1.0, cell.depth);
      pca_inner_extents(top, x);  // its children (chunk roots or top cells) are done
      // A chunk root that is a leaf is widened after its parent's span, as build_pca_data
      // does (node_statistics); finish_chunk repeats it in the chunk's own copy.
      if (nd.sigma.y() > 2e-15)
        for (std::uint32_t k = 0; k < cell.children; ++k) {
          const top_cell& ch = nodes[cell.first_child + k];
          if (ch.st == top_cell::state::split || !(root_leaf_h[ch.chunk] > 0)) continue;
          pca_widen_leaf(top.nodes[cell.first_child + k], root_leaf_h[ch.chunk], nd.frame);
          root_widen[ch.chunk] = 1;
          root_parent_frame[ch.chunk] = nd.frame;
        }
    }
  }

  /// The whole-tree (breadth-first) number of every top cell and of the first node of every
  /// level of every chunk: a level of the whole tree lists, left to right, the top cells at that
  /// depth and the chunks' nodes at that depth.
  void number_nodes() {
    top_global.assign(nodes.size(), none);
    chunk_global.assign(chunk_top.size(), {});
    for (std::uint32_t c = 0; c < chunk_top.size(); ++c)
      chunk_global[c].assign(chunk_levels[c].size(), none);
    std::uint64_t next = 0;
    for (std::uint32_t level = 0;; ++level) {
      const std::uint64_t start = next;
      std::vector<std::uint32_t> stack{0};
      while (!stack.empty()) {
        const std::uint32_t x = stack.back();
        stack.pop_back();
        const top_cell& cell = nodes[x];
        if (cell.st == top_cell::state::split) {
          if (cell.depth == level) {
            top_global[x] = static_cast<std::uint32_t>(next++);
          } else {
            for (std::uint32_t k = cell.children; k-- > 0;) stack.push_back(cell.first_child + k);
          }
          continue;
        }
        const std::size_t l = level - cell.depth;
        if (level < cell.depth || l >= chunk_levels[cell.chunk].size()) continue;
        chunk_global[cell.chunk][l] = static_cast<std::uint32_t>(next);
        if (l == 0) top_global[x] = static_cast<std::uint32_t>(next);
        next += chunk_levels[cell.chunk][l];
      }
      if (next == start) break;
    }
    total_nodes = next;
  }

  [[nodiscard]] std::uint64_t chunk_global_id(std::uint32_t c,
                                              const std::vector<std::uint32_t>& level_first,
                                              std::uint32_t i) const {
    const auto l = static_cast<std::size_t>(
        std::upper_bound(level_first.begin(), level_first.end(), i) - level_first.begin() - 1);
    return chunk_global[c][l] + (i - level_first[l]);
  }
  static std::vector<std::uint32_t> firsts(const std::vector<std::uint32_t>& counts) {
    std::vector<std::uint32_t> f(counts.size(), 0);
    for (std::size_t l = 1; l < counts.size(); ++l) f[l] = f[l - 1] + counts[l - 1];
    return f;
  }

  /// Step 6 (rank 0): the codebooks from the nodes build_pca_data's k-means would sample.
  void train_codebooks() {
    std::array<std::uint64_t, 3> rng{};
    std::array<std::vector<std::uint32_t>, 3> picks;
    const int books = in.colour ? 3 : 2;
    std::unordered_map<std::uint64_t, std::array<pca_feature, 3>> feature;
    for (int b = 0; b < books; ++b) {
      picks[b] = pca_kmeans_picks(total_nodes, po, static_cast<std::uint64_t>(b + 1), rng[b]);
      for (const std::uint32_t g : picks[b]) feature[g];
    }
    const auto take = [&](const pca_data& d, std::size_t i, std::uint64_t g) {
      const auto it = feature.find(g);
      if (it == feature.end()) return;
      pca_features(d, i, it->second[0], it->second[1], in.colour ? &it->second[2] : nullptr);
    };
    for (std::uint32_t x = 0; x < nodes.size(); ++x)
      if (nodes[x].st == top_cell::state::split) take(top, x, top_global[x]);
    for (std::uint32_t c = 0; c < chunk_top.size(); ++c) {
      const pca_data d = load_raw(c);
      const std::vector<std::uint32_t> lf = firsts(chunk_levels[c]);
      for (std::uint32_t i = 0; i < d.nodes.size(); ++i) take(d, i, chunk_global_id(c, lf, i));
    }
    const std::array<std::uint32_t, 3> k{po.position_codebook, po.normal_codebook,
                                         po.colour_codebook};
    std::array<std::vector<pca_feature>, 3> book;
    for (int b = 0; b < books; ++b) {
      std::vector<pca_feature> xs(picks[b].size());
      for (std::size_t i = 0; i < xs.size(); ++i) xs[i] = feature.at(picks[b][i])[b];
      book[b] = pca_kmeans_train(xs, k[b], po, rng[b], workers);
    }
    top.codebook_p = book[0];
    top.codebook_n = book[1];
    top.codebook_c = book[2];
  }

  void set_options(pca_data& d) const {
    d.origin = src.origin() + centre_rel;
    d.leaf_size = po.leaf_size;
    d.max_depth = po.max_depth;
    d.gamma = po.gamma;
    d.curvature_c = po.curvature_c;
    d.lambda_max = po.lambda_max;
    d.quantised = po.quantise;
  }

  /// Step 5–6 on rank 0: the top's statistics, numbering and codebooks, the top encoded; λ's
  /// unit and the codebooks to the other ranks through a file.
  void top_and_codebooks() {
    if (rank == 0) {
      std::vector<scatter_accumulator> pa, ca;
      top_statistics(pa, ca);
      number_nodes();
      set_options(top);
      if (po.quantise) {
        train_codebooks();
        pca_encode(top, workers);  // a chunk's root is encoded in its chunk the same way
      }
      const float root_norm = top.nodes[0].sigma.norm();
      top.lambda_norm = root_norm > 0 ? root_norm : 1.0f;
      byte_writer w;
      w.put(top.lambda_norm);
      w.put(total_nodes);
      for (const auto* b : {&top.codebook_p, &top.codebook_n, &top.codebook_c}) {
        w.put(static_cast<std::uint32_t>(b->size()));
        for (const pca_feature& v : *b) put_m(w, v);
      }
      for (std::uint32_t c = 0; c < chunk_top.size(); ++c) {
        w.put(static_cast<std::uint32_t>(chunk_global[c].size()));
        for (const std::uint32_t v : chunk_global[c]) w.put(v);
      }
      for (std::uint32_t c = 0; c < chunk_top.size(); ++c) {
        w.put(root_widen[c]);
        w.put(root_leaf_h[c]);
        put_m(w, root_parent_frame[c]);
      }
      save_file_bytes(temp_path("quant", 0), w.bytes);
    }
    barrier();
    if (rank != 0) {
      const std::string path = temp_path("quant", 0);
      const std::vector<unsigned char> bytes = load_file_bytes(path);
      byte_reader r{bytes, 0, path};
      top.lambda_norm = r.get<float>("lambda");
      total_nodes = r.get<std::uint64_t>("nodes");
      for (auto* b : {&top.codebook_p, &top.codebook_n, &top.codebook_c}) {
        b->resize(r.get<std::uint32_t>("codebook"));
        for (pca_feature& v : *b) get_m(r, v);
      }
      chunk_global.resize(chunk_top.size());
      for (auto& g : chunk_global) {
        g.resize(r.get<std::uint32_t>("levels"));
        for (auto& v : g) v = r.get<std::uint32_t>("level");
      }
      root_widen.assign(chunk_top.size(), 0);
      root_leaf_h.assign(chunk_top.size(), 0);
      root_parent_frame.assign(chunk_top.size(), mat3f::Identity());
      for (std::uint32_t c = 0; c < chunk_top.size(); ++c) {
        root_widen[c] = r.get<std::uint8_t>("widen");
        root_leaf_h[c] = r.get<double>("leaf spacing");
        get_m(r, root_parent_frame[c]);
      }
      set_options(top);
    }
  }

  /// Step 6 for chunk c: encoded, decoded, bounded; its file written, its root's bounds kept.
  void finish_chunk(std::size_t c, unsigned threads) const {
    pca_data d = load_raw(c);
    set_options(d);
    d.codebook_p = top.codebook_p;
    d.codebook_n = top.codebook_n;
    d.codebook_c = top.codebook_c;
    if (po.quantise) pca_encode(d, threads);
    pca_derive_bounds_with(d, top.lambda_norm, threads);
    const top_cell& x = nodes[chunk_top[c]];
    byte_writer w;
    write_head(w, pca_chunk_format);
    w.put(static_cast<std::uint32_t>((in.colour ? 1u : 0u) | (po.quantise ? 2u : 0u)));
    w.put(static_cast<std::uint32_t>(c));
    w.put(static_cast<std::uint32_t>(x.depth));
    w.put(chunk_count[c]);
    w.put(static_cast<std::uint64_t>(d.nodes.size()));
    for (int k = 0; k < 3; ++k) w.put(x.cell_min[k]);
    w.put(size / std::ldexp(1.0, x.depth));
    w.put(static_cast<std::uint32_t>(chunk_global[c].size()));
    for (const std::uint32_t g : chunk_global[c]) w.put(g);
    put_pca_nodes(w, d);
    append_checksum(w);
    save_file_bytes((dir / pca_chunk_file_name(static_cast<std::uint32_t>(c))).string(), w.bytes);
    byte_writer rw;
    rw.put(d.nodes[0].radius);
    rw.put(d.nodes[0].cone_angle);
    rw.put(d.nodes[0].lambda);
    rw.put(d.nodes[0].mask);
    rw.put(static_cast<std::uint64_t>(d.nodes.size()));
    save_file_bytes(temp_path("root", c), rw.bytes);
  }

  /// Step 7 (rank 0): the top's bounds from the chunks' roots; the top file.
  void write_top() {
    const std::size_t m = chunk_top.size();
    std::vector<char> fixed(nodes.size(), 0);
    std::vector<std::uint8_t> root_mask(m);
    std::vector<std::uint64_t> chunk_nodes(m);
    for (std::uint32_t c = 0; c < m; ++c) {
      const std::string path = temp_path("root", c);
      const std::vector<unsigned char> bytes = load_file_bytes(path);
      byte_reader r{bytes, 0, path};
      pca_node& nd = top.nodes[chunk_top[c]];
      nd.radius = r.get<float>("radius");
      nd.cone_angle = r.get<float>("cone");
      nd.lambda = r.get<float>("lambda");
      root_mask[c] = r.get<std::uint8_t>("mask");
      chunk_nodes[c] = r.get<std::uint64_t>("nodes");
      fixed[chunk_top[c]] = 1;
    }
    pca_derive_bounds_with(top, top.lambda_norm, 1, &fixed);
    byte_writer w;
    write_head(w, chunked_pca_format);
    w.put(static_cast<std::uint32_t>((in.colour ? 1u : 0u) | (po.quantise ? 2u : 0u)));
    w.put(po.leaf_size);
    w.put(po.max_depth);
    w.put(po.gamma);
    w.put(po.curvature_c);
    w.put(po.lambda_max);
    w.put(top.lambda_norm);
    w.put(n);
    for (int k = 0; k < 3; ++k) w.put(top.origin[k]);
    for (int k = 0; k < 3; ++k) w.put(nodes[0].cell_min[k]);
    w.put(size);
    w.put(input_radius);
    w.put(static_cast<std::uint32_t>(top.codebook_p.size()));
    w.put(static_cast<std::uint32_t>(top.codebook_n.size()));
    w.put(static_cast<std::uint32_t>(top.codebook_c.size()));
    put_pca_codebooks(w, top);
    w.put(static_cast<std::uint64_t>(nodes.size()));
    w.put(static_cast<std::uint64_t>(m));
    put_pca_nodes(w, top);
    for (std::uint32_t x = 0; x < nodes.size(); ++x) {
      w.put(nodes[x].chunk);
      w.put(top_global[x]);
    }
    for (std::uint32_t c = 0; c < m; ++c) {
      w.put(chunk_top[c]);
      w.put(chunk_count[c]);
      w.put(chunk_nodes[c]);
      w.put(root_mask[c]);
      w.put(top.nodes[chunk_top[c]].radius);
      w.put(top.nodes[chunk_top[c]].cone_angle);
    }
    append_checksum(w);
    save_file_bytes((dir / chunked_top_file).string(), w.bytes);
  }

  chunked_build_report run() {
    using clk = std::chrono::steady_clock;
    const auto t0 = clk::now();
    start();
    progress(0);
    structure();
    distribute();
    rep.pass_seconds = std::chrono::duration<double>(clk::now() - t0).count();
    rep.normals_filled = missing;
    rep.estimated_normals = missing == n;
    if (missing > 0) {
      const auto te = clk::now();
      fill_normals();
      rep.estimation_seconds = std::chrono::duration<double>(clk::now() - te).count();
    }
    progress(0.1);
    const auto tc = clk::now();
    over_my_chunks(0.1, 0.5, [&](std::size_t c, unsigned t) { build_chunk(c, t); });
    barrier();
    double chunk_seconds = std::chrono::duration<double>(clk::now() - tc).count();
    const auto tt = clk::now();
    top_and_codebooks();
    rep.pass_seconds += std::chrono::duration<double>(clk::now() - tt).count();
    const auto tf = clk::now();
    over_my_chunks(0.6, 0.95, [&](std::size_t c, unsigned t) { finish_chunk(c, t); });
    barrier();
    chunk_seconds += std::chrono::duration<double>(clk::now() - tf).count();
    if (rank == 0) write_top();
    finish();  // the folder is whole when any rank returns
    rep.chunk_build_seconds = chunk_seconds;
    rep.input_points = n;
    rep.chunk_points = chunk_points;
    rep.passes = passes;
    rep.seconds = std::chrono::duration<double>(clk::now() - t0).count();
    progress(1);
    return rep;
  }
};

}  // namespace
}  // namespace detail

chunked_build_report build_pca_octree_chunked(const point_source& src, const std::string& dir,
                                              const chunked_pca_octree_options& options) {
  return detail::build_or_keep(dir, "build_pca_octree_chunked", [&] {
    detail::chunked_pca_builder b(src, dir, options);
    return b.run();
  });
}

}  // namespace pbr_lod
