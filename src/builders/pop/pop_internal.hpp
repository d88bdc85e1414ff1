// pbr_lod — what the POP builder (pop_build.cpp) and its file format (pop_io.cpp) share: the
// quantised codes of §3.5 (QSplat-style node spheres, 2-bit normal cones, RGB 565, the 16-bit
// vertex grid) and the file's size accounting. Build and load use these same expressions, so a
// loaded tree holds bit-identical values. Internal to src/builders.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>

#include "pbr_lod/builders/pop.hpp"

namespace pbr_lod::detail::pop_internal {

/// "No index": no parent, no neighbour, no face.
inline constexpr std::uint32_t none = std::numeric_limits<std::uint32_t>::max();

/// The smallest float ≥ x (x ≥ 0): stored radii never shrink below what was computed in double.
inline float round_up(double x) {
  float f = static_cast<float>(x);
  if (static_cast<double>(f) < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

// ---- QSplat-style node quantisation (§3.5; pop_options::quantise_nodes) ----------------------
// A child's centre is its parent's centre plus the parent's radius times one of 13 offsets per
// axis, (i − 6)/6 for i = 0..12; its radius is the parent's times (j + 1)/13, j = 0..12. Code 6
// on every axis with j = 12 is the parent's sphere itself (offset 0, factor exactly 1), which
// holds any child: every node has a valid code. The float expressions below are the only ones
// build and load use, so both derive bit-identical spheres.
inline constexpr std::uint16_t sphere_code_parent = 6 | 6 << 4 | 6 << 8 | 12 << 12;
// The levels as tables: the same correctly rounded float quotients, without a division per use
// (quantise_sphere() tried up to eight centres, each with four of them).
inline constexpr std::array<float, 16> centre_levels = [] {
  std::array<float, 16> t{};
  for (int i = 0; i < 16; ++i) t[static_cast<std::size_t>(i)] = static_cast<float>(i - 6) / 6.0f;
  return t;
}();
inline constexpr std::array<float, 16> radius_levels = [] {
  std::array<float, 16> t{};
  for (int j = 0; j < 16; ++j) t[static_cast<std::size_t>(j)] = static_cast<float>(j + 1) / 13.0f;
  return t;
}();
inline float centre_level(unsigned i) {
  return centre_levels[i & 15u];
}
inline float radius_level(unsigned j) {
  return radius_levels[j & 15u];
}
inline void dequantise_sphere(const vec3f& pc, float pr, std::uint16_t code, vec3f& c, float& r) {
  for (unsigned k = 0; k < 3; ++k)
    c[static_cast<int>(k)] = pc[static_cast<int>(k)] + pr * centre_level((code >> (4 * k)) & 15u);
  r = pr * radius_level(code >> 12);
}
/// The code whose sphere holds (c, r) and lies inside the parent (pc, pr), with the smallest
/// radius among the centre codes tried; checked in double on the dequantised float values, so
/// the stored sphere is conservative however the float arithmetic rounds. The nearest centre
/// code is tried first (radius levels are pr/13 apart, so it almost always gives the smallest
/// radius); the other corners of the centre's grid cell only when it fails; the parent's sphere
/// when all do.
inline std::uint16_t quantise_sphere(const vec3f& pc, float pr, const vec3f& c, float r) {
  if (!(pr > 0)) return sphere_code_parent;
  const vec3d cd = c.cast<double>(), pcd = pc.cast<double>();
  // A radius above 12/13 of the parent's fits no level below 12 (pr·(j + 1)/13 ≤ 12/13·pr), and
  // level 12 (pr itself) fits only at the parent's own centre: every other centre code lies
  // ≥ pr/6 off it (≥ pr/7 after float rounding while |pc| ≤ 2¹⁶·pr), leaving at most 6/7·pr of
  // room. The loop below would return the parent's code whatever it tried (7.6 % of the nodes
  // of the 2 M-triangle grid, a third of its tries).
  if (static_cast<double>(r) > (12.0 / 13.0) * (1 + 1e-6) * static_cast<double>(pr) &&
      pcd.cwiseAbs().maxCoeff() <= 65536.0 * static_cast<double>(pr))
    return sphere_code_parent;
  // Per axis, the two centre codes in the order they are tried (nearest first) and, for each,
  // the squared distances along that axis from the coded centre to the child's centre and to
  // the parent's: every try below then sums three of them (as Eigen's norm() does, x + y then
  // + z, so the results are those of the vector expressions, bit for bit).
  std::array<std::array<unsigned, 2>, 3> cand{};
  std::array<std::array<double, 2>, 3> to_child{}, to_parent{};
  for (int k = 0; k < 3; ++k) {
    const auto ks = static_cast<std::size_t>(k);
    // Without a branch: which of floor(t) and ceil(t) is nearer is a coin toss, and its
    // mispredictions kept each node from overlapping the next. std::max, then std::min:
    // std::clamp's value for a finite t, as maxsd and minsd.
    const double t = std::min(std::max(6.0 + 6.0 * (cd[k] - pcd[k]) / pr, 0.0), 12.0);
    const auto lo = static_cast<unsigned>(t);                   // floor: t ≥ 0
    const unsigned up = static_cast<double>(lo) < t ? 1u : 0u;  // ceil(t) = lo + up
    const unsigned far_half = t - lo > 0.5 ? 1u : 0u;           // ceil(t) is the nearer
    cand[ks] = {lo + far_half, lo + (up & (far_half ^ 1u))};    // nearest first
  }
  const auto distances = [&](std::size_t s) {
    for (int k = 0; k < 3; ++k) {
      const auto ks = static_cast<std::size_t>(k);
      // dequantise_sphere()'s centre coordinate, in float as there
      const float q = pc[k] + pr * centre_level(cand[ks][s]);
      const double dc = cd[k] - static_cast<double>(q), dp = static_cast<double>(q) - pcd[k];
      to_child[ks][s] = dc * dc;
      to_parent[ks][s] = dp * dp;
    }
  };
  // The smallest radius level j with pr·level(j) ≥ need: levels grow with j, so the two walks
  // below end there from any first guess (13·need/pr, by a multiplication instead of a division).
  const double guess_scale = 13.0 / static_cast<double>(pr);
  // Try m: bit k of m picks axis k's candidate. The code, or `none_held` (no code has 15 in a
  // field).
  constexpr std::uint16_t none_held = 0xFFFF;
  const auto attempt = [&](unsigned m) -> std::uint16_t {
    const unsigned sx = m & 1u, sy = (m >> 1) & 1u, sz = (m >> 2) & 1u;
    const double need =
        std::sqrt(to_child[0][sx] + to_child[1][sy] + to_child[2][sz]) + static_cast<double>(r);
    const double room =
        static_cast<double>(pr) - std::sqrt(to_parent[0][sx] + to_parent[1][sy] + to_parent[2][sz]);
    if (need > room) return none_held;  // no level is both ≥ need and ≤ room
    const double g = need * guess_scale;
    unsigned j = g >= 12.0 ? 12u : g > 0.0 ? static_cast<unsigned>(g) : 0u;
    while (j < 12 && static_cast<double>(pr * radius_level(j)) < need) ++j;
    while (j > 0 && static_cast<double>(pr * radius_level(j - 1)) >= need) --j;
    const double rq = static_cast<double>(pr * radius_level(j));
    if (rq < need || rq > room) return none_held;
    return static_cast<std::uint16_t>(cand[0][sx] | cand[1][sy] << 4 | cand[2][sz] << 8 | j << 12);
  };
  // The nearest code first, before the other candidates are set up: it holds 82 % of the
  // Buddha's nodes.
  distances(0);
  if (const std::uint16_t code = attempt(0); code != none_held) return code;
  distances(1);
  for (unsigned m = 1; m < 8; ++m)
    if (const std::uint16_t code = attempt(m); code != none_held) return code;
  return sphere_code_parent;
}
/// 2-bit normal cones (QSplat): half-angles asin(1/16), asin(4/16), asin(9/16), π (no culling);
/// a cone is rounded up to the next level.
inline float cone_level(unsigned k) {
  static const std::array<float, 4> levels = {
      round_up(std::asin(1.0 / 16)), round_up(std::asin(4.0 / 16)), round_up(std::asin(9.0 / 16)),
      std::numbers::pi_v<float>};
  return levels[k];
}
/// The smallest level k with angle ≤ level(k), or 3: the levels grow, so k is the number of
/// levels below the angle, counted without a branch.
inline unsigned cone_code(float angle) {
  unsigned k = 0;
  for (unsigned i = 0; i < 3; ++i) k += cone_level(i) < angle ? 1u : 0u;
  return k;
}
/// Quantised cones from cosines, without acos. The stored cone of a node is the smallest level
/// k with acos(c) + 1e-6 ≤ level(k) for the cosine c of its widest face (leaf), or with
/// acos(c_j) + level(code_j) + 1e-6 ≤ level(k) for every child j (inner node), as the angles
/// would give (round_up() to float cannot cross a float level). acos is decreasing, so each
/// test is c ≥ cos(level(k) − 1e-6) or c_j ≥ cos(level(k) − level(code_j) − 1e-6); a negative
/// angle there means no cosine passes. The thresholds are raised by 1e-12, so a cosine within
/// rounding of one gets the larger level (still a bounding cone), never a smaller one. Level 3
/// (π) holds everything.
struct cone_thresholds {
  std::array<double, 3> face;
  std::array<std::array<double, 4>, 3> child;  // [k][code of the child's cone]
};
inline const cone_thresholds& cone_table() {
  static const cone_thresholds t = [] {
    cone_thresholds c{};
    const auto threshold = [](double angle) { return angle < 0 ? 2.0 : std::cos(angle) + 1e-12; };
    for (unsigned k = 0; k < 3; ++k) {
      c.face[k] = threshold(static_cast<double>(cone_level(k)) - 1e-6);
      for (unsigned j = 0; j < 4; ++j)
        c.child[k][j] = threshold(static_cast<double>(cone_level(k)) -
                                  static_cast<double>(cone_level(j)) - 1e-6);
    }
    return c;
  }();
  return t;
}
/// RGB 565 (QSplat's 16-bit colour): encode keeps the top bits, decode replicates them, so
/// encode(decode(x)) == x.
inline std::uint16_t rgb565(rgb8 c) {
  return static_cast<std::uint16_t>((c.r >> 3) << 11 | (c.g >> 2) << 5 | (c.b >> 3));
}
inline rgb8 from565(std::uint16_t v) {
  const unsigned r = (v >> 11) & 31u, g = (v >> 5) & 63u, b = v & 31u;
  return {static_cast<std::uint8_t>(r << 3 | r >> 2), static_cast<std::uint8_t>(g << 2 | g >> 4),
          static_cast<std::uint8_t>(b << 3 | b >> 2)};
}

/// clamp(lround(s), 0, 65535) without the library call (a visible part of the vertex pass):
/// the same value for every double s, NaN included (0). Below 65535 the truncation is exact and
/// s − ⌊s⌋ is exact, so halves round away from zero as lround does.
inline std::uint16_t round_to_u16(double s) {
  if (!(s > 0)) return 0;
  if (s >= 65535) return 65535;
  const auto i = static_cast<std::uint32_t>(s);
  return static_cast<std::uint16_t>(i + (s - static_cast<double>(i) >= 0.5 ? 1u : 0u));
}
/// Vertex position from its 16-bit code (§3.5). The same expression in build and load, so a
/// loaded tree holds bit-identical positions.
inline vec3f dequantise(const std::array<std::uint16_t, 3>& q, const vec3f& mn, const vec3f& step) {
  return {mn.x() + static_cast<float>(q[0]) * step.x(),
          mn.y() + static_cast<float>(q[1]) * step.y(),
          mn.z() + static_cast<float>(q[2]) * step.z()};
}

/// The file's size by part, into d.stats (pop_io.cpp, with the format's record sizes).
void set_file_stats(pop_data& d, std::size_t size);

}  // namespace pbr_lod::detail::pop_internal
