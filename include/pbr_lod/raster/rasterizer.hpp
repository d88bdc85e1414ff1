// pbr_lod — the CPU reference rasteriser: a deterministic, z-buffered software renderer that is
// a Sink (traverse/sink.hpp) for one-pixel points, square splats, object-space elliptical splats
// and triangles.
//
// Techniques (details in docs/rasterizer.md and in detail/raster_core.hpp):
//  * elliptical splats projected exactly in perspective: pixel ray → splat-plane parameters by a
//    3×3 projective map, inside iff s² + t² ≤ 1, depth from the ray–plane intersection
//    (Zwicker et al. 2004, "Perspective accurate splatting");
//  * triangles by edge functions at pixel centres with the top-left rule, watertight, with
//    perspective-correct attributes (barycentrics over 1/z);
//  * Lambert shading with one directional light, two-sided for all primitives: a normal that
//    faces away from the eye is flipped (for triangles: when the triangle is seen from its back);
//  * shadows by a two-pass shadow map (Williams 1978) fitted to the primitives' bounds;
//  * hole filling by a screen-space reconstruction filter (Pfister et al. 2000; POP §3.4);
//  * splat blending with per-pixel normalisation (Pajarola, Sainz & Guidotti 2003, "Object-space
//    blending and splatting of points"; Botsch, Hornung, Zwicker & Kobbelt 2005, "High-quality
//    surface splatting on today's GPUs"): a visibility pass with depths offset by ε along the
//    view rays, an accumulation pass, and a normalisation pass (see "Blending" below).
//
// Effects cost nothing when off. `render<A, Compiled>` looks at the requested effects once per
// frame and calls an instantiation of rasterizer<A, E> for exactly that effect set, so inside
// the per-primitive code every effect test is `if constexpr`: an effect that is off has no
// branch, no pass and no buffer. Effects outside `Compiled` are never instantiated (and are
// ignored if requested); effects the attribute set cannot support (shading without normals,
// colour without colours) are dropped at compile time, so the same image comes out whether an
// unused effect is compiled in or not.
//
// Determinism: single-threaded, fixed traversal order, ties in the depth test keep the first
// primitive drawn; the same primitives in the same order give the same bytes.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "pbr_lod/core/attributes.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/raster/detail/postprocess.hpp"
#include "pbr_lod/raster/detail/raster_core.hpp"
#include "pbr_lod/raster/detail/shadow_map.hpp"
#include "pbr_lod/raster/effects.hpp"
#include "pbr_lod/raster/image.hpp"
#include "pbr_lod/traverse/primitives.hpp"
#include "pbr_lod/traverse/sink.hpp"

namespace pbr_lod {

/// The effects of E that attribute set A can apply: shading needs normals, colour needs colours,
/// and blending needs one of the two (with neither, every fragment has the flat colour and there
/// is nothing to average).
[[nodiscard]] constexpr effects applicable_effects(const effects& e, const attributes& a) {
  const bool shading = e.shading && a.normal, colour = e.colour && a.colour;
  return {shading,   colour,         e.backface_cull,
          e.shadows, e.hole_filling, e.blending && (shading || colour)};
}

namespace detail {}  // namespace detail

/// A z-buffered rasteriser for one frame; models Sink<A>.
///
/// E is the effect set, fixed at compile time (use render() to choose it at run time). Back-face
/// culling applies to triangles (screen winding: counter-clockwise = front) and to points and
/// splats that have normals (n·(p − eye) > 0 is back-facing); splats without normals have no
/// front side and are never culled. With E.shadows the rasteriser needs the map of a first pass
/// (render() builds it); constructed without one, nothing is in shadow.
///
/// Blending (E.blending). Two passes over the same primitives, then a normalisation in finish():
///  1. visibility: every splat and point is drawn scaled about the eye by 1 + ε·r/|c − eye| (r its
///     radius, ε = render_options::blend_depth_epsilon): the same pixels, each pushed along its own
///     view ray by about ε·r. Depth and its unblended colour are written (the colour is kept for
///     the rare pixel that no weighted fragment reaches). Triangles are drawn as without blending,
///     and each of their fragments that is still the front-most at the end of the pass is kept as
///     the pixel's first weight-1 contribution (an exact surface: no offset, so a triangle hides
///     what lies behind it and blends with splats less than their ε in front of it).
///  2. accumulation (after begin_accumulation(), the same primitives again; triangles are skipped,
///     their fragments are those kept by pass 1): every fragment whose own, unshifted depth is
///     not behind the pass-1 depth adds weight·colour and, with shading, weight·normal (turned
///     towards the eye) to the pixel. Weight 1 − r² for splats (r² = s² + t² in the splat's
///     plane, so it falls to 0 on the ellipse; −Q/g₃² from the visibility kernel's four-wide conic
///     scan), for squares r² = |pixel − centre|² over the squared half-diagonal, 1 for one-pixel
///     points. Nothing is depth-written in this pass. A frame without splats or points has
///     nothing to blend: needs_accumulation() is false and render() skips this pass, so its image
///     is the unblended one.
///  3. finish(): colour = Σ w·colour / Σ w, normal = Σ w·n normalised and shaded per pixel
///     (deferred shading, as Botsch et al.: a blended normal varies smoothly across splats, as a
///     triangle's interpolated normal does; blending shaded colours would only smear each splat's
///     flat shade), depth = the front-most contributing fragment. Fragments facing the eye and
///     facing away are summed apart and the facing ones win where they have weight, so the two
///     sides of a part thinner than ε are not averaged. Shadows and hole filling then run on the
///     blended frame as without blending.
///
/// Usage: construct, send primitives (point/splat/triangle, any order), then finish() once. With
/// E.blending: send them, call begin_accumulation(), send the same primitives again, finish()
/// (render() and render_direct() do this). Not thread-safe; one rasteriser per frame.
template <attributes A, effects E = effects{}>
class rasterizer {
 public:
  /// What this instantiation actually applies.
  static constexpr effects fx = applicable_effects(E, A);

  rasterizer(const view& v, const render_options& opt, const detail::shadow_map* shadows = nullptr)
      : view_(v),
        proj_(v),
        opt_(opt),
        shadows_(shadows),
        key_(pixel_count(v), proj_.key_far),
        colour_(pixel_count(v), detail::pack(opt.background)),
        flat_(opt.flat_colour) {
    if constexpr (kLitBuffer) lit_.assign(pixel_count(v), 1.0f);
    if constexpr (fx.blending) blend_.allocate(pixel_count(v));
    kb_ = key_.data();
    cb_ = colour_.data();
    lb_ = lit_.data();
    fw_ = static_cast<float>(v.width);
    fh_ = static_cast<float>(v.height);
    const vec3f d = opt.sun.direction;
    light_ = (all_finite(d) && d.squaredNorm() > 0) ? vec3f(d.normalized()) : vec3f::Zero();
    ambient_ = std::isfinite(opt.sun.ambient) ? std::clamp(opt.sun.ambient, 0.0f, 1.0f) : 0.0f;
  }
  // The raw buffer pointers would point into the source's buffers after a copy; a move keeps
  // the storage, so it is fine.
  rasterizer(const rasterizer&) = delete;
  rasterizer& operator=(const rasterizer&) = delete;
  rasterizer(rasterizer&&) noexcept = default;
  rasterizer& operator=(rasterizer&&) noexcept = default;

  /// A square of p.size_px pixels (≤ 1: the pixel containing the projected centre), at the depth
  /// of its centre. Points behind the near plane or beyond the far plane are dropped.
  void point(const point_prim<A>& p) {
    if constexpr (fx.blending) {
      blended_point(p);
      return;
    }
    vec3f d;
    float key, sx, sy;
    if (!project(p, d, key, sx, sy)) return;
    if (!(p.size_px > 1)) [[likely]] {
      if (!(sx >= 0 && sx < fw_ && sy >= 0 && sy < fh_)) return;
      const std::size_t i = static_cast<std::size_t>(static_cast<int>(sy)) * width() +
                            static_cast<std::size_t>(static_cast<int>(sx));
      if (!(key > kb_[i])) return;
      kb_[i] = key;
      store(i, shade(p, d));  // shading after the depth test: hidden points cost no shading
      return;
    }
    const fragment_colour c = shade(p, d);
    detail::raster_square(view_.width, view_.height, sx, sy, p.size_px, key,
                          [this, c](std::size_t i, float k) {
                            if (k > kb_[i]) {
                              kb_[i] = k;
                              store(i, c);
                            }
                          });
  }

  /// A screen-space rectangle (traverse/primitives.hpp): the pixels whose centres it contains —
  /// integer coverage by a shift of its fixed-point bounds (Duguet & Drettakis 2004, §5.1's last
  /// paragraph) — or, thinner than a pixel, the one containing its midpoint, at key 1/depth with
  /// point()'s depth test and drop behind the near plane; shaded as point() shades (the view
  /// direction from its 3-D position). With blending, drawn as as_point_prim() (the blending
  /// passes weigh squares about a 3-D centre).
  void screen_rect(const screen_rect_prim<A>& r) {
    if constexpr (fx.blending) {
      blended_point(as_point_prim(r));
      return;
    }
    const float z = r.depth;
    if (!(z >= proj_.w_near)) return;  // behind the near plane, or NaN
    const vec3f d = r.position - proj_.eye;
    if constexpr (kCullNormals)
      if (r.normal.dot(d) > 0) return;
    constexpr int F = screen_rect_prim<A>::fraction_bits;
    const float key = 1.0f / z;
    const auto [i0, i1] = detail::rect_pixel_span<F>(r.x0, r.x1, view_.width);
    const auto [j0, j1] = detail::rect_pixel_span<F>(r.y0, r.y1, view_.height);
    if (i1 - i0 == 1 && j1 - j0 == 1) [[likely]] {  // a point: shading after the depth test
      const std::size_t i = static_cast<std::size_t>(j0) * width() + static_cast<std::size_t>(i0);
      if (!(key > kb_[i])) return;
      kb_[i] = key;
      store(i, shade(r, d));
      return;
    }
    if (i0 >= i1 || j0 >= j1) return;
    const fragment_colour c = shade(r, d);
    for (int j = j0; j < j1; ++j) {
      const std::size_t row = static_cast<std::size_t>(j) * width();
      for (int i = i0; i < i1; ++i) {
        const std::size_t k = row + static_cast<std::size_t>(i);
        if (key > kb_[k]) {
          kb_[k] = key;
          store(k, c);
        }
      }
    }
  }

  /// An occluder (traverse/primitives.hpp; POP §3.4's first pass): a square like point()'s in the
  /// background colour. Where it is front-most it hides what lies behind; finish() then makes the
  /// pixel a hole (background colour, no depth) before shadows and hole filling, so the filter
  /// reconstructs it from the surface's points. The order of occluders and primitives does not
  /// matter: the nearest occluder depth per pixel is kept apart (allocated by the first occluder,
  /// so frames without occluders have no extra buffer and no extra pass). Ignored with blending.
  void occluder(const occluder_prim& o) {
    if constexpr (fx.blending) return;
    const vec3f d = o.position - proj_.eye;
    const float z = d.dot(proj_.forward);
    if (!(z >= proj_.w_near)) return;
    const float key = 1.0f / z;
    const float sx = proj_.cx + d.dot(proj_.right_px) * key;
    const float sy = proj_.cy - d.dot(proj_.up_px) * key;
    if (occluder_key_.empty()) occluder_key_.assign(key_.size(), proj_.key_far);
    const std::uint32_t bg = detail::pack(opt_.background);
    const auto write = [this, bg](std::size_t i, float k) {
      occluder_key_[i] = std::max(occluder_key_[i], k);
      if (k > kb_[i]) {
        kb_[i] = k;
        cb_[i] = bg;
        if constexpr (kLitBuffer) lb_[i] = 1.0f;
      }
    };
    detail::raster_square(view_.width, view_.height, sx, sy, o.size_px, key, write);
  }

  /// The ellipse centre ± u ± v (u, v orthogonal semi-axes), projected exactly.
  void splat(const splat_prim<A>& s) {
    if constexpr (fx.blending) {
      blended_splat(s);
      return;
    }
    const vec3f d = s.centre - proj_.eye;
    if constexpr (kCullNormals)
      if (s.normal.dot(d) > 0) return;
    const fragment_colour c = shade(s, d);
    const detail::span_target<true, kLitBuffer> out{kb_, cb_, lb_, packed(c), c.lit};
    detail::raster_ellipse(proj_, s.centre, s.u, s.v, out);
  }

  /// A 3-D Gaussian, as a z-buffer can draw one: the ellipse of its two largest axes at 2σ
  /// (as_splat_prim), its normal turned to the eye (a Gaussian has no side), or a one-pixel point
  /// where that ellipse covers less than a pixel (the emitters' rule: gaussian_hierarchy::emit).
  /// raster/gaussians.hpp draws Gaussians as they are (EWA, sorted, composited).
  void gaussian(const gaussian_prim& g) {
    splat_prim<A> s = as_splat_prim<A>(g);
    const vec3f d = s.centre - proj_.eye;
    if constexpr (A.normal)
      if (s.normal.dot(d) > 0) s.normal = -s.normal;
    const float z = d.dot(proj_.forward);
    const float k = z > 0 ? proj_.focal / z : 0.0f;
    const float pixels = 3.14159265f * k * k * std::abs(s.u.cross(s.v).dot(d.normalized()));
    if (!(pixels >= 1.0f)) {
      point_prim<A> p{s.centre, 1.0f};
      if constexpr (A.normal) p.normal = s.normal;
      if constexpr (A.colour) p.colour = s.colour;
      point(p);
    } else {
      splat(s);
    }
  }

  /// A triangle with per-vertex normal and colour interpolated perspective-correctly.
  void triangle(const triangle_prim<A>& t) {
    if constexpr (fx.blending)
      if (blend_.accumulating) return;  // its fragments were recorded by the visibility pass
    std::array<detail::tri_vertex<kNP>, 3> v;
    for (std::size_t k = 0; k < 3; ++k) {
      v[k].h = proj_.point(t.p[k]);
      if constexpr (fx.shading)
        for (int c = 0; c < 3; ++c) v[k].a[static_cast<std::size_t>(c)] = t.normal[k][c];
      if constexpr (fx.colour) {
        v[k].a[kColourAt + 0] = t.colour[k].r;
        v[k].a[kColourAt + 1] = t.colour[k].g;
        v[k].a[kColourAt + 2] = t.colour[k].b;
      }
    }
    float* const kb = kb_;
    detail::raster_triangle<fx.backface_cull>(
        proj_, v, [kb](std::size_t i, float k) { return k > kb[i]; },
        [this](std::size_t i, float k, const std::array<float, kNP>& a, bool front) {
          kb_[i] = k;
          if constexpr (fx.blending) record_triangle(i, k, a, front);
          fragment_colour c{flat_, 1.0f};
          if constexpr (fx.colour)
            c.albedo = {detail::to_channel(a[kColourAt]), detail::to_channel(a[kColourAt + 1]),
                        detail::to_channel(a[kColourAt + 2])};
          if constexpr (fx.shading) {
            c.lit = fragment_lit(a, front);
          }
          store(i, c);
        });
  }

  /// A texture-mapped triangle (traverse/primitives.hpp), drawn by backward mapping: each
  /// covered pixel centre's texture coordinates are interpolated perspective-correctly (over 1/z,
  /// as triangle()'s attributes) and the texture is sampled bilinearly between the four nearest
  /// texel centres, wrapping at the edges (GL_REPEAT, as POP's texel averages do). The sample is
  /// the albedo in place of the vertex colours; depth test, coverage, back-face culling and
  /// shading are triangle()'s; with blending, each fragment is recorded with the sampled colour
  /// as triangle()'s are. Without the colour effect or without a texture it is
  /// triangle(t.triangle).
  void textured_triangle(const textured_triangle_prim<A>& t) {
    if constexpr (!fx.colour) {
      triangle(t.triangle);
    } else {
      if constexpr (fx.blending)
        if (blend_.accumulating) return;  // recorded by the visibility pass
      const texture_image* const tex = t.texture;
      if (tex == nullptr || !tex->valid()) {
        triangle(t.triangle);
        return;
      }
      constexpr int NT = kNP + 2;
      constexpr std::size_t kUvAt = static_cast<std::size_t>(kNP);
      std::array<detail::tri_vertex<NT>, 3> v;
      for (std::size_t k = 0; k < 3; ++k) {
        v[k].h = proj_.point(t.triangle.p[k]);
        if constexpr (fx.shading)
          for (int c = 0; c < 3; ++c) v[k].a[static_cast<std::size_t>(c)] = t.triangle.normal[k][c];
        v[k].a[kColourAt + 0] = t.triangle.colour[k].r;
        v[k].a[kColourAt + 1] = t.triangle.colour[k].g;
        v[k].a[kColourAt + 2] = t.triangle.colour[k].b;
        const vec2f texel = texel_position(*tex, t.uv[k]);  // interpolated in texel space
        v[k].a[kUvAt] = texel.x();
        v[k].a[kUvAt + 1] = texel.y();
      }
      float* const kb = kb_;
      detail::raster_triangle<fx.backface_cull>(
          proj_, v, [kb](std::size_t i, float k) { return k > kb[i]; },
          [this, tex](std::size_t i, float k, const std::array<float, NT>& a, bool front) {
            kb_[i] = k;
            fragment_colour c{sample_bilinear_repeat(*tex, a[kUvAt], a[kUvAt + 1]), 1.0f};
            if constexpr (fx.blending) {
              std::array<float, kNP> rec{};
              for (std::size_t q = 0; q < kColourAt; ++q) rec[q] = a[q];
              rec[kColourAt] = c.albedo.r;
              rec[kColourAt + 1] = c.albedo.g;
              rec[kColourAt + 2] = c.albedo.b;
              record_triangle(i, k, rec, front);
            }
            if constexpr (fx.shading) {
              c.lit = fragment_lit(a, front);
            }
            store(i, c);
          });
    }
  }

  /// Blending only: ends the visibility pass. Send the same primitives again, then finish().
  /// Keeps the triangle fragments the visibility pass recorded where they are still the
  /// front-most (a splat or point drawn later and nearer wrote a larger key): the accumulation
  /// pass then skips triangles, whose weight-1 fragments are exactly those.
  void begin_accumulation() requires(fx.blending) {
    blend_.accumulating = true;
    const std::size_t n = key_.size();
    const float* const w = blend_.plane(kW);
    const float* const key = blend_.plane(kKey);
    for (std::size_t i = 0; i < n; ++i)
      if (w[i] > 0 && std::abs(key[i]) != kb_[i]) blend_.clear(i);
  }

  /// Blending only: whether the visibility pass drew any splat or point. Without them there is
  /// nothing to blend: the visibility image is the unblended one, and render() skips the
  /// accumulation pass.
  [[nodiscard]] bool needs_accumulation() const requires(fx.blending) { return blend_.drew_splats; }

  /// Runs the per-frame passes the effect set has (blend normalisation, shadow resolve, hole
  /// filling) and returns the image. Call once; the rasteriser is empty afterwards.
  [[nodiscard]] image finish() {
    if constexpr (fx.blending) normalise_blend();
    if (!occluder_key_.empty()) occluded_to_holes();
    image img;
    img.width = view_.width;
    img.height = view_.height;
    img.colour.resize(colour_.size());
    for (std::size_t i = 0; i < colour_.size(); ++i) img.colour[i] = detail::unpack(colour_[i]);
    if constexpr (fx.shadows)
      detail::resolve_shadows(view_, shadows_, ambient_, key_, proj_.key_far, img.colour, lit_);
    if constexpr (fx.hole_filling)
      detail::fill_holes(view_.width, view_.height, key_, img.colour, proj_.key_far, opt_);
    img.depth = detail::keys_to_depth(key_, proj_.key_far);
    key_.clear();
    colour_.clear();
    lit_.clear();
    occluder_key_.clear();
    if constexpr (fx.blending) blend_ = {};
    return img;
  }

 private:
  // Shading needs a lit factor per pixel only when shadows are resolved after the pass.
  static constexpr bool kLitBuffer = fx.shadows && fx.shading;
  static constexpr bool kCullNormals = fx.backface_cull && A.normal;
  static constexpr int kNP = (fx.shading ? 3 : 0) + (fx.colour ? 3 : 0);
  static constexpr std::size_t kColourAt = fx.shading ? 3 : 0;

  struct fragment_colour {
    rgb8 albedo;
    float lit;  ///< Lambert factor (1 without shading)
  };

  /// Blending: per pixel, the sums of the accumulation pass over one side of the surfaces, in
  /// planes of kBlendChannels floats (structure of arrays, so four pixels are summed at once):
  /// Σw, the front-most contributing key, and with colour Σw·colour, with shading Σw·normal.
  /// The key's sign says which side the sums are of: > 0 the fragments facing the eye (also
  /// splats and points without normals), < 0 those facing away, 0 none yet. The facing side
  /// wins where it has weight, so that the two sides of a part thinner than ε (a fin, a sheet
  /// seen edge-on) are not averaged: its first fragment of positive weight drops what the
  /// facing-away ones summed, and fragments facing away are ignored from then on. This is the
  /// same as summing the two sides apart and taking the facing sums wherever they have weight.
  static constexpr std::size_t kW = 0, kKey = 1, kR = 2, kNx = fx.colour ? 5 : 2;
  static constexpr std::size_t kBlendChannels = 2 + (fx.colour ? 3 : 0) + (fx.shading ? 3 : 0);
  struct splat_record {
    detail::ellipse_conic conic;  ///< of the splat drawn by the visibility pass (scaled by f)
    float f;
    /// The accumulation pass scans `conic` (the unscaled splat lies wholly in front of the near
    /// plane too); otherwise it projects the splat again.
    bool cached;
  };
  /// The blending buffers, kept from frame to frame on each thread (as render() keeps its
  /// primitive buffer): allocating the sums (5–8 MB at 512²) and the splat records (~20 MB for
  /// 200,000 splats, grown by doubling) afresh each frame cost more in page faults and copies
  /// than the accumulation itself (measured: 250 ms a frame against 40). A rasteriser made while
  /// another on the same thread holds them gets buffers of its own.
  struct blend_buffers {
    std::vector<float> sums;
    std::vector<splat_record> splats;
  };
  class pooled_buffers {
   public:
    pooled_buffers() {
      if (!pool().busy) {
        pool().busy = true;
        b_ = &pool().kept;
      } else {
        b_ = &own_;
      }
    }
    pooled_buffers(pooled_buffers&& o) noexcept
        : own_(std::move(o.own_)), b_(o.b_ == &o.own_ ? &own_ : o.b_) {
      o.b_ = nullptr;
    }
    pooled_buffers& operator=(pooled_buffers&& o) noexcept {
      if (this != &o) {
        release();
        own_ = std::move(o.own_);
        b_ = o.b_ == &o.own_ ? &own_ : o.b_;
        o.b_ = nullptr;
      }
      return *this;
    }
    ~pooled_buffers() { release(); }
    blend_buffers& operator*() const { return *b_; }
    blend_buffers* operator->() const { return b_; }

   private:
    struct thread_pool {
      blend_buffers kept;
      bool busy = false;
    };
    static thread_pool& pool() {
      thread_local thread_pool p;
      return p;
    }
    void release() {
      if (b_ == &pool().kept) pool().busy = false;
      b_ = nullptr;
    }
    blend_buffers own_;
    blend_buffers* b_ = nullptr;
  };
  struct blend_state {
    pooled_buffers buf;
    float* sums = nullptr;  ///< kBlendChannels planes of one float per pixel, `stride` apart
    /// Floats from one plane to the next: the pixel count rounded up to 16 and 80 more, so that
    /// the planes do not start a multiple of 4 KiB apart. A 512² plane is exactly 1 MiB: the
    /// eight planes of shading + colour and the depth buffer then share one set of every cache
    /// and evict each other (measured: shading + colour + blending 120 ms a frame against 41 ms
    /// for colour + blending's five planes, until the planes were staggered).
    std::size_t stride = 0;
    bool accumulating = false;
    bool drew_splats = false;  ///< the visibility pass drew a splat or point
    /// Per splat of the visibility pass, in order: its screen conic, which the accumulation pass
    /// scans again instead of projecting the splat a second time (the projection and the conic's
    /// set-up in double are most of a small splat's cost). The visibility pass draws the splat
    /// scaled by f about the eye, whose conic is the unscaled splat's up to the factors f² in Q
    /// and 1/f in the key, so the weight −Q/key² is the same and the key is f times.
    std::size_t next_splat = 0;  ///< the accumulation pass's position in `splats`
    void allocate(std::size_t pixels) {
      stride = (pixels + 15) / 16 * 16 + 80;
      buf->sums.assign(kBlendChannels * stride, 0.0f);
      sums = buf->sums.data();
      buf->splats.clear();
    }
    [[nodiscard]] float* plane(std::size_t c) { return sums + c * stride; }
    void clear(std::size_t i) {
      for (std::size_t c = 0; c < kBlendChannels; ++c) sums[c * stride + i] = 0;
    }
  };
  struct no_blend_state {};

  static std::size_t pixel_count(const view& v) {
    return static_cast<std::size_t>(v.width) * static_cast<std::size_t>(v.height);
  }
  [[nodiscard]] std::size_t width() const { return static_cast<std::size_t>(view_.width); }

  /// Albedo and light factor of a point or splat; `to_prim` = position − eye.
  template <class Prim>
  [[nodiscard]] fragment_colour shade(const Prim& p, [[maybe_unused]] const vec3f& to_prim) const {
    fragment_colour c{flat_, 1.0f};
    if constexpr (fx.colour) c.albedo = p.colour;
    if constexpr (fx.shading) {
      // Two-sided: light the side the eye sees.
      const vec3f n = p.normal.dot(to_prim) > 0 ? vec3f(-p.normal) : vec3f(p.normal);
      c.lit = detail::lambert(n, light_, ambient_);
    }
    return c;
  }

  /// The packed colour a pixel of this fragment stores: the final colour, or the albedo when
  /// shadows are composed in finish().
  [[nodiscard]] static std::uint32_t packed(const fragment_colour& c) {
    if constexpr (!fx.shadows && fx.shading)
      return detail::pack(detail::scale_colour(c.albedo, c.lit));
    return detail::pack(c.albedo);
  }

  void store(std::size_t i, const fragment_colour& c) {
    cb_[i] = packed(c);
    if constexpr (kLitBuffer) lb_[i] = c.lit;
  }

  // ---- blending (compiled only when fx.blending) ----

  /// The scale about the eye that pushes a primitive of world radius r at distance dist from
  /// the eye back by ε·r along its view rays, keeping its pixels.
  [[nodiscard]] float blend_push(float r, float dist) const {
    const float f = 1 + opt_.blend_depth_epsilon * r / dist;
    return std::isfinite(f) && f > 1 ? f : 1.0f;
  }

  /// What one primitive adds to the sums: colour and the normal turned towards the eye.
  struct blend_value {
    float r = 0, g = 0, b = 0;
    vec3f n = vec3f::Zero();
    std::size_t away = 0;  ///< 1 when the primitive faces away from the eye
  };
  template <class Prim>
  [[nodiscard]] blend_value blend_value_of(const Prim& p,
                                           [[maybe_unused]] const vec3f& to_prim) const {
    blend_value bv;
    if constexpr (fx.colour) {
      bv.r = p.colour.r;
      bv.g = p.colour.g;
      bv.b = p.colour.b;
    }
    if constexpr (A.normal) {
      bv.away = p.normal.dot(to_prim) > 0 ? 1 : 0;
      if constexpr (fx.shading) {
        const float len = p.normal.norm();
        if (len > 0) bv.n = p.normal * ((bv.away ? -1.0f : 1.0f) / len);
      }
    }
    return bv;
  }

  /// The value of every channel of one fragment (its colour, its normal turned to the eye).
  [[nodiscard]] static std::array<float, kBlendChannels> channel_values(const blend_value& bv) {
    std::array<float, kBlendChannels> v{};
    if constexpr (fx.colour) {
      v[kR] = bv.r;
      v[kR + 1] = bv.g;
      v[kR + 2] = bv.b;
    }
    if constexpr (fx.shading)
      for (std::size_t c = 0; c < 3; ++c) v[kNx + c] = bv.n[static_cast<Eigen::Index>(c)];
    return v;
  }

  /// Accumulation: fragment of key k and weight w at pixel i with channel values v, if not
  /// behind the offset surface (blend_state says how the two sides are kept apart).
  void accumulate(std::size_t i, float k, float w, const std::array<float, kBlendChannels>& v,
                  bool away) {
    if (!(k >= kb_[i]) || !(w > 0)) return;
    float* const key = blend_.plane(kKey);
    if (!away) {
      if (key[i] < 0) blend_.clear(i);  // facing-away sums so far: dropped
      key[i] = std::max(key[i], k);
    } else {
      if (key[i] > 0) return;  // the facing side has weight here
      key[i] = std::min(key[i], -k);
    }
    blend_.plane(kW)[i] += w;
    for (std::size_t c = 2; c < kBlendChannels; ++c) blend_.plane(c)[i] += w * v[c];
  }

  /// accumulate() of four pixels from index i at once (the lanes from `skip` on): keys k and
  /// weights w (1 − s² − t² = −Q/key² from the conic scan, weight_of). Per lane the same IEEE
  /// operations as accumulate(), so a pixel's sums do not depend on which of the two summed it.
  void accumulate4(std::size_t i, detail::f4 k, detail::f4 w, int lanes, int skip,
                   const std::array<float, kBlendChannels>& v, bool away) {
    using detail::f4;
    const f4 zero(0.0f);
    if (lanes < 4) {  // a viewport narrower than four pixels
      float kk[4], ww[4];
      k.store(kk);
      w.store(ww);
      for (int l = skip; l < lanes; ++l) accumulate(i + std::size_t(l), kk[l], ww[l], v, away);
      return;
    }
    float* const key = blend_.plane(kKey) + i;
    const f4 ks = f4::load(key);
    f4 m = (w > zero) & (k >= f4::load(kb_ + i)) & f4::lanes_from(skip);
    if (!any(m)) return;  // the bounding box's corners, and splats hidden behind others
    f4 reset = zero;      // lanes whose sums are dropped before adding
    if (!away) {
      reset = m & (ks < zero);
      select(m, max(ks, k), ks).store(key);  // ks < 0 < k: a reset lane's key becomes k
    } else {
      m = and_not(ks > zero, m);
      select(m, min(ks, zero - k), ks).store(key);
    }
    const f4 wm = m & w;  // the weight where the fragment counts, +0 elsewhere
    float* const sw = blend_.plane(kW) + i;
    (and_not(reset, f4::load(sw)) + wm).store(sw);
    for (std::size_t c = 2; c < kBlendChannels; ++c) {
      float* const sc = blend_.plane(c) + i;
      (and_not(reset, f4::load(sc)) + wm * f4(v[c])).store(sc);
    }
  }

  /// Lambert shading of a triangle fragment from its interpolated normal a[0..2], unit length
  /// and turned to the viewer on a back face.
  template <std::size_t N>
  auto fragment_lit(const std::array<float, N>& a, bool front) const {
    vec3f n(a[0], a[1], a[2]);
    const float len = n.norm();
    n = len > 0 ? vec3f(n / (front ? len : -len)) : vec3f::Zero();
    return detail::lambert(n, light_, ambient_);
  }

  /// A point's offset d from the eye, depth key 1/z and screen position; false when it is behind
  /// the near plane (or NaN) or, with normal culling, faces away.
  bool project(const point_prim<A>& p, vec3f& d, float& key, float& sx, float& sy) const {
    d = p.position - proj_.eye;
    const float z = d.dot(proj_.forward);
    if (!(z >= proj_.w_near)) return false;  // behind the near plane, or NaN
    if constexpr (kCullNormals)
      if (p.normal.dot(d) > 0) return false;
    key = 1.0f / z;
    sx = proj_.cx + d.dot(proj_.right_px) * key;
    sy = proj_.cy - d.dot(proj_.up_px) * key;
    return true;
  }

  void blended_point(const point_prim<A>& p) {
    vec3f d;
    float key, sx, sy;
    if (!project(p, d, key, sx, sy)) return;
    const float size = std::max(p.size_px, 1.0f);
    if (!blend_.accumulating) {
      blend_.drew_splats = true;
      // A square is at one depth: pushing it back by ε·(half its side in the world) divides
      // its key, and keeps its pixels.
      const float push = 1 + opt_.blend_depth_epsilon * 0.5f * size / proj_.focal;
      const float k = std::isfinite(push) && push > 1 ? key / push : key;
      const fragment_colour c = shade(p, d);
      detail::raster_square(view_.width, view_.height, sx, sy, p.size_px, k,
                            [this, c](std::size_t i, float kk) {
                              if (kk > kb_[i]) {
                                kb_[i] = kk;
                                store(i, c);
                              }
                            });
      return;
    }
    const blend_value bv = blend_value_of(p, d);
    const auto v = channel_values(bv);
    const bool away = bv.away != 0;
    if (!(p.size_px > 1)) {
      detail::raster_square(view_.width, view_.height, sx, sy, p.size_px, key,
                            [&](std::size_t i, float k) { accumulate(i, k, 1.0f, v, away); });
      return;
    }
    // r² = |pixel centre − centre|² / (half-diagonal)²: 1 at the corners.
    const float inv_h2 = 2.0f / (p.size_px * p.size_px);
    const std::size_t w = width();
    detail::raster_square(view_.width, view_.height, sx, sy, p.size_px, key,
                          [&](std::size_t i, float k) {
                            const float dx = static_cast<float>(i % w) + 0.5f - sx;
                            const float dy = static_cast<float>(i / w) + 0.5f - sy;
                            accumulate(i, k, 1 - (dx * dx + dy * dy) * inv_h2, v, away);
                          });
  }

  /// The blending weight 1 − s² − t² of a conic scan's lanes: −Q/g₃², g₃ the key (scan_conic).
  [[nodiscard]] static detail::f4 weight_of(detail::f4 key, detail::f4 q) {
    return (detail::f4(0.0f) - q) / (key * key);
  }

  void blended_splat(const splat_prim<A>& s) {
    const vec3f d = s.centre - proj_.eye;
    if constexpr (kCullNormals)
      if (s.normal.dot(d) > 0) return;
    if (!blend_.accumulating) {
      blend_.drew_splats = true;
      const float f =
          blend_push(std::sqrt(std::max(s.u.squaredNorm(), s.v.squaredNorm())), d.norm());
      const fragment_colour c = shade(s, d);
      const detail::span_target<true, kLitBuffer> out{kb_, cb_, lb_, packed(c), c.lit};
      splat_record rec{{}, f, false};
      detail::ellipse_map m;
      if (detail::map_ellipse(proj_, vec3f(proj_.eye + d * f), vec3f(s.u * f), vec3f(s.v * f), m)) {
        if (!m.in_front) {
          detail::raster_ellipse_mapped(proj_, m, out);
        } else if (detail::conic_of(m, view_.width, view_.height, rec.conic)) {
          const auto write4 = out.four();
          detail::scan_conic(rec.conic, view_.width,
                             [&](std::size_t i, detail::f4 k, detail::f4 q, int lanes, int) {
                               write4(i, k, non_positive(q), lanes);
                             });
          // The unscaled splat in front of the near plane as well: its distance to it,
          // w_c/f − w_near, at least its reach along the view axis, |(w_u, w_v)|/f.
          const double t = m.hc.w - double(f) * proj_.w_near;
          rec.cached = t >= 0 && t * t >= m.hu.w * m.hu.w + m.hv.w * m.hv.w;
        }
      }
      blend_.buf->splats.push_back(rec);
      return;
    }
    const blend_value bv = blend_value_of(s, d);
    const auto v = channel_values(bv);
    const bool away = bv.away != 0;
    const std::size_t at = blend_.next_splat++;
    if (at < blend_.buf->splats.size() && blend_.buf->splats[at].cached) {
      const splat_record& rec = blend_.buf->splats[at];
      const detail::f4 f(rec.f);
      detail::scan_conic(rec.conic, view_.width,
                         [&](std::size_t i, detail::f4 k, detail::f4 q, int lanes, int skip) {
                           accumulate4(i, k * f, weight_of(k, q), lanes, skip, v, away);
                         });
      return;
    }
    detail::ellipse_map m;
    if (!detail::map_ellipse(proj_, s.centre, s.u, s.v, m)) return;
    if (m.in_front) {
      (void)detail::scan_ellipse_conic(
          m, view_.width, view_.height,
          [&](std::size_t i, detail::f4 k, detail::f4 q, int lanes, int skip) {
            accumulate4(i, k, weight_of(k, q), lanes, skip, v, away);
          });
      return;
    }
    // Straddles the near plane: per pixel, clipped (rare).
    detail::raster_ellipse_radial(proj_, s.centre, s.u, s.v, [&](std::size_t i, float k, float r2) {
      accumulate(i, k, 1 - r2, v, away);
    });
  }

  /// Visibility pass: a triangle fragment that passed the depth test is recorded as the pixel's
  /// accumulation sums with weight 1 (an exact surface, not offset), replacing what was there;
  /// begin_accumulation() keeps it where it is still the front-most fragment.
  void record_triangle(std::size_t i, float k, const std::array<float, kNP>& a, bool front) {
    blend_.plane(kW)[i] = 1;
    blend_.plane(kKey)[i] = front ? k : -k;
    if constexpr (fx.colour)
      for (std::size_t c = 0; c < 3; ++c) blend_.plane(kR + c)[i] = a[kColourAt + c];
    if constexpr (fx.shading) {
      const vec3f nn(a[0], a[1], a[2]);
      const float len = nn.norm();
      const vec3f u = len > 0 ? vec3f(nn / (front ? len : -len)) : vec3f::Zero();
      for (std::size_t c = 0; c < 3; ++c)
        blend_.plane(kNx + c)[i] = u[static_cast<Eigen::Index>(c)];
    }
  }

  /// Pixels where an occluder is still the front-most thing drawn (nothing nearer wrote a larger
  /// key) become holes: background colour, no depth.
  void occluded_to_holes() {
    const std::uint32_t bg = detail::pack(opt_.background);
    for (std::size_t i = 0; i < key_.size(); ++i)
      if (occluder_key_[i] > proj_.key_far && !(key_[i] > occluder_key_[i])) {
        key_[i] = proj_.key_far;
        colour_[i] = bg;
      }
  }

  /// colour = Σ w·colour / Σ w, normal = Σ w·n shaded per pixel (deferred shading), depth =
  /// the front-most contributing fragment, over the fragments facing the eye, or where there
  /// are none, those facing away. Pixels no weighted fragment reached keep the visibility
  /// pass's colour and depth.
  void normalise_blend() {
    if (!blend_.accumulating) return;  // no accumulation pass was run: the visibility image
    const std::size_t n = key_.size();
    const float* const w = blend_.plane(kW);
    const float* const key = blend_.plane(kKey);
    const std::size_t stride = blend_.stride;
    for (std::size_t i = 0; i < n; ++i) {
      if (!(w[i] > 0)) continue;
      kb_[i] = std::abs(key[i]);
      fragment_colour c{flat_, 1.0f};
      if constexpr (fx.colour) {
        const float inv = 1.0f / w[i];
        const float* const r = blend_.plane(kR);
        c.albedo = {detail::to_channel(r[i] * inv), detail::to_channel(r[stride + i] * inv),
                    detail::to_channel(r[2 * stride + i] * inv)};
      }
      if constexpr (fx.shading) {
        const float* const nx = blend_.plane(kNx);
        const vec3f nn(nx[i], nx[stride + i], nx[2 * stride + i]);
        const float len = nn.norm();
        c.lit = detail::lambert(len > 0 ? vec3f(nn / len) : vec3f::Zero(), light_, ambient_);
      }
      store(i, c);
    }
  }

  view view_;
  detail::persp_projection proj_;
  render_options opt_;
  const detail::shadow_map* shadows_;
  std::vector<float> key_;             ///< depth key 1/z per pixel; key_far = empty
  std::vector<std::uint32_t> colour_;  ///< packed final colour, or albedo with shadows
  std::vector<float> lit_;             ///< Lambert factor per pixel (shadows + shading only)
  std::vector<float> occluder_key_;    ///< nearest occluder key per pixel; empty: no occluder
  float* kb_ = nullptr;                // raw views of the buffers for the inner loops
  std::uint32_t* cb_ = nullptr;
  float* lb_ = nullptr;
  float fw_ = 0, fh_ = 0;
  rgb8 flat_;
  vec3f light_ = vec3f::Zero();
  float ambient_ = 0;
  [[no_unique_address]] std::conditional_t<fx.blending, blend_state, no_blend_state> blend_;
};

static_assert(Sink<rasterizer<positions_only>, positions_only>);
static_assert(OccluderSink<rasterizer<positions_only>>);
static_assert(GaussianSink<rasterizer<positions_only>>);
static_assert(ScreenRectSink<rasterizer<positions_only>, positions_only>);
static_assert(TexturedTriangleSink<rasterizer<all_attributes, all_effects>, all_attributes>);
static_assert(Sink<rasterizer<all_attributes, all_effects>, all_attributes>);

namespace detail {

[[nodiscard]] constexpr bool effect_flag(const effects& e, int i) {
  switch (i) {
    case 0:
      return e.shading;
    case 1:
      return e.colour;
    case 2:
      return e.backface_cull;
    case 3:
      return e.shadows;
    case 4:
      return e.hole_filling;
    default:
      return e.blending;
  }
}
[[nodiscard]] constexpr effects with_effect(effects e, int i) {
  switch (i) {
    case 0:
      e.shading = true;
      break;
    case 1:
      e.colour = true;
      break;
    case 2:
      e.backface_cull = true;
      break;
    case 3:
      e.shadows = true;
      break;
    case 4:
      e.hole_filling = true;
      break;
    default:
      e.blending = true;
      break;
  }
  return e;
}

/// Calls f.template operator()<R>() for R = `run` restricted to Allowed, with R a compile-time
/// constant: one branch per effect per frame, and only subsets of Allowed are instantiated.
template <effects Allowed, effects Fixed, int I, class F>
[[nodiscard]] image dispatch_effects(const effects& run, F& f) {
  if constexpr (I == 6) {
    return f.template operator()<Fixed>();
  } else {
    if constexpr (effect_flag(Allowed, I)) {
      if (effect_flag(run, I))
        return dispatch_effects<Allowed, with_effect(Fixed, I), I + 1>(run, f);
    }
    return dispatch_effects<Allowed, Fixed, I + 1>(run, f);
  }
}

/// Sends the frame to r: once, or with blending twice (visibility, then accumulation).
template <class R, attributes A>
void replay_passes(R& r, const buffer_sink<A>& prims) {
  prims.replay(r);
  if constexpr (R::fx.blending) {
    if (!r.needs_accumulation()) return;  // triangles only: nothing to blend
    r.begin_accumulation();
    prims.replay(r);
  }
}

template <attributes A, effects E>
[[nodiscard]] image render_prims(const view& v, const render_options& opt,
                                 const buffer_sink<A>& prims) {
  if constexpr (E.shadows) {
    const shadow_map sm = build_shadow_map(prims, v, opt);
    rasterizer<A, E> r(v, opt, &sm);
    replay_passes(r, prims);
    return r.finish();
  } else {
    rasterizer<A, E> r(v, opt);
    replay_passes(r, prims);
    return r.finish();
  }
}

template <attributes A, effects E, class DrawFn>
[[nodiscard]] image render_streamed(const view& v, const render_options& opt, DrawFn& draw) {
  constexpr bool blend = rasterizer<A, E>::fx.blending;
  if constexpr (E.shadows) {
    // The light pass and the camera pass (and with blending, its two) see the same primitives.
    buffer_sink<A> prims;
    draw(prims);
    return render_prims<A, E>(v, opt, prims);
  } else if constexpr (blend) {
    // The visibility and the accumulation pass: the draw is called once for each, straight into
    // the rasteriser (no copy of the frame).
    rasterizer<A, E> r(v, opt);
    draw(r);
    if (r.needs_accumulation()) {
      r.begin_accumulation();
      draw(r);
    }
    return r.finish();
  } else {
    rasterizer<A, E> r(v, opt);
    draw(r);
    return r.finish();
  }
}

/// True when draw takes the view it draws into, `draw(sink, view)`, beside the sink.
template <class DrawFn, class Sink>
inline constexpr bool draw_takes_view = std::is_invocable_v<DrawFn&, Sink&, const view&>;

template <class Sink, class DrawFn>
void call_draw(DrawFn& draw, Sink& sink, const view& v) {
  if constexpr (draw_takes_view<DrawFn, Sink>)
    draw(sink, v);
  else
    draw(sink);
}

/// The view and options a frame is drawn with, and the factor it is filtered down by.
struct drawing {
  view v;
  render_options opt;
  int k = 1;
};

/// render_options::supersample applied: the k× view, the options for drawing into it (hole
/// filling over k times the radius, up to the frame's larger side, beyond which a larger radius
/// changes nothing).
[[nodiscard]] inline drawing drawing_for(const view& v, const render_options& opt,
                                         bool takes_view) {
  const int k = opt.supersample;
  if (k == 1) return {v, opt, 1};
  if (k > 1 && !takes_view)
    throw InvalidArgument("render: supersample = " + std::to_string(k) +
                          " needs a draw that takes the view it draws into, "
                          "[&](auto& sink, const view& v) { ... }: points are sized in its pixels");
  drawing d{v.supersampled(k), opt, k};  // throws for k < 1 or a viewport too large
  d.opt.supersample = 1;
  const std::int64_t side = std::max(d.v.width, d.v.height);
  d.opt.hole_filling_radius =
      static_cast<int>(std::min<std::int64_t>(std::int64_t{opt.hole_filling_radius} * k, side));
  return d;
}

}  // namespace detail

/// Renders one frame of buffered primitives (in the order they were buffered).
///
/// `Compiled` is the set of effects compiled in. The run-time request `opt.fx` is intersected
/// with it and with what A supports (applicable_effects), then dispatched once to the
/// rasterizer instantiated for exactly that set. Hence rendering with an effect switched off at
/// run time gives the same bytes as rendering with it compiled out.
///
/// For the attribute sets of point sets (any mix of normal, colour, ellipse) and the full
/// effect set this is compiled once in the library (extern templates below): a program that
/// renders does not instantiate the rasteriser's effect combinations again in each file.
template <attributes A, effects Compiled = all_effects>
[[nodiscard]] image render_buffered(const view& v, const render_options& opt,
                                    const buffer_sink<A>& prims) {
  if (opt.supersample != 1)
    throw InvalidArgument("render_buffered: supersample = " + std::to_string(opt.supersample) +
                          ", but buffered primitives are drawn for one view; supersample "
                          "through render(), whose draw gets the k-fold view");
  constexpr effects allowed = applicable_effects(Compiled, A);
  const effects run = opt.fx & allowed;
  auto dispatch = [&]<effects E>() { return detail::render_prims<A, E>(v, opt, prims); };
  return detail::dispatch_effects<allowed, no_effects, 0>(run, dispatch);
}

/// Renders one frame: `draw(sink)` emits the frame's primitives into the buffer_sink<A>& it is
/// given (write it as a generic lambda `[&](auto& sink) { ... }`); it is called exactly once.
/// The primitives are then drawn by render_buffered<A, Compiled>.
///
/// A draw written `[&](auto& sink, const view& dv) { ... }` is also given the view to draw into:
/// v itself, or with opt.supersample = k its k× copy (view::supersampled), in whose pixels the
/// traversal must size its points — pass k × the tolerance to select the cut of v. The k× frame
/// is then box-filtered down to v's size (downsample_box).
///
/// Why a buffer and not the rasteriser itself as the sink: shadows need the frame's primitives
/// twice anyway, and with one sink type the caller's traversal is compiled once, not once per
/// effect combination (64 of them), which is what made every file that renders slow to build.
///
/// The buffer keeps its capacity from frame to frame on each thread (one per attribute set,
/// holding up to the largest frame drawn): a fresh buffer per frame paid for growing and
/// page-faulting it every time, which tripled the cost of a frame of one-pixel points. A draw
/// that itself calls render() gets a buffer of its own.
template <attributes A, effects Compiled = all_effects, class DrawFn>
[[nodiscard]] image render(const view& v, const render_options& opt, DrawFn&& draw) {
  const detail::drawing d =
      detail::drawing_for(v, opt, detail::draw_takes_view<DrawFn, buffer_sink<A>>);
  const auto finish = [&](const buffer_sink<A>& prims) {
    image img = render_buffered<A, Compiled>(d.v, d.opt, prims);
    if (d.k != 1) img = downsample_box(img, d.k);
    return img;
  };
  thread_local buffer_sink<A> kept;
  thread_local bool busy = false;
  if (busy) {
    buffer_sink<A> prims;
    detail::call_draw(draw, prims, d.v);
    return finish(prims);
  }
  struct release {
    ~release() {
      kept.clear();
      busy = false;
    }
  } const guard;
  busy = true;
  kept.clear();
  detail::call_draw(draw, kept, d.v);
  return finish(kept);
}

/// render() without the buffer: `draw(sink)` writes straight into the rasteriser<A, E>& (with
/// shadows, a buffer_sink<A>&) it is given. With blending it is called once per pass (visibility,
/// then accumulation, which a frame without splats or points skips) and must emit the same
/// primitives each time. The same image as render(); no copy of the frame, but the caller's draw
/// is compiled once per effect combination in the calling file. For measuring the rasteriser
/// itself, and for frames too large to buffer. Supersamples as render() does.
template <attributes A, effects Compiled = all_effects, class DrawFn>
[[nodiscard]] image render_direct(const view& v, const render_options& opt, DrawFn&& draw) {
  const detail::drawing d =
      detail::drawing_for(v, opt, detail::draw_takes_view<DrawFn, buffer_sink<A>>);
  constexpr effects allowed = applicable_effects(Compiled, A);
  const effects run = d.opt.fx & allowed;
  auto at_view = [&](auto& sink) { detail::call_draw(draw, sink, d.v); };
  auto dispatch = [&]<effects E>() { return detail::render_streamed<A, E>(d.v, d.opt, at_view); };
  image img = detail::dispatch_effects<allowed, no_effects, 0>(run, dispatch);
  if (d.k != 1) img = downsample_box(img, d.k);
  return img;
}

// Compiled once, in src/raster/render_instances_*.cpp.
#define PBR_LOD_RENDER_BUFFERED(EXTERN, NORMAL, COLOUR, ELLIPSE)                        \
  EXTERN template image render_buffered<                                                \
      attributes{.normal = NORMAL, .colour = COLOUR, .ellipse = ELLIPSE}, all_effects>( \
      const view&, const render_options&,                                               \
      const buffer_sink<attributes{.normal = NORMAL, .colour = COLOUR, .ellipse = ELLIPSE}>&);
PBR_LOD_RENDER_BUFFERED(extern, false, false, false)
PBR_LOD_RENDER_BUFFERED(extern, true, false, false)
PBR_LOD_RENDER_BUFFERED(extern, false, true, false)
PBR_LOD_RENDER_BUFFERED(extern, true, true, false)
PBR_LOD_RENDER_BUFFERED(extern, false, false, true)
PBR_LOD_RENDER_BUFFERED(extern, true, false, true)
PBR_LOD_RENDER_BUFFERED(extern, false, true, true)
PBR_LOD_RENDER_BUFFERED(extern, true, true, true)

}  // namespace pbr_lod
