// pbr_lod — the POP builder, stages 4 and 5 (Chen & Nguyen 2001 §3.1, §3.5; the map of the
// stages is in pop_build_state.hpp): a triangle's smallest circle, the paper's inner-node sphere
// rules, then every node's bounding sphere, averaged normal and colour and normal cone bottom up,
// and the QSplat-style sphere codes top down. The geometry helpers sit with their one caller so
// the hot loops inline them.
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

}  // namespace pbr_lod::detail::pop_stages

namespace pbr_lod::detail {

using namespace pop_stages;

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

}  // namespace pbr_lod::detail

namespace pbr_lod::detail::pop_stages {

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

}  // namespace pbr_lod::detail::pop_stages
