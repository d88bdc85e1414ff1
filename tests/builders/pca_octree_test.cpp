// Tests of the hierarchical PCA octree (Kalaiah & Varshney 2003): the statistics of §3 and the
// quantisation of §3.1. The file and hard inputs are in pca_octree_storage_test.cpp, rendering
// and the Fig. 6 cut in pca_octree_render_test.cpp (three TUs so that each compiles in well under
// a minute under ASan). Each case says why its expectation holds. Random input is seeded
// (std::mt19937 with a fixed seed): the statistics are then fixed numbers, and the tolerances are
// several standard errors wide.
#include "builders/pca_octree_test_util.hpp"
#include "pbr_lod/core/normal_quantization.hpp"

namespace pbr_lod {
namespace pca_test {
namespace {

// ---- §3: the statistics ---------------------------------------------------------------------

// Points drawn from a known trivariate Gaussian: the sample mean is within a few σ/√n of μ,
// the sample standard deviations within a few % (standard error σ/√(2n) ≈ 0.5 % at n = 20000),
// and the principal axes within a degree (their σ are well separated: 0.5, 0.2, 0.05).
TEST(pca_octree, PositionPcaRecoversGaussian) {
  std::mt19937 rng(42);
  const mat3d R = random_rotation(rng);
  const vec3d mu(1, -2, 3), sigma(0.5, 0.2, 0.05);
  std::normal_distribution<double> g;
  std::vector<vec3d> p(20000);
  for (auto& q : p) q = mu + R * vec3d(sigma.x() * g(rng), sigma.y() * g(rng), sigma.z() * g(rng));
  const auto r = detail::pca_positions(p.data(), p.size(), R.col(2));
  EXPECT_EQ(r.zero_variances, 0);
  EXPECT_LT((r.mean - mu).norm(), 4 * 0.5 / std::sqrt(20000.0));
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(r.sigma[k] / sigma[k], 1.0, 0.03) << "sigma " << k;
    EXPECT_LT(axis_deg(r.frame.col(k), R.col(k)), 1.0) << "axis " << k;
  }
  expect_orthonormal(r.frame, "gaussian frame");
  EXPECT_GE(r.frame.col(2).dot(R.col(2)), 0) << "f³ turned towards the mean normal";
}

// Normals drawn as Gaussian points of the tangent plane at a known mean direction, wrapped onto
// the sphere (the inverse of the §3 unwrap): the normal PCA recovers σ_n, the mean normal and
// the ellipse's major axis. (The Euclidean mean of the wrapped normals is the centre direction
// by symmetry.)
TEST(pca_octree, NormalPcaRecoversGaussianOnTheSphere) {
  std::mt19937 rng(43);
  const mat3d F = random_rotation(rng);
  const vec2d sigma(0.2, 0.05);
  std::normal_distribution<double> g;
  std::vector<vec3f> n(20000);
  for (auto& m : n)
    m = detail::wrap_normal(F, vec2d(sigma.x() * g(rng), sigma.y() * g(rng))).cast<float>();
  const auto r = detail::pca_normals(n.data(), n.size(), vec3d::UnitZ());
  EXPECT_LT(angle_deg(r.frame.col(2), F.col(2)), 0.5);
  EXPECT_LT(axis_deg(r.frame.col(0), F.col(0)), 1.5);
  EXPECT_NEAR(r.sigma.x() / sigma.x(), 1.0, 0.03);
  EXPECT_NEAR(r.sigma.y() / sigma.y(), 1.0, 0.03);
  expect_orthonormal(r.frame, "normal frame");
}

// The same through the builder: a single leaf (leaf_size above the count) without quantisation
// holds the position, normal and colour statistics of all its points. Colours are rounded to
// 8 bits, which adds 1/(12·255²) to each variance — negligible against σ_c² here.
TEST(pca_octree, RootOfOneLeafHoldsTheStatistics) {
  std::mt19937 rng(44);
  const mat3d R = random_rotation(rng), C = random_rotation(rng);
  const vec3d sp(2, 1, 0.1), sc(0.1, 0.05, 0.03), mc(0.5, 0.4, 0.6);
  std::normal_distribution<double> g;
  point_set<with_normals_colours> s;
  s.origin = vec3d(100, 200, 300);
  const std::size_t n = 20000;
  s.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    s.positions[i] = (R * vec3d(sp.x() * g(rng), sp.y() * g(rng), sp.z() * g(rng))).cast<float>();
    s.normals[i] = detail::wrap_normal(R, vec2d(0.1 * g(rng), 0.02 * g(rng))).cast<float>();
    const vec3d c = mc + C * vec3d(sc.x() * g(rng), sc.y() * g(rng), sc.z() * g(rng));
    const auto b = [](double v) {
      return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0, 1.0) * 255));
    };
    s.colours[i] = {b(c.x()), b(c.y()), b(c.z())};
  }
  const auto t = build_pca_octree(
      s, {.leaf_size = 1u << 20, .surface_angle = 180, .colour_tolerance = 2, .quantise = false});
  ASSERT_EQ(t.nodes().size(), 1u);
  const auto& nd = t.at(0);
  const vec3d mean_world = t.origin() + nd.mean.cast<double>();
  EXPECT_LT((mean_world - s.origin).norm(), 4 * 2 / std::sqrt(double(n)));
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(nd.sigma[k] / sp[k], 1.0, 0.03);
    EXPECT_LT(axis_deg(nd.frame.col(k).cast<double>(), R.col(k)), 1.0);
    EXPECT_NEAR(t.colour(0).sigma[k] / sc[k], 1.0, 0.04);
    EXPECT_LT(axis_deg(t.colour(0).frame.col(k).cast<double>(), C.col(k)), 3.0);
  }
  EXPECT_LT((t.colour(0).mean.cast<double>() - mc).norm(), 0.01);
  EXPECT_NEAR(nd.normal_sigma.x() / 0.1, 1.0, 0.03);
  EXPECT_NEAR(nd.normal_sigma.y() / 0.02, 1.0, 0.03);
  EXPECT_LT(angle_deg(nd.normal_frame.col(2).cast<double>(), R.col(2)), 0.5);
}

// §3's degenerate rules, one case each: the frame is always finite, orthonormal and
// right-handed, σ never below the floor, and the directions are those the rules name.
TEST(pca_octree, DegenerateCasesGiveOrthonormalFrames) {
  const vec3d n = vec3d(1, 2, 2).normalized();
  // one point / duplicates: three zero variances → z = the normal
  for (int count : {1, 50}) {
    std::vector<vec3d> p(static_cast<std::size_t>(count), vec3d(3, -1, 2));
    const auto r = detail::pca_positions(p.data(), p.size(), n);
    EXPECT_EQ(r.zero_variances, 3);
    expect_orthonormal(r.frame, "point");
    EXPECT_LT(angle_deg(r.frame.col(2), n), 1e-6);
    EXPECT_EQ(r.sigma, vec3d::Constant(1e-15));
  }
  // collinear (including two points): the principal direction kept, z = the normal made
  // orthogonal to it
  const vec3d dir = vec3d(1, -1, 0.5).normalized();
  for (int count : {2, 40}) {
    std::vector<vec3d> p;
    for (int i = 0; i < count; ++i) p.push_back(vec3d(1, 2, 3) + dir * (0.1 * i));
    const auto r = detail::pca_positions(p.data(), p.size(), n);
    EXPECT_EQ(r.zero_variances, 2);
    expect_orthonormal(r.frame, "line");
    EXPECT_LT(axis_deg(r.frame.col(0), dir), 1e-6);
    const vec3d z = (n - dir * dir.dot(n)).normalized();
    EXPECT_LT(angle_deg(r.frame.col(2), z), 1e-6);
    EXPECT_GT(r.sigma.x(), 0.01);
    EXPECT_EQ(r.sigma.y(), 1e-15);
  }
  // a line along the normal itself: z falls back to any direction orthogonal to the line
  {
    std::vector<vec3d> p;
    for (int i = 0; i < 10; ++i) p.push_back(n * i);
    const auto r = detail::pca_positions(p.data(), p.size(), n);
    EXPECT_EQ(r.zero_variances, 2);
    expect_orthonormal(r.frame, "line along the normal");
    EXPECT_LT(axis_deg(r.frame.col(0), n), 1e-6);
  }
  // coplanar: one zero variance, f³ the plane's normal, turned towards the mean normal
  {
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(-1, 1);
    const vec3d a = vec3d(1, 0, 1).normalized(), b = vec3d(0, 1, 0), pn = a.cross(b);
    std::vector<vec3d> p;
    for (int i = 0; i < 200; ++i) p.push_back(vec3d(5, 5, 5) + a * u(rng) + b * 0.5 * u(rng));
    const auto r = detail::pca_positions(p.data(), p.size(), -pn);
    EXPECT_EQ(r.zero_variances, 1);
    expect_orthonormal(r.frame, "plane");
    EXPECT_LT(angle_deg(r.frame.col(2), -pn), 1e-6);
    EXPECT_EQ(r.sigma.z(), 1e-15);
  }
  // the normals cancel out (both sides of a sheet): the fallback direction is used
  {
    std::vector<vec3f> nn{vec3f::UnitX(), -vec3f::UnitX()};
    const auto r = detail::pca_normals(nn.data(), nn.size(), vec3d::UnitY());
    expect_orthonormal(r.frame, "cancelling normals");
    EXPECT_LT(angle_deg(r.frame.col(2), vec3d::UnitY()), 1e-9);
    EXPECT_TRUE(all_finite(r.sigma));
  }
}

// The unwrap of §3 is the sphere's log map at the pole: |uv| is the angle from the pole (arc
// length along the longitude), and wrapping it back gives the normal again.
TEST(pca_octree, UnwrapRoundTrips) {
  std::mt19937 rng(9);
  std::normal_distribution<double> g;
  for (int i = 0; i < 2000; ++i) {
    const mat3d F = random_rotation(rng);
    const vec3d n = vec3d(g(rng), g(rng), g(rng)).normalized();
    const vec2d uv = detail::unwrap_normal(F, n);
    EXPECT_NEAR(uv.norm(), std::acos(std::clamp(n.dot(F.col(2)), -1.0, 1.0)), 1e-9);
    EXPECT_LT((detail::wrap_normal(F, uv) - n).norm(), 1e-9) << i;
  }
  const mat3d I = mat3d::Identity();
  EXPECT_EQ(detail::unwrap_normal(I, vec3d::UnitZ()), vec2d::Zero());
  EXPECT_LT((detail::wrap_normal(I, vec2d::Zero()) - vec3d::UnitZ()).norm(), 1e-15);
}

// ---- §3.1: quantisation ---------------------------------------------------------------------

// pca_normals() takes a series instead of atan2 for normals near the pole: its σ_n must equal
// the brute-force moments of unwrap_normal() (the definition) to rounding, for spreads that put
// every normal near the pole, some, and none (σ 0.02, 0.2 and 0.8 rad about the mean), and
// for normals exactly on the axis.
TEST(pca_octree, NormalMomentsMatchTheUnwrapDefinition) {
  std::mt19937 rng(11);
  std::normal_distribution<double> g;
  for (const double spread : {0.02, 0.2, 0.8}) {
    const mat3d F = random_rotation(rng);
    std::vector<vec3f> n(5000);
    for (auto& m : n)
      m = detail::wrap_normal(F, vec2d(spread * g(rng), 0.5 * spread * g(rng))).cast<float>();
    const auto r = detail::pca_normals(n.data(), n.size(), vec3d::UnitZ());
    Eigen::Matrix2d m = Eigen::Matrix2d::Zero();
    for (const auto& v : n) {
      const vec2d uv = detail::unwrap_normal(r.frame, v.cast<double>());
      m += uv * uv.transpose();
    }
    m /= static_cast<double>(n.size());
    const double major = r.sigma.x() * r.sigma.x(), minor = r.sigma.y() * r.sigma.y();
    // In the result's frame the moments are diagonal, with σ² on the diagonal.
    EXPECT_NEAR(m(0, 0), major, 1e-12 * major) << spread;
    EXPECT_NEAR(m(1, 1), minor, 1e-12 * major) << spread;
    EXPECT_NEAR(m(0, 1), 0.0, 1e-12 * major) << spread;
  }
  // Normals exactly on the axis: three at +z (the mean, so the pole) and one at −z, which
  // unwraps to (π, 0): the moments are diag(π²/4, 0), so σ_n = (π/2, 0).
  const std::vector<vec3f> axis{vec3f::UnitZ(), vec3f::UnitZ(), vec3f::UnitZ(), -vec3f::UnitZ()};
  const auto r = detail::pca_normals(axis.data(), axis.size(), vec3d::UnitZ());
  EXPECT_NEAR(r.sigma.x(), std::numbers::pi / 2, 1e-12);
  EXPECT_NEAR(r.sigma.y(), 0.0, 1e-12);
}
// The quantised tree has the same octree as the float one (quantisation does not change the
// structure), so node by node: μ_p within half a step of 10 bits of its cell, f_p³ and the mean
// normal within the 16-bit normal table's stated bound, f_p¹ and f_n¹ within twice that plus
// half an 8-bit step of π, μ_c within half a 5-bit step, and each σ the codebook entry nearest
// to the node's own (brute force over the codebook).
TEST(pca_octree, QuantisedNodesDecodeWithinTheirStatedError) {
  const auto pts = demo_points(6000);
  pca_octree_options o{.position_codebook = 64, .normal_codebook = 64, .colour_codebook = 16};
  const auto q = build_pca_octree(pts, o);
  o.quantise = false;
  const auto f = build_pca_octree(pts, o);
  ASSERT_EQ(q.nodes().size(), f.nodes().size());
  EXPECT_EQ(q.record_bytes(), 17u);
  const double e16 = normal_quantizer(16).max_error_degrees();
  const double angle_step = 180.0 / 256 / 2;
  const auto& d = q.data();
  for (std::uint32_t i = 0; i < q.nodes().size(); ++i) {
    const auto &a = f.at(i), &b = q.at(i);
    ASSERT_EQ(a.first, b.first);
    ASSERT_EQ(a.mask, b.mask);
    const double step = a.cell_size / 1024 / 2;
    // (plus the float rounding of both means' coordinates)
    const double ulp = std::numeric_limits<float>::epsilon() * a.mean.cwiseAbs().maxCoeff();
    EXPECT_LE((a.mean - b.mean).cwiseAbs().maxCoeff(), step * (1 + 1e-4) + 1e-6 * a.cell_size + ulp)
        << i;
    EXPECT_LE(axis_deg(a.frame.col(2).cast<double>(), b.frame.col(2).cast<double>()), e16) << i;
    EXPECT_LE(angle_deg(a.normal_frame.col(2).cast<double>(), b.normal_frame.col(2).cast<double>()),
              e16)
        << i;
    // f¹ is only defined up to rotation when σ¹ = σ²: test where the ellipse has an axis.
    if (a.sigma.x() > 1.01f * a.sigma.y()) {
      EXPECT_LE(axis_deg(a.frame.col(0).cast<double>(), b.frame.col(0).cast<double>()),
                2 * e16 + angle_step + 1e-3)
          << i;
    }
    if (a.normal_sigma.x() > 1.01f * a.normal_sigma.y()) {
      EXPECT_LE(
          axis_deg(a.normal_frame.col(0).cast<double>(), b.normal_frame.col(0).cast<double>()),
          2 * e16 + angle_step + 1e-3)
          << i;
    }
    EXPECT_LE((f.colour(i).mean - q.colour(i).mean).cwiseAbs().maxCoeff(), 0.5f / 31 + 1e-6f);
    // σ_p and the extents: the decoded class is a nearest codebook entry of the node's feature
    // (log₂ of σ_p and of the extents over the cell edge).
    detail::pca_feature feat;
    for (int k = 0; k < 3; ++k) {
      feat[k] = static_cast<float>(
          std::log2(std::max(static_cast<double>(a.sigma[k]) / a.cell_size, 0x1p-60)));
      feat[3 + k] = static_cast<float>(
          std::log2(std::max(static_cast<double>(a.extent[k]) / a.cell_size, 0x1p-60)));
    }
    float best = std::numeric_limits<float>::infinity();
    for (const auto& c : d.codebook_p) best = std::min(best, (c - feat).squaredNorm());
    const std::uint32_t idx = d.records[i][0] | (d.records[i][1] & 0xFu) << 8;
    EXPECT_NEAR((d.codebook_p[idx] - feat).squaredNorm(), best, 1e-5f * (1 + best)) << i;
    // And the decoded σ (what rendering draws from) is that entry's: cell edge · 2^feature,
    // floored at §3's 1e-15 — the stored index alone says nothing about the decoder.
    for (int k = 0; k < 3; ++k) {
      const double want = std::max(a.cell_size * std::exp2(double(d.codebook_p[idx][k])), 1e-15);
      EXPECT_NEAR(b.sigma[k], want, 1e-5 * want) << i << " σ" << k;
      const double span =
          std::max(a.cell_size * std::exp2(double(d.codebook_p[idx][3 + k])), 1e-15);
      EXPECT_NEAR(b.extent[k], span, 1e-5 * span) << i << " extent" << k;
    }
  }
  EXPECT_LE(q.codebook_size_p(), 64u);
  EXPECT_GE(q.codebook_size_p(), 2u);
}

}  // namespace
}  // namespace pca_test
}  // namespace pbr_lod
