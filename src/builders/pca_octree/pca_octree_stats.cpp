// pbr_lod — the hierarchical PCA octree: the per-node statistics.
//
// This work is based on:
//   A. Kalaiah, A. Varshney. Statistical Point Geometry. SGP 2003.
// What this file implements:
//   §3    the PCA of a node's positions with the degenerate rules (pca_positions), of its
//         normals on the unit sphere through the unwrap at the pole (pca_normals, unwrap_normal,
//         wrap_normal) and of its colours (pca_colours). A file of its own: Eigen's eigen-
//         solvers are most of the compile time of the builder.
//   What a node's points span (pca_leaf_extents, pca_inner_extents): the bound every generated
//   position, normal and colour stays within (docs/pca-octree.md, "Deviations").

#include <Eigen/Eigenvalues>
#include <array>
#include <cmath>
#include <numbers>

#include "pca_octree_internal.hpp"

namespace pbr_lod::detail {

namespace {
/// §3: "we set a minimum value for σ_p^i (of the order 10⁻¹⁵)".
constexpr double sigma_floor = 1e-15;

/// Makes [f1 f2 f3] right-handed with f3·toward ≥ 0 and a canonical sign for f1 (its largest
/// component positive), so that the frame is a deterministic function of the data.
mat3d canonical_frame(vec3d f1, vec3d f3, const vec3d& toward) {
  if (f3.dot(toward) < 0) f3 = -f3;
  f1 -= f3 * f3.dot(f1);
  f1.normalize();
  Eigen::Index i = 0;
  f1.cwiseAbs().maxCoeff(&i);
  if (f1[i] < 0) f1 = -f1;
  mat3d f;
  f.col(0) = f1;
  f.col(1) = f3.cross(f1);
  f.col(2) = f3;
  return f;
}

/// Normals within asin(√near_pole) ≈ 11.5° of the pole take theta_over_sin_squared() instead
/// of atan2: most normals of a node lie there, and atan2 was most of the normal PCA's time.
constexpr double near_pole = 0.04;
/// (θ / sin θ)² for s = sin²θ ≤ near_pole, θ < π/2: the series asin²(x) / x² =
/// Σ_{n≥1} 2^(2n−1)·s^(n−1) / (n²·C(2n, n)) to n = 9; the next term is below 1e-14 relative
/// at s = near_pole (what atan2 gives, to rounding).
double theta_over_sin_squared(double s) {
  constexpr std::array<double, 9> c{
      1.0,          1.0 / 3,        8.0 / 45,     4.0 / 35,          128.0 / 1575,
      128.0 / 2079, 1024.0 / 21021, 256.0 / 6435, 131072.0 / 3938220};
  double p = c[8];
  for (std::size_t k = 8; k-- > 0;) p = p * s + c[k];
  return p;
}

/// any_orthogonal() in double (the float one would leave 1e-8 of non-orthogonality).
vec3d any_orthogonal_d(const vec3d& n) {
  const vec3d a = n.cwiseAbs();
  const vec3d axis = (a.x() <= a.y() && a.x() <= a.z()) ? vec3d::UnitX()
                     : (a.y() <= a.z())                 ? vec3d::UnitY()
                                                        : vec3d::UnitZ();
  return n.cross(axis).normalized();
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// §3: position PCA with the degenerate rules.
// ---------------------------------------------------------------------------------------------
scatter_accumulator position_moments(const vec3d* p, std::size_t n) {
  scatter_accumulator a;
  if (n == 0) return a;
  vec3d mean = vec3d::Zero();
  for (std::size_t i = 0; i < n; ++i) mean += p[i];
  mean /= static_cast<double>(n);
  mat3d s = mat3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    const vec3d d = p[i] - mean;
    s.noalias() += d * d.transpose();
  }
  a.n = static_cast<double>(n);
  a.mean = mean;
  a.scatter = s;
  return a;
}

pca_position_result pca_positions(const vec3d* p, std::size_t n, const vec3d& mean_normal) {
  if (n == 0) return {};
  const scatter_accumulator a = position_moments(p, n);
  return pca_positions_from(a.mean, a.covariance(), mean_normal);
}

pca_position_result pca_positions_from(const vec3d& mean, const mat3d& cov,
                                       const vec3d& mean_normal) {
  pca_position_result r;
  r.mean = mean;
  const vec3d normal = (all_finite(mean_normal) && mean_normal.norm() > 0.5)
                           ? mean_normal.normalized()
                           : vec3d::UnitZ();
  Eigen::SelfAdjointEigenSolver<mat3d> es(cov);
  // Eigen sorts ascending: column 2 is the principal direction.
  const vec3d ev = es.eigenvalues().cwiseMax(0.0);
  vec3d sigma(std::sqrt(ev[2]), std::sqrt(ev[1]), std::sqrt(ev[0]));
  // "Zero" variance: below the floor, or below what float coordinates of this magnitude and
  // double rounding of the sums can resolve (a collinear float cloud is collinear only to
  // within its rounding).
  const double tol = sigma_floor + 1e-6 * std::max(sigma[0], mean.cwiseAbs().maxCoeff());
  int zeros = 0;
  for (int i = 0; i < 3; ++i) zeros += sigma[i] <= tol ? 1 : 0;
  r.zero_variances = zeros;
  if (!all_finite(es.eigenvectors()) || !all_finite(sigma)) zeros = 3;
  switch (zeros) {
    case 0:
    case 1:  // a plane: f³ is its normal
      r.frame = canonical_frame(es.eigenvectors().col(2), es.eigenvectors().col(0), normal);
      break;
    case 2: {  // a line: keep the principal direction, z along the mean normal
      const vec3d f1 = es.eigenvectors().col(2).normalized();
      vec3d z = normal - f1 * f1.dot(normal);
      if (!(z.norm() > 1e-6)) z = any_orthogonal_d(f1);
      r.frame = canonical_frame(f1, z.normalized(), normal);
      sigma[1] = sigma[2] = 0;
      break;
    }
    default:  // a point: z along the normal, any tangent pair
      r.frame = canonical_frame(any_orthogonal_d(normal), normal, normal);
      sigma.setZero();
  }
  r.sigma = sigma.cwiseMax(sigma_floor);
  return r;
}

// ---------------------------------------------------------------------------------------------
// §3: normals on the unit sphere.
// ---------------------------------------------------------------------------------------------
vec2d unwrap_normal(const mat3d& frame, const vec3d& n) {
  const vec3d l = frame.transpose() * n;
  const double r = std::hypot(l.x(), l.y());
  const double theta = std::atan2(r, l.z());
  if (!(r > 0)) return {theta, 0.0};  // the pole (θ = 0) or its antipode (θ = π: any azimuth)
  return {theta * l.x() / r, theta * l.y() / r};
}

vec3d wrap_normal(const mat3d& frame, const vec2d& uv) {
  const double theta = uv.norm();
  if (!(theta > 0)) return frame.col(2);
  const double s = std::sin(theta) / theta;
  return (frame * vec3d(uv.x() * s, uv.y() * s, std::cos(theta))).normalized();
}

mat3d pca_normal_pole(const vec3d& sum, std::size_t count, const vec3d& fallback) {
  // The normals cancel out (a thin sheet seen from both sides): no mean direction exists, use
  // the caller's.
  vec3d z = sum.norm() > 1e-9 * static_cast<double>(count) ? vec3d(sum.normalized()) : fallback;
  if (!(z.norm() > 0.5)) z = vec3d::UnitZ();
  z.normalize();
  mat3d f;
  f.col(0) = any_orthogonal_d(z);
  f.col(1) = z.cross(f.col(0));
  f.col(2) = z;
  return f;
}

void pca_normal_unwrap_add(const mat3d& ft, const vec3f& normal, Eigen::Matrix2d& m) {
  // uv·uvᵀ = (θ/r)²·(x, y)(x, y)ᵀ for the normal (x, y, z) in the frame, r = |(x, y)|.
  const vec3d l = ft * normal.cast<double>();
  const vec2d xy = l.head<2>();
  const double r2 = xy.squaredNorm(), len2 = r2 + l.z() * l.z();
  double w;  // (θ/r)²
  if (l.z() > 0 && r2 <= near_pole * len2) {
    w = theta_over_sin_squared(r2 / len2) / len2;
  } else if (r2 > 0) {
    const double theta = std::atan2(std::sqrt(r2), l.z());
    w = theta * theta / r2;
  } else {  // on the axis: the pole adds nothing, the antipode unwraps to (π, 0)
    const double theta = std::atan2(0.0, l.z());
    m(0, 0) += theta * theta;
    return;
  }
  m.noalias() += w * (xy * xy.transpose());
}

pca_normal_result pca_normal_finish(const mat3d& f, Eigen::Matrix2d m, std::size_t count) {
  pca_normal_result r;
  const vec3d z = f.col(2);
  if (count > 0) m /= static_cast<double>(count);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(m);
  const vec2d ev = es.eigenvalues().cwiseMax(0.0);
  vec2d axis = es.eigenvectors().col(1);
  if (!all_finite(axis) || !(axis.norm() > 0.5) || !(ev[1] > 0)) axis = vec2d::UnitX();
  axis.normalize();
  if (axis.x() < 0 || (axis.x() == 0 && axis.y() < 0)) axis = -axis;
  r.frame.col(0) = (f.col(0) * axis.x() + f.col(1) * axis.y()).normalized();
  r.frame.col(1) = z.cross(r.frame.col(0));
  r.frame.col(2) = z;
  r.sigma = vec2d(std::sqrt(ev[1]), std::sqrt(ev[0]));
  if (!all_finite(r.sigma)) r.sigma.setZero();
  return r;
}

pca_normal_result pca_normals(const vec3f* n, std::size_t count, const vec3d& fallback) {
  vec3d sum = vec3d::Zero();
  for (std::size_t i = 0; i < count; ++i) sum += n[i].cast<double>();
  const mat3d f = pca_normal_pole(sum, count, fallback);
  // Second moments of the unwrapped normals about the pole (the generator of §4 is centred
  // there).
  const mat3d ft = f.transpose();
  Eigen::Matrix2d m = Eigen::Matrix2d::Zero();
  for (std::size_t i = 0; i < count; ++i) pca_normal_unwrap_add(ft, n[i], m);
  return pca_normal_finish(f, m, count);
}

scatter_accumulator colour_moments(const rgb8* c, std::size_t n) {
  scatter_accumulator a;
  if (n == 0) return a;
  const auto get = [&](std::size_t i) -> vec3d {
    const rgb8 k = c[i];
    return vec3d(k.r, k.g, k.b) / 255.0;
  };
  vec3d mean = vec3d::Zero();
  for (std::size_t i = 0; i < n; ++i) mean += get(i);
  mean /= static_cast<double>(n);
  mat3d s = mat3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    const vec3d d = get(i) - mean;
    s.noalias() += d * d.transpose();
  }
  a.n = static_cast<double>(n);
  a.mean = mean;
  a.scatter = s;
  return a;
}

/// §3: colour PCA of (r, g, b) in [0, 1]; no floor on σ_c (the paper finds none necessary).
pca_colour pca_colours(const rgb8* c, std::size_t n) {
  const scatter_accumulator a = colour_moments(c, n);
  return pca_colours_from(a.mean, a.covariance());
}

pca_colour pca_colours_from(const vec3d& mean, const mat3d& cov) {
  pca_colour r;
  Eigen::SelfAdjointEigenSolver<mat3d> es(cov);
  const vec3d ev = es.eigenvalues().cwiseMax(0.0);
  mat3d f = mat3d::Identity();
  if (all_finite(es.eigenvectors()))
    f = canonical_frame(es.eigenvectors().col(2), es.eigenvectors().col(0), vec3d(1, 1, 1));
  r.mean = mean.cast<float>();
  r.frame = f.cast<float>();
  r.sigma = vec3d(std::sqrt(ev[2]), std::sqrt(ev[1]), std::sqrt(ev[0])).cast<float>();
  return r;
}

// ---------------------------------------------------------------------------------------------
// What a node's points span.
// ---------------------------------------------------------------------------------------------
namespace {
/// A leaf's cone of normals about its mean normal and ball of colours about its mean colour.
void leaf_attribute_extents(pca_node& nd, pca_colour* colour, const vec3f* n, const rgb8* c,
                            std::size_t count) {
  const vec3d z = nd.normal_frame.col(2).cast<double>();
  double theta = 0;
  for (std::size_t i = 0; i < count; ++i)
    theta =
        std::max(theta, std::acos(std::clamp(z.dot(n[i].cast<double>().normalized()), -1.0, 1.0)));
  nd.normal_extent = static_cast<float>(theta);
  if (colour == nullptr) return;
  const vec3d cm = colour->mean.cast<double>();
  double r = 0;
  for (std::size_t i = 0; i < count; ++i)
    r = std::max(r, (vec3d(c[i].r, c[i].g, c[i].b) / 255.0 - cm).norm());
  colour->extent = static_cast<float>(r);
}
}  // namespace

double pca_leaf_extents(pca_node& nd, pca_colour* colour, const vec3d* p, const vec3f* n,
                        const rgb8* c, std::size_t count, double parent_spacing, const vec3f* u,
                        const vec3f* v, vec3f* for_parent) {
  const mat3d ft = nd.frame.cast<double>().transpose();
  const vec3d mu = nd.mean.cast<double>();
  vec3d e = vec3d::Zero();
  for (std::size_t i = 0; i < count; ++i) e = e.cwiseMax((ft * (p[i] - mu)).cwiseAbs());
  // Each point stands for the patch around it (the input's own render draws it as a disk of
  // 0.8 × its 8th neighbour's distance, ≈ 1.3 spacings): widen the tangential extents by the
  // points' spacing h — the side of the square each point gets (box area / count), or the gap
  // along a line of points, whichever is larger, and at least half the parent's spacing (few
  // points estimate their box poorly); two points: the parent's spacing (its cell edge over the
  // square root of its count). h is at most the cell edge.
  double h = parent_spacing;
  if (count >= 3) {
    const double k = static_cast<double>(count);
    h = std::max({std::sqrt(4 * e.x() * e.y() / k), 2 * std::max(e.x(), e.y()) / (k - 1),
                  0.5 * parent_spacing});
  }
  h = std::min(h, nd.cell_size);
  // Here only along the directions the points spread in; pca_widen_leaf() widens the others
  // when the parent's points span a surface (a line of points, one point, stays one otherwise).
  const double flat = 1e-6 * std::max(e.x(), mu.cwiseAbs().maxCoeff());
  if (e.x() > flat) e.x() += h;
  if (e.y() > flat) e.y() += h;
  nd.extent = e.cwiseMax(sigma_floor).cast<float>();
  leaf_attribute_extents(nd, colour, n, c, count);
  if (u == nullptr || v == nullptr) return h;
  // The points' own patches: an ellipse c + u·cos t + v·sin t reaches sqrt((f·u)² + (f·v)²)
  // along a direction f, so tangentially the leaf spans exactly its points' splats (across,
  // their centres: the generated points stay on the surface). Its parent still takes the box
  // above: patches tilted against the parent's plane would raise its span off the surface.
  if (for_parent != nullptr) *for_parent = nd.extent;
  // A mesh's splat bounds its vertex's dual cell: scaled to the cell's area (a regular hexagon's
  // circumscribed disk, √(3√3 / 2π) = 0.909), so that the box does not overhang a crease or an
  // open edge by the ellipse's corners (the small scene: cut → input 0.020 → 0.018).
  const double area = std::sqrt(3 * std::sqrt(3.0) / (2 * std::numbers::pi));
  vec3d s = e;
  s.x() = s.y() = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const vec3d q = ft * (p[i] - mu), a = ft * u[i].cast<double>(), b = ft * v[i].cast<double>();
    for (int k = 0; k < 2; ++k)
      s[k] = std::max(s[k], std::abs(q[k]) + area * std::hypot(a[k], b[k]));
  }
  nd.extent = s.cwiseMax(sigma_floor).cast<float>();
  return 0;
}

void pca_widen_leaf(pca_node& nd, double h, const mat3f& parent_frame) {
  // The leaf's frame follows its points' normal where they do not span a plane (§3's degenerate
  // rules): one point with its normal is a surface element, the input's own render draws it as
  // a disk across that normal. Trusted only where it agrees with the parent's surface: a normal
  // more than 30° off tilts the widened box by more than h/2 out of the parent's plane, and the
  // leaf stays what its points span.
  const double agree =
      std::abs(nd.frame.col(2).cast<double>().dot(parent_frame.col(2).cast<double>()));
  if (!(agree >= std::cos(std::numbers::pi / 6))) return;
  // A tangential direction pca_leaf_extents() widened is at least its spacing wide; one it left
  // is at most float rounding of the coordinates.
  for (int k = 0; k < 2; ++k)
    if (static_cast<double>(nd.extent[k]) < h)
      nd.extent[k] = static_cast<float>(static_cast<double>(nd.extent[k]) + h);
}

void pca_inner_extents(pca_data& d, std::size_t i, std::span<const vec3f> leaf_boxes) {
  pca_node& nd = d.nodes[i];
  const mat3d ft = nd.frame.cast<double>().transpose();
  const vec3d mu = nd.mean.cast<double>();
  const vec3d z = nd.normal_frame.col(2).cast<double>();
  const bool colour = !d.colours.empty();
  vec3d e = vec3d::Zero();
  double theta = 0, r = 0;
  for (std::uint32_t c = nd.first; c < nd.first + nd.count; ++c) {
    const pca_node& ch = d.nodes[c];
    const mat3d f = ch.frame.cast<double>();
    const vec3f& box = !leaf_boxes.empty() && ch.count == 0 ? leaf_boxes[c] : ch.extent;
    const vec3d ce = box.cast<double>(), cm = ch.mean.cast<double>();
    for (int corner = 0; corner < 8; ++corner) {
      const vec3d s((corner & 1) ? 1 : -1, (corner & 2) ? 1 : -1, (corner & 4) ? 1 : -1);
      e = e.cwiseMax((ft * (cm + f * s.cwiseProduct(ce) - mu)).cwiseAbs());
    }
    const double a = std::acos(std::clamp(z.dot(ch.normal_frame.col(2).cast<double>()), -1.0, 1.0));
    theta = std::max(theta, a + static_cast<double>(ch.normal_extent));
    if (colour)
      r = std::max(r, (d.colours[c].mean - d.colours[i].mean).cast<double>().norm() +
                          static_cast<double>(d.colours[c].extent));
  }
  nd.extent = e.cwiseMax(sigma_floor).cast<float>();
  nd.normal_extent = static_cast<float>(std::min(theta, std::numbers::pi));
  // (never beyond the diagonal of the RGB cube)
  if (colour) d.colours[i].extent = static_cast<float>(std::min(r, std::sqrt(3.0)));
}

}  // namespace pbr_lod::detail
