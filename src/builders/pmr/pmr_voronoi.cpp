// pbr_lod — PMR (Dey & Hudson, IEEE Vis 2002), the Voronoi part of §2 for one octree leaf:
// poles, heights, tangent polygons and radii of the Voronoi cells (Amenta & Bern 1999), the
// iterative deletion of samples with r/h < ρ (Point hierarchy), and the umbrellas (Triangle
// hierarchy). The only translation unit of the builder that includes CGAL (its own object
// library, src/builders/pmr/sources.cmake).
//
// Robustness. The triangulation and every removal use CGAL's exact predicates (Epick), so the
// combinatorics are exact whatever the input's degeneracies (cospherical, coplanar samples). The
// tangent-plane tests compare constructed points (circumcentres, which are not input points)
// against a constructed plane, where an exact sign has no meaning; they use one half-open rule
// (s < 0 versus s ≥ 0) for every Voronoi vertex, so the edges of a cell that the plane crosses
// always close into one polygon. Coordinates arrive relative to the leaf's centre (subtracted
// in double by the caller), so scans far from the origin lose nothing here.
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Delaunay_triangulation_cell_base_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <numbers>
#include <queue>
#include <utility>
#include <vector>

#include "pbr_lod/builders/pmr.hpp"
#include "pbr_lod/core/knn.hpp"

namespace pbr_lod::detail {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_3<std::uint32_t, K>;
/// A Delaunay cell that caches its circumcentre in place: CGAL's
/// Delaunay_triangulation_cell_base_with_circumcenter_3 computes the same value (the base's
/// circumcenter(), from the vertices in order) but allocates it on the heap, one allocation per
/// cell and a pointer to follow on every visit of a Voronoi cell (malloc and free were 40 % of a
/// build). The cache is mutable: a triangulation belongs to one thread.
template <class GT, class Base = CGAL::Delaunay_triangulation_cell_base_3<GT>>
class cell_with_circumcentre : public Base {
 public:
  using Vertex_handle = typename Base::Vertex_handle;
  using Cell_handle = typename Base::Cell_handle;
  using Geom_traits = GT;
  template <class Tds2>
  struct Rebind_TDS {
    using Other = cell_with_circumcentre<GT, typename Base::template Rebind_TDS<Tds2>::Other>;
  };

  cell_with_circumcentre() = default;
  cell_with_circumcentre(Vertex_handle v0, Vertex_handle v1, Vertex_handle v2, Vertex_handle v3)
      : Base(v0, v1, v2, v3) {}
  cell_with_circumcentre(Vertex_handle v0, Vertex_handle v1, Vertex_handle v2, Vertex_handle v3,
                         Cell_handle n0, Cell_handle n1, Cell_handle n2, Cell_handle n3)
      : Base(v0, v1, v2, v3, n0, n1, n2, n3) {}

  // Whatever changes a vertex forgets the circumcentre.
  void set_vertex(int i, Vertex_handle v) {
    known_ = false;
    Base::set_vertex(i, v);
  }
  void set_vertices() {
    known_ = false;
    Base::set_vertices();
  }
  void set_vertices(Vertex_handle v0, Vertex_handle v1, Vertex_handle v2, Vertex_handle v3) {
    known_ = false;
    Base::set_vertices(v0, v1, v2, v3);
  }
  const typename GT::Point_3& circumcenter(const GT& gt = GT()) const {
    if (!known_) {
      centre_ = Base::circumcenter(gt);
      known_ = true;
    }
    return centre_;
  }

 private:
  mutable typename GT::Point_3 centre_;
  mutable bool known_ = false;
};

using Cb = cell_with_circumcentre<K>;
using Tds = CGAL::Triangulation_data_structure_3<Vb, Cb>;
using Dt = CGAL::Delaunay_triangulation_3<K, Tds>;
using Point = K::Point_3;
using Vertex = Dt::Vertex_handle;
using Cell = Dt::Cell_handle;

constexpr double inf = std::numeric_limits<double>::infinity();

vec3d to_vec(const Point& p) {
  return {p.x(), p.y(), p.z()};
}

/// Pole, height, normal and tangent polygon of one Voronoi cell (Amenta & Bern; PMR Fig. 2).
struct cell_shape {
  vec3d normal = vec3d::UnitZ();
  vec3d pole = vec3d::Zero();
  double height = inf;
  double radius = 0;
  bool hull = false;
  bool crossed = false;  ///< the tangent plane crossed at least one Voronoi edge
  /// r/h, the decimation ratio; +inf when it cannot be measured (no finite pole, no crossing),
  /// so such samples are never deleted.
  [[nodiscard]] double ratio() const {
    if (!(height > 0) || !std::isfinite(height) || !crossed) return inf;
    return radius / height;
  }
};

/// A Delaunay triangle dual to a Voronoi edge of V_p that p's tangent plane crosses (a triangle
/// of p's umbrella before the surface rules): its sorted point indices and its dual Voronoi
/// edge, the segment [a, b] or, when `ray`, the ray from a along b.
struct umbrella_candidate {
  std::array<std::uint32_t, 3> tri{};
  vec3d a = vec3d::Zero(), b = vec3d::Zero();
  bool ray = false;
};

/// Whether the Voronoi edge of c meets the cocone of sample q with unit normal m: the points x
/// with |m·(x − q)| ≤ sin θ · |x − q| (Amenta, Choi, Dey, Leekha 2002; the restriction to V_q
/// holds by itself, since the edge dual to a triangle at q lies on V_q's boundary). Outside the
/// cocone are two convex cones about ±m (the nappes); a segment misses the cocone exactly when
/// both ends lie in the same nappe, a ray when its start does and its direction points into that
/// nappe's cone.
bool meets_cocone(const vec3d& q, const vec3d& m, double sin_theta, const umbrella_candidate& c) {
  const auto nappe = [&](const vec3d& x) {
    const double g = m.dot(x), h = sin_theta * x.norm();
    return g > h ? 1 : (g < -h ? -1 : 0);
  };
  const int sa = nappe(c.a - q);
  if (sa == 0) return true;
  return nappe(c.ray ? c.b : vec3d(c.b - q)) != sa;
}

class leaf_voronoi {
 public:
  explicit leaf_voronoi(const pmr_cell_input& in) : in_(in) {
    std::vector<std::pair<Point, std::uint32_t>> pts;
    pts.reserve(in.points.size());
    for (std::uint32_t i = 0; i < in.points.size(); ++i) {
      const vec3d& p = in.points[i];
      pts.emplace_back(Point(p.x(), p.y(), p.z()), i);
    }
    dt_.insert(pts.begin(), pts.end());  // spatially sorted range insertion
    vertex_.assign(in.points.size(), Vertex());
    for (auto v = dt_.finite_vertices_begin(); v != dt_.finite_vertices_end(); ++v)
      vertex_[v->info()] = v;
  }

  [[nodiscard]] int dimension() const { return dt_.dimension(); }
  [[nodiscard]] std::size_t size() const { return dt_.number_of_vertices(); }
  [[nodiscard]] bool alive(std::uint32_t i) const { return vertex_[i] != Vertex(); }

  /// The cell of sample i: pole and normal (§2 Point hierarchy; hull cells from the outward
  /// hull normals), height, and the tangent polygon's radius; with `umbrella`, also the Delaunay
  /// triangles dual to the Voronoi edges the tangent polygon crosses, with those edges. Needs
  /// dimension 3.
  cell_shape shape(std::uint32_t i, std::vector<umbrella_candidate>* umbrella,
                   const vec3d* plane_normal = nullptr) {
    const Vertex v = vertex_[i];
    const Point& P = v->point();
    const vec3d p = to_vec(P);
    cells_.clear();
    dt_.incident_cells(v, std::back_inserter(cells_));
    cell_shape s;
    // Pole: the farthest Voronoi vertex, or for an unbounded cell the direction of the average
    // outward normal of the incident hull facets (Amenta & Bern's convention).
    vec3d out = vec3d::Zero();
    double far2 = -1;
    vec3d farc = p;
    for (const Cell& c : cells_) {
      if (dt_.is_infinite(c)) {
        s.hull = true;
        out += hull_normal(c, c->index(dt_.infinite_vertex())).normalized();
      } else {
        const vec3d cc = to_vec(c->circumcenter());
        const double d2 = (cc - p).squaredNorm();
        if (d2 > far2) {
          far2 = d2;
          farc = cc;
        }
      }
    }
    if (s.hull && out.squaredNorm() > 0) {
      s.normal = out.normalized();
      // Height: the farthest Voronoi vertex on the inner side (the other pole).
      double h2 = -1;
      for (const Cell& c : cells_) {
        if (dt_.is_infinite(c)) continue;
        const vec3d d = to_vec(c->circumcenter()) - p;
        if (d.dot(s.normal) < 0) h2 = std::max(h2, d.squaredNorm());
      }
      s.height = h2 > 0 ? std::sqrt(h2) : inf;
      s.pole = std::isfinite(s.height) ? vec3d(p - s.height * s.normal) : p;
    } else if (far2 > 0) {
      s.height = std::sqrt(far2);
      s.normal = (farc - p) / s.height;
      s.pole = farc;
    } else {
      return s;  // no usable cell (cannot happen in dimension 3; kept safe)
    }
    // Tangent polygon: the plane through p orthogonal to the normal cuts the Voronoi edges of
    // V_p (duals of the Delaunay triangles at p) where their ends lie on opposite sides.
    // The tangent plane: orthogonal to the pole vector, or to the given normal.
    const vec3d& n = plane_normal ? *plane_normal : s.normal;
    double r = 0;
    for (const Cell& c : cells_) {
      const int iv = c->index(v);
      const bool c_inf = dt_.is_infinite(c);
      const int c_inf_index = c_inf ? c->index(dt_.infinite_vertex()) : -1;
      for (int j = 0; j < 4; ++j) {
        if (j == iv) continue;
        if (c_inf && j != c_inf_index) continue;  // the triangle holds the infinite vertex
        const Cell nb = c->neighbor(j);
        const bool nb_inf = dt_.is_infinite(nb);
        // Each triangle once: from the cell with the lower address (both hold v). A hull
        // triangle is visited from its finite cell only.
        if (c_inf) continue;
        if (!nb_inf && std::less<const void*>{}(&*nb, &*c)) continue;
        const vec3d c1 = to_vec(c->circumcenter());
        const double s1 = n.dot(c1 - p);
        vec3d x, far;
        if (!nb_inf) {
          far = to_vec(nb->circumcenter());
          const double s2 = n.dot(far - p);
          if ((s1 < 0) == (s2 < 0)) continue;
          x = c1 + (far - c1) * (s1 / (s1 - s2));
        } else {
          // An unbounded Voronoi edge: the ray from c1 along the hull facet's outward normal.
          far = hull_normal(nb, nb->index(dt_.infinite_vertex()));
          const double nd = n.dot(far);
          if (!((s1 < 0 && nd > 0) || (s1 >= 0 && nd < 0))) continue;
          x = c1 - far * (s1 / nd);
        }
        s.crossed = true;
        r = std::max(r, (x - p).norm());
        if (umbrella) {
          umbrella_candidate u{{}, c1, far, nb_inf};
          int k = 0;
          for (int m = 0; m < 4; ++m)
            if (m != j) u.tri[k++] = c->vertex(m)->info();
          std::sort(u.tri.begin(), u.tri.end());
          umbrella->push_back(u);
        }
      }
    }
    s.radius = r;
    return s;
  }

  /// Removes sample i (CGAL vertex removal keeps the triangulation Delaunay) and returns its
  /// finite neighbours before the removal, whose cells grew.
  void remove(std::uint32_t i, std::vector<std::uint32_t>& neighbours) {
    const Vertex v = vertex_[i];
    adj_.clear();
    dt_.finite_adjacent_vertices(v, std::back_inserter(adj_));
    neighbours.clear();
    for (const Vertex& a : adj_) neighbours.push_back(a->info());
    dt_.remove(v);
    vertex_[i] = Vertex();
  }

  /// Inserts sample i again (after a removal that lowered the dimension).
  void reinsert(std::uint32_t i) {
    const vec3d& p = in_.points[i];
    vertex_[i] = dt_.insert(Point(p.x(), p.y(), p.z()));
    vertex_[i]->info() = i;
  }

  /// 2-D triangulation (coplanar samples): the triangles around each vertex and the plane's
  /// normal.
  void flat_umbrellas(std::vector<std::vector<std::array<std::uint32_t, 3>>>& per_vertex,
                      vec3d& normal) const {
    normal = vec3d::UnitZ();
    bool have_normal = false;
    for (auto f = dt_.finite_facets_begin(); f != dt_.finite_facets_end(); ++f) {
      const Cell c = f->first;
      std::array<std::uint32_t, 3> t{c->vertex(0)->info(), c->vertex(1)->info(),
                                     c->vertex(2)->info()};
      if (!have_normal) {
        const vec3d a = to_vec(c->vertex(0)->point()), b = to_vec(c->vertex(1)->point()),
                    d = to_vec(c->vertex(2)->point());
        const vec3d nn = (b - a).cross(d - a);
        if (nn.squaredNorm() > 0) {
          normal = nn.normalized();
          have_normal = true;
        }
      }
      std::sort(t.begin(), t.end());
      for (const std::uint32_t k : t) per_vertex[k].push_back(t);
    }
  }

 private:
  /// Outward normal (not normalised) of the hull triangle of infinite cell c, the triangle
  /// opposite its infinite vertex k: away from the finite cell on its other side.
  [[nodiscard]] vec3d hull_normal(const Cell& c, int k) const {
    const vec3d a = to_vec(c->vertex((k + 1) & 3)->point());
    const vec3d b = to_vec(c->vertex((k + 2) & 3)->point());
    const vec3d d = to_vec(c->vertex((k + 3) & 3)->point());
    vec3d nn = (b - a).cross(d - a);
    const Cell in = c->neighbor(k);
    const vec3d inner = to_vec(in->vertex(in->index(c))->point());
    if (nn.dot(inner - a) > 0) nn = -nn;
    return nn;
  }

  const pmr_cell_input& in_;
  Dt dt_;
  std::vector<Vertex> vertex_;  // by point index; null once removed (or never inserted)
  std::vector<Cell> cells_;
  std::vector<Vertex> adj_;
};

/// Neighbours whose distance is a sample's local spacing (the k-th nearest).
constexpr int spacing_neighbours = 4;

/// Whether umbrella triangle t of sample p lies on the surface (docs/pmr.md, "Umbrellas on the
/// surface"): its longest edge at most edge_spacing × the largest spacing of its vertices, and
/// its dual Voronoi edge in the cocone of its other two vertices. Normals and spacings are those
/// of the current level (samples still present), computed once per sample and level.
class umbrella_rules {
 public:
  umbrella_rules(leaf_voronoi* vor, const pmr_cell_input& in)
      : vor_(vor),
        in_(in),
        sin_theta_(std::sin(static_cast<double>(in.cocone_degrees) * std::numbers::pi / 180)) {}

  [[nodiscard]] bool active() const { return in_.edge_spacing > 0 || in_.cocone_degrees > 0; }

  /// A new level: the samples present are those with alive(i); the previous level's normals
  /// and spacings are forgotten.
  template <class Alive>
  void new_level(const Alive& alive) {
    normal_.assign(in_.points.size(), vec3d::Zero());
    spacing_.assign(in_.points.size(), -1.0);
    if (!(in_.edge_spacing > 0)) return;
    // The spacing: distance to the k-th nearest sample present (an exact k-d tree per level).
    std::vector<vec3f> pts;
    for (std::uint32_t i = 0; i < in_.points.size(); ++i)
      if (alive(i)) pts.push_back(in_.points[i].cast<float>());
    index_ = std::make_unique<knn_index>(pts);
  }

  [[nodiscard]] bool keep(std::uint32_t p, const std::array<std::uint32_t, 3>& t,
                          const umbrella_candidate* dual) {
    if (in_.edge_spacing > 0) {
      double longest2 = 0, sigma = 0;
      for (int k = 0; k < 3; ++k) {
        longest2 =
            std::max(longest2, (in_.points[t[k]] - in_.points[t[(k + 1) % 3]]).squaredNorm());
        sigma = std::max(sigma, spacing(t[k]));
      }
      const double limit = static_cast<double>(in_.edge_spacing) * sigma;
      if (longest2 > limit * limit) return false;
    }
    if (in_.cocone_degrees > 0 && dual)
      for (const std::uint32_t q : t)
        if (q != p && !meets_cocone(in_.points[q], normal(q), sin_theta_, *dual)) return false;
    return true;
  }

  /// Whether point i has a given normal (pmr_cell_input::normals).
  [[nodiscard]] bool given(std::uint32_t i) const {
    return !in_.normals.empty() && in_.normals[i].squaredNorm() > 0;
  }

 private:
  double spacing(std::uint32_t i) {
    if (spacing_[i] < 0) {
      index_->query(in_.points[i].cast<float>(), spacing_neighbours + 1, idx_, d2_);
      // The first answer is the sample itself (the points are distinct).
      spacing_[i] = d2_.empty() ? 0.0 : std::sqrt(static_cast<double>(d2_.back()));
    }
    return spacing_[i];
  }
  const vec3d& normal(std::uint32_t i) {
    if (given(i)) return in_.normals[i];
    if (normal_[i].squaredNorm() == 0) normal_[i] = vor_->shape(i, nullptr).normal;
    return normal_[i];
  }

  leaf_voronoi* vor_;
  const pmr_cell_input& in_;
  double sin_theta_;
  std::vector<vec3d> normal_;
  std::vector<double> spacing_;
  std::vector<std::uint32_t> idx_;
  std::vector<float> d2_;
  std::unique_ptr<knn_index> index_;
};

void record_umbrellas(leaf_voronoi& vor, const pmr_cell_input& in, umbrella_rules& rules,
                      pmr_cell_output::level_umbrellas& out) {
  rules.new_level([&](std::uint32_t i) { return vor.alive(i); });
  std::vector<umbrella_candidate> cand;
  std::vector<std::array<std::uint32_t, 3>> tris;
  for (std::uint32_t i = 0; i < in.own; ++i) {
    if (!vor.alive(i)) continue;
    cand.clear();
    (void)vor.shape(i, &cand, rules.given(i) ? &in.normals[i] : nullptr);
    tris.clear();
    double ur2 = 0;
    for (const umbrella_candidate& c : cand) {
      if (rules.active() && !rules.keep(i, c.tri, &c)) continue;
      tris.push_back(c.tri);
      for (const std::uint32_t k : c.tri)
        ur2 = std::max(ur2, (in.points[k] - in.points[i]).squaredNorm());
    }
    std::sort(tris.begin(), tris.end());
    out.sample.push_back(i);
    out.first.push_back(static_cast<std::uint32_t>(out.tris.size()));
    out.tris.insert(out.tris.end(), tris.begin(), tris.end());
    out.radius.push_back(tris.empty() ? 0.0 : std::sqrt(ur2));
  }
  out.first.push_back(static_cast<std::uint32_t>(out.tris.size()));
}

/// Levels for a triangulation of dimension < 3: no Voronoi cells to measure, so no deletion;
/// every level is the input, with the plane's triangles as umbrellas in dimension 2 (the edge
/// rule applies; a plane has no cocone to test).
pmr_cell_output flat_cell(leaf_voronoi& vor, const pmr_cell_input& in) {
  pmr_cell_output out;
  out.dimension = vor.dimension();
  const std::size_t levels = in.rho.size() + 1;
  out.levels.assign(in.own, static_cast<std::uint8_t>(levels));
  vec3d normal = vec3d::UnitZ();
  std::vector<std::vector<std::array<std::uint32_t, 3>>> per_vertex(in.points.size());
  if (vor.dimension() == 2) vor.flat_umbrellas(per_vertex, normal);
  out.normal.assign(in.own, normal);
  out.pole.assign(in.points.begin(), in.points.begin() + in.own);
  out.height.assign(in.own, inf);
  out.radius.assign(in.own, 0.0);
  out.hull.assign(in.own, 1);
  umbrella_rules rules(nullptr, in);
  if (rules.active()) rules.new_level([](std::uint32_t) { return true; });
  pmr_cell_output::level_umbrellas lu;
  for (std::uint32_t i = 0; i < in.own; ++i) {
    auto& t = per_vertex[i];
    if (rules.active())
      t.erase(std::remove_if(t.begin(), t.end(),
                             [&](const auto& tri) { return !rules.keep(i, tri, nullptr); }),
              t.end());
    std::sort(t.begin(), t.end());
    double ur2 = 0;
    for (const auto& tri : t)
      for (const std::uint32_t k : tri)
        ur2 = std::max(ur2, (in.points[k] - in.points[i]).squaredNorm());
    lu.sample.push_back(i);
    lu.first.push_back(static_cast<std::uint32_t>(lu.tris.size()));
    lu.tris.insert(lu.tris.end(), t.begin(), t.end());
    lu.radius.push_back(std::sqrt(ur2));
  }
  lu.first.push_back(static_cast<std::uint32_t>(lu.tris.size()));
  out.umbrellas.assign(levels, lu);
  return out;
}

}  // namespace

pmr_cell_output pmr_process_cell(const pmr_cell_input& in) {
  leaf_voronoi vor(in);
  if (vor.dimension() < 3) return flat_cell(vor, in);
  const std::uint32_t n = static_cast<std::uint32_t>(in.points.size());
  pmr_cell_output out;
  out.dimension = 3;
  out.levels.assign(in.own, 1);
  out.normal.resize(in.own);
  out.pole.resize(in.own);
  out.height.resize(in.own);
  out.radius.resize(in.own);
  out.hull.resize(in.own);
  out.umbrellas.resize(in.rho.size() + 1);

  // Level 0: every cell's shape (own samples: stored), ratios for the deletion.
  std::vector<double> ratio(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    const cell_shape s = vor.shape(i, nullptr);
    ratio[i] = s.ratio();
    if (i < in.own) {
      out.normal[i] = s.normal;
      out.pole[i] = s.pole;
      out.height[i] = s.height;
      out.radius[i] = s.radius;
      out.hull[i] = s.hull ? 1 : 0;
    }
  }
  umbrella_rules rules(&vor, in);
  record_umbrellas(vor, in, rules, out.umbrellas[0]);

  // Iterative deletion per threshold: the sample of smallest known r/h next (ties by index, so
  // the result is deterministic). A removal makes its neighbours' cells grow, so their ratios
  // are stale: they are marked and recomputed when they come up (lazily — most neighbours of a
  // removed sample are removed themselves before their ratio would matter), and those whose
  // stale ratio was already ≥ ρ are recomputed once the queue runs dry, since a grown cell can
  // lower r/h (a farther pole). The loop ends when every sample has a fresh ratio ≥ ρ.
  using entry = std::pair<double, std::uint32_t>;
  std::priority_queue<entry, std::vector<entry>, std::greater<>> heap;
  std::vector<std::uint32_t> nbrs, pending;
  std::vector<unsigned char> stale(n, 0);
  bool frozen = false;  // the triangulation would lose its third dimension: stop deleting
  for (std::size_t li = 0; li < in.rho.size(); ++li) {
    const double rho = in.rho[li];
    for (std::uint32_t i = 0; i < n; ++i)
      if (vor.alive(i) && ratio[i] < rho) heap.emplace(ratio[i], i);
    while (!frozen) {
      while (!heap.empty()) {
        const auto [q, i] = heap.top();
        heap.pop();
        if (!vor.alive(i) || q != ratio[i]) continue;  // removed, or a superseded entry
        if (stale[i]) {
          stale[i] = 0;
          ratio[i] = vor.shape(i, nullptr).ratio();
          if (ratio[i] < rho) heap.emplace(ratio[i], i);
          continue;
        }
        if (vor.size() <= 5) {
          frozen = true;
          break;
        }
        vor.remove(i, nbrs);
        if (vor.dimension() < 3) {
          // The rest is coplanar: put the sample back (the triangulation is as before), stop.
          vor.reinsert(i);
          frozen = true;
          break;
        }
        ++out.removals;
        for (const std::uint32_t k : nbrs) {
          if (stale[k]) continue;
          stale[k] = 1;
          if (!(ratio[k] < rho)) pending.push_back(k);  // else its entry is still queued
        }
      }
      bool more = false;
      for (const std::uint32_t k : pending) {
        if (!vor.alive(k) || !stale[k]) continue;
        stale[k] = 0;
        ratio[k] = vor.shape(k, nullptr).ratio();
        if (ratio[k] < rho) {
          heap.emplace(ratio[k], k);
          more = true;
        }
      }
      pending.clear();
      if (!more) break;
    }
    if (frozen) {
      // Whatever is still stale keeps its last ratio: no more deletions happen anyway.
      std::fill(stale.begin(), stale.end(), 0);
      pending.clear();
    }
    heap = {};
    for (std::uint32_t i = 0; i < in.own; ++i)
      if (vor.alive(i)) out.levels[i] = static_cast<std::uint8_t>(li + 2);
    record_umbrellas(vor, in, rules, out.umbrellas[li + 1]);
  }
  return out;
}

}  // namespace pbr_lod::detail
