// Quantised normals (Pajarola 2003 §5, Fig. 9): table layout, round trips, the nearest-
// direction search against brute force, and the angular error over 10⁶ random normals (the
// numbers quoted in docs/normal-quantization.md).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <span>
#include <thread>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/normal_quantization.hpp"

namespace pbr_lod {
namespace {

constexpr double rad_to_deg = 180.0 / std::numbers::pi;

/// Angle in degrees between n (any length) and unit d, in double; accurate for tiny angles.
double angle_deg(const vec3f& n, const vec3f& d) {
  const vec3d a = n.cast<double>().normalized(), b = d.cast<double>();
  return std::atan2(a.cross(b).norm(), a.dot(b)) * rad_to_deg;
}

/// Uniform random unit vectors: a normalised isotropic Gaussian. Seeded, so the statistics in
/// the docs are reproducible; random input is the right test because a quantiser's error is a
/// property of the whole sphere, not of a few chosen directions.
std::vector<vec3f> random_normals(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g;
  std::vector<vec3f> out(n);
  for (auto& v : out) {
    vec3d d;
    do d = vec3d(g(rng), g(rng), g(rng));
    while (d.squaredNorm() < 1e-12);
    v = d.normalized().cast<float>();
  }
  return out;
}

/// The same double dot product encode() maximises, for a code's direction.
double dot_with(const vec3f& n, const vec3f& d) {
  const double x = n.x(), y = n.y(), z = n.z();
  const double inv = 1.0 / std::sqrt(x * x + y * y + z * z);
  return std::abs(x) * inv * std::abs(double(d.x())) + std::abs(y) * inv * std::abs(double(d.y())) +
         std::abs(z) * inv * std::abs(double(d.z()));
}

// k is the largest integer with k(k+1)/2 ≤ 2^(q−3): the paper's q = 12 has 31 latitude steps
// and 496 directions per octant (§7, Fig. 13).
TEST(NormalQuantizer, TableSizes) {
  const struct { int q, k; } cases[] = {{6, 3}, {9, 10}, {12, 31}, {13, 44}, {16, 127}, {24, 2047}};
  for (const auto& c : cases) {
    const normal_quantizer nq(c.q);
    EXPECT_EQ(nq.bits(), c.q);
    EXPECT_EQ(nq.latitude_steps(), c.k) << "q = " << c.q;
    EXPECT_EQ(nq.size(), 8u * std::size_t(c.k) * std::size_t(c.k + 1) / 2);
    EXPECT_LE(nq.size(), std::size_t{1} << c.q);
  }
  EXPECT_EQ(normal_quantizer(12).size(), 8u * 496u);
}

TEST(NormalQuantizer, BitsOutOfRangeThrow) {
  EXPECT_THROW(normal_quantizer(5), InvalidArgument);
  EXPECT_THROW(normal_quantizer(25), InvalidArgument);
  EXPECT_THROW(normal_quantizer(-1), InvalidArgument);
  EXPECT_NO_THROW(normal_quantizer(normal_quantizer::min_bits));
}

// shared(): one instance per q up to max_shared_bits, the same from every thread, behaving as a
// fresh quantizer; above that a fresh one each time; bad bits throw as the constructor does.
TEST(NormalQuantizer, SharedInstances) {
  std::vector<std::shared_ptr<const normal_quantizer>> got(8);
  {
    std::vector<std::thread> pool;
    for (std::size_t t = 0; t < got.size(); ++t)
      pool.emplace_back([&got, t] { got[t] = normal_quantizer::shared(16); });
    for (auto& th : pool) th.join();
  }
  for (const auto& g : got) EXPECT_EQ(g.get(), got[0].get());
  EXPECT_NE(normal_quantizer::shared(12).get(), got[0].get());
  EXPECT_EQ(normal_quantizer::shared(12)->bits(), 12);
  const normal_quantizer fresh(16);
  for (const auto& n : random_normals(10000, 7)) EXPECT_EQ(got[0]->encode(n), fresh.encode(n));
  const int above = normal_quantizer::max_shared_bits + 1;
  EXPECT_NE(normal_quantizer::shared(above).get(), normal_quantizer::shared(above).get());
  EXPECT_THROW((void)normal_quantizer::shared(5), InvalidArgument);
  EXPECT_THROW((void)normal_quantizer::shared(25), InvalidArgument);
}

// Every valid code decodes to a unit vector in its own octant (no component is zero: no table
// direction lies on an octant boundary), which encodes back to the same code, and negate()
// gives exactly the opposite direction.
TEST(NormalQuantizer, EveryCodeRoundTrips) {
  for (const int q : {6, 9, 12, 16}) {
    const normal_quantizer nq(q);
    std::size_t valid = 0;
    for (std::uint32_t code = 0; code < (1u << q); ++code) {
      if (!nq.valid(code)) {
        EXPECT_THROW((void)nq.decode(code), InvalidArgument);
        continue;
      }
      ++valid;
      const vec3f d = nq.decode(code);
      ASSERT_NEAR(d.norm(), 1.0f, 1e-6f);
      const std::uint32_t octant = code >> (q - 3);
      EXPECT_EQ(d.x() < 0, (octant & 1u) != 0);
      EXPECT_EQ(d.y() < 0, (octant & 2u) != 0);
      EXPECT_EQ(d.z() < 0, (octant & 4u) != 0);
      EXPECT_NE(d.x() * d.y() * d.z(), 0.0f);
      ASSERT_EQ(nq.encode(d), code) << "q = " << q;
      EXPECT_EQ(nq.decode(nq.negate(code)), vec3f(-d));
    }
    EXPECT_EQ(valid, nq.size());
  }
}

TEST(NormalQuantizer, InvalidCodesThrow) {
  const normal_quantizer nq(12);  // 496 of 512 indices per octant are used
  EXPECT_THROW((void)nq.decode(496), InvalidArgument);
  EXPECT_THROW((void)nq.decode((3u << 9) | 511u), InvalidArgument);
  EXPECT_THROW((void)nq.decode(1u << 12), InvalidArgument);
  EXPECT_THROW((void)nq.negate(1u << 12), InvalidArgument);
  EXPECT_NO_THROW((void)nq.decode((7u << 9) | 495u));
}

// Zero, NaN and Inf have no direction: they get the code of +z, which is 0 (row 0 of octant 0
// is the sample nearest the pole). −0.0 is "not negative", so −0 components pick octant 0 too.
TEST(NormalQuantizer, DegenerateInputsEncodeAsPlusZ) {
  const normal_quantizer nq(12);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  EXPECT_EQ(nq.encode(vec3f::UnitZ()), 0u);
  EXPECT_EQ(nq.encode(vec3f::Zero()), 0u);
  EXPECT_EQ(nq.encode(vec3f(nan, 0, 1)), 0u);
  EXPECT_EQ(nq.encode(vec3f(0, inf, 0)), 0u);
  EXPECT_EQ(nq.encode(vec3f(-inf, -inf, -inf)), 0u);
  EXPECT_EQ(nq.encode(vec3f(-0.0f, -0.0f, 1)), 0u);
  // Tiny and huge (but finite) vectors are normalised in double: same code as the unit vector.
  const vec3f n = vec3f(0.3f, -0.5f, 0.8f).normalized();
  EXPECT_EQ(nq.encode(n * 1e-30f), nq.encode(n));
  EXPECT_EQ(nq.encode(n * 1e30f), nq.encode(n));
  EXPECT_EQ(nq.encode(vec3f(1e-45f, 0, 0)), nq.encode(vec3f::UnitX()));  // a denormal
}

// encode() searches a few rows and columns around the rounded latitude/longitude; brute force
// over all 2^q codes (every octant, not just the folded one) must find nothing nearer.
void expect_nearest(const normal_quantizer& nq, const std::vector<vec3f>& normals) {
  // Plain arrays and loops: this is ~10⁸ dot products, and must stay quick in Debug builds.
  std::vector<double> tx, ty, tz;
  for (std::uint32_t code = 0; code < (1u << nq.bits()); ++code)
    if (nq.valid(code)) {
      const vec3f d = nq.decode(code);
      tx.push_back(d.x());
      ty.push_back(d.y());
      tz.push_back(d.z());
    }
  for (const auto& n : normals) {
    const vec3d nd = n.cast<double>().normalized();
    const double x = nd.x(), y = nd.y(), z = nd.z();
    double best = -2;
    for (std::size_t t = 0; t < tx.size(); ++t)
      best = std::max(best, x * tx[t] + y * ty[t] + z * tz[t]);
    const vec3f got = nq.decode(nq.encode(n));
    // encode's own arithmetic (folded, same expression) against the brute-force maximum; the
    // 1e-15 only absorbs the different rounding of the two normalisations.
    ASSERT_GE(dot_with(n, got), best - 1e-15)
        << "q = " << nq.bits() << ", n = " << n.transpose() << ": " << angle_deg(n, got)
        << "° vs brute force " << std::acos(std::min(1.0, best)) * rad_to_deg;
  }
}

TEST(NormalQuantizer, EncodeFindsTheNearestDirection) {
  for (const auto& [q, count] :
       {std::pair{6, 20000}, {9, 20000}, {12, 20000}, {13, 5000}, {16, 1500}}) {
    const normal_quantizer nq(q);
    expect_nearest(nq, random_normals(std::size_t(count), 7 + std::uint64_t(q)));
  }
}

// The hard places for a row/column search: poles, axes, octant boundaries (including exact
// zeros), the diagonal, and directions exactly on band edges and cell edges.
TEST(NormalQuantizer, EncodeFindsTheNearestOnBoundaries) {
  for (const int q : {6, 9, 12, 16}) {
    const normal_quantizer nq(q);
    const int k = nq.latitude_steps();
    std::vector<vec3f> special = {vec3f::UnitX(),  vec3f::UnitY(),   vec3f::UnitZ(),
                                  -vec3f::UnitX(), -vec3f::UnitY(),  -vec3f::UnitZ(),
                                  vec3f(1, 1, 0),  vec3f(1, 0, 1),   vec3f(0, -1, 1),
                                  vec3f(1, 1, 1),  vec3f(-1, 1, -1), vec3f(1e-7f, 1e-7f, 1)};
    const double hp = std::numbers::pi / 2;
    for (int i = 0; i < k; ++i) {
      const double x = double(i + 1) * (i + 2) / (double(k) * (k + 1));
      const double b = 2 * std::asin(std::sqrt(std::min(1.0, x / 2)));  // band edge
      for (int j = 0; j <= i + 1; ++j) {
        const double phi = hp * j / (i + 1);  // cell edge
        for (const double th : {b, hp * i / std::max(1, k - 1)})
          special.emplace_back(float(std::sin(th) * std::cos(phi)),
                               float(std::sin(th) * std::sin(phi)), float(std::cos(th)));
      }
      if (special.size() > 3000) break;
    }
    expect_nearest(nq, special);
  }
}

// encode() compares a row's neighbouring cell only when the longitude lies within a margin of
// the cell edge (the float table makes the two dot products compete there). Directions just off
// cell edges, by 10⁻⁶ to 10⁻² of a cell on either side, at the rows' own latitudes and on band
// edges, must still get the brute-force nearest; at q ≥ 19 the margin is the whole cell.
TEST(NormalQuantizer, EncodeFindsTheNearestJustOffCellEdges) {
  for (const auto& [q, wanted] : {std::pair{12, 1500}, {16, 1500}, {18, 400}, {20, 120}}) {
    const normal_quantizer nq(q);
    const int k = nq.latitude_steps();
    const double hp = std::numbers::pi / 2;
    const auto edge = [k](int i) {
      if (i < 0) return 0.0;
      const double x = double(i + 1) * (i + 2) / (double(k) * (k + 1));
      return 2 * std::asin(std::sqrt(std::min(1.0, x / 2)));
    };
    std::vector<vec3f> near_edges;
    std::mt19937_64 rng{static_cast<std::uint64_t>(q)};
    std::uniform_int_distribution<int> row(0, k - 1);
    while (near_edges.size() < std::size_t(wanted)) {
      const int i = row(rng);
      if (i == 0) continue;  // one cell: no edge inside the row
      const int j = 1 + int(rng() % std::uint64_t(i));
      for (const double off : {-1e-2, -1e-3, -1e-4, -1e-5, -1e-6, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2}) {
        const double phi = hp * (j + off) / (i + 1);
        for (const double th : {0.5 * (edge(i - 1) + edge(i)), edge(i)})
          near_edges.emplace_back(float(std::sin(th) * std::cos(phi)),
                                  float(std::sin(th) * std::sin(phi)), float(std::cos(th)));
      }
    }
    expect_nearest(nq, near_edges);
  }
}

// Up to q = 16 encode() looks the folded normal up in a grid over its octahedral coordinates
// (u, v) = (|x|, |y|)/(|x| + |y| + |z|) and compares only the cell's candidates. The hard places
// for that are the cell edges and corners (rounding can put a normal in the neighbouring cell)
// and the octant's edges u + v = 1, u = 0, v = 0: directions exactly on them and 10⁻¹² … 10⁻⁶ of
// a cell off, at every q the grid serves, must get the brute-force nearest.
TEST(NormalQuantizer, EncodeFindsTheNearestOnCandidateGridEdges) {
  for (int q = normal_quantizer::min_bits; q <= 17; ++q) {
    const normal_quantizer nq(q);
    const std::uint32_t g = nq.candidate_grid();
    if (q > 16) {
      EXPECT_EQ(g, 0u) << "q = " << q;
      continue;
    }
    ASSERT_GE(g, 2u * std::uint32_t(nq.latitude_steps())) << "q = " << q;
    ASSERT_EQ(g & (g - 1), 0u) << "q = " << q;
    std::vector<vec3f> hard;
    std::mt19937_64 rng{static_cast<std::uint64_t>(q) + 5};
    std::uniform_int_distribution<std::uint32_t> cell(0, g);
    std::uniform_int_distribution<int> octant(0, 7);
    const auto add = [&](double u, double v) {
      if (u < 0 || v < 0 || u + v > 1) return;
      const int o = octant(rng);
      hard.emplace_back(float((o & 1) ? -u : u), float((o & 2) ? -v : v),
                        float((o & 4) ? -(1 - u - v) : 1 - u - v));
    };
    while (hard.size() < 1500) {
      const std::uint32_t a = cell(rng), b = cell(rng);
      for (const double off : {0.0, 1e-12, -1e-12, 1e-9, -1e-9, 1e-6, -1e-6}) {
        const double u = (a + off) / g, v = (b + off) / g;
        add(u, v);                    // a cell corner
        add(u, (b + 0.37) / g);       // a vertical cell edge
        add((a + 0.61) / g, v);       // a horizontal one
        add(u, 1 - u - off / g);      // the octant's edge u + v = 1
        add(0.0 + std::abs(off), v);  // u = 0 (x = 0, then just off it)
      }
    }
    expect_nearest(nq, hard);
  }
}

// Between two latitude rows lies a curve where the best entry of one row and the best of the
// next are equally near; the row walk prunes a row by a bound on its dot products, which must
// allow for the float entries not being exactly unit length. Directions on that curve (found by
// bisection in θ at random longitudes), and just off it, must get the brute-force nearest. With
// the bound's float-length term removed, q = 16 fails here (as 2 of 2.4 M random normals did).
TEST(NormalQuantizer, EncodeFindsTheNearestWhereTwoRowsTie) {
  for (const auto& [q, wanted] : {std::pair{12, 600}, {16, 600}}) {
    const normal_quantizer nq(q);
    const int k = nq.latitude_steps();
    const double hp = std::numbers::pi / 2;
    const auto dir = [](double th, double phi) {
      return vec3d(std::sin(th) * std::cos(phi), std::sin(th) * std::sin(phi), std::cos(th));
    };
    // The best dot product of row i's entries with the unit direction (θ, φ), all in double.
    const auto row_best = [&](int i, double th, double phi) {
      const vec3d x = dir(th, phi);
      double best = -2;
      for (int j = 0; j <= i; ++j)
        best = std::max(best, x.dot(nq.decode(std::uint32_t(i * (i + 1) / 2 + j)).cast<double>()));
      return best;
    };
    const auto row_theta = [&](int i) {
      return std::acos(double(nq.decode(std::uint32_t(i * (i + 1) / 2)).z()));
    };
    std::vector<vec3f> ties;
    std::mt19937_64 rng{static_cast<std::uint64_t>(q) + 99};
    std::uniform_int_distribution<int> row(0, k - 2);
    std::uniform_real_distribution<double> longitude(0, hp);
    while (ties.size() < std::size_t(wanted)) {
      const int i = row(rng);
      const double phi = longitude(rng);
      double lo = row_theta(i), hi = row_theta(i + 1);  // row i nearer at lo, row i + 1 at hi
      for (int it = 0; it < 60; ++it) {
        const double mid = 0.5 * (lo + hi);
        (row_best(i, mid, phi) >= row_best(i + 1, mid, phi) ? lo : hi) = mid;
      }
      for (const double off : {-1e-7, 0.0, 1e-7}) ties.push_back(dir(lo + off, phi).cast<float>());
    }
    expect_nearest(nq, ties);
  }
}

struct error_stats {
  double worst = 0, mean = 0;
};

error_stats measure(const normal_quantizer& nq, const std::vector<vec3f>& normals) {
  error_stats s;
  for (const auto& n : normals) {
    const double e = angle_deg(n, nq.decode(nq.encode(n)));
    s.worst = std::max(s.worst, e);
    s.mean += e;
  }
  s.mean /= double(normals.size());
  return s;
}

// encode(span, span) loads the cells of a run of normals before it searches any: the codes must
// be encode()'s, one by one, for every table (with a candidate grid, q ≤ 16, and without), for
// lengths that end inside a run, and for the inputs that skip the grid (zero, NaN, ±Inf) mixed
// in among the others.
TEST(NormalQuantizer, EncodeOverASpanGivesTheSameCodes) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  auto normals = random_normals(1000, 11);
  for (std::size_t i = 0; i < normals.size(); i += 7) normals[i] *= 1e-30f;  // tiny, not unit
  for (std::size_t i = 3; i < normals.size(); i += 97) normals[i] = vec3f::Zero();
  for (std::size_t i = 5; i < normals.size(); i += 89) normals[i] = vec3f(nan, 0, 1);
  for (std::size_t i = 9; i < normals.size(); i += 83) normals[i] = vec3f(-inf, 0, 0);
  normals[1] = vec3f(-0.0f, -0.0f, -1);
  normals[2] = vec3f(1e-45f, 0, 0);
  for (const int q : {6, 12, 16, 17, 20}) {
    const normal_quantizer nq(q);
    for (const std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{31}, std::size_t{32},
                                std::size_t{33}, normals.size()}) {
      std::vector<std::uint32_t> codes(n, 0xDEADBEEF);
      nq.encode(std::span(normals.data(), n), codes);
      for (std::size_t i = 0; i < n; ++i)
        ASSERT_EQ(codes[i], nq.encode(normals[i])) << "q = " << q << ", run of " << n << ", normal "
                                                   << i << " = " << normals[i].transpose();
    }
    std::vector<std::uint32_t> small(3);
    EXPECT_THROW(nq.encode(std::span(normals.data(), 4), small), InvalidArgument) << "q = " << q;
  }
}

// Worst and mean angular error over 10⁶ random unit normals. The worst must stay under the
// guaranteed bound, and the bound must be tight enough to be useful (within 20 %). The
// expected values are the measured ones (docs/normal-quantization.md) with a little headroom;
// for comparison the paper's literal layout gives 2.63° / 1.31° at q = 12.
TEST(NormalQuantizer, AngularErrorOverAMillionNormals) {
  const auto normals = random_normals(1'000'000, 42);
  const struct {
    int q;
    double worst_below, mean_below;
  } cases[] = {{9, 7.2, 3.75}, {12, 2.40, 1.25}, {13, 1.70, 0.88}, {16, 0.60, 0.31}};
  for (const auto& c : cases) {
    const normal_quantizer nq(c.q);
    const error_stats s = measure(nq, normals);
    std::printf("q = %2d  k = %3d  directions = %6zu  worst = %.4f°  mean = %.4f°  bound = %.4f°\n",
                c.q, nq.latitude_steps(), nq.size(), s.worst, s.mean, nq.max_error_degrees());
    EXPECT_LE(s.worst, nq.max_error_degrees()) << "q = " << c.q;
    EXPECT_LE(nq.max_error_degrees(), 1.2 * s.worst) << "q = " << c.q;
    EXPECT_LT(s.worst, c.worst_below) << "q = " << c.q;
    EXPECT_LT(s.mean, c.mean_below) << "q = " << c.q;
  }
}

// The bound for q = 24 (too large a table for the million-normal run above) still holds on a
// smaller random sample.
TEST(NormalQuantizer, BoundHoldsAtTwentyFourBits) {
  const normal_quantizer nq(24);
  const error_stats s = measure(nq, random_normals(100'000, 3));
  std::printf("q = 24  k = %d  worst = %.4f°  mean = %.4f°  bound = %.4f°\n", nq.latitude_steps(),
              s.worst, s.mean, nq.max_error_degrees());
  EXPECT_LE(s.worst, nq.max_error_degrees());
  EXPECT_LT(nq.max_error_degrees(), 0.05);
}

}  // namespace
}  // namespace pbr_lod
