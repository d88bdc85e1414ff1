// Tests of the PCA octree's file and of hard inputs (Kalaiah & Varshney 2003 §3.1 storage; the
// DESIGN's numerics and errors). Each case says why its expectation holds.
#include <Eigen/Eigenvalues>
#include <bit>
#include <cmath>
#include <numbers>

#include "builders/pca_octree_test_util.hpp"

namespace pbr_lod {
namespace pca_test {
namespace {

// Without colour the records are 13 bytes and there is no colour codebook; the file holds
// exactly header + codebooks (6 floats a position class, 3 a normal class) + (1 + 13) bytes per
// node + checksum.
TEST(pca_octree, NoColourMeansNoColourBits) {
  auto cloud = sample_surface(make_demo_scene(16), 3000, 3);
  cloud.colours.clear();
  const auto t = build_pca_octree(point_set<with_normals>::from(cloud));
  EXPECT_EQ(t.record_bytes(), 13u);
  EXPECT_EQ(t.codebook_size_c(), 0u);
  EXPECT_EQ(t.file_bytes(),
            128 + 24 * t.codebook_size_p() + 12 * t.codebook_size_n() + t.nodes().size() * 14 + 8);
}

// save → load gives an equal hierarchy (every decoded value, code and codebook entry), and
// saving it again gives the same bytes: quantised with and without colour, and float records.
TEST(pca_octree, SaveLoadRoundTripsBitExactly) {
  const auto pts = demo_points(4000);
  for (bool quantise : {true, false}) {
    const auto t = build_pca_octree(pts, {.quantise = quantise});
    const std::string p = temp(quantise ? "q.lod" : "f.lod");
    t.save(p);
    EXPECT_EQ(std::filesystem::file_size(p), t.file_bytes());
    const auto u = tree_nc::load(p);
    EXPECT_TRUE(u == t) << quantise;
    EXPECT_FALSE(u.stats().has_timings);
    EXPECT_EQ(u.stats().input_points, pts.size());
    const std::string p2 = temp("again.lod");
    u.save(p2);
    EXPECT_EQ(read_bytes(p), read_bytes(p2));
    EXPECT_THROW((void)tree_n::load(p), FormatError) << "colour file as a colourless tree";
  }
  auto cloud = sample_surface(make_demo_scene(16), 3000, 3);
  cloud.colours.clear();
  const auto t = build_pca_octree(point_set<with_normals>::from(cloud));
  const std::string p = temp("n.lod");
  t.save(p);
  EXPECT_TRUE(tree_n::load(p) == t);
}

// The same input and options give the same bytes whatever the thread count (no timings in the
// file, parallel steps combine in a fixed order). 70 000 points: enough for the root to be
// partitioned in parallel chunks (≥ 65 536 points) and for k-means' 16 k sample.
TEST(pca_octree, FileBytesDoNotDependOnThreads) {
  const auto pts = demo_points(70000);
  build_pca_octree(pts, {.threads = 1}).save(temp("t1.lod"));
  build_pca_octree(pts, {.threads = 3}).save(temp("t3.lod"));
  EXPECT_EQ(read_bytes(temp("t1.lod")), read_bytes(temp("t3.lod")));
}

// The octree against a brute-force one: §3's rule (split a cell at its centre while it holds
// more than leaf_size points, or normals more than surface_angle from its first one, or colours
// farther than colour_tolerance from its first one, that are not all equal) applied breadth
// first, one node at a time.
// The builder partitions large nodes (≥ 65 536 points) in parallel chunks, splits the levels
// below 256 nodes' worth in parallel and merges the parts back;
// the result must be this tree node for node: same order, children, octant masks and depths,
// and each node's position statistics those of its own points (the builder merges moments
// bottom-up instead of summing every node's points).
TEST(pca_octree, OctreeMatchesTheBreadthFirstDefinition) {
  // The demo scene's vertices (92 k): creases, a thin fin, stripes, so that both coherence
  // rules split small nodes.
  const auto cloud = make_demo_scene(80).vertices;
  const auto pts = point_set<with_normals_colours>::from(cloud);
  const pca_octree_options opt{
      .leaf_size = 4, .colour_tolerance = 0.05f, .quantise = false, .threads = 3};
  const auto t = build_pca_octree(pts, opt);
  const double cos_surface = std::cos(opt.surface_angle * std::numbers::pi / 180);
  const double colour_tol = 255.0 * opt.colour_tolerance;
  // Small nodes split by each of the two coherence rules alone (the rules are exercised).
  std::size_t split_for_normals = 0, split_for_colours = 0;
  struct cell {
    std::vector<std::uint32_t> points;
    vec3d min;
    double size;
    std::uint8_t depth;
  };
  std::vector<cell> q(1);
  for (std::uint32_t i = 0; i < pts.size(); ++i) q[0].points.push_back(i);
  q[0].min = t.cube_min();
  q[0].size = t.cube_size();
  const auto rel = [&](std::uint32_t i) -> vec3d {
    return pts.positions[i].cast<double>() - t.origin();
  };
  ASSERT_EQ(pts.origin, vec3d::Zero());
  for (std::size_t i = 0; i < q.size(); ++i) {
    ASSERT_LT(i, t.nodes().size());
    const cell c = q[i];
    const auto& nd = t.at(static_cast<std::uint32_t>(i));
    ASSERT_EQ(nd.depth, c.depth) << i;
    // Inner nodes merge their children's moments: the same PCA as over their own points.
    std::vector<vec3d> own;
    for (const auto k : c.points) own.push_back(rel(k));
    const auto ref =
        detail::pca_positions(own.data(), own.size(), nd.normal_frame.col(2).cast<double>());
    ASSERT_LT((nd.mean.cast<double>() - ref.mean).norm(), 1e-6 * t.cube_size()) << i;
    for (int k = 0; k < 3; ++k)
      ASSERT_NEAR(nd.sigma[k], ref.sigma[k], 1e-5 * ref.sigma[0] + 1e-14) << i << " σ" << k;
    bool same = true, one_normal = true, one_colour = true;
    for (const auto k : c.points) {
      same = same && rel(k) == rel(c.points[0]);
      const rgb8 a = pts.colours[k], b = pts.colours[c.points[0]];
      one_normal = one_normal && pts.normals[k].normalized().dot(
                                     pts.normals[c.points[0]].normalized()) >= cos_surface;
      one_colour = one_colour && std::hypot(double(a.r) - b.r, double(a.g) - b.g,
                                            double(a.b) - b.b) <= colour_tol;
    }
    if (c.points.size() <= 4 && !same) {
      split_for_normals += one_normal ? 0 : 1;
      split_for_colours += one_normal && !one_colour ? 1 : 0;
    }
    if ((c.points.size() <= 4 && one_normal && one_colour) || same || c.depth >= opt.max_depth) {
      ASSERT_EQ(nd.count, 0u) << i;
      continue;
    }
    const double half = 0.5 * c.size;
    const vec3d mid = c.min + vec3d::Constant(half);
    std::array<cell, 8> kids;
    for (const auto k : c.points) {
      const vec3d p = rel(k);
      const unsigned o = (p.x() >= mid.x() ? 1u : 0u) | (p.y() >= mid.y() ? 2u : 0u) |
                         (p.z() >= mid.z() ? 4u : 0u);
      kids[o].points.push_back(k);
    }
    ASSERT_EQ(nd.first, q.size()) << i;
    unsigned mask = 0;
    for (unsigned o = 0; o < 8; ++o) {
      if (kids[o].points.empty()) continue;
      mask |= 1u << o;
      kids[o].min = c.min + vec3d((o & 1) ? half : 0, (o & 2) ? half : 0, (o & 4) ? half : 0);
      kids[o].size = half;
      kids[o].depth = static_cast<std::uint8_t>(c.depth + 1);
      q.push_back(std::move(kids[o]));
    }
    ASSERT_EQ(nd.mask, mask) << i;
    ASSERT_EQ(nd.count, std::popcount(mask)) << i;
  }
  EXPECT_EQ(q.size(), t.nodes().size());
  EXPECT_GT(q.size(), 2000u) << "deep enough for the parallel parts";
  std::printf("small nodes split for their normals %zu, for their colours alone %zu\n",
              split_for_normals, split_for_colours);
  EXPECT_GE(split_for_normals, 10u);
  EXPECT_GE(split_for_colours, 10u);
}

// Corrupt files give a FormatError naming the file and what is wrong, never a crash.
TEST(pca_octree, LoadRejectsCorruptFiles) {
  const auto t = build_pca_octree(demo_points(2000));
  const std::string p = temp("good.lod"), bad = temp("bad.lod");
  t.save(p);
  const auto good = read_bytes(p);
  const auto expect_error = [&](std::vector<char> b, const std::string& needle) {
    write_bytes(bad, b);
    try {
      (void)tree_nc::load(bad);
      ADD_FAILURE() << "no error for " << needle;
    } catch (const FormatError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find(bad), std::string::npos) << m;
      EXPECT_NE(m.find(needle), std::string::npos) << m;
    }
  };
  auto b = good;
  b[0] = 'X';
  expect_error(b, "bad magic");
  b = good;
  b[8] = 9;
  expect_error(b, "version 9");
  b = good;
  b.erase(b.end() - 5, b.end());  // (not resize(size - 5): GCC 12 under ASan warns)
  expect_error(b, "do not match the file size");
  b = good;
  b[b.size() / 2] ^= 0x40;
  expect_error(b, "checksum");
  b.erase(b.begin() + 10, b.end());
  expect_error(b, "truncated");
  EXPECT_THROW((void)tree_nc::load(temp("missing.lod")), IoError);
}

TEST(pca_octree, EmptyAndNonFiniteInputAreClearErrors) {
  point_set<with_normals> empty;
  try {
    (void)build_pca_octree(empty);
    ADD_FAILURE();
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("no points"), std::string::npos) << e.what();
  }
  point_set<positions_only> nan;
  nan.positions = {vec3f(0, 0, 0), vec3f(1, 0, 0), vec3f(0, 1, 0),
                   vec3f(std::numeric_limits<float>::quiet_NaN(), 0, 0)};
  try {
    (void)build_pca_octree(nan);
    ADD_FAILURE();
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("position 3"), std::string::npos) << e.what();
  }
  point_set<with_normals> zero_normal;
  zero_normal.positions = {vec3f(0, 0, 0)};
  zero_normal.normals = {vec3f::Zero()};
  // A zero normal is no normal: estimated (fill_missing_normals), not refused.
  EXPECT_NO_THROW((void)build_pca_octree(zero_normal));
  EXPECT_THROW((void)build_pca_octree(demo_points(100), {.position_codebook = 5000}),
               InvalidArgument);
}

/// Distance from p to the affine hull of pts (a point, a line or a plane; rank from the
/// covariance's eigenvalues).
double affine_hull_distance(const std::vector<vec3f>& pts, const vec3d& p) {
  vec3d mean = vec3d::Zero();
  for (const auto& q : pts) mean += q.cast<double>();
  mean /= double(pts.size());
  mat3d cov = mat3d::Zero();
  for (const auto& q : pts)
    cov += (q.cast<double>() - mean) * (q.cast<double>() - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<mat3d> es(cov);
  const double top = std::max(es.eigenvalues().maxCoeff(), 1e-300);
  vec3d off = p - mean;
  for (int k = 0; k < 3; ++k)  // remove the spanned directions
    if (es.eigenvalues()[k] > 1e-9 * top)
      off -= es.eigenvectors().col(k) * es.eigenvectors().col(k).dot(off);
  return off.norm();
}

// The CGAL-style ladder: 1 point, a repeated point, 2 points, a line, a plane — each builds a
// finite hierarchy that draws finite points. And the points drawn lie where the input does:
// §3's rules give a zero variance a σ of 1e-15 along the right axis, so the generated points of
// a point, a line or a plane stay on that point, line or plane (up to float rounding of the
// coordinates, ~1e-6 of their size here) — finiteness alone would not see a floor of the wrong
// size or a frame with its columns swapped. Checked on the float records: quantisation (§3.1)
// rounds the frame's directions by up to e16, which moves points off the line by design.
TEST(pca_octree, DegenerateInputsBuildFiniteHierarchies) {
  std::vector<std::pair<std::string, std::vector<vec3f>>> cases;
  cases.push_back({"one point", {vec3f(1, 2, 3)}});
  cases.push_back({"duplicates", std::vector<vec3f>(100, vec3f(1, 2, 3))});
  cases.push_back({"two points", {vec3f(0, 0, 0), vec3f(1, 1, 1)}});
  std::vector<vec3f> line, plane;
  for (int i = 0; i < 200; ++i) line.push_back(vec3f(0.01f * i, 0.02f * i, -0.005f * i));
  for (int i = 0; i < 30; ++i)
    for (int j = 0; j < 30; ++j) plane.push_back(vec3f(0.1f * i, 0.05f * j, 0.1f * i + 0.02f * j));
  cases.push_back({"collinear", line});
  cases.push_back({"coplanar", plane});
  for (const auto& [name, pts] : cases) {
    point_set<with_normals> s;
    s.positions = pts;
    s.normals.assign(pts.size(), vec3f(0, 0, 1));
    const auto t = build_pca_octree(s, {.leaf_size = 4});
    expect_finite_tree(t, name);
    const auto sink = draw(
        t, camera_for(t.origin() + t.at(0).mean.cast<double>(), std::max(1.0f, t.at(0).radius)), 1);
    EXPECT_GT(sink.points.size(), 0u) << name;
    for (const auto& p : sink.points)
      ASSERT_TRUE(all_finite(p.position) && all_finite(p.normal)) << name;
    const auto f = build_pca_octree(s, {.leaf_size = 4, .quantise = false});
    const auto on = draw(
        f, camera_for(f.origin() + f.at(0).mean.cast<double>(), std::max(1.0f, f.at(0).radius)), 1);
    ASSERT_GT(on.points.size(), 0u) << name;
    for (const auto& p : on.points)
      ASSERT_LT(affine_hull_distance(pts, f.origin() + p.position.cast<double>()), 1e-5)
          << name << ": " << p.position.transpose();
  }
  // positions only: normals come from the k-NN estimation, which handles the same ladder
  point_set<positions_only> s;
  s.positions = plane;
  const auto t = build_pca_octree(s);
  EXPECT_TRUE(t.stats().estimated_normals);
  expect_finite_tree(t, "estimated normals");
}

}  // namespace
}  // namespace pca_test
}  // namespace pbr_lod
