// pbr_lod — the effects a render applies, the light, and the render options.
//
// `effects` is a structural type so that it can be a template argument: the rasteriser is
// compiled once per effect set it can meet (raster/rasterizer.hpp), and an effect that is off
// costs nothing — no pass, no per-primitive branch. This is the image side of "simulate only the
// effects a scene calls for" (DESIGN.md); attributes.hpp is the data side.
#pragma once

#include <string>
#include <string_view>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

struct effects {
  bool shading = false;        ///< Lambert shading with `render_options::sun` (needs normals)
  bool colour = true;          ///< per-primitive colours (needs colours; else flat_colour)
  bool backface_cull = false;  ///< drop back-facing triangles, and splats/points with normals
  bool shadows = false;        ///< two-pass directional shadow map
  bool hole_filling = false;   ///< screen-space reconstruction of background pixels in surfaces
  /// Splat blending with per-pixel normalisation (Pajarola, Sainz & Guidotti 2003; Botsch et al.
  /// 2005): overlapping splats and points of one surface are averaged with a radially
  /// decreasing weight instead of the front-most one winning. Two passes over the primitives.
  bool blending = false;

  friend constexpr bool operator==(const effects&, const effects&) = default;

  [[nodiscard]] constexpr effects operator&(const effects& o) const {
    return {shading && o.shading,
            colour && o.colour,
            backface_cull && o.backface_cull,
            shadows && o.shadows,
            hole_filling && o.hole_filling,
            blending && o.blending};
  }
  [[nodiscard]] constexpr effects operator|(const effects& o) const {
    return {shading || o.shading,
            colour || o.colour,
            backface_cull || o.backface_cull,
            shadows || o.shadows,
            hole_filling || o.hole_filling,
            blending || o.blending};
  }
  /// The effects of *this that are not in o.
  [[nodiscard]] constexpr effects operator-(const effects& o) const {
    return {shading && !o.shading,
            colour && !o.colour,
            backface_cull && !o.backface_cull,
            shadows && !o.shadows,
            hole_filling && !o.hole_filling,
            blending && !o.blending};
  }
  /// True when every effect of `other` is also in *this.
  [[nodiscard]] constexpr bool contains(const effects& other) const {
    return (other - *this) == effects{false, false, false, false, false, false};
  }

  /// "shading+colour+...", or "none".
  [[nodiscard]] std::string to_string() const {
    std::string s;
    const auto add = [&](bool on, const char* name) {
      if (!on) return;
      if (!s.empty()) s += '+';
      s += name;
    };
    add(shading, "shading");
    add(colour, "colour");
    add(backface_cull, "backface_cull");
    add(shadows, "shadows");
    add(hole_filling, "hole_filling");
    add(blending, "blending");
    return s.empty() ? "none" : s;
  }
};

inline constexpr effects all_effects{true, true, true, true, true, true};
inline constexpr effects no_effects{false, false, false, false, false, false};

/// Parses the `--effects` list of the pbrlod tool: names separated by ',' or '+' (shading,
/// colour|color, backface_cull|cull, shadows, hole_filling|holes, blending|blend), or "all" /
/// "none".
/// Throws InvalidArgument naming the unknown word.
[[nodiscard]] inline effects parse_effects(std::string_view list) {
  effects fx = no_effects;
  std::size_t start = 0;
  while (start <= list.size()) {
    std::size_t end = list.find_first_of(",+", start);
    if (end == std::string_view::npos) end = list.size();
    const std::string_view w = list.substr(start, end - start);
    if (w.empty() || w == "none") {
    } else if (w == "all") {
      fx = all_effects;
    } else if (w == "shading") {
      fx.shading = true;
    } else if (w == "colour" || w == "color") {
      fx.colour = true;
    } else if (w == "backface_cull" || w == "cull") {
      fx.backface_cull = true;
    } else if (w == "shadows") {
      fx.shadows = true;
    } else if (w == "hole_filling" || w == "holes") {
      fx.hole_filling = true;
    } else if (w == "blending" || w == "blend") {
      fx.blending = true;
    } else {
      throw InvalidArgument("effects: unknown effect '" + std::string(w) +
                            "' (expected shading, colour, backface_cull, shadows, hole_filling, "
                            "blending, all or none)");
    }
    start = end + 1;
  }
  return fx;
}

/// A directional light (the sun).
struct light {
  /// Direction *towards* the light, in the axes of the primitives (the hierarchy's frame; a
  /// direction does not depend on the origin, so this is also the world axes). Need not be unit;
  /// a zero vector means "no directional light": ambient only, and no shadows.
  vec3f direction = vec3f(0.35f, 0.8f, 0.5f);
  /// Fraction of the colour that reaches surfaces the light does not (shadowed or facing away).
  float ambient = 0.15f;
};

/// Options of one render. Every field has a default that gives a sensible image.
struct render_options {
  effects fx{};  ///< requested effects (see render(): masked by what is compiled)
  light sun{};   ///< light for shading and shadows
  rgb8 flat_colour{200, 200, 200};  ///< colour of primitives without (or with disabled) colour
  rgb8 background{0, 0, 0};         ///< colour stored in pixels nothing covers
  int hole_filling_radius = 3;      ///< window radius (pixels) of the hole-filling filter
  /// A background pixel is filled only when front-most covered pixels lie in at least this many
  /// of the 8 45° sectors around it. 6 is the smallest value for which no straight or convex
  /// silhouette can grow: the pixels beyond a straight edge see it within < 180°, i.e. in at
  /// most 5 sectors (docs/rasterizer.md).
  int hole_filling_min_sectors = 6;
  /// Neighbours count only when their depth is within this relative distance of the front-most
  /// depth in the window, so geometry behind a surface does not bleed into its holes.
  float hole_filling_depth_tolerance = 0.03f;
  /// Blending: the visibility pass draws each splat or point this many of its own radii further
  /// from the eye along the view ray (Botsch et al. 2005's ε), and every fragment of the
  /// accumulation pass in front of that offset surface is blended. Large enough to span the
  /// depth spread of overlapping splats of one curved surface (their tangent planes part by
  /// about κr²/2 over a radius r), small enough that a surface one radius behind stays hidden.
  float blend_depth_epsilon = 1.0f;
  int shadow_map_size = 1024;  ///< texels per side of the square shadow map
  /// Depth bias, in shadow-map texels (world size of one texel times this), against self-shadowing
  /// ("shadow acne") from the discretised depth of sloped surfaces and flat point squares.
  float shadow_bias_texels = 2.0f;
  /// render_reference(point_cloud): splat radius = factor × distance to the k-th nearest neighbour.
  int reference_knn = 8;
  /// 0.8 × the 8th-neighbour distance: 1.6–2.4× the covering radius of regular samplings
  /// (square/hexagonal lattice) and, for Poisson-random samples, an uncovered fraction of
  /// exp(−8·0.8²) ≈ 0.6 %; see docs/rasterizer.md.
  float reference_radius_factor = 0.8f;
  /// Supersampling (the antialiasing of Chen & Nguyen 2001 §3.4, "as in Surfel"): render() draws
  /// the frame at k × k the resolution, through view::supersampled(k), and box-filters it down
  /// (downsample_box). The draw must then take the view it draws into, `draw(sink, view)`, since
  /// traversals size points in that view's pixels; hole_filling_radius is scaled by k so the
  /// filter spans the same part of the output. 1 = off; k costs about k² of the raster work.
  int supersample = 1;
};

}  // namespace pbr_lod
