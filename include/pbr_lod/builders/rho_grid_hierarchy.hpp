// pbr_lod — the ρ-grid as a Hierarchy, and its §4.1 traversal as a policy of the common traverse
// (Duguet & Drettakis 2004, §4, §4.1, §4.2 child order, §5.1).
//
// rho_grid_hierarchy<ρ, A> models Hierarchy (traverse/hierarchy.hpp) over a built rho_grid<ρ>:
// a node is a cell with its depth and integer position (positions are implicit in the path),
// A ⊆ {normal, colour} is the compile-time attribute set of the primitives (normal = the decoded
// σ-bit normal, colour = the decoded colour when the grid stores colours, else the material's
// palette colour), and emit() sends one point_prim at the cell centre. Any traversal policy can
// drive it; rho_grid_policy is the paper's.
//
// rho_grid_policy is the paper's Render(cell, centre, level) with Botsch et al.'s transformation
// factorisation: the homogeneous screen position H = (X, Y, W) of a cell centre is its parent's
// plus an entry of a per-depth displacement table (one vec add per cell, no matrix product) —
// the traversal's per-entry state — and the conservative screen bounds of a cell come from a
// per-depth bounds table:
//   A_x = max over the cube's corners of |ΔX|, A_y likewise, B = max |ΔW|.
// With E_x = A_x·W + B·|X|, every corner's x = X'/W' lies within E_x / (W·(W − B)) of X/W
// (while W − B > 0: the cell is wholly in front of the eye). So, all in homogeneous coordinates
// without a division (§4.1, Eq. 6):
//   splat condition   2·E_x ≤ s·W·(W − B)  and  2·E_y ≤ s·W·(W − B)
//   frustum culling   X·(W − B) + E_x < −c_x·W·(W − B)  (left of the screen; likewise right,
//                     top, bottom), W − B > z_far (beyond), W + B < z_near (behind the viewer)
// s is traverse_options::tolerance_px. A cell meeting the splat condition is emitted as a square
// splat of s pixels (an inner cell's intermediate sample); a leaf is emitted in any case, as a
// square of its own conservative projected width (§4.1's bounds of the cell), or a one-pixel
// point when that is at most a pixel — so that leaves larger than a pixel in close views leave
// no holes (rho_grid_policy::leaf_splats); a cell that straddles the near plane is refined. X is
// measured from the principal point, so |X| is small near the screen centre.
//
// §5.1 fixed point: rho_grid_policy<ρ, rho_grid_arithmetic::fixed> runs the same tests with H,
// the displacement and bounds tables in 64-bit fixed point (F fractional bits chosen per view so
// every |value| < 2^40) and 128-bit products. rho_grid_arithmetic::fixed32 is §5.1 as the paper
// has it, for a 32-bit CPU: H and the tables in int32 (F chosen so every |value| ≤ 2^30), no
// product wider than int32 × int32 → int64, and the tests divided by W through a reciprocal
// look-up table (detail::rho_reciprocal): on the projected centre x = X/W, y = Y/W
//   splat condition   2·(A_x + B·|x|) ≤ s·(W − B)  (and y)
//   frustum culling   x·(W − B) + A_x + B·|x| < −c_x·(W − B)  (left; likewise the others)
// which are the tests above divided by W > 0. Cells where the arithmetics disagree are those
// whose test is within rounding (or, for fixed32, the table's 2^-13) of equality (measured in
// docs/rho-grid.md; the tests bound it).
//
// Drawing (rho_grid_policy::screen_draw, §5.1 and §4.1): by default a drawn cell is a point_prim
// at its centre, which the sink projects itself (the rasteriser in float). With screen_draw, a
// sink that takes screen rectangles (ScreenRectSink) gets a screen_rect_prim placed from the
// traversal's own H divided by W — float a float division, int64 an integer division, fixed32
// the reciprocal table of its tests, then pixel indices by a shift (§5.1's last paragraph) —
// and, with the per-corner bounds, an inner cell covers the rectangle of its sampled children
// that its test measured (§4.1's rectangular splat) instead of an s × s square.
//
// §4.2: the policy visits children in any fixed order; rho_grid_light_order() gives the one that
// is front to back from a directional light, which raster/one_pass_shadows.hpp needs.
//
// Files: this header is the hierarchy (rho_grid_hierarchy, its cells); builders/rho_grid_policy.hpp
// the policies (rho_grid_policy, rho_grid_light_policy, rho_grid_light_order), over
// detail/rho_grid_traversal.hpp (tables and tests) and detail/rho_grid_arith.hpp (the number
// types, rho_grid_arithmetic, rho_grid_bounds). Include rho_grid_policy.hpp to draw with the
// paper's traversal.
#pragma once
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <numeric>
#include <optional>
#include <ranges>
#include <type_traits>
#include <vector>

#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/normal_quantization.hpp"
#include "pbr_lod/traverse/hierarchy.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod {

/// A node of a ρ-grid hierarchy: the cell index (rho_grid numbering), its depth below the root
/// cube (the paper's level + 1, see rho_grid) and its integer position in [0, ρ^depth)³ — the
/// path the implicit positions need.
struct rho_grid_cell {
  std::uint32_t cell;
  int depth;
  std::array<std::uint32_t, 3> pos;
};

/// Where rho_grid_policy::screen_draw puts a drawn cell: screen_rect_prim's pixel rectangle
/// (pixels × 2^8 from the image's top-left corner, y down) and depth.
struct rho_grid_screen_rect {
  std::int32_t x0, y0, x1, y1;
  float depth;
};

/// The colour of material m (8-entry palette, repeated).
[[nodiscard]] inline rgb8 rho_grid_material_colour(std::uint32_t m) {
  static constexpr std::array<rgb8, 8> palette{
      rgb8{200, 200, 200}, rgb8{220, 80, 60},  rgb8{80, 180, 90},  rgb8{70, 110, 210},
      rgb8{230, 200, 70},  rgb8{170, 90, 200}, rgb8{70, 200, 200}, rgb8{240, 140, 60}};
  return palette[m % 8];
}

/// A built rho_grid<Rho> seen as a Hierarchy whose primitives carry the attributes A (normals
/// decoded from the σ-bit attribute; colours decoded from it when the grid stores colours, else
/// from the material palette). Holds a pointer to the grid, which must outlive it. Const member
/// functions are safe for concurrent readers.
template <int Rho, attributes A>
class rho_grid_hierarchy {
  static_assert(attributes{.normal = true, .colour = true}.contains(A),
                "a ρ-grid has normals and colours (or materials, drawn as colours) only");

 public:
  static constexpr attributes attrs = A;
  static constexpr int children_per_cell = Rho * Rho * Rho;
  using node_id = rho_grid_cell;

  /// Throws InvalidArgument when A asks for normals or colours the grid does not store.
  explicit rho_grid_hierarchy(const rho_grid<Rho>& g) : g_(&g) {
    if (A.normal && !g.has_normals())
      throw InvalidArgument("rho-grid: normals requested, the grid stores none");
    if (A.colour && !g.has_colours() && !g.has_materials())
      throw InvalidArgument("rho-grid: colours requested, the grid stores no colours or materials");
    if constexpr (A.normal) q_ = normal_quantizer::shared(g.normal_bits());  // one per process
    // cell_side() takes a pow(); a frame asks for it once per drawn cell.
    for (int d = 0; d <= g.leaf_depth(); ++d) side_.push_back(g.cell_side(d));
  }

  [[nodiscard]] const rho_grid<Rho>& grid() const { return *g_; }
  [[nodiscard]] vec3d origin() const { return g_->origin(); }
  [[nodiscard]] bool empty() const { return g_->empty(); }
  [[nodiscard]] node_id root() const { return {0, 0, {0, 0, 0}}; }
  [[nodiscard]] bool is_leaf(const node_id& n) const { return g_->is_leaf(n.cell); }

  /// Child j (digit j = x + ρ·y + ρ²·z, set in n's code) of inner cell n.
  [[nodiscard]] node_id child(const node_id& n, int j) const {
    return child(n, j, g_->first_child(n.cell) + std::uint32_t(g_->code(n.cell).rank(j)));
  }
  /// Child j of n when its cell index is already known (a traversal counting set bits).
  [[nodiscard]] static node_id child(const node_id& n, int j, std::uint32_t cell) {
    return {
        cell,
        n.depth + 1,
        {n.pos[0] * Rho + std::uint32_t(j % Rho), n.pos[1] * Rho + std::uint32_t((j / Rho) % Rho),
         n.pos[2] * Rho + std::uint32_t(j / (Rho * Rho))}};
  }
  [[nodiscard]] auto children(const node_id& n) const {
    const int count = is_leaf(n) ? 0 : children_per_cell;
    return std::views::iota(0, count) |
           std::views::filter([this, c = n.cell](int j) { return g_->code(c).test(j); }) |
           std::views::transform([this, n](int j) { return child(n, j); });
  }

  /// Centre of cell n relative to origin().
  [[nodiscard]] vec3f centre(const node_id& n) const {
    const double s = side_[std::size_t(n.depth)];
    return vec3f(float((double(n.pos[0]) + 0.5) * s), float((double(n.pos[1]) + 0.5) * s),
                 float((double(n.pos[2]) + 0.5) * s));
  }
  /// The cell's circumscribed sphere: the surface it samples lies in the cell.
  [[nodiscard]] sphere bounding_sphere(const node_id& n) const {
    return {centre(n), 0.5f * std::sqrt(3.0f) * float(side_[std::size_t(n.depth)])};
  }

  /// The cell's sample as a square of size_px pixels at the cell centre.
  template <class S>
  void emit_sample(const node_id& n, float size_px, S& sink) const {
    point_prim<A> p{centre(n), size_px};
    set_attributes(n, p);
    sink.point(p);
  }
  /// The cell's sample as the screen rectangle r (its pixels and depth, computed by the caller:
  /// rho_grid_policy::screen_draw).
  template <ScreenRectSink<A> S>
  void emit_rect(const node_id& n, const rho_grid_screen_rect& r, S& sink) const {
    screen_rect_prim<A> p{r.x0, r.y0, r.x1, r.y1, r.depth, centre(n)};
    set_attributes(n, p);
    sink.screen_rect(p);
  }
  /// A leaf as a one-pixel point, an inner cell as a square covering its projected cell (the
  /// projected diameter of its bounding sphere). rho_grid_policy emits inner cells at its splat
  /// size s instead, as the paper does.
  template <class S>
  void emit(const node_id& n, const view& v, S& sink) const {
    emit_sample(
        n, is_leaf(n) ? 1.0f : std::max(1.0f, 2 * projected_radius_exact(v, bounding_sphere(n))),
        sink);
  }

 private:
  template <class P>
  void set_attributes([[maybe_unused]] const node_id& n, [[maybe_unused]] P& p) const {
    if constexpr (A.normal) p.normal = q_->decode(g_->normal_code(n.cell));
    if constexpr (A.colour)
      p.colour =
          g_->has_colours() ? g_->colour(n.cell) : rho_grid_material_colour(g_->material(n.cell));
  }

  const rho_grid<Rho>* g_;
  std::shared_ptr<const normal_quantizer> q_;
  std::vector<double> side_;  // cell side per depth
};

/// Calls f(rho_grid_hierarchy<Rho, A>(g)) with A the attributes g stores (normals when it has
/// normals, colours when it has colours or materials): the ρ-grid's run-time σ split, made
/// compile time.
template <int Rho, class F>
decltype(auto) with_rho_grid_hierarchy(const rho_grid<Rho>& g, F&& f) {
  constexpr attributes N{.normal = true}, C{.colour = true};
  const bool colour = g.has_colours() || g.has_materials();
  if (g.has_normals() && colour) return f(rho_grid_hierarchy<Rho, N | C>(g));
  if (g.has_normals()) return f(rho_grid_hierarchy<Rho, N>(g));
  if (colour) return f(rho_grid_hierarchy<Rho, C>(g));
  return f(rho_grid_hierarchy<Rho, positions_only>(g));
}

static_assert(Hierarchy<rho_grid_hierarchy<3, positions_only>>);
static_assert(Hierarchy<rho_grid_hierarchy<2, attributes{.normal = true, .colour = true}>>);

}  // namespace pbr_lod
