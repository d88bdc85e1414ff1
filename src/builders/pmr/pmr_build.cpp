// pbr_lod — PMR (Dey & Hudson, IEEE Vis 2002): the builder around the per-leaf Voronoi work.
//
// §2 Spatial decomposition: the octree (at most max_leaf_points samples per leaf), and for each
// leaf the samples of its neighbourhood handed to pmr_process_cell (pmr_voronoi.cpp, the only
// CGAL code); §2 Records: the levels of each leaf as prefixes of its samples, umbrellas with
// their radii, each level's triangles stored once, the average umbrella radius per level; the
// bounding spheres the traversal culls with. No CGAL here.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <queue>
#include <thread>
#include <vector>

#include "pbr_lod/builders/pmr.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pmr_internal.hpp"

namespace pbr_lod::detail {
namespace {

void validate(const point_cloud& cloud, const pmr_options& o) {
  cloud.validate("build_pmr input");
  if (cloud.empty()) throw InvalidArgument("build_pmr: the input has no points");
  if (cloud.size() >= std::numeric_limits<std::uint32_t>::max() - 1)
    throw InvalidArgument("build_pmr: more than 2^32 - 2 points");
  validate_pmr_options(o);
}

}  // namespace

void validate_pmr_options(const pmr_options& o) {
  if (o.max_leaf_points < 8)
    throw InvalidArgument("build_pmr: max_leaf_points must be at least 8, got " +
                          std::to_string(o.max_leaf_points));
  if (o.max_depth < 1 || o.max_depth > 40)
    throw InvalidArgument("build_pmr: max_depth must lie in 1..40");
  if (o.rho.size() > 31) throw InvalidArgument("build_pmr: at most 31 rho thresholds");
  for (std::size_t i = 0; i < o.rho.size(); ++i)
    if (!(o.rho[i] > 0 && o.rho[i] <= 10) || (i > 0 && !(o.rho[i] > o.rho[i - 1])))
      throw InvalidArgument("build_pmr: rho must be strictly increasing values in (0, 10]; rho[" +
                            std::to_string(i) + "] = " + std::to_string(o.rho[i]));
  if (!(o.neighbour_margin >= 0 && o.neighbour_margin <= 2))
    throw InvalidArgument("build_pmr: neighbour_margin must lie in [0, 2]");
  if (o.triangulation_points < 8)
    throw InvalidArgument("build_pmr: triangulation_points must be at least 8");
  if (!(o.cocone_degrees >= 0 && o.cocone_degrees < 90))
    throw InvalidArgument("build_pmr: cocone_degrees must lie in [0, 90)");
  if (!(o.edge_spacing >= 0 && o.edge_spacing <= 1000))
    throw InvalidArgument("build_pmr: edge_spacing must lie in [0, 1000]");
}

namespace {

/// A float radius at least r (the conversion rounds up, plus a relative ulp of slack).
float outward(double r) {
  float f = static_cast<float>(r);
  if (static_cast<double>(f) < r) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f * (1 + 1e-6f) + 1e-30f;
}

/// An octree node during the build, in double, in the frame of the new origin.
struct build_node {
  vec3d lo;
  double size;
  std::uint32_t begin, end;  // range of `order`
  std::uint32_t depth;
  std::uint32_t first = 0, count = 0;  // children, when inner
  bool leaf = true;
};

/// §2 Spatial decomposition: cells split into octants while they hold more than
/// max_leaf_points samples; breadth-first, so every node's children are contiguous. Empty
/// octants get no node. The tree holds samples [0, owned) of `local` below the cell `root`.
std::vector<build_node> build_octree(const std::vector<vec3d>& local, std::uint32_t owned,
                                     const pmr_cell& root, std::vector<std::uint32_t>& order,
                                     const pmr_options& o) {
  order.resize(owned);
  std::iota(order.begin(), order.end(), 0u);
  std::vector<build_node> nodes;
  nodes.push_back({root.lo, root.size, 0, owned, root.depth});
  std::vector<std::uint32_t> tmp;
  for (std::size_t k = 0; k < nodes.size(); ++k) {
    const build_node nd = nodes[k];
    if (nd.end - nd.begin <= o.max_leaf_points || nd.depth >= o.max_depth) continue;
    const vec3d mid = pmr_cell_mid(nd.lo, nd.size);
    const auto octant = [&](std::uint32_t i) { return pmr_octant(local[i], mid); };
    std::array<std::uint32_t, 9> start{};
    for (std::uint32_t j = nd.begin; j < nd.end; ++j) ++start[octant(order[j]) + 1];
    for (int c = 0; c < 8; ++c) start[c + 1] += start[c];
    tmp.resize(nd.end - nd.begin);
    auto fill = start;
    for (std::uint32_t j = nd.begin; j < nd.end; ++j) tmp[fill[octant(order[j])]++] = order[j];
    std::copy(tmp.begin(), tmp.end(), order.begin() + nd.begin);
    nodes[k].leaf = false;
    nodes[k].first = static_cast<std::uint32_t>(nodes.size());
    for (int c = 0; c < 8; ++c) {
      if (start[c + 1] == start[c]) continue;
      const pmr_cell ch = pmr_child_cell({nd.lo, nd.size, nd.depth}, c);
      nodes.push_back({ch.lo, ch.size, nd.begin + start[c], nd.begin + start[c + 1], ch.depth});
    }
    nodes[k].count = static_cast<std::uint32_t>(nodes.size()) - nodes[k].first;
  }
  return nodes;
}

/// What one leaf's processing leaves for the assembly: input indices throughout.
struct leaf_result {
  std::vector<std::uint32_t> own;    // unique own samples (input indices), in cell order
  std::vector<std::uint8_t> levels;  // per own
  std::vector<vec3f> normal;         // per own
  std::vector<std::uint8_t> hull;    // per own
  // per level, per own sample alive there: umbrella (input-index triples) and radius
  struct level {
    std::vector<std::uint32_t> sample;  // index into own
    std::vector<std::uint32_t> first;
    std::vector<std::array<std::uint32_t, 3>> tris;
    std::vector<float> radius;
  };
  std::vector<level> lv;
  std::size_t triangulated = 0, removals = 0;
  bool flat = false;
};

struct builder {
  const point_cloud& cloud;
  const pmr_options& opt;
  std::uint32_t owned;                   // the tree's samples: [0, owned); the rest is halo
  std::span<const std::uint64_t> input;  // input index per sample (a part); empty: itself
  std::vector<vec3d> local;              // world − origin, double
  std::vector<std::uint32_t> rep;        // representative of each sample's duplicates (itself)
  std::vector<std::uint32_t> order;      // octree order of the samples
  std::vector<build_node> nodes;
  std::vector<std::uint32_t> leaf_nodes;
  std::vector<std::uint32_t> block_nodes;                // one triangulation each
  std::vector<std::vector<std::uint32_t>> block_leaves;  // per block: its leaves
  std::vector<leaf_result> results;

  builder(const point_cloud& c, const pmr_options& o, std::uint32_t own,
          std::span<const std::uint64_t> in = {})
      : cloud(c), opt(o), owned(own), input(in) {}

  /// A sample's index in the whole input: ties and neighbour order follow it.
  [[nodiscard]] std::uint64_t key(std::uint32_t i) const { return input.empty() ? i : input[i]; }

  /// Samples equal to an earlier one (exactly, as stored) are duplicates: one triangulation
  /// vertex for all of them, the others at level 0 only.
  std::size_t find_duplicates() {
    const std::size_t n = cloud.size();
    std::vector<std::uint32_t> idx(n);
    std::iota(idx.begin(), idx.end(), 0u);
    const auto& P = cloud.positions;
    const auto less = [&](std::uint32_t a, std::uint32_t b) {
      if (P[a].x() != P[b].x()) return P[a].x() < P[b].x();
      if (P[a].y() != P[b].y()) return P[a].y() < P[b].y();
      if (P[a].z() != P[b].z()) return P[a].z() < P[b].z();
      return key(a) < key(b);
    };
    std::sort(idx.begin(), idx.end(), less);
    rep.resize(n);
    std::size_t dups = 0;
    for (std::size_t k = 0; k < n; ++k) {
      if (k > 0 && P[idx[k]] == P[idx[k - 1]]) {
        rep[idx[k]] = rep[idx[k - 1]];
        dups += idx[k] < owned ? 1 : 0;  // a part counts its own, not its halo's
      } else {
        rep[idx[k]] = idx[k];
      }
    }
    return dups;
  }

  /// The leaf's own unique samples, then every unique sample of other leaves (and of the halo)
  /// within the margin of its cube, in input order; relative to the cube's centre. A node whose
  /// cell misses the margin box is skipped; its cell is widened by a millionth of its size, as
  /// a sample on its upper face may lie an ulp outside it.
  void gather(std::uint32_t node, std::vector<std::uint32_t>& ids, std::vector<vec3d>& pts,
              std::uint32_t& own) const {
    const build_node& L = nodes[node];
    ids.clear();
    for (std::uint32_t j = L.begin; j < L.end; ++j)
      if (rep[order[j]] == order[j]) ids.push_back(order[j]);
    own = static_cast<std::uint32_t>(ids.size());
    const double m = static_cast<double>(opt.neighbour_margin) * L.size;
    const vec3d lo = L.lo - vec3d::Constant(m), hi = L.lo + vec3d::Constant(L.size + m);
    std::vector<std::uint32_t> stack{0};
    while (!stack.empty()) {
      const build_node& nd = nodes[stack.back()];
      const std::uint32_t k = stack.back();
      stack.pop_back();
      if (k == node) continue;
      const double slack = nd.size * 1e-6;
      const vec3d nhi = nd.lo + vec3d::Constant(nd.size + slack);
      const vec3d nlo = nd.lo - vec3d::Constant(slack);
      if ((nhi.array() < lo.array()).any() || (nlo.array() > hi.array()).any()) continue;
      if (!nd.leaf) {
        for (std::uint32_t c = nd.first; c < nd.first + nd.count; ++c) stack.push_back(c);
        continue;
      }
      // A leaf the box touches: all its samples (the paper's rule), or those in the box.
      for (std::uint32_t j = nd.begin; j < nd.end; ++j) {
        const std::uint32_t i = order[j];
        if (rep[i] != i) continue;
        const vec3d& p = local[i];
        if (opt.neighbour_leaves ||
            ((p.array() >= lo.array()).all() && (p.array() <= hi.array()).all()))
          ids.push_back(i);
      }
    }
    for (auto i = owned; i < local.size(); ++i) {
      const vec3d& p = local[i];
      if (rep[i] == i && (p.array() >= lo.array()).all() && (p.array() <= hi.array()).all())
        ids.push_back(i);
    }
    // Neighbours in input order, so the triangulation's insertion does not depend on the
    // traversal above (nor on which chunk a neighbour came from).
    std::sort(ids.begin() + own, ids.end(),
              [&](std::uint32_t a, std::uint32_t b) { return key(a) < key(b); });
    const vec3d c = L.lo + vec3d::Constant(L.size / 2);
    pts.resize(ids.size());
    for (std::size_t k = 0; k < ids.size(); ++k) pts[k] = local[ids[k]] - c;
  }

  /// The triangulations (docs/pmr.md, deviations: "Triangulations"): the highest octree nodes
  /// holding at most triangulation_points samples (a leaf holding more is one by itself), in
  /// node order; and for each, its leaves in sample order.
  void find_blocks() {
    std::vector<std::uint32_t> stack{0};
    while (!stack.empty()) {
      const std::uint32_t k = stack.back();
      stack.pop_back();
      const build_node& nd = nodes[k];
      if (nd.leaf || nd.end - nd.begin <= opt.triangulation_points) {
        block_nodes.push_back(k);
        continue;
      }
      for (std::uint32_t c = nd.first; c < nd.first + nd.count; ++c) stack.push_back(c);
    }
    std::sort(block_nodes.begin(), block_nodes.end());
    std::vector<std::uint32_t> leaf_index(nodes.size(), 0);
    for (std::uint32_t l = 0; l < leaf_nodes.size(); ++l) leaf_index[leaf_nodes[l]] = l;
    block_leaves.assign(block_nodes.size(), {});
    for (std::size_t b = 0; b < block_nodes.size(); ++b) {
      stack.assign(1, block_nodes[b]);
      while (!stack.empty()) {
        const std::uint32_t k = stack.back();
        stack.pop_back();
        if (nodes[k].leaf) {
          block_leaves[b].push_back(leaf_index[k]);
          continue;
        }
        for (std::uint32_t c = nodes[k].first; c < nodes[k].first + nodes[k].count; ++c)
          stack.push_back(c);
      }
      std::sort(block_leaves[b].begin(), block_leaves[b].end(),
                [&](std::uint32_t a, std::uint32_t c) {
                  return nodes[leaf_nodes[a]].begin < nodes[leaf_nodes[c]].begin;
                });
    }
  }

  /// §2 Point and Triangle hierarchy of the leaves of one block (the Voronoi work, one
  /// triangulation), split into their leaf_results, in input indices.
  void process_block(std::size_t b) {
    std::vector<std::uint32_t> ids;
    std::vector<vec3d> pts;
    std::uint32_t own = 0;
    gather(block_nodes[b], ids, pts, own);
    // The input's normals, when it has them and they are wanted (pmr_options::input_normals).
    std::vector<vec3d> given;
    const bool with_normals = opt.input_normals && !cloud.normals.empty();
    if (with_normals) {
      given.resize(ids.size());
      for (std::size_t k = 0; k < ids.size(); ++k) {
        const vec3d g = cloud.normals[ids[k]].cast<double>();
        given[k] = g.squaredNorm() > 0 ? vec3d(g.normalized()) : vec3d::Zero();
      }
    }
    pmr_cell_output c =
        pmr_process_cell({pts, own, opt.rho, opt.cocone_degrees, opt.edge_spacing, given});
    // The block's own samples are its leaves' unique samples, leaf after leaf (sample order).
    const auto& leaves = block_leaves[b];
    std::vector<std::uint32_t> which(own), at(own);
    std::uint32_t k = 0;
    for (std::uint32_t w = 0; w < leaves.size(); ++w) {
      const build_node& L = nodes[leaf_nodes[leaves[w]]];
      leaf_result& r = results[leaves[w]];
      r = {};
      for (std::uint32_t j = L.begin; j < L.end; ++j) {
        if (rep[order[j]] != order[j]) continue;
        which[k] = w;
        at[k] = static_cast<std::uint32_t>(r.own.size());
        r.own.push_back(ids[k]);
        r.levels.push_back(c.levels[k]);
        r.normal.push_back(with_normals && given[k].squaredNorm() > 0 ? given[k].cast<float>()
                                                                      : c.normal[k].cast<float>());
        r.hull.push_back(c.hull[k]);
        ++k;
      }
      r.flat = c.dimension < 3;
      r.lv.resize(c.umbrellas.size());
    }
    results[leaves.front()].triangulated = pts.size();
    results[leaves.front()].removals = c.removals;
    for (std::size_t l = 0; l < c.umbrellas.size(); ++l) {
      const auto& src = c.umbrellas[l];
      for (std::size_t e = 0; e < src.sample.size(); ++e) {
        const std::uint32_t i = src.sample[e];
        auto& dst = results[leaves[which[i]]].lv[l];
        if (dst.first.empty()) dst.first.push_back(0);
        dst.sample.push_back(at[i]);
        for (std::uint32_t t = src.first[e]; t < src.first[e + 1]; ++t)
          dst.tris.push_back({ids[src.tris[t][0]], ids[src.tris[t][1]], ids[src.tris[t][2]]});
        dst.first.push_back(static_cast<std::uint32_t>(dst.tris.size()));
        dst.radius.push_back(static_cast<float>(src.radius[e]));
      }
    }
    for (const std::uint32_t l : leaves)
      for (auto& lv : results[l].lv)
        if (lv.first.empty()) lv.first.push_back(0);
  }

  void process_leaves(pmr_build_stats& st) {
    const unsigned threads = resolve_threads(opt.threads);
    results.assign(leaf_nodes.size(), {});
    find_blocks();
    // Largest blocks first: the last to start is a small one.
    std::vector<std::uint32_t> by_size(block_nodes.size());
    std::iota(by_size.begin(), by_size.end(), 0u);
    std::stable_sort(by_size.begin(), by_size.end(), [&](std::uint32_t a, std::uint32_t b) {
      const build_node &x = nodes[block_nodes[a]], &y = nodes[block_nodes[b]];
      return x.end - x.begin > y.end - y.begin;
    });
    std::atomic<std::size_t> done{0};
    std::atomic<bool> cancel{false};
    const auto caller = std::this_thread::get_id();
    parallel_tasks(block_nodes.size(), threads, [&](std::size_t k, unsigned) {
      if (cancel.load()) return;
      process_block(by_size[k]);
      const std::size_t d = ++done;
      if (opt.progress && std::this_thread::get_id() == caller &&
          !opt.progress(0.05 +
                        0.9 * static_cast<double>(d) / static_cast<double>(block_nodes.size())))
        cancel.store(true);
    });
    if (cancel.load()) throw Cancelled("build_pmr: cancelled");
    for (const auto& r : results) {
      st.triangulated_points += r.triangulated;
      st.removals += r.removals;
      st.flat_leaves += r.flat ? 1 : 0;
      for (const auto h : r.hull) st.hull_points += h;
    }
  }

  /// §2 Records: samples leaf by leaf, most persistent first; per leaf and level the distinct
  /// triangles (global sample indices, each once) and each sample's umbrella into them.
  void assemble(pmr_data& d) {
    const std::size_t n = cloud.size();
    const std::uint32_t levels = static_cast<std::uint32_t>(opt.rho.size() + 1);
    // Levels per input sample and where its umbrellas are in its leaf's result.
    std::vector<std::uint8_t> lev(n, 1);
    std::vector<std::uint32_t> own_pos(n, std::numeric_limits<std::uint32_t>::max());
    for (const auto& r : results)
      for (std::size_t k = 0; k < r.own.size(); ++k) {
        lev[r.own[k]] = r.levels[k];
        own_pos[r.own[k]] = static_cast<std::uint32_t>(k);
      }
    // Global order.
    std::vector<std::uint32_t> global(n);
    d.source.clear();
    d.source.reserve(n);
    d.leaf_list.resize(leaf_nodes.size());
    for (std::size_t l = 0; l < leaf_nodes.size(); ++l) {
      const build_node& L = nodes[leaf_nodes[l]];
      std::vector<std::uint32_t> s(order.begin() + L.begin, order.begin() + L.end);
      std::sort(s.begin(), s.end(), [&](std::uint32_t a, std::uint32_t b) {
        return lev[a] != lev[b] ? lev[a] > lev[b] : a < b;
      });
      d.leaf_list[l] = {static_cast<std::uint32_t>(d.source.size()),
                        static_cast<std::uint32_t>(s.size()), leaf_nodes[l]};
      for (const std::uint32_t i : s) {
        global[i] = static_cast<std::uint32_t>(d.source.size());
        d.source.push_back(i);
      }
    }
    add_foreign(d, global);
    const std::size_t total = d.source.size();
    d.positions.resize(total);
    d.normals.assign(total, vec3f::Zero());
    for (std::size_t g = 0; g < total; ++g) d.positions[g] = local[d.source[g]].cast<float>();
    // Colours travel with their samples (every level is a subset of the input).
    d.colours.clear();
    if (!cloud.colours.empty()) {
      d.colours.resize(total);
      for (std::size_t g = 0; g < total; ++g) d.colours[g] = cloud.colours[d.source[g]];
    }
    for (const auto& r : results)
      for (std::size_t k = 0; k < r.own.size(); ++k) d.normals[global[r.own[k]]] = r.normal[k];
    // Levels.
    d.levels.assign(leaf_nodes.size() * levels, {});
    d.triangles.clear();
    d.umbrellas.clear();
    d.umbrella_index.clear();
    std::vector<std::array<std::uint32_t, 3>> tris;
    std::vector<std::int64_t> entry_of;  // own index → position in the level's sample list
    for (std::size_t l = 0; l < leaf_nodes.size(); ++l) {
      const auto& r = results[l];
      const auto& leaf = d.leaf_list[l];
      for (std::uint32_t li = 0; li < levels; ++li) {
        const auto& src = r.lv[li];
        entry_of.assign(r.own.size(), -1);
        for (std::size_t k = 0; k < src.sample.size(); ++k)
          entry_of[src.sample[k]] = static_cast<std::int64_t>(k);
        pmr_level& L = d.levels[l * levels + li];
        std::uint32_t count = 0;
        while (count < leaf.point_count && lev[d.source[leaf.first_point + count]] > li) ++count;
        L.points = count;
        // Distinct triangles of the level, in global indices, sorted.
        tris.clear();
        for (const auto& t : src.tris) {
          std::array<std::uint32_t, 3> g{global[t[0]], global[t[1]], global[t[2]]};
          std::sort(g.begin(), g.end());
          tris.push_back(g);
        }
        std::sort(tris.begin(), tris.end());
        tris.erase(std::unique(tris.begin(), tris.end()), tris.end());
        L.first_tri = static_cast<std::uint32_t>(d.triangles.size());
        L.tris = static_cast<std::uint32_t>(tris.size());
        d.triangles.insert(d.triangles.end(), tris.begin(), tris.end());
        L.first_entry = static_cast<std::uint32_t>(d.umbrellas.size());
        double sum = 0;
        std::size_t with = 0;
        for (std::uint32_t k = 0; k < count; ++k) {
          const std::uint32_t i = d.source[leaf.first_point + k];
          pmr_umbrella u;
          u.first = static_cast<std::uint32_t>(d.umbrella_index.size());
          const std::uint32_t op = own_pos[i];
          if (rep[i] == i && op != std::numeric_limits<std::uint32_t>::max() && entry_of[op] >= 0) {
            const auto e = static_cast<std::size_t>(entry_of[op]);
            for (std::uint32_t j = src.first[e]; j < src.first[e + 1]; ++j) {
              const auto& t = src.tris[j];
              std::array<std::uint32_t, 3> g{global[t[0]], global[t[1]], global[t[2]]};
              std::sort(g.begin(), g.end());
              const auto it = std::lower_bound(tris.begin(), tris.end(), g);
              d.umbrella_index.push_back(static_cast<std::uint32_t>(it - tris.begin()));
            }
            u.count = static_cast<std::uint32_t>(d.umbrella_index.size()) - u.first;
            u.radius = u.count ? src.radius[e] : 0.0f;
          }
          if (u.count) {
            sum += u.radius;
            ++with;
          }
          d.umbrellas.push_back(u);
        }
        L.mean_umbrella = with ? static_cast<float>(sum / static_cast<double>(with)) : 0.0f;
      }
    }
    orient(d, levels);
    for (std::size_t g = 0; g < owned; ++g) {
      const std::uint32_t i = d.source[g];
      if (rep[i] != i) d.normals[g] = d.normals[global[rep[i]]];
    }
  }

  /// A part's triangle vertices in its halo: samples after the own ones, in input order.
  void add_foreign(pmr_data& d, std::vector<std::uint32_t>& global) const {
    if (owned == local.size()) return;
    std::vector<std::uint32_t> f;
    for (const auto& r : results)
      for (const auto& lv : r.lv)
        for (const auto& t : lv.tris)
          for (const std::uint32_t i : t)
            if (i >= owned) f.push_back(i);
    std::sort(f.begin(), f.end(),
              [&](std::uint32_t a, std::uint32_t b) { return key(a) < key(b); });
    f.erase(std::unique(f.begin(), f.end()), f.end());
    for (const std::uint32_t i : f) {
      global[i] = static_cast<std::uint32_t>(d.source.size());
      d.source.push_back(i);
    }
    d.foreign = static_cast<std::uint32_t>(f.size());
  }

  /// The pole vector gives a normal's line, not its side (the farthest Voronoi vertex may be
  /// inside or outside). Sides are made consistent: with the input's normals when it has them,
  /// else by Hoppe et al.'s propagation (1992) over the level-0 umbrella edges, most parallel
  /// neighbours first, each connected part seeded by its sample farthest from the centre with
  /// the normal pointing away from it. Then each triangle is wound counter-clockwise about its
  /// vertices' normals (the rasteriser shades a triangle seen from its back as such).
  void orient(pmr_data& d, std::uint32_t levels) const {
    const std::size_t n = owned;  // a part's foreign samples are oriented by their own chunk
    if (n >= std::numeric_limits<std::uint32_t>::max()) return;  // validated; bounds n for GCC
    if (!cloud.normals.empty()) {
      for (std::size_t g = 0; g < n; ++g)
        if (d.normals[g].dot(cloud.normals[d.source[g]]) < 0) d.normals[g] = -d.normals[g];
    } else {
      std::vector<std::pair<std::uint32_t, std::uint32_t>> edges;
      for (std::size_t l = 0; l < d.leaf_list.size(); ++l) {
        const pmr_level& L = d.levels[l * levels];
        for (std::uint32_t t = L.first_tri; t < L.first_tri + L.tris; ++t) {
          const auto& T = d.triangles[t];
          for (int k = 0; k < 3; ++k) {
            if (T[k] >= n || T[(k + 1) % 3] >= n) continue;
            edges.emplace_back(T[k], T[(k + 1) % 3]);
            edges.emplace_back(T[(k + 1) % 3], T[k]);
          }
        }
      }
      std::sort(edges.begin(), edges.end());
      edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
      std::vector<std::uint32_t> start(n + 1, 0);
      for (const auto& e : edges) ++start[e.first + 1];
      for (std::size_t g = 0; g < n; ++g) start[g + 1] += start[g];
      std::vector<std::uint32_t> seeds(n);
      std::iota(seeds.begin(), seeds.end(), 0u);
      std::vector<float> dist(n);
      for (std::size_t g = 0; g < n; ++g) dist[g] = d.positions[g].squaredNorm();
      std::sort(seeds.begin(), seeds.end(), [&](std::uint32_t a, std::uint32_t b) {
        return dist[a] != dist[b] ? dist[a] > dist[b] : a < b;
      });
      std::vector<unsigned char> done(n, 0);
      using item =
          std::pair<float, std::pair<std::uint32_t, std::uint32_t>>;  // (|dot|, (to, from))
      std::priority_queue<item> q;
      for (const std::uint32_t s : seeds) {
        if (done[s]) continue;
        if (d.normals[s].dot(d.positions[s]) < 0) d.normals[s] = -d.normals[s];
        done[s] = 1;
        q.push({2.0f, {s, s}});
        while (!q.empty()) {
          const auto [w, e] = q.top();
          q.pop();
          const auto [to, from] = e;
          if (to != from) {
            if (done[to]) continue;
            done[to] = 1;
            if (d.normals[to].dot(d.normals[from]) < 0) d.normals[to] = -d.normals[to];
          }
          for (std::uint32_t k = start[to]; k < start[to + 1]; ++k) {
            const std::uint32_t m = edges[k].second;
            if (!done[m]) q.push({std::abs(d.normals[m].dot(d.normals[to])), {m, to}});
          }
        }
      }
    }
    if (d.foreign == 0) pmr_wind_triangles(d);
  }

  /// Bounding spheres: a leaf's holds its samples and every vertex of its umbrella triangles
  /// (which may belong to neighbouring leaves); an inner node's holds its children's.
  void node_records(pmr_data& d) const {
    const std::uint32_t levels = static_cast<std::uint32_t>(opt.rho.size() + 1);
    d.nodes.resize(nodes.size());
    for (std::size_t k = 0; k < nodes.size(); ++k) {
      const build_node& b = nodes[k];
      pmr_node& nd = d.nodes[k];
      nd.cell_min = b.lo.cast<float>();
      nd.cell_size = static_cast<float>(b.size);
      nd.first = b.first;
      nd.count = b.leaf ? 0 : b.count;
      nd.leaf = b.leaf ? 1 : 0;
      nd.depth = b.depth;
    }
    for (std::uint32_t l = 0; l < d.leaf_list.size(); ++l) {
      const auto& leaf = d.leaf_list[l];
      pmr_node& nd = d.nodes[leaf.node];
      nd.first = l;
      vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
      const auto add = [&](std::uint32_t g) {
        const vec3d p = d.positions[g].cast<double>();
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
      };
      for (std::uint32_t g = leaf.first_point; g < leaf.first_point + leaf.point_count; ++g) add(g);
      for (std::uint32_t li = 0; li < levels; ++li) {
        const auto& L = d.levels[static_cast<std::size_t>(l) * levels + li];
        for (std::uint32_t t = L.first_tri; t < L.first_tri + L.tris; ++t)
          for (const std::uint32_t g : d.triangles[t]) add(g);
      }
      const vec3d c = 0.5 * (lo + hi);
      double r2 = 0;
      const auto far = [&](std::uint32_t g) {
        r2 = std::max(r2, (d.positions[g].cast<double>() - c).squaredNorm());
      };
      for (std::uint32_t g = leaf.first_point; g < leaf.first_point + leaf.point_count; ++g) far(g);
      for (std::uint32_t li = 0; li < levels; ++li) {
        const auto& L = d.levels[static_cast<std::size_t>(l) * levels + li];
        for (std::uint32_t t = L.first_tri; t < L.first_tri + L.tris; ++t)
          for (const std::uint32_t g : d.triangles[t]) far(g);
      }
      nd.centre = c.cast<float>();
      nd.radius = outward(std::sqrt(r2) + (c - nd.centre.cast<double>()).norm());
    }
    // Children come after their parent (breadth-first): bottom-up is a reverse sweep.
    for (std::size_t k = nodes.size(); k-- > 0;) {
      pmr_node& nd = d.nodes[k];
      if (!nd.leaf)
        pmr_bound_inner(nd, std::span<const pmr_node>(d.nodes).subspan(nd.first, nd.count));
    }
  }
};

/// The octree, the leaves' Voronoi work and the records of d (its origin, bounds and options
/// set).
void build_into(builder& b, pmr_data& d, const pmr_cell& root) {
  const pmr_options& opt = b.opt;
  d.max_leaf_points = opt.max_leaf_points;
  d.neighbour_margin = opt.neighbour_margin;
  d.rho = opt.rho;
  b.local.resize(b.cloud.size());
  for (std::size_t i = 0; i < b.cloud.size(); ++i) b.local[i] = b.cloud.world(i) - d.origin;
  d.stats.input_points = b.owned;
  d.stats.duplicates = b.find_duplicates();
  b.nodes = build_octree(b.local, b.owned, root, b.order, opt);
  for (std::uint32_t k = 0; k < b.nodes.size(); ++k)
    if (b.nodes[k].leaf) b.leaf_nodes.push_back(k);
  b.process_leaves(d.stats);
  b.assemble(d);
  b.node_records(d);
}

}  // namespace

void pmr_wind_triangles(pmr_data& d) {
  for (auto& T : d.triangles) {
    // Vertices in input order first: a chunk of a chunked build numbers its samples otherwise
    // but stores the same vertex order, so both draw the same triangle the same way.
    std::sort(T.begin(), T.end(),
              [&](std::uint32_t a, std::uint32_t b) { return d.source[a] < d.source[b]; });
    const vec3f g =
        (d.positions[T[1]] - d.positions[T[0]]).cross(d.positions[T[2]] - d.positions[T[0]]);
    if (g.dot(d.normals[T[0]] + d.normals[T[1]] + d.normals[T[2]]) < 0) std::swap(T[1], T[2]);
  }
}

void pmr_bound_inner(pmr_node& nd, std::span<const pmr_node> children) {
  vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const pmr_node& ch : children) {
    const vec3d cc = ch.centre.cast<double>();
    lo = lo.cwiseMin(cc - vec3d::Constant(ch.radius));
    hi = hi.cwiseMax(cc + vec3d::Constant(ch.radius));
  }
  const vec3d c = 0.5 * (lo + hi);
  double r = 0;
  for (const pmr_node& ch : children)
    r = std::max(r, (ch.centre.cast<double>() - c).norm() + ch.radius);
  nd.centre = c.cast<float>();
  nd.radius = outward(r + (c - nd.centre.cast<double>()).norm());
}

pmr_data build_pmr_data(const point_cloud& cloud, const pmr_options& opt) {
  const auto t0 = std::chrono::steady_clock::now();
  validate(cloud, opt);
  if (opt.progress && !opt.progress(0)) throw Cancelled("build_pmr: cancelled");
  builder b(cloud, opt, static_cast<std::uint32_t>(cloud.size()));
  pmr_data d;
  // A double-precision origin at the centre of the input's box: everything below (octree,
  // triangulations, stored floats) is relative to it.
  vec3d lo = cloud.world(0), hi = lo;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const vec3d w = cloud.world(i);
    lo = lo.cwiseMin(w);
    hi = hi.cwiseMax(w);
  }
  d.origin = 0.5 * (lo + hi);
  d.input_min = lo;
  d.input_max = hi;
  // The local box is the world box moved by the origin: rounding is monotonic, so the extremes
  // of the moved points are the moved extremes (the chunked build relies on it).
  build_into(b, d, pmr_root_cell(lo - d.origin, hi - d.origin));
  if (opt.progress && !opt.progress(1)) throw Cancelled("build_pmr: cancelled");
  d.stats.build_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return d;
}

pmr_data build_pmr_part(const pmr_part_input& in, const pmr_options& opt) {
  validate_pmr_options(opt);
  if (in.owned == 0 || in.owned > in.cloud.size() || in.input.size() != in.cloud.size())
    throw InvalidArgument("build_pmr_part: inconsistent chunk");
  builder b(in.cloud, opt, in.owned, in.input);
  pmr_data d;
  d.origin = in.origin;
  d.input_min = in.input_min;
  d.input_max = in.input_max;
  build_into(b, d, in.root);
  for (auto& s : d.source) s = static_cast<std::uint32_t>(in.input[s]);
  d.input_total = in.input_total;
  return d;
}

}  // namespace pbr_lod::detail
