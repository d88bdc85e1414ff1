// pbr_lod — the interface every builder's hierarchy models.
//
// A Hierarchy is a tree of nodes, each with a bounding sphere, that can emit its primitives to a
// Sink. Required, for a type H:
//
//   typename H::node_id                         cheap to copy (an index)
//   H::attrs                                    static constexpr attributes of the primitives
//   h.origin() -> vec3d                         double-precision origin; node data are relative
//   h.empty() -> bool                           a hierarchy over no input has no root
//   h.root() -> node_id
//   h.is_leaf(n) -> bool
//   h.children(n) -> forward range of node_id   empty for a leaf
//   h.bounding_sphere(n) -> sphere              contains everything the subtree emits
//   h.emit(n, view, sink)                       send n's primitives: the node's own
//                                               representation for an inner node, full detail
//                                               for a leaf
// Optional:
//   h.normal_cone(n) -> normal_cone             enables back-face culling (HasNormalCones)
//
// Models: the builders in builders/, and tests/support/sphere_tree.hpp (a plain bounding-sphere
// tree used to prove the interface). Const member functions must be safe to call from several
// threads at once (traversals of different views may run concurrently).
#pragma once

#include <concepts>
#include <ranges>

#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/traverse/culling.hpp"
#include "pbr_lod/traverse/screen_size.hpp"
#include "pbr_lod/traverse/sink.hpp"

namespace pbr_lod {

template <class H>
concept Hierarchy = requires(const H& h, typename H::node_id n, const view& v,
                             counting_sink<H::attrs>& sink) {
  typename H::node_id;
  requires std::copyable<typename H::node_id>;
  { H::attrs } -> std::convertible_to<attributes>;
  { h.origin() } -> std::convertible_to<vec3d>;
  { h.empty() } -> std::convertible_to<bool>;
  { h.root() } -> std::same_as<typename H::node_id>;
  { h.is_leaf(n) } -> std::convertible_to<bool>;
  { h.children(n) } -> std::ranges::forward_range;
  requires std::convertible_to < std::ranges::range_value_t<decltype(h.children(n))>,
  typename H::node_id > ;
  { h.bounding_sphere(n) } -> std::convertible_to<sphere>;
  h.emit(n, v, sink);
};

template <class H>
concept HasNormalCones = Hierarchy<H> && requires(const H& h, typename H::node_id n) {
  { h.normal_cone(n) } -> std::convertible_to<normal_cone>;
};

}  // namespace pbr_lod
