// pbr_lod — covariance accumulators (Pajarola 2003 §4) and the numerically stable alternative.
//
// generic_homogeneous_covariance<T>  — the paper's EQ 2–4: M̄ = Σ p̂·p̂ᵀ over homogeneous points
//   p̂ = (p, 1). Sums of two sets add (EQ 4); the covariance about any centre o, in any rotated
//   frame, is n⁻¹·R·T·M̄·Tᵀ·Rᵀ (EQ 3). Elegant, but the centring happens *after* summing, so the
//   result is Σppᵀ/n − μμᵀ in disguise: it cancels catastrophically when the points are far from
//   the coordinate origin relative to their spread (PCL issues #2403, #2184). In float it is
//   useless for georeferenced data; in double it loses ~log10(|μ|²/σ²) digits.
//
// scatter_accumulator — count, mean and centred scatter S = Σ(p−μ)(p−μ)ᵀ, accumulated in double
//   relative to a local origin and merged pairwise with Chan, Golub & LeVeque's update
//   (S = S_a + S_b + δδᵀ·n_a·n_b/n, δ = μ_b − μ_a). Never subtracts two large numbers; this is
//   what the builders use by default.
#pragma once

#include <Eigen/Core>
#include <cstdint>

#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// The paper's generic homogeneous covariance matrix M̄ (EQ 2), accumulated in T (float or
/// double) exactly as written: no centring before summing.
template <class T>
struct generic_homogeneous_covariance {
  using mat4 = Eigen::Matrix<T, 4, 4>;
  using vec3 = Eigen::Matrix<T, 3, 1>;
  mat4 sum = mat4::Zero();  ///< Σ p̂ p̂ᵀ; sum(3,3) is the count

  void add(const vec3& p) {
    const Eigen::Matrix<T, 4, 1> h(p.x(), p.y(), p.z(), T(1));
    sum.noalias() += h * h.transpose();
  }
  /// EQ 4: the union of two point sets.
  generic_homogeneous_covariance& operator+=(const generic_homogeneous_covariance& o) {
    sum += o.sum;
    return *this;
  }
  [[nodiscard]] T count() const { return sum(3, 3); }
  [[nodiscard]] vec3 mean() const { return sum.template block<3, 1>(0, 3) / count(); }

  /// EQ 3: n⁻¹·R·T·M̄·Tᵀ·Rᵀ, T the translation by −centre, R the rotation whose rows are the
  /// new axes. Returns the full 4×4 homogeneous covariance; its upper-left 3×3 block is the
  /// Cartesian covariance in that frame, the upper-left 2×2 the covariance projected onto the
  /// plane of the first two axes.
  [[nodiscard]] mat4 in_frame(const vec3& centre, const Eigen::Matrix<T, 3, 3>& rotation) const {
    mat4 Tm = mat4::Identity();
    Tm.template block<3, 1>(0, 3) = -centre;
    mat4 Rm = mat4::Identity();
    Rm.template block<3, 3>(0, 0) = rotation;
    const mat4 RT = Rm * Tm;
    return RT * sum * RT.transpose() / count();
  }
  /// Cartesian covariance about the mean (EQ 1 computed through EQ 2).
  [[nodiscard]] Eigen::Matrix<T, 3, 3> covariance() const {
    return in_frame(mean(), Eigen::Matrix<T, 3, 3>::Identity()).template block<3, 3>(0, 0);
  }
};

/// Count, mean and centred scatter, merged with Chan et al.'s pairwise update. Positions are
/// given relative to whatever local origin the caller uses (the hierarchy's); accumulation is in
/// double.
struct scatter_accumulator {
  double n = 0;
  vec3d mean = vec3d::Zero();
  mat3d scatter = mat3d::Zero();  ///< Σ (p − mean)(p − mean)ᵀ

  /// Welford's update for one point.
  void add(const vec3d& p) {
    n += 1;
    const vec3d d = p - mean;
    mean += d / n;
    scatter.noalias() += d * (p - mean).transpose();
  }
  /// Chan et al.'s merge of two disjoint sets.
  scatter_accumulator& operator+=(const scatter_accumulator& o) {
    if (o.n == 0) return *this;
    if (n == 0) return *this = o;
    const double total = n + o.n;
    const vec3d delta = o.mean - mean;
    scatter += o.scatter + delta * delta.transpose() * (n * o.n / total);
    mean += delta * (o.n / total);
    n = total;
    return *this;
  }
  /// Covariance about the mean (EQ 1), symmetrised against rounding.
  [[nodiscard]] mat3d covariance() const {
    if (n == 0) return mat3d::Zero();
    const mat3d c = scatter / n;
    return 0.5 * (c + c.transpose());
  }
  /// Covariance about another centre o: M + (μ − o)(μ − o)ᵀ.
  [[nodiscard]] mat3d covariance_about(const vec3d& o) const {
    const vec3d d = mean - o;
    return covariance() + d * d.transpose();
  }
};

}  // namespace pbr_lod
