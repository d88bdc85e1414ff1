// pbr_lod — k-nearest neighbours through FLANN's exact single k-d tree (Muja & Lowe 2009,
// flann::KDTreeSingleIndex: median-free "middle split" tree, exact search with eps = 0 and
// unlimited checks). FLANN's C++ API is header-only; its headers call LZ4, hence the private
// PkgConfig::LZ4 link of the library (DEPENDENCIES.md gotcha 3).
#include "pbr_lod/core/knn.hpp"

#include <flann/flann.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "pbr_lod/core/error.hpp"

namespace pbr_lod {

namespace {

/// Keeps the k best (distance, index) pairs in caller-owned arrays, ordered by distance then
/// index, so that ties come out the same whatever order the tree visits them in.
class sorted_result final : public flann::ResultSet<float> {
 public:
  sorted_result(std::size_t capacity, std::uint32_t* idx, float* dist)
      : capacity_(capacity), idx_(idx), dist_(dist) {}

  [[nodiscard]] bool full() const override { return count_ == capacity_; }
  // FLANN only offers points with dist < worstDist(): one ulp more lets an equal distance with a
  // smaller index in, so ties are decided by index, not by the tree's visiting order.
  [[nodiscard]] float worstDist() const override {
    return full() ? std::nextafter(dist_[capacity_ - 1], std::numeric_limits<float>::infinity())
                  : std::numeric_limits<float>::max();
  }
  void addPoint(float dist, std::size_t index) override {
    const auto id = static_cast<std::uint32_t>(index);
    if (full() && !less(dist, id, dist_[capacity_ - 1], idx_[capacity_ - 1])) return;
    std::size_t i = count_ < capacity_ ? count_++ : capacity_ - 1;
    for (; i > 0 && less(dist, id, dist_[i - 1], idx_[i - 1]); --i) {
      dist_[i] = dist_[i - 1];
      idx_[i] = idx_[i - 1];
    }
    dist_[i] = dist;
    idx_[i] = id;
  }
  [[nodiscard]] std::size_t size() const { return count_; }

 private:
  static bool less(float d, std::uint32_t i, float d2, std::uint32_t i2) {
    return d < d2 || (d == d2 && i < i2);
  }
  std::size_t capacity_;
  std::size_t count_ = 0;
  std::uint32_t* idx_;
  float* dist_;
};

}  // namespace

struct knn_index::impl {
  using index_type = flann::KDTreeSingleIndex<flann::L2_Simple<float>>;
  std::vector<float> coords;  // #P × 3, owned: FLANN's Matrix only points at it
  std::size_t n = 0;
  std::unique_ptr<index_type> index;
  // Exact search: unlimited checks, eps = 0. Ties resolved by sorted_result.
  flann::SearchParams params{flann::FLANN_CHECKS_UNLIMITED, 0.0f, true};
};

knn_index::knn_index(std::span<const vec3f> pts) : impl_(std::make_unique<impl>()) {
  if (pts.size() > std::numeric_limits<std::uint32_t>::max())
    throw InvalidArgument("knn_index: more than 2^32 - 1 points");
  impl_->n = pts.size();
  impl_->coords.resize(pts.size() * 3);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    if (!all_finite(pts[i]))
      throw InvalidArgument("knn_index: point " + std::to_string(i) + " is not finite");
    for (int c = 0; c < 3; ++c) impl_->coords[3 * i + static_cast<std::size_t>(c)] = pts[i][c];
  }
  if (impl_->n == 0) return;
  const flann::Matrix<float> data(impl_->coords.data(), impl_->n, 3);
  impl_->index = std::make_unique<impl::index_type>(data, flann::KDTreeSingleIndexParams(10));
  impl_->index->buildIndex();
}

knn_index::~knn_index() = default;
knn_index::knn_index(knn_index&&) noexcept = default;
knn_index& knn_index::operator=(knn_index&&) noexcept = default;

std::size_t knn_index::size() const {
  return impl_ ? impl_->n : 0;
}

void knn_index::query(const vec3f& q, int k, std::vector<std::uint32_t>& idx,
                      std::vector<float>& dist2) const {
  const std::size_t want =
      (k <= 0 || !impl_ || !impl_->index) ? 0 : std::min<std::size_t>(std::size_t(k), impl_->n);
  idx.resize(want);
  dist2.resize(want);
  if (want == 0) return;
  sorted_result rs(want, idx.data(), dist2.data());
  const float qv[3] = {q.x(), q.y(), q.z()};
  impl_->index->findNeighbors(rs, qv, impl_->params);
  idx.resize(rs.size());
  dist2.resize(rs.size());
}

float knn_index::nearest_distance(const vec3f& q) const {
  if (!impl_ || !impl_->index) return std::numeric_limits<float>::infinity();
  std::uint32_t i = 0;
  float d2 = std::numeric_limits<float>::infinity();
  sorted_result rs(1, &i, &d2);
  const float qv[3] = {q.x(), q.y(), q.z()};
  impl_->index->findNeighbors(rs, qv, impl_->params);
  return rs.size() == 0 ? std::numeric_limits<float>::infinity() : std::sqrt(d2);
}

std::vector<float> knn_spacing(std::span<const vec3f> pts, int k) {
  std::vector<float> out(pts.size(), 0.0f);
  if (pts.size() < 2 || k <= 0) return out;
  const knn_index index(pts);
  // k + 1 neighbours: the first is the point itself (or a duplicate at distance 0, which is
  // the same thing for a spacing).
  const int want =
      std::min<int>(k + 1, static_cast<int>(std::min<std::size_t>(pts.size(), 1u << 30)));
  std::vector<std::uint32_t> idx;
  std::vector<float> d2;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    index.query(pts[i], want, idx, d2);
    out[i] = d2.empty() ? 0.0f : std::sqrt(d2.back());
  }
  return out;
}

}  // namespace pbr_lod
