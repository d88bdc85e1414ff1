// pbr_lod — the POP builder. This work is based on:
//   B. Chen, M. X. Nguyen, "POP: A Hybrid Point and Polygon Rendering System for Large Data",
//   IEEE Visualization 2001 (section-by-section map in builders/pop.hpp and docs/pop.md).
// build_pop_data() runs the paper's steps as named stages of pop_build_state, in order:
//   prepare()            §3.5  vertices quantised to 16 bits; leaves = ≤ 4 edge-adjacent triangles
//   colour_vertices/faces §3.1 per-triangle colour (texel average or vertex average)
//   leaf_keys(), partition_leaves(), lay_out_nodes()  §3.1 topology: median splits, 4-ary tree
//   spheres_and_cones()  §3.1  bounding spheres, averaged normals/colours, normal cones, bottom up
//   quantise_spheres()   §3.5  QSplat-style sphere codes, top down
// The stages share pop_build_state (pop_build_state.hpp); stage 1 is in pop_adjacency.cpp, stages 4
// and 5 in pop_spheres.cpp, stages 2 and 3 and the driver here. The file format is in pop_io.cpp.
#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <exception>
#include <fstream>
#include <mutex>
#include <numeric>
#include <optional>
#include <span>
#include <thread>

#include "lanes.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/mesh_normals.hpp"
#include "pop_build_state.hpp"

namespace pbr_lod::detail::pop_stages {

namespace {
// ---- the leaves' split keys (§3.1 topology) ----------------------------------------------------
/// Order-preserving map of a finite float to an unsigned integer (−0 maps as +0, so equal floats
/// map to equal integers), and back.
std::uint32_t ordered_bits(float f) {
  const auto u = std::bit_cast<std::uint32_t>(f + 0.0f);  // + 0.0f turns −0 into +0
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}
float from_ordered_bits(std::uint32_t u) {
  return std::bit_cast<float>((u & 0x80000000u) ? (u & 0x7fffffffu) : ~u);
}
/// The split order along axis K, (key, leaf index), as one integer: a total order.
template <int K>
std::uint64_t rank_on(const split_key& x) {
  return std::uint64_t{x.k[K]} << 32 | x.id;
}
/// std::nth_element(a, a + m, a + n) by rank_on<K>: the element of rank m at a[m], the smaller
/// ones before it, the larger after. Quickselect with a median-of-three pivot and a branch-free
/// (Lomuto) partition: which side a key falls on is a coin toss, and the branches on it were most
/// of std::nth_element's time. After 64 rounds (a pathological input) std::nth_element finishes,
/// so the worst case stays O(n log n).
template <int K>
void select_rank(split_key* a, std::size_t n, std::size_t m) {
  const auto less = [](const split_key& x, const split_key& y) {
    return rank_on<K>(x) < rank_on<K>(y);
  };
  std::size_t lo = 0, hi = n;
  for (int round = 0; hi - lo > 16; ++round) {
    if (round == 64) {
      std::nth_element(a + lo, a + m, a + hi, less);
      return;
    }
    std::size_t i0 = lo, i1 = lo + (hi - lo) / 2, i2 = hi - 1;
    if (less(a[i1], a[i0])) std::swap(i0, i1);
    if (less(a[i2], a[i1])) i1 = less(a[i2], a[i0]) ? i0 : i2;
    std::swap(a[i1], a[hi - 1]);
    const std::uint64_t pivot = rank_on<K>(a[hi - 1]);
    std::size_t i = lo;
    for (std::size_t j = lo; j < hi - 1; ++j) {
      const split_key t = a[j];
      const bool smaller = rank_on<K>(t) < pivot;
      a[j] = a[i];
      a[i] = t;
      i += smaller ? 1 : 0;
    }
    std::swap(a[i], a[hi - 1]);
    if (m == i) return;
    if (m < i)
      hi = i;
    else
      lo = i + 1;
  }
  std::sort(a + lo, a + hi, less);
}
}  // namespace

/// The checks build_pop_data() makes before any work (InvalidArgument on each).
void check_pop_input(const triangle_mesh& mesh, const pop_options& opt, bool colour) {
  if (opt.max_leaf_triangles < 1 || opt.max_leaf_triangles > 4)
    throw InvalidArgument("build_pop: max_leaf_triangles must be 1..4, got " +
                          std::to_string(opt.max_leaf_triangles));
  if (opt.spheres != pop_sphere_rule::paper && opt.spheres != pop_sphere_rule::exact)
    throw InvalidArgument("build_pop: unknown sphere rule");
  (void)normal_quantizer::shared(opt.normal_bits);  // throws on bad bits
  mesh.validate("build_pop");
  if (mesh.faces.empty()) throw InvalidArgument("build_pop: the mesh has no triangles");
  if (mesh.faces.size() >= none || mesh.num_vertices() >= none)
    throw InvalidArgument("build_pop: more than 2^32 - 1 vertices or triangles");
  if (opt.adjacency == pop_adjacency::edge_sort && mesh.faces.size() > none / 3)
    throw InvalidArgument(
        "build_pop: the edge-sort adjacency indexes 3 edges per face in 32 bits: at most " +
        std::to_string(none / 3) + " triangles");
  const bool textured = !mesh.face_texcoords.empty() && mesh.texture != nullptr;
  if (colour && !textured && mesh.vertices.colours.empty())
    throw InvalidArgument(
        "build_pop: colours requested but the mesh has neither vertex colours nor a texture" +
        std::string(mesh.texture_path.empty() || mesh.face_texcoords.empty()
                        ? ""
                        : " (" + mesh.texture_path +
                              " was not loaded: read_mesh's report says why)") +
        " (build pop_tree<with_normals> instead)");
}

// ---- Stage 2 (§3.1): colours ----------------------------------------------------------------

/// Vertex colours, or with a texture the texel under each corner averaged per vertex.
void pop_build_state::colour_vertices() {
  if (textured) {
    tex.img = *mesh.texture;
    if (tex.img.width <= 0 || tex.img.height <= 0)
      throw InvalidArgument("build_pop: " + mesh.texture_path + ": empty texture");
    if (tex.img.texels.size() !=
        static_cast<std::size_t>(tex.img.width) * static_cast<std::size_t>(tex.img.height))
      throw InvalidArgument("build_pop: " + mesh.texture_path +
                            ": texel count does not match the size");
    for (std::size_t f = 0; f < nf; ++f)
      for (const auto& uv : mesh.face_texcoords[f])
        if (!all_finite(uv))
          throw InvalidArgument("build_pop: face " + std::to_string(f) +
                                " has a non-finite texture coordinate");
    std::vector<rgb_sum> acc(nv);
    for (std::size_t f = 0; f < nf; ++f)
      for (std::size_t k = 0; k < 3; ++k) {
        const vec2d t = tex.texel(mesh.face_texcoords[f][k]);
        acc[mesh.faces[f][k]].add(tex.at(t.x(), t.y()));
      }
    d.colours.resize(nv);
    for (std::size_t i = 0; i < nv; ++i) d.colours[i] = acc[i].n > 0 ? acc[i].mean() : rgb8{};
  } else {
    d.colours = mesh.vertices.colours;
  }
}

/// Per triangle colour (§3.1: the average of the texels inside it, or of its vertices'). The
/// triangles' normals and spheres are computed where they are used, in the bottom-up pass over
/// the leaves (each triangle is in exactly one leaf): no per-face arrays (the double centres and
/// radii alone were 64 MB for 2 M triangles).
void pop_build_state::colour_faces() {
  face_colour.resize(nf);
  for_pieces(nf, threads, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t f = lo; f < hi; ++f) {
      if (textured) {
        face_colour[f] = tex.average(mesh.face_texcoords[f]);
      } else {
        rgb_sum s;
        for (auto i : mesh.faces[f]) s.add(d.colours[i]);
        face_colour[f] = s.mean();
      }
    }
  });
}

// ---- Stage 3 (§3.1 topology, QSplat): median splits over the leaves --------------------------

/// Split key of a leaf: the mean of its triangles' corners, stored with the leaf's index so
/// that the splits run over one contiguous array (no indirection through a permutation).
void pop_build_state::leaf_keys() {
  resize_fresh(perm, n_leaves, threads);
  for_pieces(n_leaves, threads, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t g = lo; g < hi; ++g) {
      vec3d s = vec3d::Zero();
      for (std::uint32_t k = gstart[g]; k < gstart[g + 1]; ++k)
        for (auto i : mesh.faces[gfaces[k]]) s += d.positions[i].cast<double>();
      const vec3f key = (s / (3.0 * (gstart[g + 1] - gstart[g]))).cast<float>();
      perm[g] = {{ordered_bits(key.x()), ordered_bits(key.y()), ordered_bits(key.z())},
                 static_cast<std::uint32_t>(g)};
    }
  });
}

/// Orders perm[lo, hi) about its median on the longest axis of its keys' box; returns where.
std::uint32_t pop_build_state::split(std::uint32_t lo, std::uint32_t hi) {
  // The box of the keys, in the order-preserving integers (the same extremes as in float).
  std::array<std::uint32_t, 3> mn{~0u, ~0u, ~0u}, mx{0u, 0u, 0u};
  for (std::uint32_t i = lo; i < hi; ++i)
    for (std::size_t k = 0; k < 3; ++k) {
      mn[k] = std::min(mn[k], perm[i].k[k]);
      mx[k] = std::max(mx[k], perm[i].k[k]);
    }
  vec3f e;
  for (std::size_t k = 0; k < 3; ++k)
    e[static_cast<int>(k)] = from_ordered_bits(mx[k]) - from_ordered_bits(mn[k]);
  const int axis = (e.x() >= e.y() && e.x() >= e.z()) ? 0 : (e.y() >= e.z() ? 1 : 2);
  const std::uint32_t mid = mid_of(lo, hi);
  if (axis == 0)
    select_rank<0>(perm.data() + lo, hi - lo, mid - lo);
  else if (axis == 1)
    select_rank<1>(perm.data() + lo, hi - lo, mid - lo);
  else
    select_rank<2>(perm.data() + lo, hi - lo, mid - lo);
  return mid;
}

/// The depth-first recursive binary partition of perm[lo, hi).
void pop_build_state::partition(std::uint32_t lo, std::uint32_t hi) {
  if (hi - lo <= 1) return;
  const std::uint32_t m = split(lo, hi);
  partition(lo, m);
  partition(m, hi);
}

/// The breadth-first node list. It depends on the number of leaves alone (where each range
/// splits), not on the order of `perm`.
void pop_build_state::build_topology() {
  reserve_huge(tn, 2 * n_leaves);
  tn.push_back({0, static_cast<std::uint32_t>(n_leaves)});
  for (std::size_t a = 0; a < tn.size();) {
    const std::size_t b = tn.size();
    levels.emplace_back(a, b);
    for (std::size_t i = a; i < b; ++i) {
      const std::uint32_t lo = tn[i].lo, hi = tn[i].hi;
      if (hi - lo <= 1) continue;
      const std::uint32_t m = mid_of(lo, hi);
      std::array<std::uint32_t, 5> cut{};
      std::uint32_t k = 0;
      cut[k++] = lo;
      if (m - lo >= 2) cut[k++] = mid_of(lo, m);
      cut[k++] = m;
      if (hi - m >= 2) cut[k++] = mid_of(m, hi);
      cut[k] = hi;  // k parts: cut[0..k]
      tn[i].first = static_cast<std::uint32_t>(tn.size());
      tn[i].count = k;
      const auto depth = static_cast<std::uint16_t>(tn[i].depth + 1);
      for (std::uint32_t j = 0; j < k; ++j)
        tn.push_back({cut[j], cut[j + 1], 0, 0, static_cast<std::uint32_t>(i), depth});
    }
    a = b;
  }
}

/// A node over leaves [lo, hi) of `perm` is split at the median of the longest axis of its
/// keys' box, and each half again: up to four children. The 4-ary tree is therefore the binary
/// median-split tree with every other level merged, and where each split falls
/// (lo + (hi − lo)/2) depends only on lo and hi. So `perm` is ordered first, by a depth-first
/// recursive binary partition (subtrees in parallel; cache-friendly), and the breadth-first node
/// list is then derived from the ranges alone. The order of `perm` does not depend on how the
/// work is scheduled, nor on the selection algorithm: each split selects by a total order (key,
/// leaf id), so the set of leaves in each half is unique, and below a single leaf there is
/// nothing to order.
///
/// The top levels are split one at a time, each level's ranges as tasks on the pool, until there
/// are enough ranges to share out (8 per thread) or they are small; then each range's subtree as
/// one task. The ranges of a level are disjoint, so the order they are done in does not matter.
/// The topology is built beside the partition's first level, which leaves the other threads
/// idle, or after the partition with one thread.
void pop_build_state::partition_leaves() {
  bool topology_built = false;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> ranges{
      {0, static_cast<std::uint32_t>(n_leaves)}};
  while (threads > 1 && ranges.size() < 8 * std::size_t{threads} && n_leaves >= 8192) {
    std::vector<std::pair<std::uint32_t, std::uint32_t>> next(2 * ranges.size());
    bool small = false;
    const bool with_topology = !topology_built;
    parallel_tasks(ranges.size() + (with_topology ? 1 : 0), threads, [&](std::size_t t, unsigned) {
      if (t == ranges.size()) {
        build_topology();
        return;
      }
      const auto [lo, hi] = ranges[t];
      const std::uint32_t m = hi - lo >= 2 ? split(lo, hi) : hi;
      next[2 * t] = {lo, m};
      next[2 * t + 1] = {m, hi};
    });
    topology_built = true;
    ranges.swap(next);
    for (const auto& [lo, hi] : ranges) small = small || hi - lo < 4096;
    if (small) break;
  }
  parallel_tasks(ranges.size(), threads,
                 [&](std::size_t t, unsigned) { partition(ranges[t].first, ranges[t].second); });
  if (!topology_built) build_topology();
  if (levels.size() > 65535) throw InvalidArgument("build_pop: tree deeper than 65535 levels");
}

/// The node records, and each leaf's range of faces in leaf order. Two parallel passes over
/// fixed blocks of nodes: faces per block, then (after a prefix sum) the records; the faces
/// themselves are copied by the bottom-up pass (gather()).
void pop_build_state::lay_out_nodes() {
  const std::size_t nn = tn.size();
  resize_fresh(d.nodes, nn, threads);
  // The adjacency (nf × 3 u32, huge pages) is dead after the grouping: its storage takes the
  // faces (every entry is overwritten by gather()), instead of 24 MB of fresh, zeroed pages.
  d.faces.swap(nbr);
  std::vector<face_slots>().swap(nbr);
  if (d.faces.size() != nf) d.faces.resize(nf);
  if (keep_texture) d.face_texcoords.resize(nf);
  // A leaf's group's members start at gfaces[leaf_members[i]] (one dependent load fewer than
  // through the group's index in the bottom-up pass, where each is a likely cache miss).
  resize_fresh(leaf_members, nn, threads);
  const std::size_t blocks = std::max<std::size_t>(1, std::min<std::size_t>(threads, nn / 4096));
  std::vector<std::uint32_t> block_faces(blocks + 1, 0);
  const auto block_lo = [&](std::size_t t) { return nn * t / blocks; };
  const auto group_of = [&](std::size_t i) { return perm[tn[i].lo].id; };
  detail::parallel_chunks(blocks, threads, 1, [&](std::size_t b0, std::size_t b1) {
    for (std::size_t t = b0; t < b1; ++t) {
      std::uint32_t sum = 0;
      for (std::size_t i = block_lo(t); i < block_lo(t + 1); ++i)
        if (tn[i].count == 0) sum += gstart[group_of(i) + 1] - gstart[group_of(i)];
      block_faces[t + 1] = sum;
    }
  });
  for (std::size_t t = 0; t < blocks; ++t) block_faces[t + 1] += block_faces[t];
  detail::parallel_chunks(blocks, threads, 1, [&](std::size_t b0, std::size_t b1) {
    for (std::size_t t = b0; t < b1; ++t) {
      std::uint32_t next = block_faces[t];
      for (std::size_t i = block_lo(t); i < block_lo(t + 1); ++i) {
        auto& nd = d.nodes[i];
        nd.parent = tn[i].parent;
        nd.depth = tn[i].depth;
        if (tn[i].count == 0) {
          const std::uint32_t g = group_of(i);
          leaf_members[i] = gstart[g];
          nd.leaf = 1;
          nd.first = next;
          nd.count = static_cast<std::uint8_t>(gstart[g + 1] - gstart[g]);
          next += nd.count;
        } else {
          leaf_members[i] = none;
          nd.first = tn[i].first;
          nd.count = static_cast<std::uint8_t>(tn[i].count);
        }
      }
    }
  });
  if (colour) resize_fresh(d.node_colours, nn, threads);
  resize_fresh(d.node_normal_codes, nn, threads);
}

void pop_build_state::finish_stats(clock::time_point t0, clock::time_point t_prep,
                                   clock::time_point t1) {
  auto& st = d.stats;
  st.vertices = nv;
  st.triangles = nf;
  st.nodes = d.nodes.size();
  for (const auto& nd : d.nodes) {
    if (nd.leaf) {
      ++st.leaves;
      ++st.leaves_by_size[nd.count - 1u];
    }
    st.max_depth = std::max<std::size_t>(st.max_depth, nd.depth);
  }
  st.prepare_seconds = std::chrono::duration<double>(t_prep - t0).count();
  st.adjacency_seconds = adjacency_seconds;
  st.tree_seconds = std::chrono::duration<double>(t1 - t_prep).count();
  st.build_seconds = std::chrono::duration<double>(t1 - t0).count();
  st.has_timings = true;
  set_file_stats(d, pop_file_bytes(d));
}

}  // namespace pbr_lod::detail::pop_stages

namespace pbr_lod::detail {

pop_data build_pop_data(const triangle_mesh& mesh, const pop_options& opt, bool colour) {
  using namespace pop_stages;
  using clock = pop_build_state::clock;
  const auto t0 = clock::now();
  check_pop_input(mesh, opt, colour);
  pop_build_state s(mesh, opt, colour);
  s.d.origin = mesh.vertices.origin;
  s.d.normal_bits = opt.normal_bits;
  s.d.spheres = opt.spheres;
  s.d.adjacency = opt.adjacency;
  s.d.quantised_nodes = opt.quantise_nodes;

  s.prepare();  // §3.5 vertex quantisation; leaves from the adjacency
  if (colour) {
    s.colour_vertices();  // §3.1 colours
    s.colour_faces();
  }
  const auto t_prep = clock::now();
  s.leaf_keys();  // §3.1 topology
  s.partition_leaves();
  s.lay_out_nodes();
  s.spheres_and_cones();                         // §3.1 spheres, normals, cones, bottom up
  if (opt.quantise_nodes) s.quantise_spheres();  // §3.5, top down
  if (s.keep_texture) {  // Figure 5: leaves drawn texture-mapped (RGB; alpha is not kept)
    texture_image img = std::move(s.tex.img);
    img.alpha.clear();
    s.d.texture = std::make_shared<const texture_image>(std::move(img));
  }
  s.finish_stats(t0, t_prep, clock::now());
  return std::move(s.d);
}

}  // namespace pbr_lod::detail
