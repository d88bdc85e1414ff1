// Missing normals estimated from the positions: see include/pbr_lod/core/normal_repair.hpp.
#include "pbr_lod/core/normal_repair.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <string>
#include <thread>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/estimation.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod {
namespace {

/// The k-NN PCA normal of the neighbourhood `nb` (indices into P), unoriented; zero when the
/// neighbourhood has no spread (all neighbours at one position).
vec3f pca_normal(std::span<const vec3f> P, const std::vector<std::uint32_t>& nb) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto j : nb) mean += P[j].cast<double>();
  mean /= double(nb.size());
  Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
  for (const auto j : nb) {
    const Eigen::Vector3d d = P[j].cast<double>() - mean;
    c += d * d.transpose();
  }
  if (!(c.trace() > 0)) return vec3f::Zero();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(c);
  return es.eigenvectors().col(0).normalized().cast<float>();  // smallest eigenvalue first
}

}  // namespace

normal_repair fill_missing_normals(std::span<const vec3f> positions, std::span<vec3f> normals,
                                   int k, unsigned threads) {
  if (positions.size() != normals.size())
    throw InvalidArgument("fill_missing_normals: " + std::to_string(positions.size()) +
                          " positions but " + std::to_string(normals.size()) + " normals");
  if (k < 3) throw InvalidArgument("fill_missing_normals: k = " + std::to_string(k) + " < 3");
  normal_repair r;
  std::vector<std::uint32_t> missing;
  for (std::size_t i = 0; i < normals.size(); ++i)
    if (missing_normal(normals[i])) missing.push_back(static_cast<std::uint32_t>(i));
  r.missing = missing.size();
  if (missing.empty()) return r;
  if (missing.size() == normals.size()) {
    const std::vector<vec3f> est = estimate_normals(positions, k, true, threads);
    std::copy(est.begin(), est.end(), normals.begin());
    r.all_estimated = true;
    return r;
  }
  threads = resolve_threads(threads);
  const knn_index index(positions);  // throws on a non-finite position
  // Unoriented PCA normals and neighbourhoods of the missing points (in parallel: each entry
  // is its own point's, so the result does not depend on the thread count).
  std::vector<vec3f> est(missing.size());
  std::vector<std::vector<std::uint32_t>> hood(missing.size());
  detail::parallel_chunks(missing.size(), threads, 256, [&](std::size_t lo, std::size_t hi) {
    std::vector<float> d2;
    for (std::size_t m = lo; m < hi; ++m) {
      index.query(positions[missing[m]], k, hood[m], d2);
      est[m] = pca_normal(positions, hood[m]);
    }
  });
  // Orientation in rounds: a point whose neighbours include an oriented normal (given, or
  // settled in an earlier round) takes the sign that agrees with them; the rest wait. Each
  // round reads only normals settled before it, so the order within a round does not matter.
  std::vector<char> settled(normals.size(), 1);
  for (const auto i : missing) settled[i] = 0;
  std::vector<std::size_t> left(missing.size());
  for (std::size_t m = 0; m < left.size(); ++m) left[m] = m;
  while (!left.empty()) {
    std::vector<std::size_t> next, done;
    std::vector<vec3f> oriented;
    for (const std::size_t m : left) {
      double agree = 0;
      bool any = false;
      vec3f nearest = vec3f::Zero();
      for (const auto j : hood[m]) {
        if (!settled[j]) continue;
        if (!any) nearest = normals[j];
        any = true;
        agree += double(est[m].dot(normals[j]));
      }
      if (!any) {
        next.push_back(m);
        continue;
      }
      vec3f n = est[m];
      if (n.squaredNorm() == 0)
        n = nearest;  // no spread: the nearest oriented normal
      else if (agree < 0)
        n = -n;
      done.push_back(m);
      oriented.push_back(n);
    }
    if (done.empty()) {
      // A patch with no oriented neighbour at all (apart from the given normals): its first
      // point faces +z, and the next rounds orient the rest of the patch from it.
      const std::size_t m = next.front();
      vec3f n = est[m].squaredNorm() > 0 ? est[m] : vec3f(0, 0, 1);
      if (n.z() < 0) n = -n;
      done.push_back(m);
      oriented.push_back(n);
      next.erase(next.begin());
    }
    for (std::size_t t = 0; t < done.size(); ++t) {
      normals[missing[done[t]]] = oriented[t];
      settled[missing[done[t]]] = 1;
    }
    left = std::move(next);
  }
  return r;
}

}  // namespace pbr_lod
