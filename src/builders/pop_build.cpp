// pbr_lod — the POP builder. This work is based on:
//   B. Chen, M. X. Nguyen, "POP: A Hybrid Point and Polygon Rendering System for Large Data",
//   IEEE Visualization 2001 (section-by-section map in builders/pop.hpp and docs/pop.md).
// build_pop_data() runs the paper's steps as named stages of pop_build_state, in order:
//   prepare()            §3.5  vertices quantised to 16 bits; leaves = ≤ 4 edge-adjacent triangles
//   colour_vertices/faces §3.1 per-triangle colour (texel average or vertex average)
//   leaf_keys(), partition_leaves(), lay_out_nodes()  §3.1 topology: median splits, 4-ary tree
//   spheres_and_cones()  §3.1  bounding spheres, averaged normals/colours, normal cones, bottom up
//   quantise_spheres()   §3.5  QSplat-style sphere codes, top down
// The file format is in pop_io.cpp. The triangle adjacency comes from a parallel sorted-edge
// pass or, selectable, OpenMesh's halfedge structure; OpenMesh stays in this file.

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
#include "pbr_lod/builders/pop.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/memory.hpp"
#include "pbr_lod/core/mesh_normals.hpp"
#include "pbr_lod/core/normal_quantization.hpp"
#include "pbr_lod/core/normal_repair.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pbr_lod/io/texture.hpp"
#include "pop_internal.hpp"

namespace pbr_lod::detail {

using namespace pop_internal;

namespace {

/// Three u32 per face: the adjacency's neighbours, and the same type as pop_data::faces, so the
/// adjacency's storage is recycled for the faces in leaf order once the grouping is done.
using face_slots = std::array<std::uint32_t, 3>;

/// f(lo, hi) over contiguous pieces of at least 2048 indices, 8 per thread, handed out one at a
/// time (core/parallel.hpp): every caller's work is element by element, and more pieces than
/// threads keep both cores busy when one of them runs slower.
constexpr std::size_t pieces_per_thread = 8, min_piece = 2048;
template <class F>
void for_pieces(std::size_t n, unsigned threads, F&& f) {
  detail::parallel_pieces(n, threads, pieces_per_thread * threads, min_piece, f);
}

/// cos of the angle between unit vectors a and b, measured in double and clamped to [−1, 1].
double clamped_cos(const vec3f& a, const vec3f& b) {
  return std::clamp(a.cast<double>().dot(b.cast<double>()), -1.0, 1.0);
}

/// A centre as stored (float), in double for measuring from it. Through an empty asm, so the
/// compiler cannot see where the floats came from: GCC 12.2 (Debian 12's) at -O2 and above
/// folds the SLP-vectorised pair (vector double)(vector float)x back to x, so that after
/// `out = x.cast<float>()`, `out.cast<double>()` gave x's unrounded x and y (z, converted alone,
/// was right). The radii were then measured from a point up to half a float ulp off the stored
/// centre, and a stored sphere could miss a corner by that much (test
/// PopBuild.FloatSpheresHoldExactly). Clang does not fold it.
vec3d as_stored(const vec3f& c) {
  vec3f s = c;
#if defined(__GNUC__)
  asm("" : "+m"(s));
#endif
  return s.cast<double>();
}

/// Sphere (double centre x, radius r) made safe to store in float: the float centre, and a
/// radius rounded up so that it still holds every child sphere measured from that centre.
void finalise(const vec3d& x, double r, const vec3d* c, const double* cr, std::size_t n,
              vec3f& out_c, float& out_r) {
  out_c = x.cast<float>();
  const vec3d xc = as_stored(out_c);
  double need = std::isfinite(r) ? r : 0.0;
  for (std::size_t i = 0; i < n; ++i) need = std::max(need, (c[i] - xc).norm() + cr[i]);
  out_r = round_up(need);
}
/// finalise() for n points (radius 0): the largest distance is the root of the largest square
/// (sqrt is correctly rounded, so monotone, and d + 0 = d), one root instead of n.
void finalise_points(const vec3d& x, double r, const vec3d* c, std::size_t n, vec3f& out_c,
                     float& out_r) {
  out_c = x.cast<float>();
  const vec3d xc = as_stored(out_c);
  double far2 = 0;
  for (std::size_t i = 0; i < n; ++i) far2 = std::max(far2, (c[i] - xc).squaredNorm());
  out_r = round_up(std::max(std::isfinite(r) ? r : 0.0, std::sqrt(far2)));
}

struct texture {
  texture_image img;
  [[nodiscard]] rgb8 at(double x, double y) const {  // texel coordinates, wrapped (GL_REPEAT)
    const auto w = static_cast<long>(img.width), h = static_cast<long>(img.height);
    long ix = static_cast<long>(std::floor(x)) % w, iy = static_cast<long>(std::floor(y)) % h;
    if (ix < 0) ix += w;
    if (iy < 0) iy += h;
    return img.texels[static_cast<std::size_t>(iy) * static_cast<std::size_t>(w) +
                      static_cast<std::size_t>(ix)];
  }
  /// Texel coordinates of texture coordinate (u, v): OBJ's v grows upwards, the image's rows down.
  [[nodiscard]] vec2d texel(const vec2f& uv) const {
    return {static_cast<double>(uv.x()) * img.width,
            (1.0 - static_cast<double>(uv.y())) * img.height};
  }
  /// §3.1: "the average of all texels inside the triangle" (texel centres inside; the texel at
  /// the centroid when the triangle covers no texel centre). Large triangles are sampled on a
  /// coarser grid of at most ~65k texels.
  [[nodiscard]] rgb8 average(const std::array<vec2f, 3>& uv) const {
    const vec2d a = texel(uv[0]), b = texel(uv[1]), c = texel(uv[2]);
    const double x0 = std::floor(std::min({a.x(), b.x(), c.x()})),
                 x1 = std::ceil(std::max({a.x(), b.x(), c.x()})),
                 y0 = std::floor(std::min({a.y(), b.y(), c.y()})),
                 y1 = std::ceil(std::max({a.y(), b.y(), c.y()}));
    const double area = (x1 - x0) * (y1 - y0);
    const double stride = std::max(1.0, std::ceil(std::sqrt(area / 65536.0)));
    const auto edge = [](const vec2d& p, const vec2d& q, double x, double y) {
      return (q.x() - p.x()) * (y - p.y()) - (q.y() - p.y()) * (x - p.x());
    };
    double sr = 0, sg = 0, sb = 0, n = 0;
    for (double y = y0 + 0.5 * stride; y < y1; y += stride)
      for (double x = x0 + 0.5 * stride; x < x1; x += stride) {
        const double e0 = edge(a, b, x, y), e1 = edge(b, c, x, y), e2 = edge(c, a, x, y);
        if (!((e0 >= 0 && e1 >= 0 && e2 >= 0) || (e0 <= 0 && e1 <= 0 && e2 <= 0))) continue;
        const rgb8 t = at(x, y);
        sr += t.r;
        sg += t.g;
        sb += t.b;
        n += 1;
      }
    if (n == 0) {
      const vec2d m = (a + b + c) / 3.0;
      return at(m.x(), m.y());
    }
    return {static_cast<std::uint8_t>(std::lround(sr / n)),
            static_cast<std::uint8_t>(std::lround(sg / n)),
            static_cast<std::uint8_t>(std::lround(sb / n))};
  }
};

struct rgb_sum {
  double r = 0, g = 0, b = 0, n = 0;
  void add(rgb8 c) {
    r += c.r;
    g += c.g;
    b += c.b;
    n += 1;
  }
  [[nodiscard]] rgb8 mean() const {
    if (n == 0) return {};
    return {static_cast<std::uint8_t>(std::lround(r / n)),
            static_cast<std::uint8_t>(std::lround(g / n)),
            static_cast<std::uint8_t>(std::lround(b / n))};
  }
};

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

// ---------------------------------------------------------------------------------------------
// Spheres (§3.1)
// ---------------------------------------------------------------------------------------------

namespace {
/// pop_triangle_circle() given ab = b − a, ac = c − a and w = ab × ac, which its callers have
/// at hand (the leaves need w as the face normal, the 4-child rule as the base's normal), with
/// the squared radius: the 4-child rule needs only that.
[[gnu::always_inline]] inline void triangle_circle_sq(const vec3d& a, const vec3d& b,
                                                      const vec3d& c, const vec3d& ab,
                                                      const vec3d& ac, const vec3d& w, double w2,
                                                      vec3d& centre, double& radius2) {
  const vec3d bc = c - b;
  const double lab = ab.squaredNorm(), lac = ac.squaredNorm(), lbc = bc.squaredNorm();
  const auto longest_edge = [&] {
    if (lab >= lac && lab >= lbc)
      centre = 0.5 * (a + b);
    else if (lac >= lbc)
      centre = 0.5 * (a + c);
    else
      centre = 0.5 * (b + c);
  };
  // An angle exceeds 90° where the two edges leaving its corner have a negative dot product.
  const bool obtuse = ab.dot(ac) < 0 || (-ab).dot(bc) < 0 || ac.dot(bc) < 0;
  const double scale = std::max({lab, lac, lbc});
  if (obtuse || !(w2 > 1e-24 * scale * scale)) {
    longest_edge();  // obtuse (paper), or degenerate: the circumcentre is at infinity
  } else {
    centre = a + (lab * ac.cross(w) + lac * w.cross(ab)) / (2 * w2);
    if (!all_finite(centre)) longest_edge();
  }
  radius2 = std::max(
      {(a - centre).squaredNorm(), (b - centre).squaredNorm(), (c - centre).squaredNorm()});
}
/// The same with the radius: sqrt is correctly rounded, so monotone, and one root of the largest
/// square is the largest root.
[[gnu::always_inline]] inline void triangle_circle(const vec3d& a, const vec3d& b, const vec3d& c,
                                                   const vec3d& ab, const vec3d& ac, const vec3d& w,
                                                   double w2, vec3d& centre, double& radius) {
  triangle_circle_sq(a, b, c, ab, ac, w, w2, centre, radius);
  radius = std::sqrt(radius);
}

/// triangle_circle_sq() for four triangles at once, one per lane: the same operations per lane,
/// so the same bits (lanes.hpp), with the branches as selects (both centres are computed).
[[gnu::always_inline]] inline void triangle_circle_sq4(const lanes::v3& a, const lanes::v3& b,
                                                       const lanes::v3& c, const lanes::v3& ab,
                                                       const lanes::v3& ac, const lanes::v3& w,
                                                       lanes::d4 w2, lanes::v3& centre,
                                                       lanes::d4& radius2) {
  using namespace lanes;
  const v3 bc = c - b;
  const d4 lab = dot(ab, ab), lac = dot(ac, ac), lbc = dot(bc, bc);
  const d4 half = splat(0.5);
  const v3 longest = select((lab >= lac) & (lab >= lbc), half * (a + b),
                            select(lac >= lbc, half * (a + c), half * (b + c)));
  const m4 obtuse = (dot(ab, ac) < 0) | (dot(-ab, bc) < 0) | (dot(ac, bc) < 0);
  const d4 scale = max(max(lab, lac), lbc);
  const m4 round = ~obtuse & (w2 > splat(1e-24) * scale * scale);
  const v3 t1 = cross(ac, w), t2 = cross(w, ab);
  const d4 twice = 2 * w2;
  const v3 circum = {a.x + (lab * t1.x + lac * t2.x) / twice,
                     a.y + (lab * t1.y + lac * t2.y) / twice,
                     a.z + (lab * t1.z + lac * t2.z) / twice};
  centre = select(round & finite(circum), circum, longest);
  const v3 da = a - centre, db = b - centre, dc = c - centre;
  radius2 = max(max(dot(da, da), dot(db, db)), dot(dc, dc));
}
}  // namespace

void pop_triangle_circle(const vec3d& a, const vec3d& b, const vec3d& c, vec3d& centre,
                         double& radius) {
  const vec3d ab = b - a, ac = c - a;
  const vec3d w = ab.cross(ac);
  triangle_circle(a, b, c, ab, ac, w, w.squaredNorm(), centre, radius);
}

void pop_triangle_circle4(const vec3d* a, const vec3d* b, const vec3d* c, vec3d* centre,
                          double* radius) {
  using namespace lanes;
  const v3 A = load(a[0], a[1], a[2], a[3]), B = load(b[0], b[1], b[2], b[3]),
           C = load(c[0], c[1], c[2], c[3]);
  const v3 ab = B - A, ac = C - A, w = cross(ab, ac);
  v3 x;
  d4 r2;
  triangle_circle_sq4(A, B, C, ab, ac, w, dot(w, w), x, r2);
  for (int k = 0; k < 4; ++k) {
    centre[k] = lane(x, k);
    radius[k] = std::sqrt(r2[k]);
  }
}

namespace {
/// The paper's inner-node sphere; returns true when rule 0 (one child holds the others) applied.
bool paper_sphere(const vec3d* c, const double* r, std::size_t n, vec3d& centre, double& radius) {
  // Rule 0: one child's sphere holds all the others (the largest such, for determinism).
  int best = -1;
  for (std::size_t i = 0; i < n; ++i) {
    bool holds = true;
    // r[j] > r[i] fails without the square root: d + r[j] ≥ r[j] for d ≥ 0 in floating point.
    for (std::size_t j = 0; j < n && holds; ++j)
      holds = j == i || (r[j] <= r[i] && (c[j] - c[i]).norm() + r[j] <= r[i]);
    if (holds && (best < 0 || r[i] > r[static_cast<std::size_t>(best)])) best = static_cast<int>(i);
  }
  if (best >= 0) {
    centre = c[best];
    radius = r[best];
    return true;
  }
  const double rmax = *std::max_element(r, r + n);
  if (n == 2) {  // centre on the segment, r = (d + r1 + r2) / 2
    const vec3d dv = c[1] - c[0];
    const double d = dv.norm();
    radius = 0.5 * (d + r[0] + r[1]);
    centre = d > 0 ? vec3d(c[0] + dv * ((radius - r[0]) / d)) : c[0];
    return false;
  }
  if (n == 3) {  // the centres' triangle circle, plus the largest radius
    pop_triangle_circle(c[0], c[1], c[2], centre, radius);
    radius += rmax;
    return false;
  }
  // n == 4: for each face of the tetrahedron of centres, the centre lies on the line through the
  // face's circle centre perpendicular to it; we take the point on that line where the fourth
  // centre is no farther than the face's corners (the face circle's centre itself when it
  // already is). Radius: distance to the corners plus the largest radius. Minimum over faces.
  // With the face's circle centre b, its squared radius ρ², the unnormalised face normal n and
  // v = c_k − b, the point b + s·n is at squared distance ρ² + s²|n|² from the face's corners and
  // |v|² − 2s(v·n) + s²|n|² from c_k: they agree at s = (|v|² − ρ²) / (2 v·n). So no normalised
  // normal and no face radius are needed (two square roots and three divisions per face fewer
  // than with the unit normal and the signed height h = v·n/|n|, the same point up to rounding),
  // and the faces compare by squared distance: one root at the end.
  // The four faces as four lanes (lanes.hpp): face k is the base of the other three centres,
  // in ascending order, and c_k is its fourth.
  using namespace lanes;
  const v3 A = load(c[1], c[0], c[0], c[0]), B = load(c[2], c[2], c[1], c[1]),
           C = load(c[3], c[3], c[3], c[2]), D = load(c[0], c[1], c[2], c[3]);
  const v3 e1 = B - A, e2 = C - A;
  const v3 nrm = cross(e1, e2);  // the base's normal, and the circle's ab × ac
  const d4 n2 = dot(nrm, nrm);
  v3 bc;
  d4 br2;
  triangle_circle_sq4(A, B, C, e1, e2, nrm, n2, bc, br2);
  const v3 to4 = D - bc;
  const d4 far = dot(to4, to4) - br2;  // > 0: c_k lies outside the face's sphere
  // A collinear base: any direction across the line, towards the fourth centre.
  const v3 line = select(dot(e1, e1) > dot(e2, e2), e1, e2);
  const d4 line2 = dot(line, line);
  const v3 across = select(line2 > 0, to4 - line * (dot(to4, line) / line2), to4);
  const v3 axis = select(n2 > 0, nrm, across);
  const d4 h = dot(to4, axis);
  const d4 s = select((far > 0) & (h != 0), far / (2 * h), splat(0));
  const v3 x = bc + s * axis;
  // The largest squared distance: one root for the largest (monotone). A centre that is not
  // finite (a near-flat face far off) gets ∞: it is never taken.
  d4 dist2 = splat(0);
  for (std::size_t i = 0; i < 4; ++i) {
    const v3 d = load(c[i], c[i], c[i], c[i]) - x;
    dist2 = max(dist2, dot(d, d));
  }
  dist2 = select(finite(x), dist2, splat(std::numeric_limits<double>::infinity()));
  double best2 = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 4; ++k)
    if (dist2[k] < best2) {  // false for NaN and ∞
      best2 = dist2[k];
      centre = lane(x, k);
    }
  if (!(best2 < std::numeric_limits<double>::infinity())) {
    // No face gave a finite sphere (not seen): the centres' mean, where the callers' finalise()
    // measures the radius that holds every child.
    centre = 0.25 * (c[0] + c[1] + c[2] + c[3]);
    best2 = 0;
    for (std::size_t i = 0; i < 4; ++i) best2 = std::max(best2, (c[i] - centre).squaredNorm());
  }
  radius = std::sqrt(best2) + rmax;
  return false;
}
}  // namespace

void pop_paper_sphere(const vec3d* c, const double* r, std::size_t n, vec3d& centre,
                      double& radius) {
  if (n == 0) throw InvalidArgument("pop_paper_sphere: no spheres");
  if (n > 4) throw InvalidArgument("pop_paper_sphere: the paper's rules cover 1..4 children");
  paper_sphere(c, r, n, centre, radius);
}

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
/// A leaf's split key (the mean of its triangles' corners, as ordered_bits) and its index.
struct split_key {
  std::array<std::uint32_t, 3> k;
  std::uint32_t id;
};
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

// ---------------------------------------------------------------------------------------------
// Build: build_pop_data() runs the stages below in the paper's order, on one pop_build_state.
// ---------------------------------------------------------------------------------------------

namespace {

/// The tree's shape before it has geometry: node i covers leaves [lo, hi) of the sorted split
/// keys; `first`/`count` are its children (count 0: a leaf).
struct topo {
  std::uint32_t lo, hi, first = 0, count = 0, parent = none;
  std::uint16_t depth = 0;
};
using node_ranges = std::vector<std::pair<std::size_t, std::size_t>>;

/// Per-worker counts of the bottom-up pass (one cache line each: no false sharing).
struct alignas(64) counts {
  std::size_t contained = 0, degenerate = 0;
};
/// What node_geometry() hands to normal_cone(): a leaf's face normals; fdeg bit j: face j is
/// degenerate.
struct pending {
  std::array<vec3f, 4> fn;
  std::uint8_t fdeg;
};
/// Nodes are done in blocks of `block`: the geometry of the whole block, then its normal encodes
/// back to back, which do not depend on each other, so they overlap in the pipeline (bench_core:
/// BM_Encode, independent encodes, against BM_EncodeLatency, a chain of them); through
/// encode(span, span), which also loads their candidate cells first (−5 %).
constexpr std::size_t block = 32;

/// Where a range of sorted leaves splits: the partition and the topology must agree exactly.
std::uint32_t mid_of(std::uint32_t lo, std::uint32_t hi) {
  return lo + (hi - lo) / 2;
}

/// The state the stages share: the input, the options, the output under construction and the
/// intermediate arrays one stage hands to the next.
struct pop_build_state {
  using clock = std::chrono::steady_clock;

  const triangle_mesh& mesh;
  const pop_options& opt;
  const bool colour;
  std::shared_ptr<const normal_quantizer> shared_quant;
  const normal_quantizer& quant;
  const bool textured, qn, exact;
  /// With colours from a texture: the leaves keep their texture coordinates and the texture.
  const bool keep_texture;
  const unsigned threads;
  const std::size_t nv, nf;
  const std::vector<vec3f>& P;

  pop_data d;
  // prepare(): the leaves as CSR groups of faces, and the adjacency (becomes d.faces).
  scratch_vector<std::uint32_t> gstart, gfaces;
  std::vector<face_slots> nbr;
  double adjacency_seconds = 0;
  // colour_faces()
  std::vector<rgb8> face_colour;
  texture tex;
  // leaf_keys(), partition_leaves()
  std::size_t n_leaves = 0;
  scratch_vector<split_key> perm;
  scratch_vector<topo> tn;
  node_ranges levels;  // node ranges by depth
  // lay_out_nodes(): a leaf's group's members start at gfaces[leaf_members[i]]
  scratch_vector<std::uint32_t> leaf_members;
  // spheres_and_cones(), reused by quantise_spheres()
  std::size_t split_level = 0, roots_begin = 0, roots = 0;
  std::vector<node_ranges> subtrees;

  pop_build_state(const triangle_mesh& m, const pop_options& o, bool c)
      : mesh(m),
        opt(o),
        colour(c),
        shared_quant(normal_quantizer::shared(o.normal_bits)),
        quant(*shared_quant),
        textured(!m.face_texcoords.empty() && !m.texture_path.empty()),
        qn(o.quantise_nodes),
        exact(o.spheres == pop_sphere_rule::exact),
        keep_texture(c && textured),
        threads(o.threads ? o.threads : std::max(1u, std::thread::hardware_concurrency())),
        nv(m.num_vertices()),
        nf(m.num_faces()),
        P(m.vertices.positions) {}

  void prepare();
  void quantise_vertices(std::size_t lo, std::size_t hi, bool estimate,
                         const std::vector<vec3d>& normal_sum);
  void colour_vertices();
  void colour_faces();
  void leaf_keys();
  std::uint32_t split(std::uint32_t lo, std::uint32_t hi);
  void partition(std::uint32_t lo, std::uint32_t hi);
  void build_topology();
  void partition_leaves();
  void lay_out_nodes();
  void leaf4_geometry(const std::array<std::uint32_t, 3>* tri, vec3d& x, double& r, vec3d& nsum,
                      rgb_sum& csum, const std::uint32_t* members, counts& acc, pending& out,
                      pop_node& nd) const;
  void node_geometry(std::size_t i, counts& acc, pending& out, vec3f& nsum_out);
  void normal_cone(std::size_t i, std::uint32_t code, const pending& in);
  void gather(std::size_t i);
  void bottom_up(std::size_t a, std::size_t b, counts& acc);
  void subtree_levels(std::size_t root, node_ranges& out) const;
  void spheres_and_cones();
  void top_down(std::size_t i);
  void quantise_spheres();
  void finish_stats(clock::time_point t0, clock::time_point t_prep, clock::time_point t1);
};

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
  const bool textured = !mesh.face_texcoords.empty() && !mesh.texture_path.empty();
  if (colour && !textured && mesh.vertices.colours.empty())
    throw InvalidArgument(
        "build_pop: colours requested but the mesh has neither vertex colours nor a texture "
        "(build pop_tree<with_normals> instead)");
}

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

// ---- Stage 2 (§3.1): colours ----------------------------------------------------------------

/// Vertex colours, or with a texture the texel under each corner averaged per vertex.
void pop_build_state::colour_vertices() {
  if (textured) {
    tex.img = read_png_texture(mesh.texture_path);
    if (tex.img.width <= 0 || tex.img.height <= 0)
      throw FormatError(mesh.texture_path + ": empty texture");
    if (tex.img.texels.size() !=
        static_cast<std::size_t>(tex.img.width) * static_cast<std::size_t>(tex.img.height))
      throw FormatError(mesh.texture_path + ": texel count does not match the size");
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

// ---- Stage 4 (§3.1): bounding spheres, normals, colours and normal cones, bottom up ----------

/// A leaf of four triangles (most leaves): the general leaf loop of node_geometry() with the
/// four triangles as lanes (lanes.hpp; the same bits), the corners measured by lanes too.
void pop_build_state::leaf4_geometry(const std::array<std::uint32_t, 3>* tri, vec3d& x, double& r,
                                     vec3d& nsum, rgb_sum& csum, const std::uint32_t* members,
                                     counts& acc, pending& out, pop_node& nd) const {
  using namespace lanes;
  for (std::size_t j = 0; j < 4; ++j) {
    for (auto v : tri[j]) nsum += d.normals[v].cast<double>();
    if (colour) csum.add(face_colour[members[j]]);
  }
  const auto coord = [&](std::size_t m, int k) {
    return make(static_cast<double>(d.positions[tri[0][m]][k]),
                static_cast<double>(d.positions[tri[1][m]][k]),
                static_cast<double>(d.positions[tri[2][m]][k]),
                static_cast<double>(d.positions[tri[3][m]][k]));
  };
  const v3 a = {coord(0, 0), coord(0, 1), coord(0, 2)}, b = {coord(1, 0), coord(1, 1), coord(1, 2)},
           c = {coord(2, 0), coord(2, 1), coord(2, 2)};
  // Geometric normals (zero and `degenerate` when the cross product vanishes).
  const v3 e1 = b - a, e2 = c - a;
  const v3 n = cross(e1, e2);
  const d4 n2 = dot(n, n);
  const d4 len = lanes::sqrt(n2);
  const m4 fine = (len > 0) & finite(len);
  const v3 unit = {n.x / len, n.y / len, n.z / len};
  out.fdeg = 0;
  for (int j = 0; j < 4; ++j) {
    const bool deg = !fine[j];
    out.fn[static_cast<std::size_t>(j)] =
        deg ? vec3f::Zero()
            : vec3f(static_cast<float>(unit.x[j]), static_cast<float>(unit.y[j]),
                    static_cast<float>(unit.z[j]));
    out.fdeg = static_cast<std::uint8_t>(out.fdeg | unsigned{deg} << j);
    acc.degenerate += deg ? 1 : 0;
  }
  if (exact) {  // smallest sphere of the leaf's corners
    std::array<vec3d, 12> corner;
    std::array<double, 12> zero{};
    for (int j = 0; j < 4; ++j) {
      corner[3 * static_cast<std::size_t>(j)] = lane(a, j);
      corner[3 * static_cast<std::size_t>(j) + 1] = lane(b, j);
      corner[3 * static_cast<std::size_t>(j) + 2] = lane(c, j);
    }
    min_sphere_of_spheres(corner.data(), zero.data(), 12, x, r);
  } else {  // the paper's rules over the triangles' spheres
    v3 cc4;
    d4 cr2;
    triangle_circle_sq4(a, b, c, e1, e2, n, n2, cc4, cr2);
    std::array<vec3d, 4> cc;
    std::array<double, 4> cr;
    for (int j = 0; j < 4; ++j) {
      cc[static_cast<std::size_t>(j)] = lane(cc4, j);
      cr[static_cast<std::size_t>(j)] = std::sqrt(cr2[j]);
    }
    paper_sphere(cc.data(), cr.data(), 4, x, r);
  }
  // finalise_points() over the twelve corners: the largest squared distance from the stored
  // centre (a maximum, so in any order), one root.
  nd.centre = x.cast<float>();
  const vec3d xc = as_stored(nd.centre);
  const v3 o = {splat(xc.x()), splat(xc.y()), splat(xc.z())};
  const v3 da = a - o, db = b - o, dc = c - o;
  const d4 far4 = max(max(dot(da, da), dot(db, db)), dot(dc, dc));
  const double far2 = std::max(std::max(far4[0], far4[1]), std::max(far4[2], far4[3]));
  nd.radius = round_up(std::max(std::isfinite(r) ? r : 0.0, std::sqrt(far2)));
}

/// Node i's sphere (§3.1: a leaf's from its triangles' circles, an inner node's from its
/// children's spheres), colour and normal sum; keeps a leaf's face normals for normal_cone().
void pop_build_state::node_geometry(std::size_t i, counts& acc, pending& out, vec3f& nsum_out) {
  std::array<vec3d, 12> cc, corner;
  std::array<double, 12> cr;
  auto& fn = out.fn;
  out.fdeg = 0;
  auto& nd = d.nodes[i];
  vec3d x;
  double r = 0;
  vec3d nsum = vec3d::Zero();
  rgb_sum csum;
  std::size_t m = 0;
  if (nd.leaf) {
    // The leaf's triangles, its group's faces, are at d.faces[first, first + count) (gather()).
    const std::size_t nt = nd.count;
    std::array<std::uint32_t, 3>* tri = d.faces.data() + nd.first;
    const std::uint32_t* members = gfaces.data() + leaf_members[i];
    if (nt == 4) {
      leaf4_geometry(tri, x, r, nsum, csum, members, acc, out, nd);
    } else {
      for (std::size_t j = 0; j < nt; ++j) {
        const auto& F = tri[j];
        for (auto v : F) nsum += d.normals[v].cast<double>();
        if (colour) csum.add(face_colour[members[j]]);
        // Geometric normal (zero and `degenerate` when the cross product vanishes).
        // The corners from registers, not from the array they are stored to (reading back a
        // vector written as two halves stalled the store forwarding).
        const vec3d a = d.positions[F[0]].cast<double>(), b = d.positions[F[1]].cast<double>(),
                    c = d.positions[F[2]].cast<double>();
        vec3d* p = corner.data() + 3 * j;
        p[0] = a;
        p[1] = b;
        p[2] = c;
        const vec3d e1 = b - a, e2 = c - a;
        const vec3d n = e1.cross(e2);
        const double n2 = n.squaredNorm();
        const double len = std::sqrt(n2);  // n.norm()
        const bool deg = !(len > 0 && std::isfinite(len));
        fn[j] = deg ? vec3f::Zero() : vec3f((n / len).cast<float>());
        out.fdeg = static_cast<std::uint8_t>(out.fdeg | unsigned{deg} << j);
        acc.degenerate += deg ? 1 : 0;
        // The triangle's sphere (§3.1): needed unless the exact rule takes the corners.
        if (nt == 1 || !exact) triangle_circle(a, b, c, e1, e2, n, n2, cc[j], cr[j]);
      }
      if (nt == 1) {
        x = cc[0];
        r = cr[0];
      } else if (exact) {  // smallest sphere of the leaf's corners
        for (std::size_t k = 0; k < 3 * nt; ++k) cr[k] = 0;
        min_sphere_of_spheres(corner.data(), cr.data(), 3 * nt, x, r);
      } else {  // the paper's rules over the triangles' spheres
        paper_sphere(cc.data(), cr.data(), nt, x, r);
      }
      // Every corner, measured from the stored centre.
      finalise_points(x, r, corner.data(), 3 * nt, nd.centre, nd.radius);
    }
    if (!(nsum.squaredNorm() > 0))
      for (std::size_t j = 0; j < nt; ++j) nsum += fn[j].cast<double>();
  } else {
    for (std::uint32_t c = nd.first; c < nd.first + nd.count; ++c) {
      const auto& ch = d.nodes[c];
      cc[m] = ch.centre.cast<double>();
      cr[m++] = ch.radius;
      nsum += ch.normal.cast<double>();
      if (colour) csum.add(d.node_colours[c]);
    }
    if (exact)
      min_sphere_of_spheres(cc.data(), cr.data(), m, x, r);
    else
      acc.contained += paper_sphere(cc.data(), cr.data(), m, x, r) ? 1 : 0;
    finalise(x, r, cc.data(), cr.data(), m, nd.centre, nd.radius);
  }
  nsum_out = nsum.cast<float>();
  if (colour) d.node_colours[i] = qn ? from565(rgb565(csum.mean())) : csum.mean();
}

/// Node i's normal (§3.1: the average, quantised to `code`) and its normal cone, measured about
/// the decoded axis: over a leaf's face normals, or over the children's cones.
void pop_build_state::normal_cone(std::size_t i, std::uint32_t code, const pending& in) {
  auto& nd = d.nodes[i];
  const auto& fn = in.fn;
  d.node_normal_codes[i] = code;
  nd.normal = quant.decode(code);
  // The cosines the cone is measured by: to the leaf's non-degenerate face normals (only the
  // smallest matters: the widest face), or to each child's axis.
  const std::size_t nc = nd.count;
  double min_cos = 2;
  std::array<double, 4> cs;
  if (nd.leaf) {
    for (std::size_t j = 0; j < nc; ++j)
      if (!(in.fdeg >> j & 1u)) min_cos = std::min(min_cos, clamped_cos(nd.normal, fn[j]));
  } else {
    for (std::size_t j = 0; j < nc; ++j)
      cs[j] = clamped_cos(nd.normal, d.nodes[nd.first + j].normal);
  }
  if (qn) {  // the level straight from the cosines (cone_table())
    // The thresholds fall as the level grows (face[k]; child[k][c] is 2 while the level is
    // below the child's, then falls), so the levels that fail come first: the smallest level
    // that holds is the number that fail, counted without a branch on the cosines.
    const auto& table = cone_table();
    unsigned k = 0;
    if (nd.leaf) {
      for (unsigned level = 0; level < 3; ++level) k += min_cos < table.face[level] ? 1u : 0u;
    } else {
      std::array<unsigned, 4> cc;
      for (std::size_t j = 0; j < nc; ++j) cc[j] = cone_code(d.nodes[nd.first + j].cone_angle);
      for (unsigned level = 0; level < 3; ++level) {
        bool holds = true;
        for (std::size_t j = 0; j < nc; ++j) holds = holds & (cs[j] >= table.child[level][cc[j]]);
        k += holds ? 0u : 1u;
      }
    }
    nd.cone_angle = cone_level(k);
    return;
  }
  double cone = 0;
  if (nd.leaf) {
    // The largest angle to a face normal is the acos of the smallest cosine (acos is
    // monotone): one acos per leaf instead of one per triangle.
    if (min_cos <= 1) cone = std::acos(min_cos);
  } else {
    // max over children of acos(cos to the child's axis) + the child's cone. Children with
    // the same cone (quantised cones have four levels) need one acos, of their smallest
    // cosine; a child with an unbounded cone (π) makes this one unbounded without any.
    std::array<float, 4> ca;
    bool unbounded = false;
    for (std::size_t j = 0; j < nc; ++j) {
      ca[j] = d.nodes[nd.first + j].cone_angle;
      unbounded = unbounded || ca[j] >= std::numbers::pi_v<float>;
    }
    if (unbounded) {
      cone = std::numbers::pi;  // the result is clamped to π below
    } else {
      for (std::size_t j = 0; j < nc; ++j) {
        bool seen = false;
        for (std::size_t k = 0; k < j; ++k) seen = seen || ca[k] == ca[j];
        if (seen) continue;
        double smallest = cs[j];
        for (std::size_t k = j + 1; k < nc; ++k)
          if (ca[k] == ca[j]) smallest = std::min(smallest, cs[k]);
        cone = std::max(cone, std::acos(smallest) + static_cast<double>(ca[j]));
      }
    }
  }
  nd.cone_angle = std::min(std::numbers::pi_v<float>, round_up(cone + 1e-6));
}

/// A leaf's triangles, its group's faces, to d.faces[first, first + count). Done for a block of
/// nodes before their node_geometry(): each face is a chain of three likely cache misses (group
/// start, member, face), and in a short loop of their own the chains of many leaves overlap
/// (Buddha −1.5 to −3 %; a pass over the whole tree instead cost a second miss per face).
void pop_build_state::gather(std::size_t i) {
  const auto& nd = d.nodes[i];
  if (!nd.leaf) return;
  std::array<std::uint32_t, 3>* tri = d.faces.data() + nd.first;
  const std::uint32_t* members = gfaces.data() + leaf_members[i];
  for (std::size_t j = 0; j < nd.count; ++j) tri[j] = mesh.faces[members[j]];
  if (keep_texture)  // the corners' texture coordinates follow their faces (Figure 5)
    for (std::size_t j = 0; j < nd.count; ++j)
      d.face_texcoords[nd.first + j] = mesh.face_texcoords[members[j]];
}

/// Nodes [a, b) of one level (their children are done), in blocks of `block`.
void pop_build_state::bottom_up(std::size_t a, std::size_t b, counts& acc) {
  std::array<pending, block> p;
  std::array<vec3f, block> nsum;
  std::array<std::uint32_t, block> code;
  for (std::size_t lo = a; lo < b; lo += block) {
    const std::size_t n = std::min(block, b - lo);
    for (std::size_t k = 0; k < n; ++k) gather(lo + k);
    for (std::size_t k = 0; k < n; ++k) node_geometry(lo + k, acc, p[k], nsum[k]);
    quant.encode(std::span(nsum.data(), n), std::span(code.data(), n));
    for (std::size_t k = 0; k < n; ++k) normal_cone(lo + k, code[k], p[k]);
  }
}

/// The node ranges of the subtree below `root`, level by level from the root's.
void pop_build_state::subtree_levels(std::size_t root, node_ranges& out) const {
  const std::size_t nn = d.nodes.size();
  out.assign(1, {root, root + 1});
  for (;;) {
    const auto [a, b] = out.back();
    std::size_t lo = nn, hi = 0;
    for (std::size_t i = a; i < b; ++i)
      if (!d.nodes[i].leaf) {
        lo = std::min<std::size_t>(lo, d.nodes[i].first);
        hi = std::max<std::size_t>(hi, d.nodes[i].first + d.nodes[i].count);
      }
    if (hi == 0) return;
    out.emplace_back(lo, hi);
  }
}

/// Bottom-up (children before parents). Work units are the subtrees below the first level with
/// at least 64 nodes per thread, handed out one at a time (their sizes differ: leaves sit at
/// different depths), each done level by level inside itself while its records are in cache;
/// the few levels above them run on this thread. In the breadth-first layout the nodes of one
/// subtree at one level are a contiguous range. A node's values depend only on its children's,
/// so the output does not depend on the schedule.
void pop_build_state::spheres_and_cones() {
  std::vector<counts> per_worker(threads);
  split_level = levels.size();
  for (std::size_t li = 0; li < levels.size(); ++li)
    if (levels[li].second - levels[li].first >= 64 * std::size_t{threads}) {
      split_level = li;
      break;
    }
  // split_level == levels.size() (a small tree): no subtrees, every level on this thread.
  roots_begin = split_level < levels.size() ? levels[split_level].first : d.nodes.size();
  roots = split_level < levels.size() ? levels[split_level].second - roots_begin : 0;
  // Each subtree's ranges, found by the bottom-up task and walked again top-down.
  subtrees.resize(roots);
  parallel_tasks(roots, threads, [&](std::size_t t, unsigned w) {
    auto& sub = subtrees[t];
    subtree_levels(roots_begin + t, sub);
    for (std::size_t k = sub.size(); k-- > 0;)
      bottom_up(sub[k].first, sub[k].second, per_worker[w]);
  });
  for (std::size_t li = split_level; li-- > 0;)
    bottom_up(levels[li].first, levels[li].second, per_worker[0]);
  for (const auto& c : per_worker) {
    d.stats.contained_inner += c.contained;
    d.stats.degenerate_faces += c.degenerate;
  }
}

// ---- Stage 5 (§3.5): quantised spheres, top down ---------------------------------------------

void pop_build_state::top_down(std::size_t i) {
  auto& nd = d.nodes[i];
  const auto& pa = d.nodes[nd.parent];
  const std::uint16_t code = quantise_sphere(pa.centre, pa.radius, nd.centre, nd.radius);
  d.node_sphere_codes[i] = code;
  dequantise_sphere(pa.centre, pa.radius, code, nd.centre, nd.radius);
}

/// A parent's quantised sphere before its children's: the exact sphere of each node is replaced
/// by the smallest coded sphere that holds it and lies inside the parent's, so by induction
/// every stored sphere holds its subtree, and children stay inside parents (the coherent
/// traversal and culling rely on both). The same subtrees as spheres_and_cones(); a node
/// depends only on its parent, so the output does not depend on the schedule.
void pop_build_state::quantise_spheres() {
  resize_fresh(d.node_sphere_codes, d.nodes.size(), threads, sphere_code_parent);
  for (std::size_t li = 1; li < split_level; ++li)
    for (std::size_t i = levels[li].first; i < levels[li].second; ++i) top_down(i);
  parallel_tasks(roots, threads, [&](std::size_t t, unsigned) {
    for (const auto& [a, b] : subtrees[t])
      for (std::size_t i = a; i < b; ++i) top_down(i);
  });
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

}  // namespace

pop_data build_pop_data(const triangle_mesh& mesh, const pop_options& opt, bool colour) {
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
