// The chunked (out-of-core) PMR build: see include/pbr_lod/builders/chunked_pmr.hpp for the
// steps and why the result equals build_pmr's.
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <queue>
#include <thread>

#include "builders/chunked/chunk_files.hpp"
#include "pbr_lod/builders/chunked_pmr.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pmr_internal.hpp"

namespace pbr_lod {
namespace detail {
namespace {

namespace fs = std::filesystem;

/// A cell of the octree above the chunks.
struct pmr_top_cell {
  pmr_cell cell;
};
using top_cell = top_tree<pmr_top_cell>::node;

/// What step 5 keeps of a chunk for the top: its root's record and counts.
struct chunk_root {
  pmr_node record;
  std::uint64_t leaves = 0, nodes = 0;
  pmr_build_stats stats;
};

struct chunked_pmr_builder : chunked_pass_base {
  const chunked_pmr_options& opt;
  pmr_options po;  // the PMR options without the progress callback
  std::uint64_t n;
  std::uint64_t chunk_points;
  unsigned workers = 1;
  vec3d origin = vec3d::Zero(), wlo = vec3d::Zero(), whi = vec3d::Zero();
  top_tree<pmr_top_cell> upper;  // the tree above the chunks
  std::vector<top_cell>& nodes = upper.nodes;
  std::vector<std::uint32_t>& chunk_top = upper.chunk_top;  // per chunk: its top cell
  std::vector<std::uint64_t> chunk_count;
  chunked_build_report rep;
  vec3f sphere_centre = vec3f::Zero();  // of the input's float positions' box (rank 0)
  double sphere_r2 = 0;
  // The chunk of the sample farthest from the origin (first in input order among equals): the
  // seed of build_pmr's orientation (rank 0).
  std::uint32_t far_chunk = 0;
  float far_d2 = -1;

  chunked_pmr_builder(const point_source& s, const std::string& d, const chunked_pmr_options& o)
      : chunked_pass_base(s, d, o.block_points, o.distributed, "build_pmr_chunked"),
        opt(o),
        po(o.builder),
        n(s.size()) {
    validate_pmr_options(po);
    po.progress = {};
    if (n >= std::numeric_limits<std::uint32_t>::max() - 1)
      throw InvalidArgument("build_pmr_chunked: more than 2^32 - 2 points");
    workers = resolve_threads(po.threads);
    // Chunks are built `workers` at a time (build_parts).
    chunk_points = chunk_points_for(opt.memory_bytes, opt.chunk_points,
                                    {chunked_pmr_bytes_per_point, workers, po.max_leaf_points});
    // A triangulation never spans chunks (nor its neighbours beyond a chunk's halo): equal to
    // build_pmr with triangulation_points at most chunk_points.
    po.triangulation_points =
        static_cast<std::uint32_t>(std::min<std::uint64_t>(po.triangulation_points, chunk_points));
    // A chunk's halo is a margin about it: equal to build_pmr with neighbour_leaves = false.
    po.neighbour_leaves = false;
  }

  void progress(double f) const {
    if (opt.builder.progress && !opt.builder.progress(f))
      throw Cancelled("build_pmr_chunked: cancelled");
  }

  [[nodiscard]] vec3d local(const vec3f& p) const {
    return (src.origin() + p.cast<double>()) - origin;
  }

  [[nodiscard]] std::uint32_t descend(const vec3d& p) const {
    return upper.descend(p, [&](const top_cell& x, const vec3d& q) { return octant(x, q); });
  }

  // ---- build_pmr's octree, as top_tree's rule: a cell splits at its midpoint while it holds
  // more than a chunk, down to max_depth (where build_pmr's octree stops too).
  [[nodiscard]] bool split(const top_cell& x) const {
    return x.count > chunk_points && x.cell.depth < po.max_depth;
  }
  static int octant(const top_cell& x, const vec3d& p) {
    return pmr_octant(p, pmr_cell_mid(x.cell.lo, x.cell.size));
  }
  static void add(top_cell&, int, const vec3d&) {}
  static bool keep_whole(const top_cell&) { return false; }
  static pmr_top_cell child(const top_cell& x, int o) { return {pmr_child_cell(x.cell, o)}; }

  /// Steps 1–2: the input's box and origin, then one pass per level splitting every cell above
  /// chunk size that is not at max_depth (where build_pmr's octree stops too).
  void structure() {
    wlo = vec3d::Constant(std::numeric_limits<double>::infinity());
    whi = -wlo;
    stream([&](std::uint64_t first, const point_block& b) {
      for (std::size_t k = 0; k < b.size(); ++k) {
        if (!all_finite(b.positions[k]))
          throw InvalidArgument("build_pmr_chunked: " + src.name() + ": position " +
                                std::to_string(first + k) + " is not finite");
        const vec3d w = src.origin() + b.positions[k].cast<double>();
        wlo = wlo.cwiseMin(w);
        whi = whi.cwiseMax(w);
      }
    });
    origin = 0.5 * (wlo + whi);
    upper.grow(*this, {pmr_root_cell(wlo - origin, whi - origin)}, n, *this);
  }

  /// The box a chunk's leaves gather neighbours from: its cell widened by the margin of a leaf
  /// as large as the cell (leaves below it are no larger, and their margins no wider), plus a
  /// ten-millionth of the cell for the rounding of the leaves' own boxes.
  [[nodiscard]] std::array<vec3d, 2> halo_box(std::uint32_t c) const {
    const pmr_cell& cell = nodes[chunk_top[c]].cell;
    const double m = static_cast<double>(po.neighbour_margin) * cell.size + 1e-7 * cell.size;
    return {cell.lo - vec3d::Constant(m), cell.lo + vec3d::Constant(cell.size + m)};
  }

  /// Step 3 (rank 0): every point into its chunk's file and into the halo of every other chunk
  /// whose halo box holds it (a coarse grid over the root cell lists the boxes).
  void distribute() {
    const std::size_t m = chunk_top.size();
    std::vector<append_file> halos;
    box_grid grid(nodes[0].cell.lo, vec3d::Constant(nodes[0].cell.size));
    if (rank == 0) {
      halos.reserve(m);
      for (std::size_t c = 0; c < m; ++c) {
        halos.emplace_back(temp_path("halo", c), buffer_bytes(2 * m));
        const auto box = halo_box(static_cast<std::uint32_t>(c));
        grid.add(static_cast<std::uint32_t>(c), box[0], box[1]);
      }
    }
    // The stored positions are the local ones in float; their box is the local box in float
    // (rounding is monotonic), so its centre is known before the pass.
    sphere_centre =
        box3::of(std::vector<vec3f>{(wlo - origin).cast<float>(), (whi - origin).cast<float>()})
            .centre();
    const auto chunk_of = [&](const point_block& b, std::size_t k) {
      const vec3d p = local(b.positions[k]);
      const std::uint32_t own = nodes[descend(p)].chunk;
      const vec3f pf = p.cast<float>();
      sphere_r2 = std::max(sphere_r2, (pf - sphere_centre).cast<double>().squaredNorm());
      if (pf.squaredNorm() > far_d2) {
        far_d2 = pf.squaredNorm();
        far_chunk = own;
      }
      return own;
    };
    const auto halo = [&](const point_record& r, std::uint32_t own) {
      const vec3d p = local(r.position);
      for (const std::uint32_t c : grid.at(p)) {
        const auto box = halo_box(c);
        if (c != own && (p.array() >= box[0].array()).all() && (p.array() <= box[1].array()).all())
          halos[c].put(r);
      }
    };
    const auto flush = [&] {
      for (auto& f : halos) {
        f.flush();
        rep.halo_points += f.count();
      }
    };
    const std::vector<chunk_extent> ext =
        chunked_pass_base::distribute(m, 2 * m, chunk_of, halo, flush);
    chunk_count.resize(m);
    for (std::size_t c = 0; c < m; ++c) {
      chunk_count[c] = ext[c].count;
      rep.largest_chunk = std::max(rep.largest_chunk, chunk_count[c]);
    }
    if (rank != 0)
      for (std::size_t c = 0; c < m; ++c)
        rep.halo_points += fs::file_size(temp_path("halo", c)) / record_bytes;
  }

  /// Step 4 over this rank's chunks: a chunk's leaves are few (chunk / max_leaf_points), so the
  /// chunks are built side by side, one thread each, when there are enough of them; else one at a
  /// time on every thread. (The output does not depend on the threads.)
  void build_parts() {
    chunked_pass_base::over_my_chunks(
        chunk_top.size(), workers,
        [&](std::size_t c, unsigned threads) {
          pmr_options part = po;
          part.threads = threads;
          build_part(c, part);
        },
        [&](double done) { progress(0.05 + 0.85 * done); });
  }

  /// Step 4 for chunk c: the part over chunk + halo, saved; its own normals in input order.
  void build_part(std::size_t c, const pmr_options& part_options) const {
    const auto recs = read_records(temp_path("chunk", c));
    const std::vector<point_record> halo = read_records(temp_path("halo", c));
    const attributes a = src.attrs();
    point_cloud cloud;
    cloud.origin = src.origin();
    std::vector<std::uint64_t> input;
    for (const std::vector<point_record>* part : {&recs, &halo})
      for (const point_record& r : *part) {
        cloud.positions.push_back(r.position);
        if (a.normal) cloud.normals.push_back(r.normal);
        if (a.colour) cloud.colours.push_back(r.colour);
        input.push_back(r.index);
      }
    const pmr_data d = build_pmr_part({cloud, static_cast<std::uint32_t>(recs.size()), input, n,
                                       origin, wlo, whi, nodes[chunk_top[c]].cell},
                                      part_options);
    save_pmr_data(d, temp_path("part", c));
    if (!a.normal) save_crossings(c, d, halo);
    // The own samples' normals in the chunk file's order (input order).
    std::vector<std::pair<std::uint32_t, vec3f>> own(recs.size());
    for (std::size_t g = 0; g < recs.size(); ++g) own[g] = {d.source[g], d.normals[g]};
    std::sort(own.begin(), own.end(),
              [](const auto& x, const auto& y) { return x.first < y.first; });
    byte_writer w;
    for (const auto& [i, nrm] : own) w.put_vec(nrm);
    save_file_bytes(temp_path("normals", c), w.bytes);
  }

  /// Without input normals each chunk orients its own by propagation (build_pmr's rule); whether
  /// two chunks agree is seen where their level-0 umbrella edges meet. Per such edge from an own
  /// sample to another chunk's: that chunk, the other sample's input index, the own normal.
  void save_crossings(std::size_t c, const pmr_data& d,
                      const std::vector<point_record>& halo) const {
    std::vector<std::pair<std::uint64_t, std::uint32_t>> owner;  // (input index, chunk)
    owner.reserve(halo.size());
    for (const point_record& r : halo)
      owner.emplace_back(r.index, nodes[descend(local(r.position))].chunk);
    std::sort(owner.begin(), owner.end());
    const std::size_t own = d.positions.size() - d.foreign;
    const std::size_t levels = d.rho.size() + 1;
    byte_writer w;
    for (std::size_t l = 0; l < d.leaf_list.size(); ++l) {
      const pmr_level& L = d.levels[l * levels];
      for (std::uint32_t t = L.first_tri; t < L.first_tri + L.tris; ++t)
        for (int k = 0; k < 3; ++k) {
          std::uint32_t a = d.triangles[t][k], b = d.triangles[t][(k + 1) % 3];
          if ((a < own) == (b < own)) continue;
          if (a >= own) std::swap(a, b);
          const auto it = std::lower_bound(owner.begin(), owner.end(),
                                           std::pair<std::uint64_t, std::uint32_t>{d.source[b], 0});
          if (it == owner.end() || it->first != d.source[b])
            throw IoError(temp_path("halo", c) + ": an umbrella vertex is not in the halo");
          w.put(it->second);
          w.put(d.source[b]);
          w.put_vec(d.normals[a]);
        }
    }
    save_file_bytes(temp_path("cross", c), w.bytes);
  }

  /// Rank 0: which chunks to flip so that neighbouring chunks agree, decided as build_pmr
  /// decides between samples (Hoppe et al. 1992), one level up: over the chunk graph weighted by
  /// the summed n·n' of the umbrella edges between two chunks, most agreeing first, from the
  /// chunk of the sample farthest from the centre (which that chunk oriented outwards). The
  /// flipped chunks' normals are rewritten in `normals`.
  std::vector<std::uint8_t> orient_chunks(index_file& normals) const {
    const std::size_t m = chunk_top.size();
    std::map<std::pair<std::uint32_t, std::uint32_t>, double> w;
    std::vector<vec3f> nb;
    for (std::uint32_t c = 0; c < m; ++c) {
      const std::string path = temp_path("cross", c);
      const std::vector<unsigned char> bytes = load_file_bytes(path);
      byte_reader r{bytes, 0, path};
      for (std::size_t e = 0; r.pos < bytes.size(); ++e) {
        const auto d = r.get<std::uint32_t>("chunk");
        const auto i = r.get<std::uint32_t>("input index");
        const vec3f na = r.get_vec("normal", e);
        if (d >= m || i >= n) throw IoError(path + ": bad crossing");
        normals.read(i, 1, nb);
        w[{std::min(c, d), std::max(c, d)}] += static_cast<double>(na.dot(nb[0]));
      }
    }
    std::vector<std::vector<std::pair<std::uint32_t, double>>> adj(m);
    for (const auto& [cd, x] : w) {
      adj[cd.first].emplace_back(cd.second, x);
      adj[cd.second].emplace_back(cd.first, x);
    }
    std::vector<std::uint8_t> flip(m, 0), done(m, 0);
    using item = std::pair<double, std::pair<std::uint32_t, std::uint32_t>>;  // (|w|, (to, from))
    std::priority_queue<item> q;
    q.push({0, {far_chunk, far_chunk}});
    for (std::uint32_t seed = 0; seed <= m; ++seed) {
      while (!q.empty()) {
        const auto [x, e] = q.top();
        q.pop();
        const auto [to, from] = e;
        if (done[to]) continue;
        done[to] = 1;
        if (to != from) {
          double agree = 0;
          for (const auto& [k, v] : adj[to])
            if (k == from) agree = v;
          flip[to] = static_cast<std::uint8_t>(flip[from] ^ (agree < 0 ? 1 : 0));
        }
        for (const auto& [k, v] : adj[to])
          if (!done[k]) q.push({std::abs(v), {k, to}});
      }
      if (seed < m && !done[seed]) q.push({0, {seed, seed}});  // a part of its own: as it is
    }
    for (std::uint32_t c = 0; c < m; ++c)
      if (flip[c]) scatter_normals(normals, c, true);
    return flip;
  }

  /// Every chunk's normals into one file in input order (rank 0).
  void gather_normals(index_file& normals) const {
    for (std::size_t c = 0; c < chunk_top.size(); ++c) scatter_normals(normals, c, false);
  }

  /// Chunk c's own normals (as build_part saved them, in input order) into `normals`, negated
  /// when `flip`.
  void scatter_normals(index_file& normals, std::size_t c, bool flip) const {
    const auto recs = read_records(temp_path("chunk", c));
    const std::string path = temp_path("normals", c);
    const std::vector<unsigned char> bytes = load_file_bytes(path);
    byte_reader r{bytes, 0, path};
    std::vector<vec3f> nrm(recs.size());
    for (std::size_t k = 0; k < nrm.size(); ++k)
      nrm[k] = (flip ? -1.0f : 1.0f) * r.get_vec("normal", k);
    normals.scatter(recs, nrm);
  }

  /// Step 5 for chunk c: the foreign samples' normals, the triangles wound, the chunk's file.
  void finish_part(std::size_t c, const index_file& normals, bool flip) const {
    pmr_data d = load_pmr_data(temp_path("part", c));
    const std::size_t own = d.positions.size() - d.foreign;
    if (flip)
      for (std::size_t g = 0; g < own; ++g) d.normals[g] = -d.normals[g];
    std::vector<vec3f> one;
    for (std::size_t g = own; g < d.positions.size(); ++g) {
      normals.read(d.source[g], 1, one);
      d.normals[g] = one[0];
    }
    pmr_wind_triangles(d);
    save_pmr_data(d, (dir / pmr_chunk_file_name(static_cast<std::uint32_t>(c))).string());
    byte_writer w;
    put_node(w, d.nodes[0]);
    w.put(static_cast<std::uint64_t>(d.leaf_list.size()));
    w.put(static_cast<std::uint64_t>(d.nodes.size()));
    for (const std::size_t s : stat_counts(d.stats)) w.put(static_cast<std::uint64_t>(s));
    save_file_bytes(temp_path("root", c), w.bytes);
  }

  [[nodiscard]] chunk_root load_root(std::size_t c) const {
    const std::string path = temp_path("root", c);
    const std::vector<unsigned char> bytes = load_file_bytes(path);
    byte_reader r{bytes, 0, path};
    chunk_root out;
    out.record = get_node(r, c);
    out.leaves = r.get<std::uint64_t>("leaves");
    out.nodes = r.get<std::uint64_t>("nodes");
    for (std::size_t* s : stat_fields(out.stats)) *s = r.get<std::uint64_t>("build counts");
    return out;
  }

  /// Step 6: the top cells' records, bottom up from the chunks' roots (rank 0).
  void write_top(const std::vector<chunk_root>& roots) const {
    std::vector<pmr_node> rec(nodes.size());
    for (std::size_t i = nodes.size(); i-- > 0;) {
      const top_cell& x = nodes[i];
      if (x.st == top_cell::state::chunk) {
        rec[i] = roots[x.chunk].record;
        continue;
      }
      rec[i].cell_min = x.cell.lo.cast<float>();
      rec[i].cell_size = static_cast<float>(x.cell.size);
      rec[i].first = x.first_child;
      rec[i].count = x.children;
      rec[i].depth = x.cell.depth;
      pmr_bound_inner(rec[i], std::span<const pmr_node>(rec).subspan(x.first_child, x.children));
    }
    pmr_build_stats total;
    for (const chunk_root& r : roots) {
      const auto from = stat_counts(r.stats);
      const auto to = stat_fields(total);
      for (std::size_t k = 0; k < from.size(); ++k) *to[k] += from[k];
    }
    byte_writer w;
    write_head(w, chunked_pmr_format);
    w.put(static_cast<std::uint32_t>(src.attrs().colour ? 1u : 0u));
    for (const vec3d* v : {&origin, &wlo, &whi})
      for (int k = 0; k < 3; ++k) w.put((*v)[k]);
    w.put(po.max_leaf_points);
    w.put(po.neighbour_margin);
    w.put(static_cast<std::uint32_t>(po.rho.size()));
    for (const float r : po.rho) w.put(r);
    for (const std::size_t s : stat_counts(total)) w.put(static_cast<std::uint64_t>(s));
    // The input's bounding sphere as bounding_sphere_about_box_centre gives it for the stored
    // positions: a view frames the folder as the in-memory hierarchy, without reading chunks.
    w.put_vec(sphere_centre);
    w.put(static_cast<float>(std::sqrt(sphere_r2)));
    w.put(static_cast<std::uint64_t>(nodes.size()));
    w.put(static_cast<std::uint64_t>(chunk_top.size()));
    for (const pmr_node& r : rec) put_node(w, r);
    for (const auto& x : nodes) w.put(x.chunk);
    for (std::size_t c = 0; c < chunk_top.size(); ++c) {
      w.put(chunk_top[c]);
      w.put(chunk_count[c]);
      w.put(roots[c].leaves);
      w.put(roots[c].nodes);
    }
    append_checksum(w);
    save_file_bytes((dir / chunked_top_file).string(), w.bytes);
  }

  chunked_build_report run() {
    using clock = std::chrono::steady_clock;
    const auto t0 = clock::now();
    start();
    rep.input_points = n;
    rep.chunk_points = chunk_points;
    rep.estimated_normals = true;
    progress(0);
    structure();
    distribute();
    rep.pass_seconds = std::chrono::duration<double>(clock::now() - t0).count();
    const auto t1 = clock::now();
    const std::size_t m = chunk_top.size();
    build_parts();
    barrier();
    rep.estimation_seconds = std::chrono::duration<double>(clock::now() - t1).count();
    const auto t2 = clock::now();
    {
      std::optional<index_file> normals;
      std::vector<std::uint8_t> flip(m, 0);
      const bool orient = !src.attrs().normal && m > 1;
      share_normals(normals, n, [&](index_file& file) {
        gather_normals(file);
        if (orient) {
          flip = orient_chunks(file);
          save_file_bytes(temp_path("flips", 0), {flip.begin(), flip.end()});
        }
      });
      if (rank != 0) {
        if (orient) flip = load_file_bytes(temp_path("flips", 0));
        if (flip.size() != m) throw IoError(temp_path("flips", 0) + ": cut short");
      }
      for (std::size_t c = 0; c < m; ++c)
        if (mine(c)) finish_part(c, *normals, flip[c] != 0);
    }
    barrier();
    rep.chunk_build_seconds = std::chrono::duration<double>(clock::now() - t2).count();
    if (rank == 0) {
      std::vector<chunk_root> roots;
      roots.reserve(m);
      for (std::size_t c = 0; c < m; ++c) roots.push_back(load_root(c));
      write_top(roots);
    }
    finish();  // the folder is whole when any rank returns
    progress(1);
    rep.passes = passes;
    rep.chunks = m;
    rep.top_nodes = nodes.size();
    rep.seconds = std::chrono::duration<double>(clock::now() - t0).count();
    return rep;
  }
};

}  // namespace

}  // namespace detail

chunked_build_report build_pmr_chunked(const point_source& src, const std::string& dir,
                                       const chunked_pmr_options& options) {
  return detail::build_or_keep(dir, "build_pmr_chunked", [&] {
    return detail::chunked_pmr_builder(src, dir, options).run();
  });
}

}  // namespace pbr_lod
