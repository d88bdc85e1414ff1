// pbr_lod — the CPU reference rasteriser for 3-D Gaussians: what a 3DGS scene, or a cut of a
// Gaussian hierarchy, looks like. Deterministic and exact to its own rules, not fast.
//
// This work is based on:
//   Zwicker, Pfister, van Baar & Gross, "EWA volume splatting", IEEE Visualization 2001: the 3-D
//     Gaussian's screen footprint is the 2-D Gaussian of covariance J W Σ Wᵀ Jᵀ, W the viewing
//     rotation and J the Jacobian of the perspective projection at the mean (the local affine
//     approximation of the projective transformation; the projected kernel integrated along the
//     ray drops the third row and column). Equations 29 and 31 of the journal version ("EWA
//     splatting", TVCG 2002), as 3DGS's computeCov2D cites them.
//   Kerbl, Kopanas, Leimkühler & Drettakis, "3D Gaussian Splatting for real-time radiance field
//     rendering", SIGGRAPH 2023: §4 (the footprint, eq. 5, Σ' = J W Σ Wᵀ Jᵀ; colour by
//     spherical harmonics), §6 (the tile rasteriser: cull against the frustum with a guard band,
//     sort by view depth, composite front to back per 16×16 tile, α ≤ 0.99, skip α < 1/255,
//     stop when the transmittance falls below 10⁻⁴) and its reference CUDA rasteriser
//     (diff-gaussian-rasterization, forward.cu: computeCov2D's x/z, y/z clamp to 1.3 tan(fov/2)
//     and 0.3 px² low-pass; renderCUDA's compositing).
//
// Conventions (docs/rasterizer.md, "3-D Gaussians"):
//   * Pixel centres at (i + ½, j + ½) in camera.hpp's screen frame. 3DGS evaluates at integer
//     pixel coordinates with a −½ in ndc2Pix, which is the same sampling.
//   * A Gaussian's screen box is where α can reach 1/255 (k = √(2 ln(255·opacity)) standard
//     deviations along x and y; k ≤ 3.33), not 3DGS's 3σ of the largest eigenvalue: the tiles
//     then only skip work, never change a pixel, and the image equals a per-pixel loop over all
//     Gaussians (3DGS's 3σ box cuts Gaussians off at α up to 0.011, along tile edges).
//   * A pixel is covered (image::depth finite) where the Gaussians leave a transmittance below
//     ½; its depth is the view depth of the Gaussian that took it below ½ (the median depth).
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "pbr_lod/core/attributes.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/gaussians.hpp"
#include "pbr_lod/core/math.hpp"
#include "pbr_lod/raster/image.hpp"
#include "pbr_lod/traverse/primitives.hpp"
#include "pbr_lod/traverse/sink.hpp"

namespace pbr_lod {

struct gaussian_render_options {
  /// Colour behind the Gaussians: a pixel's colour is Σ c·α·T + T·background (3DGS's bg_color).
  rgb8 background{0, 0, 0};
  /// Threads for the per-Gaussian set-up and the tiles (0 = every core: resolve_threads). The
  /// image does not depend on it, byte for byte.
  unsigned threads = 0;
};

/// What a frame's Gaussians became (gaussian_rasterizer::stats(), valid after finish()).
struct gaussian_raster_stats {
  std::size_t received = 0;  ///< gaussian() calls
  std::size_t drawn = 0;     ///< projected and binned to at least one tile
  /// In front of z_near (or at or behind the eye), mean outside the 1.3× guard band, box off
  /// screen, or opacity < 1/255 (no pixel can reach α ≥ 1/255).
  std::size_t culled = 0;
  /// A non-finite position, covariance, opacity or colour, sh_degree outside 0–3, or a projected
  /// covariance that is not positive definite (Σ far from positive semi-definite).
  std::size_t invalid = 0;
  std::size_t ignored = 0;  ///< points, splats and triangles (see gaussian_rasterizer)
};

/// A Sink (for any attribute set) and a GaussianSink that draws 3-D Gaussians as 3DGS does.
/// gaussian() only stores the primitive; finish() projects, sorts, bins and composites them.
/// The primitives' SH coefficients (gaussian_prim::sh, not owned) must stay alive until then.
///
/// A Gaussian hierarchy emits only Gaussians. Points, splats and triangles have no opacity or
/// falloff to composite with, so they are not drawn: they are counted as ignored() (a caller
/// that sees ignored() > 0 is drawing the wrong hierarchy into this sink).
///
/// Not thread-safe; finish() itself runs on options.threads threads.
class gaussian_rasterizer {
 public:
  gaussian_rasterizer(const view& v, const gaussian_render_options& options = {});

  void gaussian(const gaussian_prim& g) { prims_.push_back(g); }

  template <attributes A>
  void point(const point_prim<A>&) {
    ++ignored_;
  }
  template <attributes A>
  void splat(const splat_prim<A>&) {
    ++ignored_;
  }
  template <attributes A>
  void triangle(const triangle_prim<A>&) {
    ++ignored_;
  }

  /// Draws the Gaussians received since construction or the last finish() and forgets them.
  [[nodiscard]] image finish();

  [[nodiscard]] std::size_t ignored() const { return ignored_; }
  /// The last finish()'s counts (ignored: every non-Gaussian primitive received so far).
  [[nodiscard]] gaussian_raster_stats stats() const;

 private:
  view view_;
  gaussian_render_options options_;
  std::vector<gaussian_prim> prims_;
  std::size_t ignored_ = 0;
  gaussian_raster_stats last_{};
};

static_assert(Sink<gaussian_rasterizer, positions_only>);
static_assert(Sink<gaussian_rasterizer, all_attributes>);
static_assert(GaussianSink<gaussian_rasterizer>);

/// The reference render of every Gaussian of `cloud` (the frame origin is cloud.origin): what
/// `pbrlod render scene.ply` shows for a 3DGS file, and what a Gaussian hierarchy's cuts are
/// measured against. Non-finite or degenerate Gaussians are skipped, as by gaussian_rasterizer.
/// Throws InvalidArgument when the cloud's arrays disagree in length or sh_degree is not 0–3
/// (what cloud.validate() checks first; values are not validated).
[[nodiscard]] image render_gaussians(const gaussian_cloud& cloud, const camera& cam,
                                     const gaussian_render_options& options = {});

namespace detail {

/// Edge of the square screen tiles a Gaussian is binned to (3DGS's BLOCK_X = BLOCK_Y = 16).
inline constexpr int gaussian_tile = 16;

/// A Gaussian on the screen: what compositing needs. Exposed for the tests' brute-force
/// reference.
struct gaussian_2d {
  enum class fate : std::uint8_t { drawn, culled, invalid };
  fate status = fate::culled;
  float x = 0, y = 0;         ///< projected mean, screen pixels (camera.hpp's frame)
  float a = 0, b = 0, c = 0;  ///< conic: power = −½(a·dx² + c·dy²) − b·dx·dy
  float opacity = 0;
  float depth = 0;             ///< view depth of the mean (eye-space z)
  std::array<float, 3> rgb{};  ///< sh_colour(), not clamped above (as 3DGS)
  /// Tiles [tx0, tx1] × [ty0, ty1] (inclusive) and pixels [px0, px1] × [py0, py1] (inclusive,
  /// clamped to the screen) outside which α < 1/255.
  int tx0 = 0, ty0 = 0, tx1 = -1, ty1 = -1;
  int px0 = 0, py0 = 0, px1 = -1, py1 = -1;
  /// Below this power α < 1/255 for certain (−ln(255·opacity), less a margin for rounding): the
  /// tiles skip exp() there and still composite exactly what gaussian_alpha() would.
  float min_power = 0;
};

/// Projects one Gaussian for view v (Kerbl et al. 2023 §4 eq. 5 and §6; 3DGS's preprocessCUDA).
[[nodiscard]] gaussian_2d project_gaussian(const view& v, const gaussian_prim& g);

/// α of a projected Gaussian at pixel centre (px, py), before the 1/255 skip: 3DGS's
/// min(0.99, opacity·exp(power)), or 0 where power > 0 (a rounding artefact 3DGS skips too).
[[nodiscard]] inline float gaussian_alpha(const gaussian_2d& s, float px, float py) {
  const float dx = s.x - px, dy = s.y - py;
  const float power = -0.5f * (s.a * dx * dx + s.c * dy * dy) - s.b * dx * dy;
  if (power > 0.0f) return 0.0f;
  const float alpha = s.opacity * std::exp(power);
  return alpha < 0.99f ? alpha : 0.99f;
}

/// The compositing rules of renderCUDA, shared by the tiles and the tests' reference.
inline constexpr float gaussian_min_alpha = 1.0f / 255.0f;
inline constexpr float gaussian_min_transmittance = 1e-4f;

}  // namespace detail
}  // namespace pbr_lod
