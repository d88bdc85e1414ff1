// pbr_lod — k-NN normals (Hoppe et al. 1992, §3; PCA + MST orientation) and splat ellipses
// (Pajarola 2003, end of §4: the bounding-ellipse rule of Fig. 5/6a applied to the k nearest
// neighbours of each input sample). The only translation unit that includes CGAL: it is built
// as its own object library (src/core/estimation.cmake) so CGAL's -frounding-math stays here.
#include "pbr_lod/core/estimation.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/mst_orient_normals.h>
#include <CGAL/property_map.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <tuple>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/knn.hpp"

namespace pbr_lod {

namespace {

// Points per TBB task: a k-NN query is a few µs, so 1024 points amortise the scheduling.
constexpr std::size_t grain = 1024;

void check_positions(std::span<const vec3f> positions, const char* who) {
  for (std::size_t i = 0; i < positions.size(); ++i)
    if (!all_finite(positions[i]))
      throw InvalidArgument(std::string(who) + ": position " + std::to_string(i) +
                            " is not finite");
}

/// Runs body(begin, end) over [0, n) in parallel. Each index is written by exactly one call,
/// so results do not depend on how TBB splits the range.
template <class Body>
void parallel_over(std::size_t n, const Body& body) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain),
                    [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
}

/// A unit vector orthogonal to unit n, in double (math.hpp's any_orthogonal is float).
vec3d orthogonal(const vec3d& n) {
  const vec3d a = n.cwiseAbs();
  const vec3d axis = (a.x() <= a.y() && a.x() <= a.z()) ? vec3d::UnitX()
                     : (a.y() <= a.z())                 ? vec3d::UnitY()
                                                        : vec3d::UnitZ();
  return n.cross(axis).normalized();
}

/// Flips n so that its largest-magnitude component is positive (first of equals wins).
vec3d canonical_sign(const vec3d& n) {
  int m = 0;
  for (int c = 1; c < 3; ++c)
    if (std::abs(n[c]) > std::abs(n[m])) m = c;
  return n[m] < 0 ? vec3d(-n) : n;
}

/// PCA normal of the neighbourhood idx (see estimate_normals for the degenerate cases).
vec3d pca_normal(std::span<const vec3f> pts, const std::vector<std::uint32_t>& idx) {
  vec3d mean = vec3d::Zero();
  for (const auto j : idx) mean += pts[j].cast<double>();
  mean /= double(idx.size());
  // Two-pass, centred: the one-pass Σppᵀ − n·μμᵀ cancels catastrophically (DEPENDENCIES.md).
  mat3d cov = mat3d::Zero();
  for (const auto j : idx) {
    const vec3d d = pts[j].cast<double>() - mean;
    cov.noalias() += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<mat3d> es(cov);  // eigenvalues ascending
  const vec3d lambda = es.eigenvalues();
  if (es.info() != Eigen::Success || !(lambda[2] > 0) || !all_finite(lambda))
    return vec3d::UnitZ();  // one position (duplicates, single point)
  vec3d n = lambda[1] <= 1e-12 * lambda[2] ? orthogonal(es.eigenvectors().col(2).normalized())
                                           : vec3d(es.eigenvectors().col(0));
  n.normalize();
  return all_finite(n) ? canonical_sign(n) : vec3d::UnitZ();
}

/// Makes the signs of `normals` consistent with CGAL's MST propagation (Hoppe 1992). Points
/// CGAL leaves unoriented keep their sign.
void mst_orient(std::span<const vec3f> pts, std::vector<vec3f>& normals, int k) {
  using kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
  using item = std::tuple<kernel::Point_3, kernel::Vector_3, std::uint32_t>;
  std::vector<item> items;
  items.reserve(pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const vec3f& p = pts[i];
    const vec3f& n = normals[i];
    items.emplace_back(kernel::Point_3(p.x(), p.y(), p.z()), kernel::Vector_3(n.x(), n.y(), n.z()),
                       static_cast<std::uint32_t>(i));
  }
  const auto first_unoriented = CGAL::mst_orient_normals(
      items, static_cast<unsigned>(k),
      CGAL::parameters::point_map(CGAL::Nth_of_tuple_property_map<0, item>())
          .normal_map(CGAL::Nth_of_tuple_property_map<1, item>()));
  for (auto it = items.begin(); it != first_unoriented; ++it) {
    const auto& v = std::get<1>(*it);
    const vec3f n(float(v.x()), float(v.y()), float(v.z()));
    // CGAL only negates; keep our unit float normal and copy the sign.
    vec3f& out = normals[std::get<2>(*it)];
    if (n.dot(out) < 0) out = -out;
  }
}

}  // namespace

std::vector<vec3f> estimate_normals(std::span<const vec3f> positions, int k, bool orient) {
  if (k < 3) throw InvalidArgument("estimate_normals: k = " + std::to_string(k) + " < 3");
  check_positions(positions, "estimate_normals");
  const std::size_t n = positions.size();
  std::vector<vec3f> normals(n);
  if (n == 0) return normals;
  const knn_index index(positions);
  const int kk = static_cast<int>(std::min<std::size_t>(std::size_t(k), n));
  parallel_over(n, [&](std::size_t begin, std::size_t end) {
    std::vector<std::uint32_t> idx;
    std::vector<float> d2;
    for (std::size_t i = begin; i < end; ++i) {
      index.query(positions[i], kk, idx, d2);
      normals[i] = pca_normal(positions, idx).cast<float>();
    }
  });
  // CGAL needs ≥ 2 points and k ≥ 2.
  if (orient && n >= 2) mst_orient(positions, normals, std::max(kk, 2));
  return normals;
}

splat_axes estimate_splat_ellipses(std::span<const vec3f> positions, std::span<const vec3f> normals,
                                   int k) {
  if (k < 2) throw InvalidArgument("estimate_splat_ellipses: k = " + std::to_string(k) + " < 2");
  if (normals.size() != positions.size())
    throw InvalidArgument("estimate_splat_ellipses: " + std::to_string(normals.size()) +
                          " normals for " + std::to_string(positions.size()) + " positions");
  check_positions(positions, "estimate_splat_ellipses");
  for (std::size_t i = 0; i < normals.size(); ++i)
    if (!all_finite(normals[i]) || normals[i].squaredNorm() == 0)
      throw InvalidArgument("estimate_splat_ellipses: normal " + std::to_string(i) +
                            " is zero or not finite");
  const std::size_t n = positions.size();
  splat_axes out;
  out.u.resize(n);
  out.v.resize(n);
  if (n == 0) return out;

  // Scale of the last-resort disk: the bounding-box half-diagonal of all positions.
  vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& p : positions) {
    lo = lo.cwiseMin(p.cast<double>());
    hi = hi.cwiseMax(p.cast<double>());
  }
  const double half_diagonal = 0.5 * (hi - lo).norm();

  const knn_index index(positions);
  const int kk = static_cast<int>(std::min<std::size_t>(std::size_t(k), n));
  constexpr double ratio2 = splat_min_axis_ratio * splat_min_axis_ratio;
  constexpr double cover_margin = 1 + 1e-5;
  constexpr int max_fallback_k = 4096;

  parallel_over(n, [&](std::size_t begin, std::size_t end) {
    std::vector<std::uint32_t> idx;
    std::vector<float> d2;
    std::vector<vec2d> xy;
    for (std::size_t i = begin; i < end; ++i) {
      const vec3d p = positions[i].cast<double>();
      const vec3d nrm = normals[i].cast<double>().normalized();
      const vec3d t1 = orthogonal(nrm), t2 = nrm.cross(t1);
      index.query(positions[i], kk, idx, d2);
      // Second moments of the tangent-plane offsets about pᵢ (the splat's centre, not the
      // neighbourhood mean: at a boundary the neighbours lie on one side and must still be
      // covered). No division by the count: only the eigenvalue ratio and f·√λ matter.
      xy.clear();
      double a = 0, b = 0, c = 0, extent2 = 0;
      for (const auto j : idx) {
        const vec3d d = positions[j].cast<double>() - p;
        const vec2d q(d.dot(t1), d.dot(t2));
        xy.push_back(q);
        a += q.x() * q.x();
        b += q.x() * q.y();
        c += q.y() * q.y();
        extent2 += d.squaredNorm();
      }
      const double h = 0.5 * (a - c), r = std::hypot(h, b);
      const double l1 = 0.5 * (a + c) + r;
      if (!(l1 > 1e-10 * extent2) || !(l1 > 0)) {
        // Degenerate: every neighbour projects onto pᵢ. A disk reaching the nearest sample
        // that is not at pᵢ, searched among more and more neighbours.
        double radius = 0;
        for (int want = kk;; want = std::min(2 * want, max_fallback_k)) {
          if (want != kk) index.query(positions[i], want, idx, d2);
          for (const float e : d2)
            if (e > 0) {
              radius = std::sqrt(double(e));
              break;
            }
          if (radius > 0 || want >= max_fallback_k || std::size_t(want) >= n) break;
        }
        if (!(radius > 0)) radius = 1e-6 * half_diagonal;
        if (!(radius > 0)) radius = 1e-6 * std::max(1.0, p.cwiseAbs().maxCoeff());
        out.u[i] = (radius * t1).cast<float>();
        out.v[i] = (radius * t2).cast<float>();
        continue;
      }
      const double l2 = std::max(0.5 * (a + c) - r, ratio2 * l1);
      // Major axis at angle ψ = ½·atan2(2b, a − c) in the (t1, t2) frame (r > 0 here unless
      // the moments are isotropic, where any direction is an eigenvector: ψ = 0).
      const double psi = r > 0 ? 0.5 * std::atan2(b, h) : 0.0;
      const vec2d e1(std::cos(psi), std::sin(psi)), e2(-e1.y(), e1.x());
      double f2 = 0;
      for (const auto& q : xy) {
        const double x = q.dot(e1), y = q.dot(e2);
        f2 = std::max(f2, x * x / l1 + y * y / l2);
      }
      const double f = std::sqrt(f2) * cover_margin;
      const vec3d axis1 = e1.x() * t1 + e1.y() * t2, axis2 = e2.x() * t1 + e2.y() * t2;
      out.u[i] = (f * std::sqrt(l1) * axis1).cast<float>();
      out.v[i] = (f * std::sqrt(l2) * axis2).cast<float>();
    }
  });
  return out;
}

}  // namespace pbr_lod
