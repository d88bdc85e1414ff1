// ρ-grid construction (Duguet & Drettakis 2004, §3.1), level by level.
//
// The only translation unit of the ρ-grid that includes CGAL: it is compiled as its own object
// library with CGAL's flags (-frounding-math), see rho_grid.cmake.
//
// Mesh: an AABB tree over the non-degenerate triangles (CGAL::AABB_tree, Epick). Per non-empty
// cell of a level, in parallel: the closest surface point to the centre
// (closest_point_and_primitive) gives the sample and its attribute; the triangles meeting the
// cell (all_intersected_primitives with the cell's box) are tested exactly against the children
// they may touch (CGAL::do_intersect(Triangle_3, Bbox_3)) to give the childhood code. The next
// level is the children, in digit order, of the cells in order — path order, i.e. breadth first.
//
// Points: every point's leaf path is a base-ρ³ number; sorted by it, the cells of every level are
// runs, so each level is one linear scan (codes from the next digit, sample = the run's point
// closest to the centre).
//
// "Level" in this file is a cell's depth below the cube (0 = the cube, k = the leaves); the
// option's level, the paper's, is k − 1 (rho_grid.hpp).
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <numeric>
#include <optional>
#include <thread>

#include "pbr_lod/builders/detail/rho_grid_impl.hpp"
#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/estimation.hpp"
#include "pbr_lod/core/mesh_normals.hpp"
#include "pbr_lod/core/normal_quantization.hpp"
#include "pbr_lod/core/normal_repair.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pbr_lod/core/repeated_faces.hpp"

namespace pbr_lod {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using tri_vector = std::vector<K::Triangle_3>;
using primitive = CGAL::AABB_triangle_primitive<K, tri_vector::const_iterator>;
using aabb_tree = CGAL::AABB_tree<CGAL::AABB_traits<K, primitive>>;

using cell_pos = std::array<std::uint32_t, 3>;

struct frame {
  vec3d min = vec3d::Zero();  // cube minimum corner (world, double)
  double side = 1;
  double leaf = 1;  // side / ρ^k
};

void check_options(const rho_grid_options& o, int rho) {
  const int maxl = rho_grid_max_level(rho);
  if (o.level && (*o.level < -1 || *o.level > maxl))
    throw InvalidArgument("rho-grid: level must lie in [-1, " + std::to_string(maxl) +
                          "] for rho = " + std::to_string(rho) + ", got " +
                          std::to_string(*o.level));
  if (o.colour_bits != 0 && (o.colour_bits < 3 || o.colour_bits > 16))
    throw InvalidArgument("rho-grid: colour_bits must be 0 or in [3, 16], got " +
                          std::to_string(o.colour_bits));
  if (o.normal_bits != 0 && (o.normal_bits < normal_quantizer::min_bits || o.normal_bits > 16))
    throw InvalidArgument("rho-grid: normal_bits must be 0 or in [" +
                          std::to_string(normal_quantizer::min_bits) + ", 16], got " +
                          std::to_string(o.normal_bits));
  if (o.material_bits < 0 || o.material_bits > 8)
    throw InvalidArgument("rho-grid: material_bits must lie in [0, 8], got " +
                          std::to_string(o.material_bits));
  if (o.normal_bits + o.material_bits > 16)
    throw InvalidArgument("rho-grid: normal_bits + material_bits (sigma) must be at most 16");
  if (o.knn != 0 && o.knn < 3)
    throw InvalidArgument("rho-grid: knn must be 0 (no estimated normals) or at least 3, got " +
                          std::to_string(o.knn));
  if (o.viewpoint && !all_finite(*o.viewpoint))
    throw InvalidArgument("rho-grid: the viewpoint is not finite");
}

/// The bounding cube of world points: centred on their box, side = largest extent (slightly
/// enlarged so the maximum falls inside a cell); a single point (or all identical) gets side 1.
frame make_frame(const vec3d& lo, const vec3d& hi, int rho, int depth) {
  frame f;
  const double extent = (hi - lo).maxCoeff();
  const vec3d centre = 0.5 * (lo + hi);
  const double scale = std::max(1.0, centre.cwiseAbs().maxCoeff());
  f.side = extent > 1e-12 * scale ? extent * (1 + 1e-9) : 1.0;
  f.min = centre - vec3d::Constant(0.5 * f.side);
  f.leaf = f.side / std::pow(double(rho), depth);
  return f;
}

std::uint32_t pack_attr(std::uint32_t normal, std::uint32_t material, int normal_bits) {
  return normal | (material << normal_bits);
}

/// rho_grid_options::level's default for a mesh: the coarsest level with ≥ 512 leaves across
/// the cube (a leaf about a pixel when the model fills a 512-pixel view): 8, 5, 4, 3 for
/// ρ = 2, 3, 4, 5 (512, 729, 1024, 625 leaves across).
int display_level(int rho) {
  int l = 0;
  std::uint64_t across = std::uint64_t(rho);
  while (across < 512) {
    across *= std::uint64_t(rho);
    ++l;
  }
  return std::min(l, rho_grid_max_level(rho));
}

/// Mean input points per occupied leaf below which a level is too fine for a point cloud: its
/// leaves no longer tile the sampled surface (a leaf narrower than the spacing is an island
/// among empty cells, and draws as an isolated dot however it is splatted). Four points per leaf
/// on average is a leaf about two point spacings across on a surface; with two, an unevenly
/// sampled scan (the milk-carton Kinect frame) still left a fifth of its render uncovered
/// (docs/rho-grid.md).
constexpr double min_points_per_leaf = 4.0;

/// Run-time statistics of the per-level working set.
struct working_set {
  std::size_t peak = 0;
  void note(std::size_t bytes) { peak = std::max(peak, bytes); }
};

template <int Rho>
struct level_builder {
  static constexpr int R3 = Rho * Rho * Rho;
  using grid = rho_grid<Rho>;
  using access = detail::rho_grid_access<Rho>;
  using code = detail::child_code<Rho>;

  static std::uint64_t pow_rho(int e) {
    std::uint64_t p = 1;
    for (int i = 0; i < e; ++i) p *= Rho;
    return p;
  }

  /// Centre of cell p at level l relative to the cube minimum.
  static vec3d centre(const cell_pos& p, std::uint64_t span, const frame& f) {
    return {(double(p[0] * span) + 0.5 * double(span)) * f.leaf,
            (double(p[1] * span) + 0.5 * double(span)) * f.leaf,
            (double(p[2] * span) + 0.5 * double(span)) * f.leaf};
  }

  static bool progress(const rho_grid_options& o, double fr) {
    return !o.progress || o.progress(fr);
  }

  /// After level l of k: reports the progress; throws Cancelled when the callback says stop.
  static void level_done(const rho_grid_options& o, int l, int k) {
    if (!progress(o, double(l + 1) / double(k + 1))) throw Cancelled("rho-grid: build cancelled");
  }

  /// Closes the build of g (its cell count checked by finish) and records its peak working set
  /// and time since t0; returns its statistics for the caller's own fields.
  static rho_grid_stats& finish(grid& g, std::uint64_t cells, const working_set& ws,
                                std::chrono::steady_clock::time_point t0) {
    access::finish(g, cells, "rho-grid build");
    auto& st = access::stats(g);
    st.peak_working_bytes = ws.peak;
    st.build_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    st.has_timings = true;
    return st;
  }
};

// ------------------------------------------------------------------------------------------
// Point clouds
// ------------------------------------------------------------------------------------------
/// The normals a point cloud's cells sample: the cloud's own, else (normal_bits > 0, knn > 0)
/// k-NN PCA normals from core/estimation, oriented towards the viewpoint or the cloud's sensor
/// when known, else over the k-NN graph; else none.
std::vector<vec3f> estimated_normals(const point_cloud& c, const rho_grid_options& o) {
  if (!c.normals.empty() || o.normal_bits == 0 || o.knn == 0) return {};
  estimation_options e{.k_normals = o.knn, .threads = o.threads};
  const std::optional<vec3d> vp = o.viewpoint ? o.viewpoint : c.sensor;
  if (vp) {
    e.orientation = normal_orientation::viewpoint;
    e.viewpoint = vec3d(*vp - c.origin).cast<float>();
  }
  return estimate_normals(c.positions, e);
}

/// The cloud's normals with every zero or non-finite one ("no normal") estimated from the
/// positions (fill_missing_normals); empty when none is missing or normals are not stored.
std::vector<vec3f> repaired_normals(const point_cloud& c, const rho_grid_options& o,
                                    std::size_t& filled) {
  filled = 0;
  if (c.normals.empty() || o.normal_bits == 0 ||
      std::none_of(c.normals.begin(), c.normals.end(), missing_normal))
    return {};
  std::vector<vec3f> n = c.normals;
  filled = fill_missing_normals(c.positions, n, o.knn ? o.knn : 16, o.threads).missing;
  return n;
}

/// The leaf cell and path key (k base-ρ³ digits, the first level most significant) of every
/// point of a cloud at leaf depth k, and the points sorted by key: the cells of every depth are
/// then runs of `order`.
template <int Rho>
struct point_paths {
  using lb = level_builder<Rho>;
  static constexpr int R3 = lb::R3;
  int depth;
  frame f;
  std::vector<cell_pos> leaf;
  std::vector<std::uint64_t> key;
  std::vector<std::uint32_t> order;

  point_paths(const point_cloud& c, int k) : depth(k) {
    const std::size_t n = c.size();
    vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (std::size_t i = 0; i < n; ++i) {
      const vec3d w = c.world(i);
      lo = lo.cwiseMin(w);
      hi = hi.cwiseMax(w);
    }
    f = make_frame(lo, hi, Rho, k);
    const std::uint64_t cells_per_axis = lb::pow_rho(k);
    const vec3d shift = c.origin - f.min;
    leaf.resize(n);
    key.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const vec3d r = shift + c.positions[i].cast<double>();
      for (int a = 0; a < 3; ++a) {
        const double x = std::floor(r[a] / f.leaf);
        leaf[i][std::size_t(a)] = std::uint32_t(
            std::clamp(x, 0.0, double(cells_per_axis - 1)));  // clamp also maps NaN-free rounding
      }
      std::uint64_t kk = 0;
      for (int l = 1; l <= k; ++l) {
        const std::uint64_t span = lb::pow_rho(k - l);
        const auto d = [&](int a) { return (leaf[i][std::size_t(a)] / span) % Rho; };
        kk = kk * R3 + (d(0) + Rho * d(1) + Rho * Rho * d(2));
      }
      key[i] = kk;
    }
    order.resize(n);
    std::iota(order.begin(), order.end(), 0u);
    std::stable_sort(order.begin(), order.end(),
                     [&](std::uint32_t a, std::uint32_t b) { return key[a] < key[b]; });
  }

  /// The finest depth (≥ 1: level 0) whose occupied leaves hold min_points_per_leaf points on
  /// average, counted from the sorted keys (a cell of depth d is a run of equal key prefixes).
  [[nodiscard]] int auto_depth() const {
    const std::size_t n = key.size();
    std::uint64_t div = 1;
    for (int d = depth; d >= 1; --d, div *= R3) {
      std::size_t occupied = 0;
      for (std::size_t i = 0; i < n; ++occupied) {
        const std::uint64_t ck = key[order[i]] / div;
        while (i < n && key[order[i]] / div == ck) ++i;
      }
      if (double(n) >= min_points_per_leaf * double(occupied)) return d;
    }
    return std::min(depth, 1);
  }

  /// Cuts the paths to depth k ≤ depth: keys and cells are prefixes, so the order stays sorted
  /// and the frame keeps its cube.
  void truncate(int k) {
    if (k >= depth) return;
    std::uint64_t div = 1, span = 1;
    for (int e = 0; e < depth - k; ++e) {
      div *= R3;
      span *= Rho;
    }
    for (auto& kk : key) kk /= div;
    for (auto& p : leaf)
      for (auto& x : p) x = std::uint32_t(x / span);
    f.leaf = f.side / std::pow(double(Rho), k);  // as make_frame computes it
    depth = k;
  }
};

template <int Rho>
rho_grid<Rho> build_from_points(const point_cloud& c, const rho_grid_options& o) {
  using lb = level_builder<Rho>;
  using access = typename lb::access;
  constexpr int R3 = lb::R3;
  const auto t0 = std::chrono::steady_clock::now();
  c.validate("rho-grid input");
  if (c.empty()) throw InvalidArgument("rho-grid: the input has no points");
  check_options(o, Rho);
  const std::size_t n = c.size();
  const std::vector<vec3f> estimated = estimated_normals(c, o);
  std::size_t filled = 0;
  const std::vector<vec3f> repaired = repaired_normals(c, o, filled);
  const double estimation_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const std::vector<vec3f>& normals =
      !estimated.empty() ? estimated : (!repaired.empty() ? repaired : c.normals);

  // Leaf paths at the requested depth, or (no level given) at the display depth, then cut to
  // the finest depth the sampling supports (point_paths::auto_depth).
  point_paths<Rho> pp(c, o.level ? *o.level + 1 : display_level(Rho) + 1);
  if (!o.level) pp.truncate(pp.auto_depth());
  const int k = pp.depth;  // leaf depth: the paper's level l is a ρ^(l+1) grid
  const frame& f = pp.f;
  const std::vector<cell_pos>& leaf = pp.leaf;
  const std::vector<std::uint64_t>& key = pp.key;
  const std::vector<std::uint32_t>& order = pp.order;
  const vec3d shift = c.origin - f.min;
  const int nb = normals.empty() ? 0 : o.normal_bits;
  const int mb = c.materials.empty() ? 0 : o.material_bits;
  const int cb = c.colours.empty() ? 0 : o.colour_bits;
  if (mb > 0)
    for (std::size_t i = 0; i < n; ++i)
      if (c.materials[i] >= (1u << mb))
        throw InvalidArgument("rho-grid: material " + std::to_string(c.materials[i]) +
                              " of point " + std::to_string(i) + " does not fit in " +
                              std::to_string(mb) + " material bits");
  std::optional<normal_quantizer> q;
  if (nb > 0) q.emplace(nb);

  working_set ws;
  ws.note(n * (sizeof(cell_pos) + sizeof(std::uint64_t) + sizeof(std::uint32_t)));
  rho_grid<Rho> g;
  access::set_frame(g, k, f.min, f.side, nb, mb);
  access::set_colour_bits(g, cb);
  auto& codes = access::codes(g);
  auto& attrs = access::attrs(g);
  auto& colours = access::colours(g);
  auto& samples = access::samples(g);
  std::size_t cells = 0;
  for (int l = 0; l <= k; ++l) {
    std::uint64_t div = 1;
    for (int e = 0; e < k - l; ++e) div *= R3;
    const std::uint64_t span = lb::pow_rho(k - l);
    for (std::size_t i = 0; i < n;) {
      const std::uint64_t ck = key[order[i]] / div;
      std::size_t j = i;
      typename lb::code cd;
      while (j < n && key[order[j]] / div == ck) {
        if (l < k) cd.set(int((key[order[j]] / (div / R3)) % R3));
        ++j;
      }
      const cell_pos& lp = leaf[order[i]];
      const cell_pos p{std::uint32_t(lp[0] / span), std::uint32_t(lp[1] / span),
                       std::uint32_t(lp[2] / span)};
      const vec3d ctr = lb::centre(p, span, f);
      std::uint32_t best = order[i];
      double best_d = std::numeric_limits<double>::infinity();
      for (std::size_t t = i; t < j; ++t) {
        const double d = (shift + c.positions[order[t]].cast<double>() - ctr).squaredNorm();
        if (d < best_d) {
          best_d = d;
          best = order[t];
        }
      }
      const std::uint32_t nc = nb ? q->encode(normals[best]) : 0u;
      const std::uint32_t mc = mb ? std::uint32_t(c.materials[best]) : 0u;
      if (nb + mb > 0) attrs.push_back(std::uint16_t(pack_attr(nc, mc, nb)));
      if (cb > 0) colours.push_back(std::uint16_t(rho_grid_encode_colour(c.colours[best], cb)));
      if (l < k) codes.push_back(cd);
      if (o.keep_sample_points)
        samples.push_back((shift + c.positions[best].cast<double>()).cast<float>());
      ++cells;
      i = j;
    }
    if (cells > 0xffffffffull)
      throw InvalidArgument("rho-grid: more cells than 32-bit child indices address");
    lb::level_done(o, l, k);
  }
  auto& st = lb::finish(g, cells, ws, t0);
  st.estimated_normals = !estimated.empty();
  st.normals_filled = filled;
  st.estimation_seconds = st.estimated_normals || filled > 0 ? estimation_seconds : 0.0;
  return g;
}

// ------------------------------------------------------------------------------------------
// Triangle meshes
// ------------------------------------------------------------------------------------------
/// A mesh's surface in the grid's frame: the cube over the vertices its faces use, and its
/// triangles relative to the cube's corner (exact repeats and zero-area faces dropped), each with
/// the index of its face.
struct mesh_surface {
  frame f;
  tri_vector tris;
  std::vector<std::uint32_t> face_of;
};

mesh_surface surface_of(const triangle_mesh& m, int rho, int k) {
  vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& fc : m.faces)
    for (auto v : fc) {
      const vec3d w = m.vertices.world(v);
      lo = lo.cwiseMin(w);
      hi = hi.cwiseMax(w);
    }
  mesh_surface ms{make_frame(lo, hi, rho, k), {}, {}};
  const vec3d shift = m.vertices.origin - ms.f.min;
  const auto rel = [&](std::uint32_t v) {
    const vec3d p = shift + m.vertices.positions[v].cast<double>();
    return K::Point_3(p.x(), p.y(), p.z());
  };
  ms.tris.reserve(m.faces.size());
  // Exact repeats add nothing to the surface; without this their count set the AABB tree's
  // cost and the depth of the k-d tree of its distance queries (a stack overflow at 50,000
  // copies of one triangle).
  for (const std::uint32_t i : unique_faces(m)) {
    const auto& fc = m.faces[i];
    const K::Point_3 a = rel(fc[0]), b = rel(fc[1]), cc = rel(fc[2]);
    if (CGAL::collinear(a, b, cc)) continue;  // zero area: measure-zero geometry, skipped
    ms.tris.emplace_back(a, b, cc);
    ms.face_of.push_back(std::uint32_t(i));
  }
  return ms;
}

/// The vertices a mesh without surface is sampled from as a point cloud: those of its faces, or
/// all of them when it has none.
point_cloud vertices_of(const triangle_mesh& m) {
  point_cloud pc;
  pc.origin = m.vertices.origin;
  std::vector<std::uint32_t> used;
  if (m.faces.empty()) {
    used.resize(m.vertices.size());
    std::iota(used.begin(), used.end(), 0u);
  } else {
    for (const auto& fc : m.faces) used.insert(used.end(), fc.begin(), fc.end());
    std::sort(used.begin(), used.end());
    used.erase(std::unique(used.begin(), used.end()), used.end());
  }
  for (auto v : used) {
    pc.positions.push_back(m.vertices.positions[v]);
    if (!m.vertices.normals.empty()) pc.normals.push_back(m.vertices.normals[v]);
    if (!m.vertices.materials.empty()) pc.materials.push_back(m.vertices.materials[v]);
    if (!m.vertices.colours.empty()) pc.colours.push_back(m.vertices.colours[v]);
  }
  return pc;
}

/// A cell's sample attributes from the closest point s on triangle ti: the normal interpolated
/// from the vertex normals, the nearest corner's material, the colour interpolated as the mesh's
/// render does.
struct mesh_attributes {
  const triangle_mesh& m;
  const mesh_surface& ms;
  const std::vector<vec3f>& vnormals;
  const normal_quantizer* q;
  int nb, mb, cb;

  void operator()(std::size_t ti, const vec3d& s, std::uint16_t* attr,
                  std::uint16_t* colour) const {
    const auto& tris = ms.tris;
    const auto& fc = m.faces[ms.face_of[ti]];
    // Barycentric coordinates of the closest point (double, Cramer on the normal
    // equations).
    const auto P = [&](int i) {
      const auto& v = tris[ti].vertex(i);
      return vec3d(v.x(), v.y(), v.z());
    };
    const vec3d a = P(0), e1 = P(1) - a, e2 = P(2) - a, d = s - a;
    const double d11 = e1.dot(e1), d12 = e1.dot(e2), d22 = e2.dot(e2);
    const double den = d11 * d22 - d12 * d12;
    double b1 = 0, b2 = 0;
    if (den > 0) {
      b1 = std::clamp((d22 * e1.dot(d) - d12 * e2.dot(d)) / den, 0.0, 1.0);
      b2 = std::clamp((d11 * e2.dot(d) - d12 * e1.dot(d)) / den, 0.0, 1.0 - b1);
    }
    const double b0 = 1 - b1 - b2;
    std::uint32_t nc = 0, mc = 0;
    if (nb > 0) {
      vec3d nrm = b0 * vnormals[fc[0]].cast<double>() + b1 * vnormals[fc[1]].cast<double>() +
                  b2 * vnormals[fc[2]].cast<double>();
      if (!(nrm.norm() > 1e-12) || !all_finite(nrm)) nrm = e1.cross(e2);
      nc = q->encode(nrm.cast<float>());
    }
    if (mb > 0) {
      const int vmax = b0 >= b1 && b0 >= b2 ? 0 : (b1 >= b2 ? 1 : 2);
      mc = m.vertices.materials[fc[std::size_t(vmax)]];
    }
    if (nb + mb > 0) *attr = std::uint16_t(pack_attr(nc, mc, nb));
    if (cb > 0) {
      // The colour at the closest point, interpolated as the mesh's render does.
      const auto& vc = m.vertices.colours;
      const auto mix = [&](std::uint8_t rgb8::*ch) {
        const double x = b0 * (vc[fc[0]].*ch) + b1 * (vc[fc[1]].*ch) + b2 * (vc[fc[2]].*ch);
        return std::uint8_t(std::clamp(std::lround(x), 0l, 255l));
      };
      *colour = std::uint16_t(
          rho_grid_encode_colour(rgb8{mix(&rgb8::r), mix(&rgb8::g), mix(&rgb8::b)}, cb));
    }
  }
};

/// The childhood code of cell p (side `span` leaves, children of `child_span`): the children
/// that a triangle meeting the cell intersects, by exact triangle/box tests; s, the cell's
/// sample, names the one child kept when rounding at a cell face leaves none.
template <int Rho>
typename level_builder<Rho>::code childhood_code(const aabb_tree& tree, const frame& f,
                                                 const cell_pos& p, std::uint64_t span,
                                                 std::uint64_t child_span, const vec3d& s,
                                                 std::vector<tri_vector::const_iterator>& hits) {
  using lb = level_builder<Rho>;
  // Childhood code: exact triangle/box tests of the triangles meeting this cell.
  const auto box = [&](std::uint64_t x0, std::uint64_t y0, std::uint64_t z0, std::uint64_t sp) {
    return CGAL::Bbox_3(double(x0) * f.leaf, double(y0) * f.leaf, double(z0) * f.leaf,
                        double(x0 + sp) * f.leaf, double(y0 + sp) * f.leaf,
                        double(z0 + sp) * f.leaf);
  };
  const std::uint64_t bx = p[0] * span, by = p[1] * span, bz = p[2] * span;
  hits.clear();
  tree.all_intersected_primitives(box(bx, by, bz, span), std::back_inserter(hits));
  typename lb::code cd;
  const double cs = double(child_span) * f.leaf;
  for (const auto& h : hits) {
    const CGAL::Bbox_3 tb = h->bbox();
    const auto range_of = [&](double lo_, double hi_, std::uint64_t base) {
      const double o0 = double(base) * f.leaf;
      const int a0 = std::clamp(int(std::floor((lo_ - o0) / cs)) - 1, 0, Rho - 1);
      const int a1 = std::clamp(int(std::floor((hi_ - o0) / cs)) + 1, 0, Rho - 1);
      return std::pair{a0, a1};
    };
    const auto [x0, x1] = range_of(tb.xmin(), tb.xmax(), bx);
    const auto [y0, y1] = range_of(tb.ymin(), tb.ymax(), by);
    const auto [z0, z1] = range_of(tb.zmin(), tb.zmax(), bz);
    for (int z = z0; z <= z1; ++z)
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
          const int j = x + Rho * y + Rho * Rho * z;
          if (cd.test(j)) continue;
          if (CGAL::do_intersect(
                  *h, box(bx + std::uint64_t(x) * child_span, by + std::uint64_t(y) * child_span,
                          bz + std::uint64_t(z) * child_span, child_span)))
            cd.set(j);
        }
  }
  if (cd.empty()) {
    // Only possible through rounding at a cell face: keep the child holding the sample.
    const auto axis = [&](double v, std::uint64_t base) {
      return std::clamp(int(std::floor((v - double(base) * f.leaf) / cs)), 0, Rho - 1);
    };
    cd.set(axis(s.x(), bx) + Rho * axis(s.y(), by) + Rho * Rho * axis(s.z(), bz));
  }
  return cd;
}

template <int Rho>
rho_grid<Rho> build_from_mesh(const triangle_mesh& m, const rho_grid_options& o) {
  using lb = level_builder<Rho>;
  using access = typename lb::access;
  constexpr int R3 = lb::R3;
  const auto t0 = std::chrono::steady_clock::now();
  m.validate("rho-grid input mesh");
  check_options(o, Rho);
  if (m.vertices.empty()) throw InvalidArgument("rho-grid: the input mesh has no vertices");
  // Leaf depth: the paper's level l is a ρ^(l+1) grid.
  const int k = (o.level ? *o.level : display_level(Rho)) + 1;
  const mesh_surface ms = surface_of(m, Rho, k);
  if (ms.tris.empty()) return build_from_points<Rho>(vertices_of(m), o);  // no surface
  const frame& f = ms.f;
  const int nb = o.normal_bits;  // a mesh always has (geometric) normals
  const int mb = m.vertices.materials.empty() ? 0 : o.material_bits;
  const int cb = m.vertices.colours.empty() ? 0 : o.colour_bits;
  if (mb > 0)
    for (std::size_t i = 0; i < m.vertices.size(); ++i)
      if (m.vertices.materials[i] >= (1u << mb))
        throw InvalidArgument("rho-grid: material " + std::to_string(m.vertices.materials[i]) +
                              " of vertex " + std::to_string(i) + " does not fit in " +
                              std::to_string(mb) + " material bits");
  std::optional<normal_quantizer> q;
  if (nb > 0) q.emplace(nb);
  const std::vector<vec3f> vnormals =
      nb == 0 ? std::vector<vec3f>{}
              : (m.vertices.normals.empty() ? area_weighted_normals(m) : m.vertices.normals);

  aabb_tree tree(ms.tris.cbegin(), ms.tris.cend());
  tree.build();
  tree.accelerate_distance_queries();
  (void)tree.closest_point(K::Point_3(0, 0, 0));  // builds the search structure before threads

  // The library's pool with an explicit thread count (core/parallel.hpp): no process-wide TBB
  // limit that would also cap every other thread of the caller's program.
  const unsigned threads = resolve_threads(o.threads);
  const mesh_attributes attributes{m, ms, vnormals, q ? &*q : nullptr, nb, mb, cb};

  rho_grid<Rho> g;
  access::set_frame(g, k, f.min, f.side, nb, mb);
  access::set_colour_bits(g, cb);
  auto& codes = access::codes(g);
  auto& attrs = access::attrs(g);
  auto& colours = access::colours(g);
  auto& samples = access::samples(g);
  working_set ws;
  std::vector<cell_pos> level{cell_pos{0, 0, 0}}, next;
  std::size_t cells = 0;
  for (int l = 0; l <= k; ++l) {
    const std::uint64_t span = lb::pow_rho(k - l);
    const std::uint64_t child_span = l < k ? span / Rho : 1;
    const std::size_t nl = level.size();
    std::vector<typename lb::code> lcodes(l < k ? nl : 0);
    std::vector<std::uint16_t> lattrs(nb + mb > 0 ? nl : 0);
    std::vector<std::uint16_t> lcolours(cb > 0 ? nl : 0);
    std::vector<vec3f> lsamples(o.keep_sample_points ? nl : 0);
    ws.note((level.capacity() + nl * R3) * sizeof(cell_pos) + nl * sizeof(typename lb::code) +
            (lattrs.size() + lcolours.size()) * 2 + lsamples.size() * sizeof(vec3f));
    detail::parallel_pieces(
        nl, threads, 8 * std::size_t(threads), 64, [&](std::size_t first, std::size_t last) {
          std::vector<tri_vector::const_iterator> hits;
          for (std::size_t ci = first; ci != last; ++ci) {
            const cell_pos& p = level[ci];
            const vec3d ctr = lb::centre(p, span, f);
            const auto [pt, it] =
                tree.closest_point_and_primitive(K::Point_3(ctr.x(), ctr.y(), ctr.z()));
            const vec3d s(pt.x(), pt.y(), pt.z());
            if (o.keep_sample_points) lsamples[ci] = s.cast<float>();
            const std::size_t ti = std::size_t(it - ms.tris.cbegin());
            if (nb + mb + cb > 0)
              attributes(ti, s, nb + mb > 0 ? &lattrs[ci] : nullptr,
                         cb > 0 ? &lcolours[ci] : nullptr);
            if (l < k) lcodes[ci] = childhood_code<Rho>(tree, f, p, span, child_span, s, hits);
          }
        });
    cells += nl;
    if (cells > 0xffffffffull)
      throw InvalidArgument("rho-grid: more cells than 32-bit child indices address");
    attrs.insert(attrs.end(), lattrs.begin(), lattrs.end());
    colours.insert(colours.end(), lcolours.begin(), lcolours.end());
    samples.insert(samples.end(), lsamples.begin(), lsamples.end());
    if (l < k) {
      next.clear();
      for (std::size_t ci = 0; ci < nl; ++ci) {
        const auto& cd = lcodes[ci];
        for (int j = 0; j < R3; ++j)
          if (cd.test(j))
            next.push_back({std::uint32_t(level[ci][0] * Rho + std::uint32_t(j % Rho)),
                            std::uint32_t(level[ci][1] * Rho + std::uint32_t((j / Rho) % Rho)),
                            std::uint32_t(level[ci][2] * Rho + std::uint32_t(j / (Rho * Rho)))});
      }
      codes.insert(codes.end(), lcodes.begin(), lcodes.end());
      std::swap(level, next);
      ws.note((level.capacity() + next.capacity()) * sizeof(cell_pos));
    }
    lb::level_done(o, l, k);
  }
  lb::finish(g, cells, ws, t0);
  return g;
}

}  // namespace

/// Records the input's bounding sphere (rho_grid::input_centre) in g.
template <int Rho>
rho_grid<Rho> with_input_bounds(rho_grid<Rho> g, const point_cloud& in) {
  const sphere s = bounding_sphere_about_box_centre(in.positions);
  detail::rho_grid_access<Rho>::set_input_bounds(g, in.origin + s.centre.cast<double>(),
                                                 double(s.radius));
  return g;
}

template <int Rho>
rho_grid<Rho> build_rho_grid(const triangle_mesh& mesh, const rho_grid_options& options) {
  return with_input_bounds(build_from_mesh<Rho>(mesh, options), mesh.vertices);
}
template <int Rho>
rho_grid<Rho> build_rho_grid(const point_cloud& points, const rho_grid_options& options) {
  return with_input_bounds(build_from_points<Rho>(points, options), points);
}

template <int Rho>
int rho_grid_auto_level(const triangle_mesh& mesh) {
  mesh.validate("rho-grid input mesh");
  if (mesh.vertices.empty()) throw InvalidArgument("rho-grid: the input mesh has no vertices");
  for (const auto& fc : mesh.faces) {
    const auto p = [&](int i) { return mesh.vertices.positions[fc[std::size_t(i)]]; };
    if ((p(1) - p(0)).cross(p(2) - p(0)).squaredNorm() > 0) return display_level(Rho);
  }
  return rho_grid_auto_level<Rho>(mesh.vertices);  // no surface: built from the vertices
}
template <int Rho>
int rho_grid_auto_level(const point_cloud& points) {
  points.validate("rho-grid input");
  if (points.empty()) throw InvalidArgument("rho-grid: the input has no points");
  return point_paths<Rho>(points, display_level(Rho) + 1).auto_depth() - 1;
}

#define PBR_LOD_RHO_GRID_BUILD(R)                                                        \
  template rho_grid<R> build_rho_grid<R>(const triangle_mesh&, const rho_grid_options&); \
  template rho_grid<R> build_rho_grid<R>(const point_cloud&, const rho_grid_options&);   \
  template int rho_grid_auto_level<R>(const triangle_mesh&);                             \
  template int rho_grid_auto_level<R>(const point_cloud&);
PBR_LOD_RHO_GRID_BUILD(2)
PBR_LOD_RHO_GRID_BUILD(3)
PBR_LOD_RHO_GRID_BUILD(4)
PBR_LOD_RHO_GRID_BUILD(5)
#undef PBR_LOD_RHO_GRID_BUILD

}  // namespace pbr_lod
