// pbr_lod — the scan-conversion kernels shared by the camera pass and the shadow-map pass.
//
// Each kernel finds the pixels of one primitive and hands them, with their depth key, to a
// fragment callback (or a span_target) that does the depth test and the write. The kernels are
// templated on the projection (perspective camera or orthographic light) and on the callback, so
// everything inlines into the caller's loop: no virtual call, no heap allocation per primitive.
//
// Depth key. For a perspective view the key is 1/z (z = eye-space depth); for an orthographic
// view it is −z. Larger is nearer in both. For any plane, 1/z is an affine function of the screen
// position (z is not), so triangle and splat keys are evaluated as affine planes and the depth
// test is exact for planar primitives. z is recovered once per pixel at the end of the frame.
//
// Kernels:
//  * raster_square:   screen-aligned squares (point_prim), constant key.
//  * raster_ellipse:  object-space elliptical splats, projected exactly in perspective
//                     (Zwicker, Räsänen, Botsch, Dachsbacher, Pauly 2004, "Perspective accurate
//                     splatting"; Weyrich et al. 2007): the pixel ray is mapped to the splat's
//                     plane parameters (s, t) by a 3×3 projective map M⁻¹ and the pixel is inside
//                     iff s² + t² ≤ 1. The quadric s² + t² − w² ≤ 0 pulled back to the screen is a
//                     conic; its exact bounding box is scanned four pixels at a time, branch-free.
//  * raster_triangle: edge functions evaluated at pixel centres with the top-left fill rule,
//                     near-plane clipping in homogeneous space, perspective-correct attributes.
//                     Watertight: every edge function is computed from the edge's endpoints in
//                     a canonical (lexicographic) order, so two triangles sharing an edge compute
//                     bitwise-opposite values and the tie rule gives each pixel centre to exactly
//                     one of them (see docs/rasterizer.md).
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/math.hpp"

namespace pbr_lod::detail {

/// Homogeneous screen position (x, y, w) and depth-key numerator k of a point or direction:
/// the screen position is (x/w, y/w) and the key k/w.
struct hom4 {
  double x, y, w, k;
};

/// Rows of a 3×4 affine map from the primitives' frame to (x, y, w, k), in double: composed
/// once per frame so that projecting a splat's centre and axes is one 3×3 product each.
struct hom_rows {
  double origin[3];
  double x[3], y[3], w[3], k[3];
  double x0, y0, w0, k0;  ///< constant terms (for points; directions ignore them)

  /// Perspective: k is the constant 1 (k = 0 for directions); orthographic: w is.
  template <bool Perspective>
  [[nodiscard]] hom4 point(const vec3f& p) const {
    const double d0 = double(p.x()) - origin[0], d1 = double(p.y()) - origin[1],
                 d2 = double(p.z()) - origin[2];
    const double hx = x[0] * d0 + x[1] * d1 + x[2] * d2 + x0;
    const double hy = y[0] * d0 + y[1] * d1 + y[2] * d2 + y0;
    if constexpr (Perspective) return {hx, hy, w[0] * d0 + w[1] * d1 + w[2] * d2, 1.0};
    return {hx, hy, 1.0, k[0] * d0 + k[1] * d1 + k[2] * d2 + k0};
  }
  template <bool Perspective>
  [[nodiscard]] hom4 dir(const vec3f& v) const {
    const double d0 = v.x(), d1 = v.y(), d2 = v.z();
    const double hx = x[0] * d0 + x[1] * d1 + x[2] * d2, hy = y[0] * d0 + y[1] * d1 + y[2] * d2;
    if constexpr (Perspective) return {hx, hy, w[0] * d0 + w[1] * d1 + w[2] * d2, 0.0};
    return {hx, hy, 0.0, k[0] * d0 + k[1] * d1 + k[2] * d2};
  }
};

/// The camera: x = f·e_x + c_x·e_z, y = −f·e_y + c_y·e_z, w = e_z (eye depth), k = 1, with e the
/// eye coordinates; plus the float axes premultiplied for the one-pixel point path.
struct persp_projection {
  static constexpr bool perspective = true;
  vec3f eye, right, up, forward;
  vec3f right_px, up_px;  ///< right·focal, up·focal: screen offsets per unit of depth
  float focal, cx, cy;
  int width, height;
  float w_near, w_far;      ///< clip range of eye-space z
  float key_near, key_far;  ///< 1/z_near and 1/z_far (the key of an empty pixel)
  hom_rows rows;

  explicit persp_projection(const view& v)
      : eye(v.eye),
        right(v.right),
        up(v.up),
        forward(v.forward),
        right_px(v.right * v.focal_px),
        up_px(v.up * v.focal_px),
        focal(v.focal_px),
        cx(0.5f * static_cast<float>(v.width)),
        cy(0.5f * static_cast<float>(v.height)),
        width(v.width),
        height(v.height),
        w_near(v.z_near),
        w_far(v.z_far),
        key_near(1.0f / v.z_near),
        key_far(1.0f / v.z_far) {
    for (int i = 0; i < 3; ++i) {
      const double r = right[i], u = up[i], f = forward[i];
      rows.origin[i] = eye[i];
      rows.x[i] = double(focal) * r + double(cx) * f;
      rows.y[i] = -double(focal) * u + double(cy) * f;
      rows.w[i] = f;
      rows.k[i] = 0;
    }
    rows.x0 = rows.y0 = rows.w0 = 0;
    rows.k0 = 1;
  }

  [[nodiscard]] vec3f frame(const vec3f& p) const {
    const vec3f d = p - eye;
    return {d.dot(right), d.dot(up), d.dot(forward)};
  }
  [[nodiscard]] hom4 point(const vec3f& p) const { return rows.point<true>(p); }
  [[nodiscard]] hom4 dir(const vec3f& d) const { return rows.dir<true>(d); }
};

/// An orthographic view along `forward` (the light of the shadow pass): screen = centre +
/// scale·(x, −y), key = −z. Nothing is clipped: the view is fitted around all primitives.
/// Call update() after changing the frame.
struct ortho_projection {
  static constexpr bool perspective = false;
  vec3f origin = vec3f::Zero(), right = vec3f::UnitX(), up = vec3f::UnitY(),
        forward = vec3f::UnitZ();
  float scale = 1;  ///< pixels per world unit
  float cx = 0, cy = 0;
  int width = 0, height = 0;
  float w_near = -std::numeric_limits<float>::infinity();
  float w_far = std::numeric_limits<float>::infinity();
  float key_near = std::numeric_limits<float>::infinity();
  float key_far = -std::numeric_limits<float>::infinity();
  hom_rows rows{};

  void update() {
    for (int i = 0; i < 3; ++i) {
      rows.origin[i] = origin[i];
      rows.x[i] = double(scale) * right[i];
      rows.y[i] = -double(scale) * up[i];
      rows.w[i] = 0;
      rows.k[i] = -double(forward[i]);
    }
    rows.x0 = cx;
    rows.y0 = cy;
    rows.w0 = 1;
    rows.k0 = 0;
  }
  [[nodiscard]] vec3f frame(const vec3f& p) const {
    const vec3f d = p - origin;
    return {d.dot(right), d.dot(up), d.dot(forward)};
  }
  [[nodiscard]] hom4 point(const vec3f& p) const { return rows.point<false>(p); }
  [[nodiscard]] hom4 dir(const vec3f& d) const { return rows.dir<false>(d); }
};

/// First pixel index whose centre (i + 0.5) is ≥ lo, clamped to [0, n]; NaN-safe (→ n).
[[nodiscard]] inline int first_centre_at_or_after(double lo, int n) {
  const double v = lo - 0.5;  // the answer is ceil(v), clamped
  if (!(v > -1)) return v == v ? 0 : n;
  if (!(v < n)) return n;
  const int t = static_cast<int>(v);  // v ∈ (−1, n): truncation, then up to the ceiling
  return t + (static_cast<double>(t) < v ? 1 : 0);
}
/// Last pixel index whose centre is ≤ hi, clamped to [−1, n−1]; NaN-safe (→ −1).
[[nodiscard]] inline int last_centre_at_or_before(double hi, int n) {
  const double v = hi - 0.5;  // the answer is floor(v), clamped
  if (!(v < n)) return v == v ? n - 1 : -1;
  if (!(v >= 0)) return -1;
  return static_cast<int>(v);  // v ∈ [0, n): truncation is the floor
}

// ---------------------------------------------------------------------------------------------
// Depth-tested writes
// ---------------------------------------------------------------------------------------------

/// Colours are kept packed in one 32-bit word per pixel while rasterising (r | g<<8 | b<<16), so
/// that a masked colour write is a single blend; unpacked to rgb8 once per frame.
[[nodiscard]] constexpr std::uint32_t pack(rgb8 c) {
  return std::uint32_t(c.r) | (std::uint32_t(c.g) << 8) | (std::uint32_t(c.b) << 16);
}
[[nodiscard]] constexpr rgb8 unpack(std::uint32_t c) {
  return {std::uint8_t(c & 0xff), std::uint8_t((c >> 8) & 0xff), std::uint8_t((c >> 16) & 0xff)};
}

/// Four float lanes: SSE2 when the target has it, else plain floats. Both perform the same IEEE
/// single-precision operations in the same order, so the images are identical either way.
#if defined(__SSE2__)
struct f4 {
  __m128 v;
  f4() = default;
  explicit f4(__m128 x) : v(x) {}
  explicit f4(float a) : v(_mm_set1_ps(a)) {}
  static f4 lanes() { return f4(_mm_set_ps(3, 2, 1, 0)); }
  friend f4 operator+(f4 a, f4 b) { return f4(_mm_add_ps(a.v, b.v)); }
  friend f4 operator*(f4 a, f4 b) { return f4(_mm_mul_ps(a.v, b.v)); }
  /// All-ones lanes where x ≤ 0.
  friend f4 non_positive(f4 x) { return f4(_mm_cmple_ps(x.v, _mm_setzero_ps())); }
  void store(float* out) const { _mm_storeu_ps(out, v); }
  // For the blending pass's accumulation (rasterizer::accumulate4): loads, division, min/max,
  // comparisons giving all-ones lane masks, and bitwise selection by such masks.
  static f4 load(const float* p) { return f4(_mm_loadu_ps(p)); }
  friend f4 operator-(f4 a, f4 b) { return f4(_mm_sub_ps(a.v, b.v)); }
  friend f4 operator/(f4 a, f4 b) { return f4(_mm_div_ps(a.v, b.v)); }
  friend f4 min(f4 a, f4 b) { return f4(_mm_min_ps(a.v, b.v)); }
  friend f4 max(f4 a, f4 b) { return f4(_mm_max_ps(a.v, b.v)); }
  friend f4 operator>=(f4 a, f4 b) { return f4(_mm_cmpge_ps(a.v, b.v)); }
  friend f4 operator>(f4 a, f4 b) { return f4(_mm_cmpgt_ps(a.v, b.v)); }
  friend f4 operator<(f4 a, f4 b) { return f4(_mm_cmplt_ps(a.v, b.v)); }
  friend f4 operator&(f4 a, f4 b) { return f4(_mm_and_ps(a.v, b.v)); }
  /// The lanes of b where mask is clear (~mask & b).
  friend f4 and_not(f4 mask, f4 b) { return f4(_mm_andnot_ps(mask.v, b.v)); }
  /// a where mask is set, else b.
  friend f4 select(f4 mask, f4 a, f4 b) {
    return f4(_mm_or_ps(_mm_and_ps(mask.v, a.v), _mm_andnot_ps(mask.v, b.v)));
  }
  /// Whether any lane of a mask is set.
  friend bool any(f4 mask) { return _mm_movemask_ps(mask.v) != 0; }
  /// All-ones in lanes l with first ≤ l (first in 0..4).
  static f4 lanes_from(int first) {
    const __m128i l = _mm_set_epi32(3, 2, 1, 0);
    return f4(_mm_castsi128_ps(_mm_cmpgt_epi32(l, _mm_set1_epi32(first - 1))));
  }
};
#else
struct f4 {
  float v[4];
  f4() = default;
  explicit f4(float a) : v{a, a, a, a} {}
  static f4 lanes() {
    f4 r;
    for (int i = 0; i < 4; ++i) r.v[i] = static_cast<float>(i);
    return r;
  }
  friend f4 operator+(f4 a, f4 b) {
    for (int i = 0; i < 4; ++i) a.v[i] += b.v[i];
    return a;
  }
  friend f4 operator*(f4 a, f4 b) {
    for (int i = 0; i < 4; ++i) a.v[i] *= b.v[i];
    return a;
  }
  friend f4 non_positive(f4 x) {  // all-ones bits where x ≤ 0, as _mm_cmple_ps
    for (int i = 0; i < 4; ++i) x.v[i] = mask_of(x.v[i] <= 0);
    return x;
  }
  void store(float* out) const {
    for (int i = 0; i < 4; ++i) out[i] = v[i];
  }
  static f4 load(const float* p) {
    f4 r;
    for (int i = 0; i < 4; ++i) r.v[i] = p[i];
    return r;
  }
  friend f4 operator-(f4 a, f4 b) {
    for (int i = 0; i < 4; ++i) a.v[i] -= b.v[i];
    return a;
  }
  friend f4 operator/(f4 a, f4 b) {
    for (int i = 0; i < 4; ++i) a.v[i] /= b.v[i];
    return a;
  }
  // min/max as minps/maxps: the second operand when either is NaN.
  friend f4 min(f4 a, f4 b) {
    for (int i = 0; i < 4; ++i) a.v[i] = a.v[i] < b.v[i] ? a.v[i] : b.v[i];
    return a;
  }
  friend f4 max(f4 a, f4 b) {
    for (int i = 0; i < 4; ++i) a.v[i] = a.v[i] > b.v[i] ? a.v[i] : b.v[i];
    return a;
  }
  friend f4 operator>=(f4 a, f4 b) {
    for (int i = 0; i < 4; ++i) a.v[i] = mask_of(a.v[i] >= b.v[i]);
    return a;
  }
  friend f4 operator>(f4 a, f4 b) {
    for (int i = 0; i < 4; ++i) a.v[i] = mask_of(a.v[i] > b.v[i]);
    return a;
  }
  friend f4 operator<(f4 a, f4 b) {
    for (int i = 0; i < 4; ++i) a.v[i] = mask_of(a.v[i] < b.v[i]);
    return a;
  }
  friend f4 operator&(f4 a, f4 b) {
    for (int i = 0; i < 4; ++i) a.v[i] = from_bits(bits(a.v[i]) & bits(b.v[i]));
    return a;
  }
  friend f4 and_not(f4 mask, f4 b) {
    for (int i = 0; i < 4; ++i) b.v[i] = from_bits(~bits(mask.v[i]) & bits(b.v[i]));
    return b;
  }
  friend f4 select(f4 mask, f4 a, f4 b) {
    for (int i = 0; i < 4; ++i) a.v[i] = bits(mask.v[i]) ? a.v[i] : b.v[i];
    return a;
  }
  friend bool any(f4 mask) {
    for (int i = 0; i < 4; ++i)
      if (bits(mask.v[i]) != 0) return true;
    return false;
  }
  static f4 lanes_from(int first) {
    f4 r;
    for (int i = 0; i < 4; ++i) r.v[i] = mask_of(i >= first);
    return r;
  }

 private:
  static std::uint32_t bits(float f) { return std::bit_cast<std::uint32_t>(f); }
  static float from_bits(std::uint32_t u) { return std::bit_cast<float>(u); }
  static float mask_of(bool b) { return from_bits(b ? 0xffffffffu : 0u); }
};
#endif

/// Where a kernel writes covered pixels, and what: every covered pixel whose key beats the
/// stored one gets `key`, and (when Colour / Lit) `colour_value` / `lit_value`.
template <bool Colour, bool Lit>
struct span_target {
  float* key;
  std::uint32_t* colour = nullptr;
  float* lit = nullptr;
  std::uint32_t colour_value = 0;
  float lit_value = 1;

  void write1(std::size_t i, float k, bool inside) const {
    // Branch-free: the store happens either way (single-threaded, so rewriting the old value is
    // harmless); only the selected value depends on the tests.
    const bool w = inside && k > key[i];
    key[i] = w ? k : key[i];
    if constexpr (Colour) colour[i] = w ? colour_value : colour[i];
    if constexpr (Lit) lit[i] = w ? lit_value : lit[i];
  }

  /// Writes four consecutive pixels from index i (only the first n ≤ 4 when n < 4: rows
  /// narrower than four pixels). `inside` is a lane mask from non_positive(). Holds its pointers
  /// and broadcast values by value: a colour store through __m128i* may alias anything, which
  /// would otherwise force them to be reloaded from the target after every store.
  struct writer4 {
    span_target t;
#if defined(__SSE2__)
    __m128i colour_value;
    __m128 lit_value;
#endif

    void operator()(std::size_t i, f4 k, f4 inside, int n = 4) const {
#if defined(__SSE2__)
      if (n == 4) {
        const __m128 old = _mm_loadu_ps(t.key + i);
        const __m128 w = _mm_and_ps(inside.v, _mm_cmpgt_ps(k.v, old));
        _mm_storeu_ps(t.key + i, _mm_or_ps(_mm_and_ps(w, k.v), _mm_andnot_ps(w, old)));
        if constexpr (Colour) {
          const __m128i wi = _mm_castps_si128(w);
          __m128i* p = reinterpret_cast<__m128i*>(t.colour + i);
          const __m128i c = _mm_loadu_si128(p);
          _mm_storeu_si128(p,
                           _mm_or_si128(_mm_and_si128(wi, colour_value), _mm_andnot_si128(wi, c)));
        }
        if constexpr (Lit) {
          const __m128 l = _mm_loadu_ps(t.lit + i);
          _mm_storeu_ps(t.lit + i, _mm_or_ps(_mm_and_ps(w, lit_value), _mm_andnot_ps(w, l)));
        }
        return;
      }
#endif
      float kk[4], in[4];
      k.store(kk);
      inside.store(in);
      for (int l = 0; l < n; ++l)
        t.write1(i + static_cast<std::size_t>(l), kk[l], in[l] != 0);  // all-ones is a NaN ≠ 0
    }
  };
  [[nodiscard]] writer4 four() const {
#if defined(__SSE2__)
    return {*this, _mm_set1_epi32(static_cast<int>(colour_value)), _mm_set1_ps(lit_value)};
#else
    return {*this};
#endif
  }
};

// ---------------------------------------------------------------------------------------------
// Squares
// ---------------------------------------------------------------------------------------------

/// Screen-aligned square of side `size` pixels centred at (sx, sy), constant key.
/// size ≤ 1: the one pixel that contains (sx, sy) (a point never vanishes).
/// size > 1: the pixels whose centres lie in [sx − size/2, sx + size/2) × [sy − size/2, ...).
template <class Frag>
inline void raster_square(int width, int height, float sx, float sy, float size, float key,
                          Frag&& frag) {
  if (!(size > 1)) {
    if (!(sx >= 0 && sx < static_cast<float>(width) && sy >= 0 && sy < static_cast<float>(height)))
      return;
    frag(static_cast<std::size_t>(static_cast<int>(sy)) * static_cast<std::size_t>(width) +
             static_cast<std::size_t>(static_cast<int>(sx)),
         key);
    return;
  }
  const double h = 0.5 * double(size);
  // Half-open: the last centre is the one strictly before sx + h.
  const int i0 = first_centre_at_or_after(double(sx) - h, width);
  const int i1 = first_centre_at_or_after(double(sx) + h, width) - 1;
  const int j0 = first_centre_at_or_after(double(sy) - h, height);
  const int j1 = first_centre_at_or_after(double(sy) + h, height) - 1;
  for (int j = j0; j <= j1; ++j) {
    const std::size_t row = static_cast<std::size_t>(j) * static_cast<std::size_t>(width);
    for (int i = i0; i <= i1; ++i) frag(row + static_cast<std::size_t>(i), key);
  }
}

/// The pixels [first, end) along one axis of n pixels that a screen_rect_prim covers between lo
/// and hi (fixed point, F fractional bits): those whose centres (i + ½)·2^F lie in [lo, hi), by a
/// shift — first = ⌈(lo − 2^(F−1)) / 2^F⌉ = (lo + 2^(F−1) − 1) >> F, likewise end — or, when no
/// centre does, the pixel containing the midpoint; clipped to [0, n) (empty when off-screen).
template <int F>
[[nodiscard]] inline std::array<int, 2> rect_pixel_span(std::int32_t lo, std::int32_t hi, int n) {
  constexpr std::int64_t round = (std::int64_t(1) << (F - 1)) - 1;
  std::int64_t first = (std::int64_t(lo) + round) >> F, end = (std::int64_t(hi) + round) >> F;
  if (end <= first) {
    first = (std::int64_t(lo) + std::int64_t(hi)) >> (F + 1);
    end = first + 1;
  }
  first = std::max<std::int64_t>(first, 0);
  end = std::min<std::int64_t>(end, n);
  return {int(first), int(std::max(first, end))};
}

// ---------------------------------------------------------------------------------------------
// Elliptical splats, exact perspective
// ---------------------------------------------------------------------------------------------

/// The projective map of the ellipse {c + s·u + t·v : s² + t² ≤ 1} that raster_ellipse and
/// raster_ellipse_radial scan: hc the centre's homogeneous image, r1..r3 the rows of
/// P⁻¹ = adj(P)/det for P = [u' v' c'], the key kx·x + ky·y + k0, and whether the ellipse lies
/// wholly in front of the near plane. False when it lies wholly outside the clip range or has no
/// area (edge-on, a zero or doubled axis, NaN).
struct ellipse_map {
  hom4 hc, hu, hv;
  double r1[3], r2[3], r3[3];
  double kx, ky, k0;
  bool in_front;
};

template <class Proj>
inline bool map_ellipse(const Proj& pr, const vec3f& c, const vec3f& u, const vec3f& v,
                        ellipse_map& m) {
  m.hc = pr.point(c);
  m.hu = pr.dir(u);
  m.hv = pr.dir(v);
  const hom4 &hc = m.hc, &hu = m.hu, &hv = m.hv;
  // w (eye-space z for the camera) over the ellipse is w_c ± r with r = |(w_u, w_v)|; the tests
  // against the clip range are done on squares to avoid a square root per splat.
  const double wr2 = hu.w * hu.w + hv.w * hv.w;
  const double to_near = hc.w - pr.w_near, to_far = hc.w - pr.w_far;
  if (!(to_near >= 0 || to_near * to_near <= wr2)) return false;  // wholly behind the near plane
  if (!(to_far < 0 || to_far * to_far < wr2)) return false;       // wholly beyond the far plane
  m.in_front = to_near >= 0 && to_near * to_near >= wr2;

  // Rows of P⁻¹ = adj(P)/det: (m2×m3, m3×m1, m1×m2)/det with columns m1 = u', m2 = v', m3 = c'.
  const double m1[3] = {hu.x, hu.y, hu.w}, m2[3] = {hv.x, hv.y, hv.w}, m3[3] = {hc.x, hc.y, hc.w};
  const auto cross = [](const double* a, const double* b, double* o) {
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
  };
  double* r1 = m.r1;
  double* r2 = m.r2;
  double* r3 = m.r3;
  cross(m2, m3, r1);
  cross(m3, m1, r2);
  cross(m1, m2, r3);
  const double det = m3[0] * r3[0] + m3[1] * r3[1] + m3[2] * r3[2];
  const auto norm2 = [](const double* a) { return a[0] * a[0] + a[1] * a[1] + a[2] * a[2]; };
  // det = c'·(u'×v') = |c'||u'×v'|·cos θ, θ the angle between the plane's image normal and the
  // centre's ray: |cos θ| ≤ 1e-9 is edge-on, u'×v' = 0 a zero or doubled axis; no area either
  // way (the test also catches NaN).
  if (!(det * det > 1e-18 * norm2(m3) * norm2(r3))) return false;
  const double inv = 1.0 / det;
  for (int i = 0; i < 3; ++i) {
    r1[i] *= inv;
    r2[i] *= inv;
    r3[i] *= inv;
  }
  // key(x, y) = kx·x + ky·y + k0 (the key numerators weight the plane parameters); for the
  // camera the numerators are (0, 0, 1), so the key is the third row: 1/z is affine.
  if constexpr (Proj::perspective) {
    m.kx = r3[0];
    m.ky = r3[1];
    m.k0 = r3[2];
  } else {
    m.kx = hu.k * r1[0] + hv.k * r2[0] + hc.k * r3[0];
    m.ky = hu.k * r1[1] + hv.k * r2[1] + hc.k * r3[1];
    m.k0 = hu.k * r1[2] + hv.k * r2[2] + hc.k * r3[2];
  }
  return true;
}

/// The screen conic of an ellipse wholly in front of the near plane (ellipse_map::in_front),
/// relative to the image (x₀, y₀) of its centre, where g = (0, 0, 1/w_c) exactly and the terms
/// stay small: Q(X, Y) = g₁² + g₂² − g₃² = αX² + 2βXY + γY² + 2δX + 2εY + ζ (inside iff Q ≤ 0),
/// the key kc + kx·X + ky·Y, and the pixel box [i0, i1] × [j0, j1] of its exact bounding box
/// (empty when i0 > i1 or j0 > j1). What scan_conic needs: computed once per splat, and kept by
/// the blending passes from the visibility pass for the accumulation pass.
struct ellipse_conic {
  double x0, y0, alpha, beta, gamma, delta, eps, zeta, kc, kx, ky;
  int i0, i1, j0, j1;
};

/// The conic of m (m.in_front); false when it is numerically not an ellipse (no area).
inline bool conic_of(const ellipse_map& m, int width, int height, ellipse_conic& c) {
  const hom4& hc = m.hc;
  const double* r1 = m.r1;
  const double* r2 = m.r2;
  const double* r3 = m.r3;
  const double g3 = 1.0 / hc.w;
  const double x0 = hc.x * g3, y0 = hc.y * g3;
  const double a1 = r1[0], b1 = r1[1], a2 = r2[0], b2 = r2[1], a3 = r3[0], b3 = r3[1];
  const double alpha = a1 * a1 + a2 * a2 - a3 * a3;
  const double beta = a1 * b1 + a2 * b2 - a3 * b3;
  const double gamma = b1 * b1 + b2 * b2 - b3 * b3;
  const double delta = -a3 * g3, eps = -b3 * g3, zeta = -g3 * g3;
  const double pdet = alpha * gamma - beta * beta;
  if (!(alpha > 0 && pdet > 0)) return false;  // numerically not an ellipse: no area
  // Bounding box: the rows Y with a real span, (βY + δ)² − α(γY² + 2εY + ζ) ≥ 0, and likewise
  // the columns X: two downward parabolas, whose roots are the extremes of the ellipse.
  const double hy = beta * delta - alpha * eps, hx = beta * eps - gamma * delta;
  const double dy = hy * hy + pdet * (delta * delta - alpha * zeta);
  const double dx = hx * hx + pdet * (eps * eps - gamma * zeta);
  if (!(dy > 0 && dx > 0)) return false;
  const double inv_pdet = 1.0 / pdet, sy = std::sqrt(dy), sx = std::sqrt(dx);
  c = {x0,   y0,   alpha, beta, gamma, delta, eps, zeta, hc.k * g3 /* key at the centre */,
       m.kx, m.ky, 0,     0,    0,     0};
  c.j0 = first_centre_at_or_after(y0 + (hy - sy) * inv_pdet, height);
  c.j1 = last_centre_at_or_before(y0 + (hy + sy) * inv_pdet, height);
  c.i0 = first_centre_at_or_after(x0 + (hx - sx) * inv_pdet, width);
  c.i1 = last_centre_at_or_before(x0 + (hx + sx) * inv_pdet, width);
  return true;
}

/// The pixels of a conic's box, four at a time: calls chunk(i, key, q, lanes, skip) for chunks
/// of four consecutive pixels from index i along a row, with the depth key and Q of each lane
/// (the pixel centre is inside iff Q ≤ 0; for the camera key = g₃, so 1 − s² − t² = −Q/key²).
/// A chunk is shifted left to stay inside the row, so its first `skip` lanes were already given
/// by the chunk before it (or lie left of the box); only the first `lanes` (< 4 on viewports
/// narrower than four pixels) exist. Evaluated in float relative to the centre's image, with no
/// branch on the data (the boundary moves by ~1e-7 of the splat's radius at most).
template <class Chunk>
inline void scan_conic(const ellipse_conic& c, int width, Chunk&& chunk) {
  const int i0 = c.i0, i1 = c.i1, j0 = c.j0, j1 = c.j1;
  if (i0 > i1 || j0 > j1) return;
  const double x0 = c.x0, y0 = c.y0, beta = c.beta, gamma = c.gamma, delta = c.delta, eps = c.eps,
               zeta = c.zeta, kc = c.kc, kx = c.kx, ky = c.ky;
  // Row by row, four pixels at a time: a row of Q(X) = (αX + B)X + C. Chunks start at `xs` and
  // are shifted left to stay inside the row.
  const int span = i1 - i0 + 1;
  const int chunks = (span + 3) / 4;
  const int lanes = std::min(width, 4);
  const f4 lane = f4::lanes(), va(static_cast<float>(c.alpha));
  const f4 lane_key = f4(static_cast<float>(kx)) * lane;
  const auto chunk_start = [&](int k) { return std::max(std::min(i0 + 4 * k, width - 4), 0); };
  if (chunks <= 2) {
    // Small splats (the common case: ≤ 8 pixels wide): forward differences down the rows.
    // Q(X, Y+1) − Q(X, Y) = 2βX + γ(2Y + 1) + 2ε, whose own row difference is 2γ; the key
    // steps by ky. Per row and chunk: three additions, a compare and the blended write.
    const double Y0 = j0 + 0.5 - y0;
    const f4 b0(static_cast<float>(2 * (beta * Y0 + delta)));
    const f4 c0(static_cast<float>((gamma * Y0 + 2 * eps) * Y0 + zeta));
    const f4 d0(static_cast<float>(gamma * (2 * Y0 + 1) + 2 * eps));
    const f4 two_beta(static_cast<float>(2 * beta)), dd(static_cast<float>(2 * gamma));
    const f4 dk(static_cast<float>(ky));
    struct chunk_state {
      std::size_t xs;
      int skip;
      f4 q, dq, key;
    };
    const auto start = [&](int k) {
      const int xs = chunk_start(k);
      const double X0 = xs + 0.5 - x0;
      const f4 X = f4(static_cast<float>(X0)) + lane;
      return chunk_state{static_cast<std::size_t>(xs), i0 + 4 * k - xs, (va * X + b0) * X + c0,
                         two_beta * X + d0,
                         f4(static_cast<float>(kc + ky * Y0 + kx * X0)) + lane_key};
    };
    const auto step = [&](chunk_state& ch, std::size_t row) {
      chunk(row + ch.xs, ch.key, ch.q, lanes, ch.skip);
      ch.q = ch.q + ch.dq;
      ch.dq = ch.dq + dd;
      ch.key = ch.key + dk;
    };
    chunk_state a = start(0);
    std::size_t row = static_cast<std::size_t>(j0) * static_cast<std::size_t>(width);
    if (chunks == 1) {
      for (int j = j0; j <= j1; ++j, row += static_cast<std::size_t>(width)) step(a, row);
    } else {
      chunk_state b = start(1);
      for (int j = j0; j <= j1; ++j, row += static_cast<std::size_t>(width)) {
        step(a, row);
        step(b, row);
      }
    }
    return;
  }
  // Wider splats: the row polynomial is evaluated afresh on every row (forward differences
  // over hundreds of rows would accumulate rounding).
  for (int j = j0; j <= j1; ++j) {
    const double Y = j + 0.5 - y0;
    const f4 b(static_cast<float>(2 * (beta * Y + delta)));
    const f4 cq(static_cast<float>((gamma * Y + 2 * eps) * Y + zeta));
    const std::size_t row = static_cast<std::size_t>(j) * static_cast<std::size_t>(width);
    for (int k = 0; k < chunks; ++k) {
      const int xs = chunk_start(k);
      const double X0 = xs + 0.5 - x0;
      const f4 X = f4(static_cast<float>(X0)) + lane;
      const f4 key = f4(static_cast<float>(kc + ky * Y + kx * X0)) + lane_key;
      chunk(row + static_cast<std::size_t>(xs), key, (va * X + b) * X + cq, lanes, i0 + 4 * k - xs);
    }
  }
}

/// conic_of(m) scanned by scan_conic; false when m is numerically not an ellipse.
template <class Chunk>
inline bool scan_ellipse_conic(const ellipse_map& m, int width, int height, Chunk&& chunk) {
  ellipse_conic c;
  if (!conic_of(m, width, height, c)) return false;
  scan_conic(c, width, chunk);
  return true;
}

/// Rasterises the ellipse {c + s·u + t·v : s² + t² ≤ 1} (c, u, v in the primitives' frame) into
/// `out`, depth-tested.
///
/// With P = [u' v' c'] the 3×3 matrix of homogeneous screen images (x, y, w) of the axes and the
/// centre, a pixel (x, y) sees the plane point with parameters (s, t, 1) ∝ P⁻¹ (x, y, 1): the
/// pixel is covered iff g₁² + g₂² ≤ g₃² with g = P⁻¹(x, y, 1), and its key is the affine
/// function k·g (k = the key numerators of u, v, c). Splats that straddle the near plane are
/// clipped per pixel (key ≤ 1/z_near) inside the bounding box of their clipped bounding
/// rectangle; splats whose axes are zero or parallel, or whose plane contains the eye
/// (edge-on), have no area and draw nothing.
template <class Proj, bool Colour, bool Lit>
inline void raster_ellipse_mapped(const Proj& pr, const ellipse_map& m,
                                  const span_target<Colour, Lit>& out);
template <class Proj, bool Colour, bool Lit>
inline void raster_ellipse(const Proj& pr, const vec3f& c, const vec3f& u, const vec3f& v,
                           const span_target<Colour, Lit>& out) {
  ellipse_map m;
  if (!map_ellipse(pr, c, u, v, m)) return;
  raster_ellipse_mapped(pr, m, out);
}

/// Calls f(index, key, e, g₃) for every pixel centre inside the mapped ellipse and behind the
/// near plane (key ≤ 1/z_near), with g = P⁻¹(x, y, 1) and e = g₁² + g₂² (inside iff e ≤ g₃²).
/// Scans the bounding box of the projected rectangle c ± u ± v clipped to w ≥ w_near, which
/// contains the visible part of the ellipse's image: per pixel and in double, for splats that
/// straddle the near plane and for the blending pass.
template <class Proj, class F>
inline void scan_clipped_ellipse(const Proj& pr, const ellipse_map& m, F&& f) {
  const hom4 &hc = m.hc, &hu = m.hu, &hv = m.hv;
  double xlo = std::numeric_limits<double>::infinity(), xhi = -xlo, ylo = xlo, yhi = -xlo;
  const double wn = pr.w_near;
  const auto add = [&](double x, double y, double w) {
    xlo = std::min(xlo, x / w);
    xhi = std::max(xhi, x / w);
    ylo = std::min(ylo, y / w);
    yhi = std::max(yhi, y / w);
  };
  const double su[4] = {1, -1, -1, 1}, sv[4] = {1, 1, -1, -1};
  for (int i = 0; i < 4; ++i) {
    const int j = (i + 1) % 4;
    const double ax = hc.x + su[i] * hu.x + sv[i] * hv.x, ay = hc.y + su[i] * hu.y + sv[i] * hv.y,
                 aw = hc.w + su[i] * hu.w + sv[i] * hv.w;
    const double bx = hc.x + su[j] * hu.x + sv[j] * hv.x, by = hc.y + su[j] * hu.y + sv[j] * hv.y,
                 bw = hc.w + su[j] * hu.w + sv[j] * hv.w;
    const bool ain = aw >= wn, bin = bw >= wn;
    if (ain) add(ax, ay, aw);
    if (ain != bin) {
      const double t = (wn - aw) / (bw - aw);
      add(ax + t * (bx - ax), ay + t * (by - ay), wn);
    }
  }
  const int width = pr.width, height = pr.height;
  const int i0 = first_centre_at_or_after(xlo, width), i1 = last_centre_at_or_before(xhi, width);
  const int j0 = first_centre_at_or_after(ylo, height), j1 = last_centre_at_or_before(yhi, height);
  const double *r1 = m.r1, *r2 = m.r2, *r3 = m.r3;
  for (int j = j0; j <= j1; ++j) {
    const double py = j + 0.5;
    const std::size_t row = static_cast<std::size_t>(j) * static_cast<std::size_t>(width);
    for (int i = i0; i <= i1; ++i) {
      const double px = i + 0.5;
      const double g1 = r1[0] * px + r1[1] * py + r1[2];
      const double g2 = r2[0] * px + r2[1] * py + r2[2];
      const double g3 = r3[0] * px + r3[1] * py + r3[2];
      const double e = g1 * g1 + g2 * g2;
      if (!(e <= g3 * g3)) continue;
      const double key = m.kx * px + m.ky * py + m.k0;
      if (!(key <= pr.key_near)) continue;  // in front of the near plane (or behind the eye)
      f(row + static_cast<std::size_t>(i), key, e, g3);
    }
  }
}

/// raster_ellipse() of the ellipse map_ellipse() mapped.
template <class Proj, bool Colour, bool Lit>
inline void raster_ellipse_mapped(const Proj& pr, const ellipse_map& m,
                                  const span_target<Colour, Lit>& out) {
  if (m.in_front) {
    // Whole ellipse in front of the near plane: its image is a bounded ellipse, scanned four
    // pixels at a time; a pixel seen by two chunks gets the same value twice, which the strict
    // depth test makes harmless. Rows narrower than four pixels (tiny viewports) write only
    // their own lanes.
    const auto write4 = out.four();
    (void)scan_ellipse_conic(m, pr.width, pr.height,
                             [&](std::size_t i, f4 key, f4 q, int lanes, int) {
                               write4(i, key, non_positive(q), lanes);
                             });
    return;
  }

  // Straddles the near plane (perspective only): test every pixel of the box that bounds the
  // visible part.
  scan_clipped_ellipse(pr, m, [&](std::size_t index, double key, double, double) {
    out.write1(index, static_cast<float>(key), true);
  });
}

/// Calls frag(index, key, r2) for every pixel centre inside the ellipse {c + s·u + t·v :
/// s² + t² ≤ 1}, with r2 = s² + t² of the plane point the pixel sees: the radial coordinate of
/// a blending weight. The same projective map as raster_ellipse (g = P⁻¹(x, y, 1), inside iff
/// g₁² + g₂² ≤ g₃², (s, t) = (g₁, g₂)/g₃), evaluated per pixel in double over the bounding box of
/// the projected rectangle c ± u ± v clipped at the near plane (which contains the ellipse's
/// image). Plainer and slower than raster_ellipse's conic scan, and only the blending pass pays
/// for it. No depth test: frag decides.
template <class Proj, class Frag>
inline void raster_ellipse_radial(const Proj& pr, const vec3f& c, const vec3f& u, const vec3f& v,
                                  Frag&& frag) {
  ellipse_map m;
  if (!map_ellipse(pr, c, u, v, m)) return;
  scan_clipped_ellipse(pr, m, [&](std::size_t index, double key, double e, double g3) {
    if (g3 == 0) return;
    frag(index, static_cast<float>(key), static_cast<float>(e / (g3 * g3)));
  });
}

// ---------------------------------------------------------------------------------------------
// Triangles
// ---------------------------------------------------------------------------------------------

/// A triangle vertex in homogeneous screen space with NP float attributes to interpolate.
template <int NP>
struct tri_vertex {
  hom4 h;
  std::array<float, static_cast<std::size_t>(NP)> a;
};

/// Twice the signed screen area, oriented so that a triangle counter-clockwise on the screen
/// (= seen from its front, since the screen shows what the eye sees) is positive. Screen y
/// points down, hence cross(v0 − v1, v2 − v1) rather than the y-up formula.
[[nodiscard]] inline double front_area2(double x0, double y0, double x1, double y1, double x2,
                                        double y2) {
  return (x0 - x1) * (y2 - y1) - (y0 - y1) * (x2 - x1);
}

/// Scan-converts one triangle whose vertices all have w > 0. For each covered pixel centre:
/// test(index, key) → bool (the depth test), and only when it passes are the attributes
/// interpolated and write(index, key, attributes, front) called (front: seen from its front).
template <bool CullBack, int NP, class Test, class Write>
inline void raster_screen_triangle(int width, int height, const tri_vertex<NP>& v0,
                                   const tri_vertex<NP>& v1, const tri_vertex<NP>& v2, Test&& test,
                                   Write&& write) {
  const tri_vertex<NP>* v[3] = {&v0, &v1, &v2};
  double sx[3], sy[3], key[3], q[3];
  for (int i = 0; i < 3; ++i) {
    q[i] = 1.0 / v[i]->h.w;
    sx[i] = v[i]->h.x * q[i];
    sy[i] = v[i]->h.y * q[i];
    key[i] = v[i]->h.k * q[i];
  }
  const double area2 = front_area2(sx[0], sy[0], sx[1], sy[1], sx[2], sy[2]);
  if (!(std::abs(area2) > 0)) return;  // zero area (or NaN): covers nothing
  const bool front = area2 > 0;
  if constexpr (CullBack)
    if (!front) return;
  const double orient = front ? 1.0 : -1.0;

  // Edge i is opposite vertex i: from a = v[i+1] to b = v[i+2]; E_i(p) = cross(p − a, b − a),
  // positive inside once multiplied by `orient`. Coefficients from the canonical endpoint order.
  double ea[3], eb[3], ec[3], sgn[3];
  bool top_left[3];
  for (int i = 0; i < 3; ++i) {
    int a = (i + 1) % 3, b = (i + 2) % 3;
    double s = orient;
    if (sx[b] < sx[a] || (sx[b] == sx[a] && sy[b] < sy[a])) {
      std::swap(a, b);
      s = -s;
    }
    // E(p) = (px − ax)(by − ay) − (py − ay)(bx − ax) = A·px + B·py + C
    ea[i] = sy[b] - sy[a];
    eb[i] = sx[a] - sx[b];
    ec[i] = sy[a] * (sx[b] - sx[a]) - sx[a] * (sy[b] - sy[a]);
    sgn[i] = s;
    // Top-left rule with the oriented gradient (s·A, s·B): a left edge has the inside towards
    // +x (A > 0); a top edge is horizontal with the inside below, towards +y (A = 0, B > 0).
    const double oa = s * ea[i], ob = s * eb[i];
    top_left[i] = oa > 0 || (oa == 0 && ob > 0);
  }

  const int i0 = first_centre_at_or_after(std::min({sx[0], sx[1], sx[2]}), width);
  const int i1 = last_centre_at_or_before(std::max({sx[0], sx[1], sx[2]}), width);
  const int j0 = first_centre_at_or_after(std::min({sy[0], sy[1], sy[2]}), height);
  const int j1 = last_centre_at_or_before(std::max({sy[0], sy[1], sy[2]}), height);
  if (i0 > i1 || j0 > j1) return;

  // key(p) = Σ E_i(p)·key_i / |area2|: an affine plane.
  const double inv_area = 1.0 / std::abs(area2);
  double kx = 0, ky = 0, k0 = 0;
  for (int i = 0; i < 3; ++i) {
    const double w = sgn[i] * key[i] * inv_area;
    kx += w * ea[i];
    ky += w * eb[i];
    k0 += w * ec[i];
  }

  for (int j = j0; j <= j1; ++j) {
    const double py = j + 0.5;
    const double row0 = eb[0] * py + ec[0], row1 = eb[1] * py + ec[1], row2 = eb[2] * py + ec[2];
    const double krow = ky * py + k0;
    const std::size_t row = static_cast<std::size_t>(j) * static_cast<std::size_t>(width);
    for (int i = i0; i <= i1; ++i) {
      const double px = i + 0.5;
      const double e0 = sgn[0] * (ea[0] * px + row0);
      const double e1 = sgn[1] * (ea[1] * px + row1);
      const double e2 = sgn[2] * (ea[2] * px + row2);
      const bool in0 = e0 > 0 || (e0 == 0 && top_left[0]);
      const bool in1 = e1 > 0 || (e1 == 0 && top_left[1]);
      const bool in2 = e2 > 0 || (e2 == 0 && top_left[2]);
      if (!(in0 && in1 && in2)) continue;
      const float k = static_cast<float>(kx * px + krow);
      if (!test(row + static_cast<std::size_t>(i), k)) continue;
      std::array<float, static_cast<std::size_t>(NP)> attr{};
      if constexpr (NP > 0) {
        // Perspective-correct: weights ∝ (screen barycentric)·(1/w).
        const double w0 = e0 * q[0], w1 = e1 * q[1], w2 = e2 * q[2];
        const double sum = w0 + w1 + w2;
        if (!(sum > 0)) continue;
        const float b0 = static_cast<float>(w0 / sum), b1 = static_cast<float>(w1 / sum),
                    b2 = static_cast<float>(w2 / sum);
        for (std::size_t n = 0; n < static_cast<std::size_t>(NP); ++n)
          attr[n] = b0 * v0.a[n] + b1 * v1.a[n] + b2 * v2.a[n];
      }
      write(row + static_cast<std::size_t>(i), k, attr, front);
    }
  }
}

/// Clips a triangle against w ≥ w_near (perspective) and scan-converts what is left.
/// The intersection on an edge is interpolated from its inside vertex towards its outside one,
/// the same in both triangles that share the edge, so clipped shared edges stay watertight.
template <bool CullBack, class Proj, int NP, class Test, class Write>
inline void raster_triangle(const Proj& pr, const std::array<tri_vertex<NP>, 3>& t, Test&& test,
                            Write&& write) {
  if constexpr (!Proj::perspective) {
    raster_screen_triangle<CullBack>(pr.width, pr.height, t[0], t[1], t[2], test, write);
  } else {
    const double wn = pr.w_near;
    const bool in[3] = {t[0].h.w >= wn, t[1].h.w >= wn, t[2].h.w >= wn};
    const int n_in = int(in[0]) + int(in[1]) + int(in[2]);
    if (n_in == 0) return;  // behind the near plane (or NaN)
    if (t[0].h.w >= pr.w_far && t[1].h.w >= pr.w_far && t[2].h.w >= pr.w_far) return;
    if (n_in == 3) {
      raster_screen_triangle<CullBack>(pr.width, pr.height, t[0], t[1], t[2], test, write);
      return;
    }
    const auto cut = [&](const tri_vertex<NP>& a, const tri_vertex<NP>& b) {  // a in, b out
      const double s = (wn - a.h.w) / (b.h.w - a.h.w);
      const float sf = static_cast<float>(s);
      tri_vertex<NP> r;
      r.h = {a.h.x + s * (b.h.x - a.h.x), a.h.y + s * (b.h.y - a.h.y), wn,
             a.h.k + s * (b.h.k - a.h.k)};
      for (std::size_t n = 0; n < static_cast<std::size_t>(NP); ++n)
        r.a[n] = a.a[n] + sf * (b.a[n] - a.a[n]);
      return r;
    };
    // Sutherland–Hodgman against one plane: at most 4 vertices, then a fan (keeps the winding).
    std::array<tri_vertex<NP>, 4> poly;
    int n = 0;
    for (int i = 0; i < 3; ++i) {
      const int k = (i + 1) % 3;
      if (in[i]) poly[static_cast<std::size_t>(n++)] = t[static_cast<std::size_t>(i)];
      if (in[i] && !in[k])
        poly[static_cast<std::size_t>(n++)] =
            cut(t[static_cast<std::size_t>(i)], t[static_cast<std::size_t>(k)]);
      else if (!in[i] && in[k])
        poly[static_cast<std::size_t>(n++)] =
            cut(t[static_cast<std::size_t>(k)], t[static_cast<std::size_t>(i)]);
    }
    for (int i = 1; i + 1 < n; ++i)
      raster_screen_triangle<CullBack>(pr.width, pr.height, poly[0],
                                       poly[static_cast<std::size_t>(i)],
                                       poly[static_cast<std::size_t>(i + 1)], test, write);
  }
}

// ---------------------------------------------------------------------------------------------
// Shading
// ---------------------------------------------------------------------------------------------

/// c·f rounded, f ∈ [0, 1].
[[nodiscard]] inline rgb8 scale_colour(rgb8 c, float f) {
  return {static_cast<std::uint8_t>(static_cast<float>(c.r) * f + 0.5f),
          static_cast<std::uint8_t>(static_cast<float>(c.g) * f + 0.5f),
          static_cast<std::uint8_t>(static_cast<float>(c.b) * f + 0.5f)};
}

/// Lambert: ambient + (1 − ambient)·max(0, n·l), clamped to [0, 1].
[[nodiscard]] inline float lambert(const vec3f& n, const vec3f& l, float ambient) {
  const float d = std::max(0.0f, n.dot(l));
  return std::clamp(ambient + (1 - ambient) * d, 0.0f, 1.0f);
}

/// Rounds and clamps a colour channel interpolated in float (NaN → 0).
[[nodiscard]] inline std::uint8_t to_channel(float x) {
  if (!(x > 0)) return 0;
  if (x >= 255) return 255;
  return static_cast<std::uint8_t>(x + 0.5f);
}

}  // namespace pbr_lod::detail
