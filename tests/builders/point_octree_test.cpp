// Tests of the point-octree builder (Pajarola 2003). Each case says why its expectation holds.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <iterator>
#include <limits>
#include <numbers>
#include <thread>

#include <filesystem>
#include <fstream>
#include <random>

#include "pbr_lod/builders/point_octree.hpp"
#include "pbr_lod/core/covariance.hpp"
#include "pbr_lod/core/mesh_splats.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/png.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/raster/reference.hpp"
#include "support/data.hpp"
#include "support/policies.hpp"
#include "support/user_view.hpp"

namespace pbr_lod {
namespace {

constexpr attributes in_attrs{.normal = true, .colour = true};
using octree_nc = point_octree<point_octree_attributes(in_attrs)>;
using octree_p = point_octree<point_octree_attributes(positions_only)>;

point_set<in_attrs> demo_points(std::size_t n, std::uint64_t seed = 7) {
  return point_set<in_attrs>::from(sample_surface(make_demo_scene(24), n, seed));
}

constexpr attributes disk_attrs{.normal = true, .colour = true, .ellipse = true};
/// Dense samples of the demo scene with overlapping circular splats (no k-NN estimation).
point_set<disk_attrs> dense_points(std::size_t n, std::uint64_t seed = 7) {
  const auto mesh = make_demo_scene(24);
  double area = 0;
  for (const auto& f : mesh.faces) {
    const auto& P = mesh.vertices.positions;
    area +=
        0.5 * (P[f[1]] - P[f[0]]).cast<double>().cross((P[f[2]] - P[f[0]]).cast<double>()).norm();
  }
  auto c = sample_surface(mesh, n, seed);
  test::add_circular_splats(c, area);
  return point_set<disk_attrs>::from(c);
}

/// Checks every invariant the paper's structure promises; returns the number of nodes checked.
template <class T>
std::size_t check_invariants(const T& t) {
  const auto& s = t.samples();
  std::vector<int> owner(s.size(), 0);
  for (typename T::node_id i = 0; i < t.nodes().size(); ++i) {
    const auto& nd = t.at(i);
    const sphere b = t.bounding_sphere(i);
    const normal_cone cone = t.normal_cone(i);
    const elliptical_disk e = t.disk(i);
    EXPECT_TRUE(all_finite(nd.centre) && all_finite(nd.normal) && all_finite(nd.axis_u) &&
                all_finite(nd.axis_v) && std::isfinite(nd.radius) && std::isfinite(nd.cone_angle))
        << "node " << i;
    EXPECT_NEAR(nd.normal.norm(), 1.0f, 1e-4f) << "node " << i;
    // The ellipse lies in the tangent plane: axes orthogonal to each other and to the normal.
    const float scale = std::max(nd.axis_u.norm(), 1e-30f);
    EXPECT_LE(std::abs(nd.axis_u.dot(nd.normal)), 1e-4f * scale) << "node " << i;
    EXPECT_LE(std::abs(nd.axis_u.dot(nd.axis_v)), 1e-4f * scale * scale) << "node " << i;
    const auto corners = [](const vec3f& c, const vec3f& u, const vec3f& v) {
      return std::array<vec3f, 4>{c + u + v, c + u - v, c - u + v, c - u - v};
    };
    if (nd.leaf) {
      for (std::uint32_t k = nd.first; k < nd.first + nd.count; ++k) {
        ++owner[k];
        EXPECT_TRUE(b.contains(s.positions[k])) << "leaf " << i << " sample " << k;
        EXPECT_TRUE(cone.contains(s.normals[k], 1e-3f)) << "leaf " << i << " sample " << k;
        for (const auto& c : corners(s.positions[k], s.axis_u[k], s.axis_v[k]))
          EXPECT_TRUE(e.covers(c, 1e-3f)) << "leaf " << i << " does not cover sample " << k;
      }
    } else {
      for (auto c : t.children(i)) {
        const auto& ch = t.at(c);
        EXPECT_TRUE(b.contains(t.bounding_sphere(c), 1e-4f)) << "node " << i << " child " << c;
        for (const auto& p : corners(ch.centre, ch.axis_u, ch.axis_v))
          EXPECT_TRUE(e.covers(p, 1e-3f)) << "node " << i << " does not cover child " << c;
      }
    }
  }
  // Cones of inner nodes contain every sample normal below them: check at the root.
  for (std::size_t k = 0; k < s.size(); ++k)
    EXPECT_TRUE(t.normal_cone(0).contains(s.normals[k], 1e-3f));
  for (std::size_t k = 0; k < s.size(); ++k) EXPECT_EQ(owner[k], 1) << "sample " << k;
  return t.nodes().size();
}

TEST(PointOctree, InvariantsOnTheDemoScene) {
  const auto pts = demo_points(30000);
  const auto t = build_point_octree(pts, {.leaf_size = 8});
  EXPECT_GT(check_invariants(t), 1000u);
  EXPECT_EQ(t.samples().size(), pts.size());
  // Nodes per point: an octree with ≤ 8 samples per leaf has roughly N/4..N/2 nodes (paper ≈ 0.4).
  const double ratio = static_cast<double>(t.nodes().size()) / static_cast<double>(pts.size());
  EXPECT_GT(ratio, 0.1);
  EXPECT_LT(ratio, 0.8);
}

TEST(PointOctree, InvariantsWithoutQuantisationAndWithThePapersRules) {
  const auto pts = demo_points(8000, 3);
  for (const auto cov : {covariance_method::stable, covariance_method::generic_double})
    for (const auto rule : {ellipse_axis_rule::sqrt_eigenvalue, ellipse_axis_rule::eigenvalue})
      for (const int bits : {0, 12, 16}) {
        SCOPED_TRACE(::testing::Message()
                     << "cov " << int(cov) << " rule " << int(rule) << " bits " << bits);
        const auto t = build_point_octree(pts, {.leaf_size = 4,
                                                .covariance = cov,
                                                .axis_rule = rule,
                                                .normal_bits = bits,
                                                .threads = 1});
        check_invariants(t);
      }
}

// Positions only (the real bunny scan): normals and splat ellipses come from k-NN (§4 end).
TEST(PointOctree, BunnyWithEstimatedNormalsAndEllipses) {
  const auto cloud = read_points(test::data_file("bun_zipper.ply"));
  const auto pts = point_set<positions_only>::from(cloud);
  const auto t = build_point_octree(pts);
  EXPECT_TRUE(t.stats().estimated_normals);
  EXPECT_TRUE(t.stats().estimated_ellipses);
  check_invariants(t);
}

// The parallel build (subtrees in tasks, spliced; the passes over the root's 150 000 samples
// split into blocks of 65 536 on several threads) gives exactly the sequential tree.
TEST(PointOctree, ParallelBuildEqualsSequential) {
  const auto pts = demo_points(150000, 11);
  const auto a = build_point_octree(pts, {.threads = 1});
  const auto b = build_point_octree(pts, {.threads = 4});
  EXPECT_TRUE(a == b);
}

// Covariance from the paper's homogeneous sums (EQ 2–4) and from the stable merge equals a
// direct two-pass computation (EQ 1), also after merging two sets.
TEST(Covariance, SumsEqualDirectComputation) {
  std::mt19937 rng(42);  // any data: the identities hold for every input
  std::normal_distribution<double> g(0, 1);
  std::vector<vec3d> a(300), b(200);
  for (auto& p : a) p = vec3d(g(rng) * 3 + 1, g(rng) + 2, g(rng) * 0.1 - 1);
  for (auto& p : b) p = vec3d(g(rng) + 4, g(rng) * 2, g(rng));
  const auto direct = [](const std::vector<vec3d>& pts) {
    vec3d m = vec3d::Zero();
    for (const auto& p : pts) m += p;
    m /= static_cast<double>(pts.size());
    mat3d c = mat3d::Zero();
    for (const auto& p : pts) c += (p - m) * (p - m).transpose();
    return mat3d(c / static_cast<double>(pts.size()));
  };
  generic_homogeneous_covariance<double> ga, gb;
  scatter_accumulator sa, sb;
  for (const auto& p : a) {
    ga.add(p);
    sa.add(p);
  }
  for (const auto& p : b) {
    gb.add(p);
    sb.add(p);
  }
  EXPECT_LT((ga.covariance() - direct(a)).norm(), 1e-10);
  EXPECT_LT((sa.covariance() - direct(a)).norm(), 1e-12);
  std::vector<vec3d> ab = a;
  ab.insert(ab.end(), b.begin(), b.end());
  ga += gb;  // EQ 4
  sa += sb;  // Chan et al.
  EXPECT_LT((ga.covariance() - direct(ab)).norm(), 1e-10);
  EXPECT_LT((sa.covariance() - direct(ab)).norm(), 1e-12);
  // EQ 3 with a rotation: the covariance in a rotated frame is R·M·Rᵀ.
  const mat3d R = Eigen::AngleAxisd(0.7, vec3d(1, 2, 3).normalized()).toRotationMatrix();
  const mat3d in_frame = ga.in_frame(sa.mean, R).block<3, 3>(0, 0);
  EXPECT_LT((in_frame - R * direct(ab) * R.transpose()).norm(), 1e-9);
}

template <class T>
double ellipse_drift(const T& a, const T& b) {
  const auto d = test::ellipse_drifts(a, b);
  return d.empty() ? 0.0 : *std::max_element(d.begin(), d.end());
}

// The hard case (PCL #2403, #2184): the same cloud 5·10⁵…10⁷ units from the origin. Moving it
// and re-expressing it relative to a new origin changes its float coordinates by rounding only
// (~1e-7 relative); the stable covariance then reproduces the at-origin ellipses to 1e-5, while
// the paper's world-coordinate sums in float are destroyed by cancellation.
TEST(PointOctree, FarFromOriginStablePathMatches) {
  const auto cloud = sample_surface(make_demo_scene(12), 4000, 5);
  const point_octree_options opt{.leaf_size = 8, .normal_bits = 0, .threads = 1};
  const auto ref = build_point_octree(point_set<in_attrs>::from(cloud), opt);
  for (const vec3d& shift : {vec3d(5e5, 4e6, 100), vec3d(1e7, 1e7, 1e7)}) {
    point_cloud moved = cloud;
    moved.origin += shift;
    rebase(moved, moved.origin + vec3d(0.0123, -0.0456, 0.0789));  // new float coordinates
    const auto pts_moved = point_set<in_attrs>::from(moved);
    const auto b = build_point_octree(pts_moved, opt);
    ASSERT_EQ(ref.nodes().size(), b.nodes().size()) << "shift " << shift.transpose();
    EXPECT_LT(ellipse_drift(ref, b), 1e-5) << "shift " << shift.transpose();
    // The paper's formulation in float, in world coordinates: catastrophic at these offsets.
    point_octree_options paper = opt;
    paper.covariance = covariance_method::generic_float;
    const auto pf = build_point_octree(pts_moved, paper);
    ASSERT_EQ(pf.nodes().size(), b.nodes().size());
    EXPECT_GT(ellipse_drift(b, pf), 1e-2) << "expected the float homogeneous sums to fail";
    check_invariants(pf);  // the coverage rule (f from the corners) still bounds everything
  }
}

// The degenerate ladder (CGAL's hierarchy_simplification_test): every rung gives a valid tree.
TEST(PointOctree, DegenerateLadder) {
  point_set<positions_only> empty;
  EXPECT_THROW((void)build_point_octree(empty), InvalidArgument);

  const auto make = [](std::vector<vec3f> p) {
    point_set<positions_only> s;
    s.positions = std::move(p);
    return s;
  };
  // 1 point: one leaf.
  {
    const auto t = build_point_octree(make({vec3f(1, 2, 3)}));
    ASSERT_EQ(t.nodes().size(), 1u);
    EXPECT_TRUE(t.is_leaf(0));
    check_invariants(t);
  }
  // 1000 copies of one point: no split separates them, one leaf of 1000.
  {
    const auto t = build_point_octree(make(std::vector<vec3f>(1000, vec3f(0.5f, 0.5f, 0.5f))));
    ASSERT_EQ(t.nodes().size(), 1u);
    EXPECT_EQ(t.at(0).count, 1000u);
    check_invariants(t);
  }
  // 2 points with leaf size 1: a root and two leaves.
  {
    const auto t = build_point_octree(make({vec3f(0, 0, 0), vec3f(1, 0, 0)}), {.leaf_size = 1});
    EXPECT_EQ(t.nodes().size(), 3u);
    check_invariants(t);
  }
  // Collinear, coplanar grid, random cube.
  std::vector<vec3f> line, grid, cube;
  for (int i = 0; i < 200; ++i) line.emplace_back(0.01f * i, 0.02f * i, -0.005f * i);
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 40; ++j) grid.emplace_back(0.1f * i, 0.05f * j, 2.0f);
  std::mt19937 rng(42);
  std::uniform_real_distribution<float> u(-1, 1);
  for (int i = 0; i < 3000; ++i) cube.emplace_back(u(rng), u(rng), u(rng));
  for (auto* pts : {&line, &grid, &cube}) {
    const auto t = build_point_octree(make(*pts), {.leaf_size = 4});
    EXPECT_GT(t.nodes().size(), pts->size() / 8);
    check_invariants(t);
  }
}

TEST(PointOctree, RejectsBadInput) {
  point_set<positions_only> s;
  s.positions = {vec3f(0, 0, 0), vec3f(std::nanf(""), 0, 0)};
  EXPECT_THROW((void)build_point_octree(s), InvalidArgument);
  s.positions[1] = vec3f(1, 1, 1);
  EXPECT_THROW((void)build_point_octree(s, {.normal_bits = 3}), InvalidArgument);
  // The check runs on several threads; the message still names the first bad position.
  s.positions.assign(300000, vec3f(1, 2, 3));
  s.positions[290000] = vec3f(0, std::numeric_limits<float>::infinity(), 0);
  s.positions[150001] = vec3f(std::nanf(""), 0, 0);
  try {
    (void)build_point_octree(s, {.threads = 4});
    ADD_FAILURE() << "no exception";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("position 150001 "), std::string::npos) << e.what();
  }
  // Cancel from the progress callback: throws, returns nothing.
  EXPECT_THROW(
      (void)build_point_octree(demo_points(5000), {.progress = [](double f) { return f < 0.05; }}),
      Cancelled);  // Positions only: the k-NN estimation reports the first tenth and is cancelled
                   // inside it.
  point_set<positions_only> bare;
  bare.positions = demo_points(5000).positions;
  std::vector<double> seen;
  EXPECT_THROW((void)build_point_octree(bare, {.progress =
                                                   [&](double f) {
                                                     seen.push_back(f);
                                                     return f < 0.05;
                                                   }}),
               Cancelled);
  ASSERT_GE(seen.size(), 2u);
  EXPECT_GT(seen.back(), 0.0);
  EXPECT_LT(seen.back(), 0.1);
}

// A parallel build reports progress only on the calling thread, rising from 0 to 1, with reports
// from inside the subtrees (not only between them); cancelling mid-build stops it.
TEST(PointOctree, ProgressOnTheCallingThreadDuringParallelBuild) {
  const auto pts = demo_points(400000, 3);
  const auto caller = std::this_thread::get_id();
  std::vector<double> seen;
  bool other_thread = false;
  const auto t = build_point_octree(pts, {.threads = 2, .progress = [&](double f) {
                                            other_thread = other_thread ||
                                                           std::this_thread::get_id() != caller;
                                            seen.push_back(f);
                                            return true;
                                          }});
  EXPECT_FALSE(other_thread);
  ASSERT_GE(seen.size(), 8u);
  EXPECT_EQ(seen.front(), 0.0);
  EXPECT_EQ(seen.back(), 1.0);
  EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
  // Reports strictly between the start of the tree (0.1) and its end: inside the subtree phase.
  EXPECT_GE(std::count_if(seen.begin(), seen.end(), [](double f) { return f > 0.1 && f < 1; }), 4);
  EXPECT_THROW(
      (void)build_point_octree(pts, {.threads = 2, .progress = [](double f) { return f < 0.5; }}),
      Cancelled);
}

// save()/load() round-trips exactly, quantised or not; bytes per point are reported.
TEST(PointOctree, SaveLoadRoundTrip) {
  const auto pts = demo_points(20000, 9);
  const auto dir = std::filesystem::temp_directory_path();
  for (const int bits : {0, 13, 16, 20}) {
    const auto t = build_point_octree(pts, {.normal_bits = bits});
    const auto path = (dir / ("pbr_lod_octree_" + std::to_string(bits) + ".lod")).string();
    t.save(path);
    EXPECT_EQ(std::filesystem::file_size(path), t.file_bytes());
    const auto u = octree_nc::load(path);
    EXPECT_TRUE(t == u) << "bits " << bits;
    // The wrong attribute set is refused, with a clear message.
    EXPECT_THROW((void)point_octree<point_octree_attributes(with_normals)>::load(path),
                 FormatError);
  }
}

// Two builds of the same input, at different thread counts, write the same bytes (the file holds
// no timings); a version 1 file (which did) is refused with a message that says to rebuild.
TEST(PointOctree, FilesAreDeterministic) {
  const auto pts = demo_points(30000, 4);
  const auto dir = std::filesystem::temp_directory_path();
  const auto bytes_of = [&](unsigned threads, const char* name) {
    const auto path = (dir / name).string();
    build_point_octree(pts, {.threads = threads}).save(path);
    std::ifstream f(path, std::ios::binary);
    return std::vector<char>(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  };
  const auto a = bytes_of(1, "pbr_lod_octree_det_a.lod"),
             b = bytes_of(2, "pbr_lod_octree_det_b.lod");
  ASSERT_GT(a.size(), 16u);
  EXPECT_TRUE(a == b);
  const auto loaded = octree_nc::load((dir / "pbr_lod_octree_det_a.lod").string());
  EXPECT_FALSE(loaded.stats().has_timings);
  auto old = a;
  old[8] = 1;  // the version field, little-endian
  const auto path = (dir / "pbr_lod_octree_v1.lod").string();
  std::ofstream(path, std::ios::binary).write(old.data(), static_cast<std::streamsize>(old.size()));
  try {
    (void)octree_nc::load(path);
    ADD_FAILURE() << "version 1 accepted";
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("version 1"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("rebuild"), std::string::npos) << e.what();
  }
}

TEST(PointOctree, LoadRejectsCorruptFiles) {
  const auto t = build_point_octree(demo_points(3000, 2));
  const auto path =
      (std::filesystem::temp_directory_path() / "pbr_lod_octree_corrupt.lod").string();
  t.save(path);
  std::vector<char> bytes;
  {
    std::ifstream f(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  const auto write = [&](const std::vector<char>& b) {
    std::ofstream f(path, std::ios::binary | std::ios::trunc);
    f.write(b.data(), static_cast<std::streamsize>(b.size()));
  };
  // Truncated at many places, one byte flipped anywhere, bad magic, lying counts: all Errors.
  for (std::size_t cut :
       {std::size_t{0}, std::size_t{5}, std::size_t{40}, bytes.size() / 2, bytes.size() - 1}) {
    write(std::vector<char>(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(cut)));
    EXPECT_THROW((void)octree_nc::load(path), Error) << "cut at " << cut;
  }
  std::mt19937 rng(1);
  for (int trial = 0; trial < 200; ++trial) {
    auto b = bytes;
    b[rng() % b.size()] ^= static_cast<char>(1 + rng() % 255);
    write(b);
    EXPECT_THROW((void)octree_nc::load(path), Error);
  }
  EXPECT_THROW((void)octree_nc::load(path + ".missing"), IoError);
}

// ---- §3's mean split and EQ 5–6's ellipse, against references computed here ---------------

constexpr attributes disk_in{.normal = true, .ellipse = true};
using octree_d = point_octree<point_octree_attributes(disk_in)>;

/// Indices (into t.samples()) of the samples below node n, found by walking to its leaves.
template <class T>
std::vector<std::uint32_t> subtree_samples(const T& t, std::uint32_t n) {
  std::vector<std::uint32_t> out, stack{n};
  while (!stack.empty()) {
    const std::uint32_t m = stack.back();
    stack.pop_back();
    const auto& nd = t.at(m);
    if (nd.leaf)
      for (std::uint32_t k = nd.first; k < nd.first + nd.count; ++k) out.push_back(k);
    else
      for (const auto c : t.children(m)) stack.push_back(c);
  }
  return out;
}

/// Octant of p about m, bit 0 = x, 1 = y, 2 = z (p ≥ m on that axis), or −1 when p lies within
/// `tie` of one of the three split planes (then rounding decides and the test does not judge).
int octant_about(const vec3d& p, const vec3d& m, double tie) {
  int o = 0;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(p[a] - m[a]) <= tie) return -1;
    o |= p[a] >= m[a] ? 1 << a : 0;
  }
  return o;
}

/// §3: every node's centre is the mean of the samples below it, and an inner node's children
/// are the non-empty octants about that mean, in octant order, each holding exactly the samples
/// of its octant. Brute force over the whole tree, from the stored samples; returns the number
/// of inner nodes checked. A tree split anywhere else than at the mean (the bounding box's
/// centre, a shifted mean) fails the octant check.
template <class T>
std::size_t check_mean_split(const T& t, std::uint32_t leaf_size) {
  const auto& s = t.samples();
  std::size_t inner = 0, ties = 0;
  for (std::uint32_t n = 0; n < t.nodes().size(); ++n) {
    const auto& nd = t.at(n);
    const auto below = subtree_samples(t, n);
    vec3d mean = vec3d::Zero();
    double extent = 0;
    for (const auto k : below) mean += s.positions[k].template cast<double>();
    mean /= static_cast<double>(below.size());
    for (const auto k : below)
      extent = std::max(extent, (s.positions[k].template cast<double>() - mean).norm());
    // Stored as float: within a few float ulps of the mean's magnitude.
    const double scale = std::max(mean.norm(), extent) + 1e-30;
    EXPECT_LE((nd.centre.template cast<double>() - mean).norm(), 4e-7 * scale) << "node " << n;
    if (nd.leaf) {
      EXPECT_LE(nd.count, leaf_size) << "leaf " << n;
      continue;
    }
    ++inner;
    EXPECT_GT(below.size(), leaf_size) << "node " << n << " should have been a leaf";
    int previous = -1;
    std::size_t held = 0;
    for (const auto c : t.children(n)) {
      const auto mine = subtree_samples(t, c);
      held += mine.size();
      int octant = -1;
      for (const auto k : mine) {
        const int o = octant_about(s.positions[k].template cast<double>(), mean, 1e-9 * scale);
        if (o < 0) {
          ++ties;
          continue;
        }
        if (octant < 0) octant = o;
        EXPECT_EQ(o, octant) << "node " << n << " child " << c << " sample " << k
                             << " lies in another octant of the mean than its siblings";
      }
      EXPECT_GT(octant, previous) << "node " << n << ": children not in octant order";
      previous = octant;
    }
    EXPECT_EQ(held, below.size()) << "node " << n;
  }
  EXPECT_EQ(ties, 0u) << "samples on a split plane: pick other data";
  return inner;
}

// Hand-computed (§3: "the one-to-eight subdivision is determined by the average of the points"):
// ten samples on a line at x = 0..8 and 20 average to x̄ = 56/10 = 5.6, so the root's children
// hold {0..5} and {6, 7, 8, 20}; the first (6 > 4 samples) splits again at its mean 2.5 into
// {0, 1, 2} and {3, 4, 5}. A split at the bounding box's centre (x = 10) would give {0..8}, {20}.
TEST(PointOctree, MeanSplitByHand) {
  point_set<disk_in> pts;
  for (const float x : {20.0f, 3.0f, 0.0f, 8.0f, 5.0f, 1.0f, 7.0f, 4.0f, 2.0f, 6.0f}) {
    pts.positions.emplace_back(x, 0.0f, 0.0f);
    pts.normals.emplace_back(0.0f, 0.0f, 1.0f);
    pts.axis_u.emplace_back(0.1f, 0.0f, 0.0f);
    pts.axis_v.emplace_back(0.0f, 0.1f, 0.0f);
  }
  const auto t = build_point_octree(pts, {.leaf_size = 4, .normal_bits = 0, .threads = 1});
  const auto xs = [&](std::uint32_t n) {
    std::vector<float> v;
    for (const auto k : subtree_samples(t, n)) v.push_back(t.samples().positions[k].x());
    std::sort(v.begin(), v.end());
    return v;
  };
  ASSERT_EQ(t.nodes().size(), 5u);  // root, {0..5}, {6, 7, 8, 20}, {0, 1, 2}, {3, 4, 5}
  EXPECT_FLOAT_EQ(t.at(0).centre.x(), 5.6f);
  ASSERT_EQ(t.at(0).count, 2u);
  const std::uint32_t lo = t.at(0).first, hi = lo + 1;
  EXPECT_EQ(xs(lo), (std::vector<float>{0, 1, 2, 3, 4, 5}));
  EXPECT_EQ(xs(hi), (std::vector<float>{6, 7, 8, 20}));
  EXPECT_FLOAT_EQ(t.at(lo).centre.x(), 2.5f);
  EXPECT_FLOAT_EQ(t.at(hi).centre.x(), 10.25f);
  EXPECT_TRUE(t.is_leaf(hi));
  ASSERT_FALSE(t.is_leaf(lo));
  EXPECT_EQ(xs(t.at(lo).first), (std::vector<float>{0, 1, 2}));
  EXPECT_EQ(xs(t.at(lo).first + 1), (std::vector<float>{3, 4, 5}));
}

// The same by brute force on 20 000 skewed samples (exponential in x, squared uniform in y: the
// mean is far from the bounding box's centre at every level), through the parallel build.
TEST(PointOctree, MeanSplitMatchesBruteForce) {
  std::mt19937 rng(42);  // any data will do; skewed so that mean and box centre differ
  std::exponential_distribution<float> ex(1.0f);
  std::uniform_real_distribution<float> u(0, 1);
  point_set<disk_in> pts;
  for (int i = 0; i < 20000; ++i) {
    const float y = u(rng);
    pts.positions.emplace_back(ex(rng), y * y, u(rng) - 0.5f);
    pts.normals.emplace_back(0.0f, 0.0f, 1.0f);
    pts.axis_u.emplace_back(0.01f, 0.0f, 0.0f);
    pts.axis_v.emplace_back(0.0f, 0.01f, 0.0f);
  }
  for (const unsigned threads : {1u, 2u}) {
    const auto t = build_point_octree(pts, {.leaf_size = 8, .threads = threads});
    EXPECT_GT(check_mean_split(t, 8), 500u) << "threads " << threads;
  }
}

/// What fit_ellipse() should have produced at node n, recomputed from the stored tree alone and
/// with other means (Eigen's 3×3 and 2×2 solvers, a frame of our own): the tangent covariance of
/// the samples below n about its centre plus the mean covariance (uuᵀ + vvᵀ)/4 of their disks
/// (docs/point-octree.md), its eigen-axes (EQ 5–6) scaled by the smallest f that covers the
/// corners c ± u ± v of the disks below (leaf: the samples', inner: the children's; Fig. 6b),
/// and the guard: the corners' bounding circle replaces the ellipse unless the ellipse is smaller
/// in area and its major axis at most the circle's diameter. `circle` also where the covariance
/// is round, as point_octree::is_circle() counts it.
struct expected_ellipse {
  double a, b;    ///< semi-axis lengths
  vec3d e1;       ///< major axis direction
  bool circle;    ///< the guard chose the bounding circle
  bool near_tie;  ///< within 10⁻⁴ of the guard's threshold: rounding decides
  bool round;     ///< λ₁ ≈ λ₂: the axis direction is not defined
};
template <class T>
expected_ellipse reference_ellipse(const T& t, std::uint32_t n, ellipse_axis_rule rule) {
  const auto& s = t.samples();
  const auto& nd = t.at(n);
  const vec3d c = nd.centre.template cast<double>(), nrm = nd.normal.template cast<double>();
  mat3d m = mat3d::Zero();
  const auto below = subtree_samples(t, n);
  for (const auto k : below) {
    const vec3d d = s.positions[k].template cast<double>() - c;
    const vec3d u = s.axis_u[k].template cast<double>(), v = s.axis_v[k].template cast<double>();
    m += d * d.transpose() + 0.25 * (u * u.transpose() + v * v.transpose());
  }
  m /= static_cast<double>(below.size());
  // Our own tangent frame: any orthonormal pair ⟂ n (the eigen-axes do not depend on it).
  const vec3d
      t1 = (std::abs(nrm.x()) < 0.6 ? vec3d::UnitX() : vec3d::UnitY()).cross(nrm).normalized(),
      t2 = nrm.cross(t1);
  Eigen::Matrix<double, 2, 3> P;
  P.row(0) = t1;
  P.row(1) = t2;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(P * m * P.transpose());
  const double l1 = std::max(0.0, es.eigenvalues()(1)), l2 = std::max(0.0, es.eigenvalues()(0));
  const vec3d e1 = (P.transpose() * es.eigenvectors().col(1)).normalized(), e2 = nrm.cross(e1);
  double a1 = rule == ellipse_axis_rule::eigenvalue ? l1 : std::sqrt(l1);
  double b1 = rule == ellipse_axis_rule::eigenvalue ? l2 : std::sqrt(l2);
  if (!(a1 > 1e-300)) a1 = b1 = 1;
  b1 = std::max(b1, 1e-3 * a1);
  double f2 = 0, r2 = 0;
  const auto visit = [&](const vec3f& corner) {
    const vec3d d = corner.template cast<double>() - c;
    const double x = d.dot(e1), y = d.dot(e2);
    f2 = std::max(f2, x * x / (a1 * a1) + y * y / (b1 * b1));
    r2 = std::max(r2, x * x + y * y);
  };
  const auto corners = [&](const vec3f& p, const vec3f& u, const vec3f& v) {
    for (const vec3f& q : std::array<vec3f, 4>{p + u + v, p + u - v, p - u + v, p - u - v})
      visit(q);
  };
  if (nd.leaf)
    for (const auto k : below) corners(s.positions[k], s.axis_u[k], s.axis_v[k]);
  else
    for (const auto ch : t.children(n)) corners(t.at(ch).centre, t.at(ch).axis_u, t.at(ch).axis_v);
  const double f = std::sqrt(f2), r = std::sqrt(r2);
  const double area_ratio = f2 * a1 * b1 / r2, length_ratio = f * a1 / (2 * r);
  expected_ellipse e{f * a1, f * b1, e1, false, false, (l1 - l2) <= 1e-3 * l1};
  // A round covariance (λ₁ = λ₂: a one-sample leaf with a circular disk, a symmetric grid)
  // scaled to reach the farthest corner is that corner's bounding circle; whether the guard then
  // fires is decided by rounding (its area ratio is exactly 1), and the disk is the same.
  const double anisotropy = (l1 - l2) / std::max(l1, 1e-300);
  const bool round = anisotropy <= 5e-7;
  e.circle = round || !(area_ratio < 1 && length_ratio <= 1);
  e.near_tie = !round && (anisotropy <= 1e-5 || std::abs(area_ratio - 1) < 1e-4 ||
                          std::abs(length_ratio - 1) < 1e-4);
  if (e.circle) e.a = e.b = r;
  return e;
}

/// Compares every node's stored ellipse with reference_ellipse(): lengths to 10⁻⁴ (the stored
/// ones carry f's 10⁻⁵ margin), the major axis to 0.1°, circle or not as the guard says. Returns
/// {circles the rule predicts, circles stored (is_circle), near ties skipped, ellipses kept}.
struct shape_counts {
  std::size_t predicted_circles = 0, stored_circles = 0, ties = 0, ellipses = 0;
};
template <class T>
shape_counts check_ellipse_shapes(const T& t, ellipse_axis_rule rule) {
  shape_counts out;
  for (std::uint32_t n = 0; n < t.nodes().size(); ++n) {
    const auto& nd = t.at(n);
    const expected_ellipse e = reference_ellipse(t, n, rule);
    out.stored_circles += t.is_circle(n);
    if (e.near_tie) {
      ++out.ties;
      continue;
    }
    out.predicted_circles += e.circle;
    out.ellipses += !e.circle;
    EXPECT_EQ(t.is_circle(n), e.circle) << "node " << n << (e.circle ? " should" : " should not")
                                        << " fall back to the bounding circle";
    EXPECT_NEAR(nd.axis_u.norm(), e.a, 1e-4 * e.a) << "node " << n;
    EXPECT_NEAR(nd.axis_v.norm(), e.b, 1e-4 * e.a) << "node " << n;
    if (!e.circle && !e.round) {
      EXPECT_GT(std::abs(nd.axis_u.template cast<double>().normalized().dot(e.e1)),
                std::cos(0.1 * std::numbers::pi / 180))
          << "node " << n << ": major axis off the covariance's eigenvector";
    }
  }
  return out;
}

/// A planar patch 4:1: a (2·80 + 1) × (2·20 + 1) grid of spacing h in the plane through o with
/// normal n, stretched along d1, each sample a circular disk of radius h.
struct stretched_patch {
  vec3d o{3, -2, 5};
  vec3d n = vec3d(1, 2, 2) / 3;
  vec3d d1 = vec3d(2, -1, 0) / std::sqrt(5.0);  // ⟂ n
  vec3d d2 = n.cross(d1);
  double h = 0.025;
  int nx = 80, ny = 20;
  point_set<disk_in> points() const {
    point_set<disk_in> p;
    p.origin = o;
    for (int i = -nx; i <= nx; ++i)
      for (int j = -ny; j <= ny; ++j) {
        p.positions.push_back((i * h * d1 + j * h * d2).cast<float>());
        p.normals.push_back(n.cast<float>());
        p.axis_u.push_back((h * d1).cast<float>());
        p.axis_v.push_back((h * d2).cast<float>());
      }
    return p;
  }
  /// EQ 5–6 for the whole patch: the grid's variances h²((2k + 1)² − 1)/12 along d1 and d2, plus
  /// the disks' r²/4 each.
  double lambda1() const { return h * h * ((2 * nx + 1) * (2 * nx + 1) - 1) / 12 + h * h / 4; }
  double lambda2() const { return h * h * ((2 * ny + 1) * (2 * ny + 1) - 1) / 12 + h * h / 4; }
};

// EQ 5–6 analytically: one leaf holding the whole 4:1 patch. Its ellipse's axes are the patch's
// directions; with a' = √λ the lengths are f·√λ₁ and f·√λ₂ with f² = x²/λ₁ + y²/λ₂ at the
// outermost disk corner (x, y) = (80h + h, 20h + h). With the paper's a' = λ (EQ 6 as printed)
// the same patch gives a ≈ 8.3 > 2r: the guard draws the corners' bounding circle of radius
// |(x, y)| instead.
TEST(PointOctree, EllipseOfAStretchedPatchIsAnalytic) {
  const stretched_patch patch;
  const auto pts = patch.points();
  const double l1 = patch.lambda1(), l2 = patch.lambda2();
  const double x = (patch.nx + 1) * patch.h, y = (patch.ny + 1) * patch.h;
  for (const int bits : {0, 16}) {
    SCOPED_TRACE(::testing::Message() << "normal_bits " << bits);
    const auto t = build_point_octree(pts, {.leaf_size = 1u << 20, .normal_bits = bits});
    ASSERT_EQ(t.nodes().size(), 1u);
    const auto& root = t.at(0);
    const double f = std::sqrt(x * x / l1 + y * y / l2);
    // Quantised (16 bits), the stored axes turn by up to a few tenths of a degree, which moves
    // f by per cents (the corner's y grows by x·θ): the lengths are checked unquantised, the
    // ratio (λ's only, computed before quantisation) and the directions both ways.
    if (bits == 0) {
      EXPECT_NEAR(root.axis_u.norm(), f * std::sqrt(l1), 2e-5 * f * std::sqrt(l1));
      EXPECT_NEAR(root.axis_v.norm(), f * std::sqrt(l2), 2e-5 * f * std::sqrt(l1));
    }
    EXPECT_NEAR(root.axis_u.norm() / root.axis_v.norm(), std::sqrt(l1 / l2), 1e-4);
    const double cos_tol = bits ? 1e-4 : 1e-6;  // 0.8° and 0.08°
    EXPECT_GT(std::abs(root.axis_u.cast<double>().normalized().dot(patch.d1)), 1 - cos_tol);
    EXPECT_GT(std::abs(root.axis_v.cast<double>().normalized().dot(patch.d2)), 1 - cos_tol);
    EXPECT_GT(std::abs(root.normal.cast<double>().dot(patch.n)), 1 - cos_tol);
    EXPECT_FALSE(t.is_circle(0));
    EXPECT_EQ(t.stats().circle_fallbacks, 0u);

    const auto paper = build_point_octree(
        pts,
        {.leaf_size = 1u << 20, .axis_rule = ellipse_axis_rule::eigenvalue, .normal_bits = bits});
    const double r = std::hypot(x, y);
    EXPECT_NEAR(paper.at(0).axis_u.norm(), r, 1e-4 * r);
    EXPECT_NEAR(paper.at(0).axis_v.norm(), r, 1e-4 * r);
    EXPECT_TRUE(paper.is_circle(0));
    EXPECT_EQ(paper.stats().circle_fallbacks, 1u);
  }
}

// The same patch in a deep tree (leaf size 8): the root's ellipse covers its children's, so f is
// larger, but its axes still follow the patch and their ratio is still √(λ₁/λ₂) ≈ 3.93 — a
// builder that always drew circles (ratio 1) or swapped the axes fails here. Every node is then
// checked against reference_ellipse().
TEST(PointOctree, EllipsesFollowTheCovarianceAtEveryLevel) {
  const stretched_patch patch;
  const auto t = build_point_octree(patch.points(), {.leaf_size = 8, .normal_bits = 0});
  const auto& root = t.at(0);
  EXPECT_FALSE(t.is_leaf(0));
  EXPECT_NEAR(root.axis_u.norm() / root.axis_v.norm(), std::sqrt(patch.lambda1() / patch.lambda2()),
              1e-4);
  EXPECT_GT(std::abs(root.axis_u.cast<double>().normalized().dot(patch.d1)), 1 - 1e-6);
  const auto c = check_ellipse_shapes(t, ellipse_axis_rule::sqrt_eigenvalue);
  std::printf("patch: %zu nodes, %zu ellipses, %zu circles, %zu near ties\n", t.nodes().size(),
              c.ellipses, c.predicted_circles, c.ties);
  EXPECT_GT(c.ellipses, t.nodes().size() / 2);
  EXPECT_EQ(t.stats().circle_fallbacks, c.stored_circles);
}

// circle_fallbacks on a crafted input where the answer is known: eight clusters at the corners
// of a 40 × 10 × 10 box, one leaf each (16 samples, leaf size 16; the root's mean is the box's
// centre, so each cluster is alone in its octant). Four are "bars" — a 4 × 4 grid 3 × 0.3 — whose
// EQ 5–6 ellipse (f² = 3.6, a·b = 0.45 < r² = 2.27) is kept; four are "crosses" — 7 samples at
// (±1, 0), 1 at (0, ±1) — whose ellipse, elongated along x (λ₁ = 7/8, λ₂ = 1/8), must stretch to
// reach (0, ±1): f² = 1/λ₂ = 8, a = f·√λ₁ = √7 ≈ 2.65 > 2r = 2 and a·b = √7 > r² = 1, so the
// bounding circle replaces it. The root (a 4:1
// spread of clusters) keeps its ellipse. So: exactly the four cross leaves fall back, and the
// count survives save() and load().
TEST(PointOctree, CircleFallbacksMatchTheRuleOnACraftedInput) {
  point_set<disk_in> pts;
  std::vector<vec3d> cross_centres;
  int corner = 0;
  for (const double cx : {-20.0, 20.0})
    for (const double cy : {-5.0, 5.0})
      for (const double cz : {-5.0, 5.0}) {
        const bool cross = (corner++ % 2) == 0;
        std::vector<vec3d> local;
        if (cross) {
          cross_centres.emplace_back(cx, cy, cz);
          for (int k = 0; k < 7; ++k) local.emplace_back(-1, 0, 0);
          for (int k = 0; k < 7; ++k) local.emplace_back(1, 0, 0);
          local.emplace_back(0, 1, 0);
          local.emplace_back(0, -1, 0);
        } else {
          for (const double x : {-1.5, -0.5, 0.5, 1.5})
            for (const double y : {-0.15, -0.05, 0.05, 0.15}) local.emplace_back(x, y, 0);
        }
        for (const vec3d& p : local) {
          pts.positions.push_back((vec3d(cx, cy, cz) + p).cast<float>());
          pts.normals.emplace_back(0.0f, 0.0f, 1.0f);
          pts.axis_u.emplace_back(0.01f, 0.0f, 0.0f);
          pts.axis_v.emplace_back(0.0f, 0.01f, 0.0f);
        }
      }
  const auto t = build_point_octree(pts, {.leaf_size = 16, .normal_bits = 0});
  ASSERT_EQ(t.nodes().size(), 9u);
  std::size_t cross_leaves = 0;
  for (std::uint32_t n = 1; n < 9; ++n) {
    ASSERT_TRUE(t.is_leaf(n));
    const vec3d c = t.at(n).centre.cast<double>();
    const bool cross = std::any_of(cross_centres.begin(), cross_centres.end(),
                                   [&](const vec3d& q) { return (q - c).norm() < 1e-3; });
    cross_leaves += cross;
    EXPECT_EQ(t.is_circle(n), cross) << "leaf " << n << " at " << c.transpose();
  }
  EXPECT_EQ(cross_leaves, 4u);
  EXPECT_FALSE(t.is_circle(0));
  EXPECT_EQ(t.stats().circle_fallbacks, 4u);
  // The brute-force rule agrees node by node, with no near ties on this input.
  const auto c = check_ellipse_shapes(t, ellipse_axis_rule::sqrt_eigenvalue);
  EXPECT_EQ(c.predicted_circles, 4u);
  EXPECT_EQ(c.ties, 0u);
  // A loaded file has no timings, but the count is recomputed from its nodes.
  const auto path = std::filesystem::temp_directory_path() / "pbr_lod_octree_fallbacks.lod";
  t.save(path.string());
  const auto back = octree_d::load(path.string());
  std::filesystem::remove(path);
  EXPECT_FALSE(back.stats().has_timings);
  EXPECT_EQ(back.stats().circle_fallbacks, 4u);
}

// The same input with circle_guard = false keeps the paper's EQ 5–6 ellipse everywhere: no
// circles, and each cross leaf's ellipse has the lengths worked out above, a = f·√λ₁ = √7 and
// b = f·√λ₂ = 1 (to 2 %: the 0.01 disks add their corners and covariance), still covering
// every corner.
TEST(PointOctree, WithoutTheCircleGuardTheCrossesKeepTheirEllipses) {
  point_set<disk_in> pts;
  for (const double cx : {-20.0, 20.0})
    for (const double cy : {-5.0, 5.0}) {
      std::vector<vec3d> local;
      for (int k = 0; k < 7; ++k) local.emplace_back(-1, 0, 0);
      for (int k = 0; k < 7; ++k) local.emplace_back(1, 0, 0);
      local.emplace_back(0, 1, 0);
      local.emplace_back(0, -1, 0);
      for (const vec3d& p : local) {
        pts.positions.push_back((vec3d(cx, cy, 0) + p).cast<float>());
        pts.normals.emplace_back(0.0f, 0.0f, 1.0f);
        pts.axis_u.emplace_back(0.01f, 0.0f, 0.0f);
        pts.axis_v.emplace_back(0.0f, 0.01f, 0.0f);
      }
    }
  const auto guarded = build_point_octree(pts, {.leaf_size = 16, .normal_bits = 0});
  EXPECT_EQ(guarded.stats().circle_fallbacks, 4u);
  const auto t =
      build_point_octree(pts, {.leaf_size = 16, .circle_guard = false, .normal_bits = 0});
  ASSERT_EQ(t.nodes().size(), 5u);
  EXPECT_EQ(t.stats().circle_fallbacks, 0u);
  for (std::uint32_t n = 1; n < 5; ++n) {
    ASSERT_TRUE(t.is_leaf(n));
    EXPECT_FALSE(t.is_circle(n));
    const auto& nd = t.at(n);
    EXPECT_NEAR(nd.axis_u.norm(), std::sqrt(7.0), 0.02 * std::sqrt(7.0)) << "leaf " << n;
    EXPECT_NEAR(nd.axis_v.norm(), 1.0, 0.02) << "leaf " << n;
    EXPECT_GT(std::abs(nd.axis_u.normalized().x()), 0.999f) << "major axis along x";
    // Every sample's disk corner inside the ellipse.
    const vec3f e1 = nd.axis_u / nd.axis_u.squaredNorm(), e2 = nd.axis_v / nd.axis_v.squaredNorm();
    for (std::uint32_t i = 0; i < pts.positions.size(); ++i) {
      const vec3f d = pts.positions[i] - nd.centre;
      if (d.norm() > 2) continue;  // another cluster
      for (const float sx : {-1.0f, 1.0f})
        for (const float sy : {-1.0f, 1.0f}) {
          const vec3f c = d + sx * pts.axis_u[i] + sy * pts.axis_v[i];
          EXPECT_LE(detail::squared(c.dot(e1)) + detail::squared(c.dot(e2)), 1.0f + 1e-5f);
        }
    }
  }
}

// On the demo scene (curved, coloured, estimated ellipses; both axis rules): every node's
// ellipse is the brute-force one, circle_fallbacks is the rule's count, and most nodes keep a
// true ellipse (a builder that always drew circles fails the lengths and this count).
TEST(PointOctree, EllipsesAndFallbacksOnTheDemoSceneMatchBruteForce) {
  const auto pts = demo_points(20000, 5);
  for (const auto rule : {ellipse_axis_rule::sqrt_eigenvalue, ellipse_axis_rule::eigenvalue}) {
    const auto t = build_point_octree(pts, {.axis_rule = rule, .normal_bits = 0});
    const auto c = check_ellipse_shapes(t, rule);
    std::printf("demo scene, rule %d: %zu nodes, %zu ellipses, %zu circles (stats %zu), %zu ties\n",
                static_cast<int>(rule), t.nodes().size(), c.ellipses, c.predicted_circles,
                t.stats().circle_fallbacks, c.ties);
    // With a' = λ a one-sample leaf is an exact tie: its corners (±|u|, ±|v|) and λᵢ = |·|²/4
    // give f²·a'·b' = |u|² + |v|² = r², so rounding decides between ellipse and circle (with
    // a' = √λ the same leaf gives 2|u||v| < r²: a clear ellipse).
    std::size_t single = 0;
    for (const auto& nd : t.nodes()) single += nd.leaf && nd.count == 1;
    EXPECT_LE(c.ties,
              t.nodes().size() / 100 + (rule == ellipse_axis_rule::eigenvalue ? single : 0));
    EXPECT_LE(t.stats().circle_fallbacks, c.predicted_circles + c.ties);
    EXPECT_GE(t.stats().circle_fallbacks, c.predicted_circles);
    EXPECT_EQ(t.stats().circle_fallbacks, c.stored_circles);
    // The paper's a' = λ is more elongated, so its guard fires far more often (see the docs).
    EXPECT_GT(c.ellipses, t.nodes().size() / (rule == ellipse_axis_rule::sqrt_eigenvalue ? 2 : 10));
  }
}

using recording_policy = test::recording_policy<point_octree_policy>;

/// Pajarola §6, Fig. 11, computed in double from the node's stored geometry and the camera alone
/// (not from the policy's derived selection records or the float view): the diameter of the
/// circle whose area is the disk's projected area cos(γ − θ_c)·πab·d²/((c − e)·w)², with
/// cos(γ − θ_c) = 1 while γ ≤ θ_c; +∞ once the node's sphere reaches the eye plane.
double reference_screen_size(const octree_nc& t, std::uint32_t n, const camera& cam) {
  const auto& nd = t.at(n);
  const vec3d ce = t.origin() + nd.centre.cast<double>() - cam.eye;
  const vec3d w = (cam.target - cam.eye).normalized();
  const double depth = ce.dot(w);
  if (depth <= nd.radius) return std::numeric_limits<double>::infinity();
  const double focal = 0.5 * cam.vp.height / std::tan(cam.fovy_degrees * std::numbers::pi / 360);
  const double gamma =
      std::acos(std::min(1.0, std::abs(nd.normal.cast<double>().dot(ce)) / ce.norm()));
  const double tilt = gamma > nd.cone_angle ? std::cos(gamma - nd.cone_angle) : 1.0;
  const double area = std::numbers::pi * nd.axis_u.cast<double>().norm() *
                      nd.axis_v.cast<double>().norm() * focal * focal / (depth * depth);
  return 2 * std::sqrt(std::max(0.0, tilt * area) / std::numbers::pi);
}

// LOD selection (§6): with culling off, the policy's cut is the brute-force one — descend from
// the root while the reference screen size exceeds τ, take the node where it does not (or the
// leaf) — and a larger τ draws fewer splats. Only nodes within float rounding of τ may differ.
TEST(PointOctree, TiltedAreaPolicyRespectsTolerance) {
  const auto pts = dense_points(200000, 4);
  const auto t = build_point_octree(pts);
  const auto cam = camera::orbit(vec3d(0, 1, 0) + pts.origin, 2.8, 30, 20, 3, 1, {256, 256});
  const view v(cam, t.origin());
  std::size_t previous = std::numeric_limits<std::size_t>::max();
  for (const float tol : {1.0f, 2.0f, 4.0f, 8.0f, 16.0f}) {
    std::vector<std::uint32_t> expected, near_tie, stack{t.root()};
    while (!stack.empty()) {
      const std::uint32_t n = stack.back();
      stack.pop_back();
      const double size = reference_screen_size(t, n, cam);
      if (std::abs(size - tol) < 1e-4 * tol) near_tie.push_back(n);
      if (t.is_leaf(n) || size <= tol)
        expected.push_back(n);
      else
        for (const auto c : t.children(n)) stack.push_back(c);
    }
    counting_sink<octree_nc::attrs> sink;
    const traverse_options o{.tolerance_px = tol, .frustum_cull = false};
    std::vector<std::uint32_t> emitted;
    const auto st = traverse(t, v, o, sink, recording_policy{{}, &emitted});
    std::sort(expected.begin(), expected.end());
    std::sort(emitted.begin(), emitted.end());
    std::vector<std::uint32_t> differ;
    std::set_symmetric_difference(expected.begin(), expected.end(), emitted.begin(), emitted.end(),
                                  std::back_inserter(differ));
    std::printf("tau %g: %zu drawn, %zu differ from the brute force, %zu near-ties\n", tol,
                emitted.size(), differ.size(), near_tie.size());
    // A tie at a node changes which of it and its descendants are drawn: allow a few per tie.
    EXPECT_LE(differ.size(), 9 * near_tie.size())
        << "tau " << tol << ": " << emitted.size() << " drawn, " << expected.size() << " expected";
    EXPECT_GT(emitted.size(), 100u);
    EXPECT_LE(sink.splats, previous);
    EXPECT_EQ(sink.splats + sink.points, st.splats + st.points);
    previous = sink.splats;
  }
  EXPECT_LT(previous, pts.size() / 10);
}

// Rendering at τ = 1 px matches the full-detail render (every sample's own splat) closely.
// Thresholds: at 1 px the cut replaces groups of samples by one bounding splat no larger than a
// pixel, so colours blend over ~1 px (PSNR well above 25 dB) and bounding splats cover at least
// what the samples cover (holes < 0.5 %; the only holes come from back-face/edge rounding).
TEST(PointOctree, ToleranceOnePixelIsCloseToFullDetail) {
  const auto pts = dense_points(300000, 8);
  const auto t = build_point_octree(pts);
  const auto cam = camera::orbit(vec3d(-0.2, 0.9, 0) + pts.origin, 2.6, 30, 20, 3, 1, {256, 256});
  const view v(cam, t.origin());
  render_options ro;
  ro.fx = effects{.shading = true, .colour = true};
  const auto draw_all = [&](auto& sink) {
    traverse(t, v, {.tolerance_px = 0}, sink, point_octree_policy{});
  };
  const auto draw_lod = [&](auto& sink) {
    traverse(t, v, {.tolerance_px = 1}, sink, point_octree_policy{});
  };
  const image full = render<octree_nc::attrs>(v, ro, draw_all);
  const image lod = render<octree_nc::attrs>(v, ro, draw_lod);
  const auto err = compare_images(full, lod);
  counting_sink<octree_nc::attrs> c1, c0, c4;
  traverse(t, v, {.tolerance_px = 1}, c1, point_octree_policy{});
  traverse(t, v, {.tolerance_px = 0}, c0, point_octree_policy{});
  EXPECT_LT(c1.splats, c0.splats);  // the cut is coarser than full detail
  // τ = 4: far fewer splats, still no real holes (bounding splats cover their subtrees).
  const image lod4 = render<octree_nc::attrs>(
      v, ro, [&](auto& sink) { traverse(t, v, {.tolerance_px = 4}, sink, point_octree_policy{}); });
  traverse(t, v, {.tolerance_px = 4}, c4, point_octree_policy{});
  const auto err4 = compare_images(full, lod4);
  EXPECT_LT(c4.splats, c0.splats / 4);
  EXPECT_GT(err4.psnr, 18.0);
  EXPECT_LT(err4.hole_fraction, 0.01);
  std::printf(
      "tau=1: %zu of %zu splats, PSNR %.2f dB, holes %.5f; tau=4: %zu splats, PSNR %.2f, holes "
      "%.5f\n",
      c1.splats, c0.splats, err.psnr, err.hole_fraction, c4.splats, err4.psnr, err4.hole_fraction);
  EXPECT_GT(err.psnr, 25.0);
  EXPECT_LT(err.hole_fraction, 0.005);
}

// ---- What the user sees: the finest cut against the input mesh's own render ----------------

/// The finest cut (τ = 1, blended splats: the tool's default effects) of a point-octree built
/// from `cloud`, scored against the mesh's render from test::user_views, and its distance to the
/// mesh (cut positions: splat centres and rims).
struct finest_cut_result {
  test::user_view_score score;
  double cut_to_input = 0;
  std::size_t splats = 0;
};

int png_calls = 0;  // numbers the PBR_LOD_TEST_PNG images of finest_cut_against

template <attributes In>
finest_cut_result finest_cut_against(const triangle_mesh& mesh, const point_cloud& cloud,
                                     int size = 256) {
  const auto t = build_point_octree(point_set<In>::from(cloud));
  constexpr attributes A = decltype(t)::attrs;
  const auto cams = test::user_views(test::frame_of(mesh.vertices), size);
  render_options ro;
  ro.fx = effects{.shading = true, .colour = true, .blending = true};
  finest_cut_result r;
  // PBR_LOD_TEST_PNG=prefix writes one image per call and view, prefix_C_V.png: the input's
  // render, the cut's and their absolute difference × 4, side by side.
  const char* png = std::getenv("PBR_LOD_TEST_PNG");
  const int call = png_calls++;
  std::vector<image> inputs, cuts;
  r.score = test::score_views(
      cams,
      [&](const camera& c) {
        image img = render_reference(mesh, c, ro);
        if (png) inputs.push_back(img);
        return img;
      },
      [&](const camera& c) {
        const view v(c, t.origin());
        image img = render<A>(v, ro, [&](auto& sink) {
          traverse(t, v, {.tolerance_px = 1}, sink, point_octree_policy{});
        });
        if (png) cuts.push_back(img);
        return img;
      });
  for (std::size_t i = 0; i < cuts.size(); ++i)
    write_png(std::string(png) + "_" + std::to_string(call) + "_" + std::to_string(i) + ".png",
              test::side_by_side_with_error(inputs[i], cuts[i]));
  buffer_sink<A> cut;
  const view v0(cams[0], t.origin());
  traverse(t, v0, {.tolerance_px = 1, .frustum_cull = false}, cut, point_octree_policy{});
  r.splats = cut.splats.size();
  r.cut_to_input = test::cut_to_input(mesh, test::cut_positions(cut), t.origin());
  for (std::size_t i = 0; i < r.score.per_view.size(); ++i)
    std::printf("  view %zu: interior PSNR %.2f dB, IoU %.4f, interior holes %zu of %zu\n", i,
                r.score.per_view[i].psnr_interior, r.score.per_view[i].silhouette_iou,
                r.score.per_view[i].interior_holes, r.score.per_view[i].interior_pixels);
  std::printf(
      "finest cut: %zu splats, interior PSNR min %.2f / mean %.2f dB, IoU min %.4f, "
      "cut->input %.5f of the diagonal\n",
      r.splats, r.score.psnr_interior_min, r.score.psnr_interior_mean, r.score.iou_min,
      r.cut_to_input);
  return r;
}

// The hard cases (two spheres 0.04 apart, an open floor with a hole, a concave crease, colours)
// sampled as a scan would be: points with normals and colours, splats estimated from k-NN,
// against the mesh's render. Issue 39's targets are ≥ 28 dB inside the silhouette, IoU ≥ 0.97
// and cut → input ≤ 0.01 of the diagonal. Measured: worst view 27.42 dB, mean 30.64, IoU 0.976,
// cut → input 0.0127 (before estimated ellipses were clipped at open edges and creases: 25.56,
// 30.21, 0.959, 0.0137; docs/estimation.md). The floors hold what it reaches, a little below,
// so a regression fails.
TEST(PointOctree, FinestCutLooksLikeTheHardCasesMesh) {
  const triangle_mesh mesh = make_hard_cases_scene(48);
  const point_cloud cloud = sample_surface(mesh, 120000, 3);
  const auto r = finest_cut_against<attributes{.normal = true, .colour = true}>(mesh, cloud);
  EXPECT_GE(r.score.psnr_interior_min, 27.0);  // target 28
  EXPECT_GE(r.score.psnr_interior_mean, 30.0);
  EXPECT_GE(r.score.iou_min, 0.97);
  EXPECT_LE(r.cut_to_input, 0.0135);  // target 0.01
}

// The same surface from its positions alone (normals estimated, no colours).
TEST(PointOctree, FinestCutLooksLikeTheHardCasesMeshFromPositions) {
  const triangle_mesh mesh = make_hard_cases_scene(48);
  point_cloud cloud = sample_surface(mesh, 120000, 5);
  cloud.normals.clear();
  cloud.colours.clear();
  triangle_mesh grey = mesh;
  grey.vertices.colours.clear();
  const auto r = finest_cut_against<positions_only>(grey, cloud);
  // Measured: worst view 26.38 dB, mean 31.94, IoU 0.977, cut → input 0.0108 (before the
  // clip: 24.27, 31.97, 0.958, 0.0141; targets as above).
  EXPECT_GE(r.score.psnr_interior_min, 26.0);
  EXPECT_GE(r.score.psnr_interior_mean, 31.5);
  EXPECT_GE(r.score.iou_min, 0.97);
  EXPECT_LE(r.cut_to_input, 0.0115);
}

// The hard cases' mesh as `pbrlod build` and the sweep give it to the point-octree: its vertices
// as splats bounding their dual cells, with the mesh's normals and colours (core/mesh_splats.hpp).
// Measured: worst view 25.30 dB, mean 26.28, IoU 0.968, cut → input 0.0097 (what is left: each
// checker tile has its own vertices, and their splats blend the two colours across its edges).
TEST(PointOctree, FinestCutLooksLikeTheHardCasesMeshFromItsVertices) {
  const triangle_mesh mesh = make_hard_cases_scene(48);
  const auto r = finest_cut_against<attributes{.normal = true, .colour = true, .ellipse = true}>(
      mesh, mesh_splats(mesh));
  EXPECT_GE(r.score.psnr_interior_min, 24.5);
  EXPECT_GE(r.score.iou_min, 0.96);
  EXPECT_LE(r.cut_to_input, 0.011);
}

// Meshes it was not tuned on, as `pbrlod build` builds them: their vertices as splats bounding
// their dual cells, with area-weighted normals (core/mesh_splats.hpp; no colours): the happy
// Buddha (res3) and the cow. Skipped without the shared data. Issue 39's targets: 28 dB, IoU
// 0.97, cut → input 0.01. Measured worst view / IoU / cut → input: 25.27 dB / 0.985 / 0.0062
// (Buddha; from its positions alone with estimated normals and ellipses 20.84 / 0.936 / 0.0168),
// 29.19 dB / 0.976 / 0.0092 (cow, 2,930 vertices; estimated 22.76 / 0.863 / 0.0259) and
// 33.55 dB / 0.991 / 0.0086 (the bunny, measured only: 34,740 of its vertices have faces).
// Floors a little below, per mesh.
TEST(PointOctree, FinestCutLooksLikeUnseenMeshes) {
  struct floors {
    const char* name;
    double psnr, iou, cut;
  };
  for (const floors f : {floors{"happy_vrip_res3.ply", 24.5, 0.975, 0.0075},
                         floors{"cow.obj", 28.5, 0.97, 0.011}, floors{"bun_zipper.ply", 0, 0, 1}}) {
    const char* name = f.name;
    // data_file throws when the scan is missing: ctest reports that as skipped, CI=true fails.
    triangle_mesh mesh = read_mesh(test::data_file(name));
    std::printf("%s\n", name);
    mesh.vertices.colours.clear();
    mesh.texture.reset();  // shape and shading: the cow drawn untextured on both sides
    const point_cloud cloud = mesh_splats(mesh);
    const auto r = finest_cut_against<attributes{.normal = true, .ellipse = true}>(mesh, cloud);
    EXPECT_GE(r.score.psnr_interior_min, f.psnr) << name;
    EXPECT_GE(r.score.iou_min, f.iou) << name;
    EXPECT_LE(r.cut_to_input, f.cut) << name;
  }
}

// The same meshes' vertices as a scan without normals arrives: normals and ellipses estimated
// from the k nearest neighbours (core/estimation.hpp). Measured worst view / IoU / cut → input:
// 20.85 dB / 0.936 / 0.0147 (Buddha: 44.6 % of its MST normals flipped, docs/estimation.md) and
// 22.76 dB / 0.863 / 0.0259 (cow: ellipses two rings wide on 2,930 vertices blur its silhouette),
// 31.15 dB / 0.967 / 0.0130 (bunny).
TEST(PointOctree, FinestCutLooksLikeUnseenMeshesFromPositions) {
  struct floors {
    const char* name;
    double psnr, iou, cut;
  };
  for (const floors f : {floors{"happy_vrip_res3.ply", 20.5, 0.93, 0.0155},
                         floors{"cow.obj", 22.5, 0.86, 0.027}, floors{"bun_zipper.ply", 0, 0, 1}}) {
    const char* name = f.name;
    triangle_mesh mesh = read_mesh(test::data_file(name));
    std::printf("%s\n", name);
    point_cloud cloud = mesh.vertices;
    cloud.normals.clear();
    cloud.colours.clear();
    mesh.vertices.colours.clear();
    mesh.texture.reset();
    const auto r = finest_cut_against<positions_only>(mesh, cloud);
    EXPECT_GE(r.score.psnr_interior_min, f.psnr) << name;
    EXPECT_GE(r.score.iou_min, f.iou) << name;
    EXPECT_LE(r.cut_to_input, f.cut) << name;
  }
}

}  // namespace
}  // namespace pbr_lod
