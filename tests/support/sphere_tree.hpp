// Test/benchmark support: the simplest hierarchy that models pbr_lod::Hierarchy — a binary
// bounding-sphere tree over points (median split on the longest box axis), used to prove the
// common interface and the reference traversal without any paper's builder.
//
// Inner nodes emit one square point (the mean of their samples, sized to the node's projected
// diameter); leaves emit their samples as one-pixel points.
#pragma once

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <ranges>
#include <vector>

#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/traverse/hierarchy.hpp"

namespace pbr_lod::test {

template <attributes A>
class sphere_tree {
 public:
  using node_id = std::uint32_t;
  static constexpr attributes attrs = A & attributes{.normal = true, .colour = true};

  struct node {
    sphere bounds;
    pbr_lod::normal_cone cone;
    vec3f mean = vec3f::Zero();
    vec3f mean_normal = vec3f::UnitZ();
    rgb8 mean_colour{};
    std::uint32_t first_child = 0;       // children are first_child, first_child + 1; 0 = leaf
    std::uint32_t first = 0, count = 0;  // samples [first, first + count) of `order`
  };

  sphere_tree(const point_set<A>& pts, std::uint32_t leaf_size = 8) : pts_(&pts) {
    order_.resize(pts.size());
    std::iota(order_.begin(), order_.end(), 0u);
    if (pts.empty()) return;
    nodes_.reserve(2 * pts.size() / std::max(1u, leaf_size) + 1);
    nodes_.push_back({});
    build(0, 0, static_cast<std::uint32_t>(pts.size()), std::max(1u, leaf_size));
  }

  [[nodiscard]] vec3d origin() const { return pts_->origin; }
  [[nodiscard]] bool empty() const { return nodes_.empty(); }
  [[nodiscard]] node_id root() const { return 0; }
  [[nodiscard]] bool is_leaf(node_id n) const { return nodes_[n].first_child == 0; }
  [[nodiscard]] auto children(node_id n) const {
    const auto& nd = nodes_[n];
    return std::views::iota(nd.first_child, nd.first_child == 0 ? 0u : nd.first_child + 2);
  }
  [[nodiscard]] sphere bounding_sphere(node_id n) const { return nodes_[n].bounds; }
  [[nodiscard]] pbr_lod::normal_cone normal_cone(node_id n) const requires(A.normal) {
    return nodes_[n].cone;
  }
  [[nodiscard]] const node& at(node_id n) const { return nodes_[n]; }
  [[nodiscard]] std::size_t size() const { return nodes_.size(); }
  [[nodiscard]] std::span<const std::uint32_t> samples(node_id n) const {
    return {order_.data() + nodes_[n].first, nodes_[n].count};
  }

  template <class S>
  void emit(node_id n, const view& v, S& sink) const {
    const node& nd = nodes_[n];
    if (!is_leaf(n)) {
      point_prim<attrs> p{nd.mean, std::max(1.0f, 2 * projected_radius_exact(v, nd.bounds))};
      if constexpr (attrs.normal) p.normal = nd.mean_normal;
      if constexpr (attrs.colour) p.colour = nd.mean_colour;
      sink.point(p);
      return;
    }
    for (auto i : samples(n)) {
      point_prim<attrs> p{pts_->positions[i], 1.0f};
      if constexpr (attrs.normal) p.normal = pts_->normals[i];
      if constexpr (attrs.colour) p.colour = pts_->colours[i];
      sink.point(p);
    }
  }

 private:
  void build(node_id n, std::uint32_t first, std::uint32_t count, std::uint32_t leaf_size) {
    const auto idx = std::span(order_).subspan(first, count);
    box3 box;
    vec3d sum = vec3d::Zero(), nsum = vec3d::Zero(), csum = vec3d::Zero();
    for (auto i : idx) {
      box.extend(pts_->positions[i]);
      sum += pts_->positions[i].template cast<double>();
      if constexpr (A.normal) nsum += pts_->normals[i].template cast<double>();
      if constexpr (A.colour)
        csum += vec3d(pts_->colours[i].r, pts_->colours[i].g, pts_->colours[i].b);
    }
    {
      node& nd = nodes_[n];
      nd.first = first;
      nd.count = count;
      nd.mean = (sum / count).cast<float>();
      const vec3f c = box.centre();
      double r2 = 0;
      for (auto i : idx)
        r2 = std::max(r2, (pts_->positions[i] - c).template cast<double>().squaredNorm());
      nd.bounds = {c, static_cast<float>(std::sqrt(r2)) * (1 + 1e-6f)};
      if constexpr (A.normal) {
        nd.mean_normal =
            nsum.norm() > 0 ? vec3f(nsum.normalized().cast<float>()) : vec3f(vec3f::UnitZ());
        float worst = 0;
        for (auto i : idx)
          worst = std::max(
              worst, std::acos(std::clamp(nd.mean_normal.dot(pts_->normals[i]), -1.0f, 1.0f)));
        nd.cone = {nd.mean_normal, std::min(worst + 1e-4f, std::numbers::pi_v<float>)};
      }
      if constexpr (A.colour) {
        const vec3d m = csum / count;
        nd.mean_colour = {static_cast<std::uint8_t>(m.x() + 0.5),
                          static_cast<std::uint8_t>(m.y() + 0.5),
                          static_cast<std::uint8_t>(m.z() + 0.5)};
      }
    }
    if (count <= leaf_size) return;
    int axis = 0;
    box.extent().maxCoeff(&axis);
    const auto mid = idx.begin() + count / 2;
    std::nth_element(idx.begin(), mid, idx.end(), [&](std::uint32_t a, std::uint32_t b) {
      return pts_->positions[a][axis] < pts_->positions[b][axis];
    });
    const auto child = static_cast<std::uint32_t>(nodes_.size());
    nodes_[n].first_child = child;
    nodes_.push_back({});
    nodes_.push_back({});
    build(child, first, count / 2, leaf_size);
    build(child + 1, first + count / 2, count - count / 2, leaf_size);
  }

  const point_set<A>* pts_;
  std::vector<std::uint32_t> order_;
  std::vector<node> nodes_;
};

static_assert(Hierarchy<sphere_tree<positions_only>>);
static_assert(HasNormalCones<sphere_tree<with_normals>>);
static_assert(!HasNormalCones<sphere_tree<positions_only>>);

}  // namespace pbr_lod::test
