// pbr_lod — the POP builder, stage 1 (Chen & Nguyen 2001 §3.5; the map of the stages is in
// pop_build_state.hpp): the triangle adjacency — a parallel sorted-edge pass or, selectable,
// OpenMesh's halfedge structure (OpenMesh stays in this file) — the leaves as groups of at most
// four edge-adjacent triangles, and the vertices quantised to 16 bits beside it.
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/System/omstream.hh>

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
#include "pbr_lod/core/normal_repair.hpp"
#include "pop_build_state.hpp"

namespace pbr_lod::detail::pop_stages {

namespace {

/// Face–face adjacency through OpenMesh's halfedge structure (the route, kept as
/// pop_adjacency::openmesh). nbr[f][j] = the j-th neighbour of face f in OpenMesh's ff_iter
/// order, `none` past the last. Faces add_face refuses (non-manifold edge or vertex, duplicate,
/// inconsistent orientation, repeated index) get no neighbours and are counted in `isolated`.
void openmesh_adjacency(std::size_t n_vertices, std::span<const std::array<std::uint32_t, 3>> faces,
                        std::vector<face_slots>& nbr, std::size_t& isolated) {
  using om_mesh = OpenMesh::TriMesh_ArrayKernelT<>;
  om_mesh om;
  om.reserve(n_vertices, 3 * faces.size(), faces.size());
  std::vector<om_mesh::VertexHandle> vh(n_vertices);
  for (std::size_t i = 0; i < n_vertices; ++i) vh[i] = om.add_vertex(om_mesh::Point(0, 0, 0));
  std::vector<std::uint32_t> input_of;  // OpenMesh face index -> input face
  input_of.reserve(faces.size());
  std::vector<int> om_of(faces.size(), -1);
  {
    // OpenMesh reports every refused face on omerr; refusals are expected here (and counted).
    static std::mutex mute;
    const std::lock_guard lock(mute);
    const bool was = ::omerr().is_enabled();
    ::omerr().disable();
    for (std::size_t f = 0; f < faces.size(); ++f) {
      const auto& F = faces[f];
      if (F[0] == F[1] || F[1] == F[2] || F[0] == F[2]) continue;
      const auto fh = om.add_face(vh[F[0]], vh[F[1]], vh[F[2]]);
      if (!fh.is_valid()) continue;
      om_of[f] = fh.idx();
      if (static_cast<std::size_t>(fh.idx()) >= input_of.size())
        input_of.resize(static_cast<std::size_t>(fh.idx()) + 1, none);
      input_of[static_cast<std::size_t>(fh.idx())] = static_cast<std::uint32_t>(f);
    }
    if (was) ::omerr().enable();
  }
  nbr.assign(faces.size(), {none, none, none});
  isolated = 0;
  for (std::size_t f = 0; f < faces.size(); ++f) {
    if (om_of[f] < 0) {
      ++isolated;
      continue;
    }
    std::size_t j = 0;
    for (auto it = om.ff_iter(om_mesh::FaceHandle(om_of[f])); it.is_valid() && j < 3; ++it) {
      const std::uint32_t h = input_of[static_cast<std::size_t>(it->idx())];
      if (h != none) nbr[f][j++] = h;
    }
  }
}

/// Face–face adjacency by sorting the undirected edge keys (min vertex, max vertex, face) —
/// pop_adjacency::edge_sort. The sort is a counting sort on the min vertex (CSR buckets) and a
/// small sort on the max vertex inside each bucket, the buckets in parallel: O(n), and no
/// halfedge structure to build. Rules, so that it is defined on any input:
///   - a face repeating a vertex index has no edges (no neighbours; counted in `isolated`);
///   - a face with the same vertex set as an earlier face (in any order or orientation) is a
///     duplicate: no neighbours, counted in `isolated`, and invisible to the other faces;
///   - an edge shared by exactly two remaining faces links them (whatever their orientation);
///   - an edge shared by three or more is non-manifold: it links none of them (`nonmanifold`).
/// nbr[f][k] = the face across edge k (corners k, k+1) of f, or `none`.
///
/// In steps, so that the bucket pass can be shared out piece by piece with other work: the
/// constructor does the counting sort, bucket(lo, hi) the buckets of vertices [lo, hi) (any
/// order, any thread; each slot and mark has one writer), isolated() counts at the end.
class edge_sorter {
 public:
  edge_sorter(std::size_t n_vertices, std::span<const std::array<std::uint32_t, 3>> faces,
              std::vector<face_slots>& nbr)
      : faces_(faces), nbr_(nbr), offset_(n_vertices + 1, 0) {
    const std::size_t nf = faces.size();
    // Bucket sizes by min vertex, then exclusive offsets.
    for (std::size_t f = 0; f < nf; ++f) {
      if (bad(f)) continue;
      const auto& F = faces[f];
      for (std::size_t k = 0; k < 3; ++k) ++offset_[std::min(F[k], F[(k + 1) % 3]) + 1];
    }
    for (std::size_t v = 0; v < n_vertices; ++v) offset_[v + 1] += offset_[v];
    // entry = (max vertex, 3 f + k, the face's third corner), scattered into its min vertex's
    // bucket. With the third corner the duplicate test is local to an edge's run: two faces on
    // the same edge {a, b} (neither repeating a vertex) have the same vertex set exactly when
    // their third corners agree. So a face is a duplicate of an earlier one exactly when, in the
    // run of any of its edges, an earlier face has its third corner, and one pass over the
    // buckets both finds the duplicates and links the edges.
    reserve_huge(e_, offset_[n_vertices]);
    e_.resize(offset_[n_vertices]);
    {
      scratch_vector<std::uint32_t> fill(offset_.begin(), offset_.end() - 1);
      for (std::size_t f = 0; f < nf; ++f) {
        if (bad(f)) continue;
        const auto& F = faces[f];
        for (std::uint32_t k = 0; k < 3; ++k) {
          const std::uint32_t a = F[k], b = F[(k + 1) % 3];
          e_[fill[std::min(a, b)]++] = {std::max(a, b), static_cast<std::uint32_t>(3 * f + k),
                                        F[(k + 2) % 3]};
        }
      }
    }
    reserve_huge(nbr, nf);
    nbr.assign(nf, {none, none, none});
    dup_.assign(nf, 0);
  }
  /// Each bucket of [lo, hi) sorted by (other, slot), then its runs (one per edge) in ascending
  /// face order: a face of a run is a duplicate when an earlier face of the run has its third
  /// corner; only the run of its edge 0 marks it, so every mark has one writer. An edge shared
  /// by exactly two remaining faces links them; each slot has one writer. Returns the number of
  /// non-manifold edges (three or more remaining faces) found.
  std::size_t bucket(std::size_t lo, std::size_t hi) {
    // (other, slot) as one integer: the order the buckets are sorted in (slots are unique).
    const auto key = [](const entry& x) { return std::uint64_t{x.other} << 32 | x.slot; };
    std::size_t nonmanifold = 0;
    for (std::size_t v = lo; v < hi; ++v) {
      entry* b = e_.data() + offset_[v];
      entry* end = e_.data() + offset_[v + 1];
      const auto n = static_cast<std::size_t>(end - b);
      if (n <= rank_sort_max) {
        // Most buckets (a vertex is the smaller end of about three edges: six entries): each
        // entry's place is the number of smaller keys (keys are unique: slots are), counted
        // without a branch; the insertion sort's branches were coin tosses.
        std::array<std::uint64_t, rank_sort_max> k;
        std::array<entry, rank_sort_max> sorted;
        for (std::size_t i = 0; i < n; ++i) k[i] = key(b[i]);
        for (std::size_t i = 0; i < n; ++i) {
          std::size_t place = 0;
          for (std::size_t j = 0; j < n; ++j) place += k[j] < k[i] ? 1 : 0;
          sorted[place] = b[i];
        }
        std::copy_n(sorted.begin(), n, b);
      } else if (n <= 32) {  // a vertex's few edges: insertion sort (std::sort's call and setup
                             // cost more than the sorting)
        for (entry* x = b + 1; x < end; ++x) {
          const entry t = *x;
          const std::uint64_t kt = key(t);
          entry* y = x;
          for (; y > b && key(y[-1]) > kt; --y) *y = y[-1];
          *y = t;
        }
      } else {
        std::sort(b, end, [&](const entry& x, const entry& y) { return key(x) < key(y); });
      }
      for (const entry* r = b; r < end;) {
        const entry* q = r + 1;
        while (q < end && q->other == r->other) ++q;
        if (q - r >= 2) {  // a run of one (a border edge) links nothing
          std::array<std::uint32_t, 2> live{};
          std::size_t n_live = 0;
          for (const entry* x = r; x < q; ++x) {
            // A face appears once per run (no repeated vertex), so earlier = ahead in the run.
            bool is_dup = false;
            for (const entry* y = r; y < x && !is_dup; ++y) is_dup = y->third == x->third;
            if (is_dup) {
              if (x->slot % 3 == 0) dup_[x->slot / 3] = 1;
              continue;
            }
            if (n_live < 2) live[n_live] = x->slot;
            ++n_live;
          }
          if (n_live == 2) {
            nbr_[live[0] / 3][live[0] % 3] = live[1] / 3;
            nbr_[live[1] / 3][live[1] % 3] = live[0] / 3;
          } else if (n_live > 2) {
            ++nonmanifold;
          }
        }
        r = q;
      }
    }
    return nonmanifold;
  }

  /// Faces repeating a vertex index or duplicating an earlier face (after every bucket).
  std::size_t isolated() const {
    std::size_t n = 0;
    for (std::size_t f = 0; f < faces_.size(); ++f) n += (bad(f) || dup_[f]) ? 1 : 0;
    return n;
  }

 private:
  struct entry {
    std::uint32_t other, slot, third;
  };
  static constexpr std::size_t rank_sort_max = 16;

  bool bad(std::size_t f) const {
    const auto& F = faces_[f];
    return F[0] == F[1] || F[1] == F[2] || F[0] == F[2];
  }
  std::span<const std::array<std::uint32_t, 3>> faces_;
  std::vector<face_slots>& nbr_;
  scratch_vector<std::uint32_t> offset_;
  scratch_vector<entry> e_;
  scratch_vector<char> dup_;
};

/// Leaves (§3.5): groups of at most `max` edge-adjacent triangles, grown breadth-first over
/// nbr (3 slots per face, `none` = no neighbour) from the first ungrouped triangle in input
/// order. Returns CSR arrays (start, members).
void group_faces(std::size_t nf, const std::vector<face_slots>& nbr, std::uint32_t max,
                 scratch_vector<std::uint32_t>& start, scratch_vector<std::uint32_t>& members) {
  // Branch-free appends (a neighbour that is `none`, taken or over the limit is written past
  // the end and not counted): which neighbours join is a coin toss the branches mispredicted.
  // taken[nf] stands for `none` and is always set; members has one slot past nf for the
  // uncounted writes.
  scratch_vector<std::uint8_t> taken(nf + 1, 0);
  taken[nf] = 1;
  start.resize(nf + 1);
  members.resize(nf + 1);
  std::uint8_t* tk = taken.data();
  std::uint32_t* st = start.data();
  std::uint32_t* mb = members.data();
  std::size_t groups = 0, n = 0;
  for (std::size_t f = 0; f < nf; ++f) {
    if (tk[f]) continue;
    const std::size_t g0 = n;
    st[groups++] = static_cast<std::uint32_t>(g0);
    mb[n++] = static_cast<std::uint32_t>(f);
    tk[f] = 1;
    for (std::size_t k = g0; k < n && n - g0 < max; ++k) {
      const face_slots& nb = nbr[mb[k]];
      for (std::size_t j = 0; j < 3; ++j) {
        const std::uint32_t h = nb[j] == none ? static_cast<std::uint32_t>(nf) : nb[j];
        const bool add = tk[h] == 0 && n - g0 < max;
        mb[n] = h;
        tk[h] = static_cast<std::uint8_t>(tk[h] | std::uint8_t{add});
        n += add ? 1 : 0;
      }
    }
  }
  st[groups++] = static_cast<std::uint32_t>(n);
  start.resize(groups);
  members.resize(nf);
}

}  // namespace

// ---- Stage 1 (§3.5): vertices quantised, leaves grouped from the adjacency -------------------

/// The edge adjacency and the grouping read only the faces, the vertex pass (§3.5 quantisation,
/// normals) only the vertices, so they run side by side. The grouping is sequential and comes
/// last on the adjacency side, so the work is shared out in pieces to keep it short: the thread
/// that runs the adjacency side (task 0) sorts the edges, then takes bucket pieces; the vertex
/// side (task 1) sums the area-weighted normals, then takes bucket pieces while there are any,
/// else vertex pieces; once every bucket is done task 0 groups the faces and then takes the
/// vertex pieces left. Other tasks (threads > 2) take whatever is ready. No task waits for
/// another that may not have started (only for bucket pieces already taken), so the tasks may
/// run in any order, on any number of threads. Each piece's writes are its own: the output is
/// the same for any `threads`.
void pop_build_state::prepare() {
  const bool by_edges = opt.adjacency == pop_adjacency::edge_sort;
  // The same pieces as for_pieces(), over the vertices (the buckets are by vertex).
  const std::size_t vertex_pieces =
      piece_count(nv, threads, pieces_per_thread * threads, min_piece);
  const std::size_t bucket_pieces = by_edges ? vertex_pieces : 0;
  std::optional<edge_sorter> sorter;
  std::atomic<bool> sorted{false}, normals_ready{false};
  std::atomic<std::size_t> next_bucket{0}, buckets_done{0}, next_vertex{0}, nonmanifold{0};

  const bool estimate = mesh.vertices.normals.empty();
  // A zero or non-finite vertex normal is no normal: it takes the area-weighted one, as a mesh
  // without normals does (the ρ-grid's rule too).
  d.stats.normals_filled =
      estimate ? 0
               : static_cast<std::size_t>(std::count_if(
                     mesh.vertices.normals.begin(), mesh.vertices.normals.end(), missing_normal));
  // Without vertex normals, or with some missing: area_weighted_normal_sums(mesh).
  std::vector<vec3d> normal_sum;
  const auto set_up_vertices = [&] {
    box3 bb = box3::of(P);
    d.q_min = bb.min;
    for (int k = 0; k < 3; ++k) {
      const float ext = bb.max[k] - bb.min[k];
      d.q_step[k] = ext > 0 ? ext / 65535.0f : 0.0f;
    }
    resize_fresh(d.vertex_q, nv, 1);
    resize_fresh(d.positions, nv, 1);
    resize_fresh(d.vertex_normal_codes, nv, 1);
    resize_fresh(d.normals, nv, 1);
    // area_weighted_normals(mesh), bit for bit, from its double sums, normalised in the vertex
    // loop: no float copy (its 36 MB of fresh 4 kB pages were a visible part of a 2 M-triangle
    // build).
    if (estimate || d.stats.normals_filled > 0) normal_sum = area_weighted_normal_sums(mesh);
    normals_ready.store(true, std::memory_order_release);
  };
  // One piece of either kind, if one is ready: true when it did one.
  const auto take_bucket = [&] {
    if (!sorted.load(std::memory_order_acquire)) return false;
    const std::size_t b = next_bucket.fetch_add(1, std::memory_order_relaxed);
    if (b >= bucket_pieces) return false;
    // Counted as done even if it throws, so that task 0 never waits for it.
    struct done {
      std::atomic<std::size_t>& c;
      ~done() { c.fetch_add(1, std::memory_order_release); }
    } mark{buckets_done};
    const auto [lo, hi] = piece_range(nv, bucket_pieces, b);
    nonmanifold.fetch_add(sorter->bucket(lo, hi), std::memory_order_relaxed);
    return true;
  };
  const auto take_vertex = [&] {
    if (!normals_ready.load(std::memory_order_acquire)) return false;
    const std::size_t v = next_vertex.fetch_add(1, std::memory_order_relaxed);
    if (v >= vertex_pieces) return false;
    const auto [lo, hi] = piece_range(nv, vertex_pieces, v);
    quantise_vertices(lo, hi, estimate, normal_sum);
    return true;
  };
  const auto adjacency_side = [&] {
    const auto ta = clock::now();
    if (by_edges) {
      sorter.emplace(nv, mesh.faces, nbr);
      sorted.store(true, std::memory_order_release);
      while (take_bucket()) {
      }
      // Pieces other tasks took are running: wait for them, helping with the vertices.
      while (buckets_done.load(std::memory_order_acquire) < bucket_pieces)
        if (!take_vertex()) std::this_thread::yield();
      d.stats.isolated_faces = sorter->isolated();
      d.stats.nonmanifold_edges = nonmanifold.load(std::memory_order_relaxed);
      sorter.reset();
    } else {
      openmesh_adjacency(nv, mesh.faces, nbr, d.stats.isolated_faces);
    }
    group_faces(nf, nbr, opt.max_leaf_triangles, gstart, gfaces);
    adjacency_seconds = std::chrono::duration<double>(clock::now() - ta).count();
    while (take_vertex()) {
    }
  };
  const auto vertex_side = [&] {
    set_up_vertices();
    while (take_bucket() || take_vertex()) {
    }
  };
  parallel_tasks(std::max(2u, threads), threads, [&](std::size_t t, unsigned) {
    if (t == 0)
      adjacency_side();
    else if (t == 1)
      vertex_side();
    else
      while (take_bucket() || take_vertex()) {
      }
  });
  n_leaves = gstart.size() - 1;
}

/// §3.5: vertices [lo, hi) quantised to 16 bits per axis over the bounding box (Deering;
/// QSplat), their normals encoded and decoded.
void pop_build_state::quantise_vertices(std::size_t lo, std::size_t hi, bool estimate,
                                        const std::vector<vec3d>& normal_sum) {
  for (std::size_t i = lo; i < hi; ++i) {
    std::array<std::uint16_t, 3> q{};
    for (int k = 0; k < 3; ++k) {
      const double s =
          d.q_step[k] > 0 ? (static_cast<double>(P[i][k]) - d.q_min[k]) / d.q_step[k] : 0.0;
      q[static_cast<std::size_t>(k)] = round_to_u16(s);
    }
    d.vertex_q[i] = q;
    d.positions[i] = dequantise(q, d.q_min, d.q_step);
  }
  // The normals in runs (the encoder then overlaps its table loads).
  constexpr std::size_t run = 256;
  std::array<vec3f, run> unit;
  for (std::size_t a = lo; a < hi; a += run) {
    const std::size_t m = std::min(run, hi - a);
    std::span<const vec3f> in;
    if (estimate) {  // the mesh has no normals (no offset into its empty array)
      for (std::size_t k = 0; k < m; ++k) unit[k] = unit_or_zero(normal_sum[a + k]);
      in = std::span<const vec3f>(unit.data(), m);
    } else if (!normal_sum.empty()) {  // some missing
      for (std::size_t k = 0; k < m; ++k) {
        const vec3f& v = mesh.vertices.normals[a + k];
        unit[k] = missing_normal(v) ? unit_or_zero(normal_sum[a + k]) : v;
      }
      in = std::span<const vec3f>(unit.data(), m);
    } else {
      in = std::span<const vec3f>(mesh.vertices.normals.data() + a, m);
    }
    quant.encode(in, std::span(d.vertex_normal_codes.data() + a, m));
    for (std::size_t i = a; i < a + m; ++i) d.normals[i] = quant.decode(d.vertex_normal_codes[i]);
  }
}

}  // namespace pbr_lod::detail::pop_stages
