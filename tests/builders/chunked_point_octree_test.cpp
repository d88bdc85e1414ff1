// The chunked (out-of-core) point-octree: the chunked layer's suite (chunked_suite.hpp), and what
// is the point-octree's own: its cuts, its lazy loading from several threads, its estimation.
#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <barrier>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <sstream>
#include <thread>

#include "chunked_suite.hpp"
#include "pbr_lod/builders/chunked_point_octree.hpp"
#include "pbr_lod/core/synthetic.hpp"

namespace pbr_lod {
namespace {

namespace fs = std::filesystem;

std::string temp_dir(const std::string& what) {
  return test::temp_dir("pbr_lod_chunked_", what);
}
using test::bytes_of;
using test::expect_same_folders;

/// The wavy surface with normals and colours, plus a few returns far off it: their chunks hold
/// fewer points than a neighbourhood, so their halo is everything.
point_cloud surface_with_strays(std::size_t n) {
  point_cloud c = make_wavy_surface(n, 7);
  for (int i = 0; i < 5; ++i) {
    c.positions.push_back(vec3f(3.0f + 0.01f * static_cast<float>(i), 2.5f, -2.0f));
    c.normals.push_back(vec3f::UnitY());
    c.colours.push_back({255, 0, 0});
  }
  return c;
}

template <class T>
void expect_same_splats(const buffer_sink<T::attrs>& a, const buffer_sink<T::attrs>& b) {
  ASSERT_EQ(a.splats.size(), b.splats.size());
  ASSERT_EQ(a.points.size(), b.points.size());
  std::size_t differ = 0;
  for (std::size_t i = 0; i < a.splats.size(); ++i) {
    const auto &s = a.splats[i], &t = b.splats[i];
    bool same = s.centre == t.centre && s.u == t.u && s.v == t.v && s.normal == t.normal;
    if constexpr (T::attrs.colour) same = same && s.colour == t.colour;
    differ += same ? 0 : 1;
  }
  EXPECT_EQ(differ, 0u) << "splats differ between the chunked and the in-memory cut";
}

/// Where two point-octrees first differ (for the failure message).
template <class T>
std::string first_difference(const T& a, const T& b) {
  std::ostringstream out;
  for (std::size_t i = 0; i < std::min(a.nodes().size(), b.nodes().size()); ++i) {
    const auto &x = a.at(static_cast<std::uint32_t>(i)), &y = b.at(static_cast<std::uint32_t>(i));
    if (x.centre != y.centre || x.radius != y.radius || x.normal != y.normal ||
        x.cone_angle != y.cone_angle || x.axis_u != y.axis_u || x.axis_v != y.axis_v ||
        x.first != y.first || x.count != y.count || x.leaf != y.leaf || x.depth != y.depth) {
      out << "node " << i << " (depth " << int(x.depth) << ", leaf " << int(x.leaf) << "): centre "
          << (x.centre - y.centre).norm() << " radius " << x.radius - y.radius << " normal "
          << (x.normal - y.normal).norm() << " cone " << x.cone_angle - y.cone_angle << " axes "
          << (x.axis_u - y.axis_u).norm() << "/" << (x.axis_v - y.axis_v).norm() << " first "
          << x.first << "/" << y.first;
      return out.str();
    }
  }
  for (std::size_t i = 0; i < std::min(a.samples().size(), b.samples().size()); ++i)
    if (a.samples().positions[i] != b.samples().positions[i] ||
        a.samples().normals[i] != b.samples().normals[i] ||
        a.samples().axis_u[i] != b.samples().axis_u[i])
      return "sample " + std::to_string(i);
  return a.nodes().size() == b.nodes().size() ? "codes or colours" : "node counts";
}
template <class T>
std::string sample_differences(const T& a, const T& b) {
  std::ostringstream out;
  std::size_t k = 0;
  for (std::size_t i = 0; i < std::min(a.samples().size(), b.samples().size()); ++i)
    if (a.samples().axis_u[i] != b.samples().axis_u[i] ||
        a.samples().axis_v[i] != b.samples().axis_v[i]) {
      if (k++ < 5)
        out << " [" << i << " at " << a.samples().positions[i].transpose() << " du "
            << (a.samples().axis_u[i] - b.samples().axis_u[i]).norm() << "]";
    }
  out << " total " << k;
  return out.str();
}

using coloured = point_octree<point_octree_attributes(attributes{.colour = true})>;

/// The point-octree's case of the chunked layer's suite (chunked_suite.hpp).
struct point_octree_case {
  using options = chunked_point_octree_options;
  using hierarchy = chunked_point_octree<point_octree_attributes(attributes{.colour = true})>;
  using uncoloured = chunked_point_octree<point_octree_attributes(attributes{})>;
  using tree = coloured;
  static constexpr const char* name = "chunked";
  static point_cloud cloud() { return surface_with_strays(60000); }
  static options options_for_many() {
    options o;
    o.chunk_points = 2500;  // ~50 chunks over 3-4 levels of top nodes
    return o;
  }
  static chunked_build_report build(const point_source& src, const std::string& dir,
                                    const options& o) {
    return build_point_octree_chunked(src, dir, o);
  }
  static tree in_memory(const point_cloud& c, const options& o) {
    return build_point_octree(point_set<attributes{.normal = true, .colour = true}>::from(c),
                              o.builder);
  }
  static void expect_equal(const tree& whole, const tree& memory) {
    EXPECT_TRUE(whole == memory) << first_difference(whole, memory)
                                 << sample_differences(whole, memory);
  }
  static std::string chunk_file(std::uint32_t c) { return chunk_file_name(c); }
  static bool is_chunked(const std::string& dir) { return is_chunked_point_octree(dir); }
  static bool has_colours(const std::string& dir) { return chunked_folder_has_colours(dir); }
  static std::vector<std::unique_ptr<point_source>> ranks_sources() {
    std::vector<std::unique_ptr<point_source>> out;
    out.push_back(std::make_unique<generated_point_source>(30000, 9, false, true));
    return out;
  }
  static options ranks_options() {
    options o;
    o.chunk_points = 2000;
    o.builder.threads = 1;
    return o;
  }
  static point_cloud one_chunk_cloud() { return make_wavy_surface(3000, 2); }
  /// The bounds pass and the read of the whole input (one process builds it in memory).
  static constexpr int one_chunk_passes = 2;
  static bool make_bad(options&) { return false; }
  static point_cloud damage_cloud() { return make_wavy_surface(20000, 4); }
  static options damage_options() {
    options o;
    o.chunk_points = 4000;
    return o;
  }
  static constexpr std::size_t top_cut = 7, top_flip = 5;
};
INSTANTIATE_TYPED_TEST_SUITE_P(ChunkedPointOctree, ChunkedLayer, point_octree_case);

using ChunkedPointOctree = test::chunked_fixture<point_octree_case>;

TEST_F(ChunkedPointOctree, SplitsIntoManyChunksWithinTheLimit) {
  EXPECT_GE(built().report.chunks, 20u);
  EXPECT_GE(built().report.top_nodes, built().report.chunks + 3);
  EXPECT_LE(built().report.largest_chunk, 2500u);
  EXPECT_GT(built().report.halo_points, 0u);
  const auto open = point_octree_case::hierarchy::open(built().dir);
  const sphere s = bounding_sphere_about_box_centre(built().cloud.positions);
  EXPECT_EQ(open.input_sphere().centre, s.centre);
  EXPECT_EQ(open.input_sphere().radius, s.radius);
}

TEST_F(ChunkedPointOctree, TraversalMatchesTheInMemoryCutAndLoadsOnlyWhatItNeeds) {
  using H = chunked_point_octree<point_octree_attributes(attributes{.colour = true})>;
  const sphere s = built().memory.bounding_sphere(built().memory.root());
  const vec3d centre = built().memory.origin() + s.centre.cast<double>();
  struct shot {
    double az, dist;
    float tol;
  };
  for (const shot sh : {shot{30, 30, 8}, shot{30, 3, 4}, shot{200, 0.8, 1}}) {
    const H h = H::open(built().dir);
    camera cam = camera::orbit(centre, s.radius, sh.az, 20, sh.dist, 1, {256, 256});
    if (sh.dist < 1) {  // close to the tube, looking at a small part of it
      cam.eye = centre + vec3d(1.9, 0.2, 0.3);
      cam.target = centre + vec3d(1.3, 0, 0);
      cam.z_near = 0.01;
    }
    traverse_options o;
    o.tolerance_px = sh.tol;
    buffer_sink<H::attrs> got, want;
    const traverse_stats a = traverse(h, view(cam, h.origin()), o, got, point_octree_policy{});
    const traverse_stats b = traverse(built().memory, view(cam, built().memory.origin()), o, want,
                                      point_octree_policy{});
    EXPECT_GT(got.splats.size(), 20u);
    EXPECT_EQ(a.visited, b.visited);
    EXPECT_EQ(a.emitted_leaves, b.emitted_leaves);
    expect_same_splats<H>(got, want);
    if (sh.dist == 30) {
      EXPECT_EQ(h.chunks_loaded(), 0u) << "a far view drew from the top file alone";
    }
    if (sh.dist < 1) {
      EXPECT_GT(h.chunks_loaded(), 0u);
      EXPECT_LT(h.chunks_loaded(), h.chunk_count()) << "a close view read every chunk";
    }
  }
}

// A chunked hierarchy loads its chunks lazily, from whichever traversal first needs one; const
// traversals from several threads are promised safe. Four threads traverse one freshly opened
// folder, each starting at another view (so they race for the same chunks), and every cut
// equals the in-memory build's; under ThreadSanitizer (scripts/tsan.sh) this checks the lazy
// loading's locking.
TEST_F(ChunkedPointOctree, ThreadsLoadingChunksLazilyDrawTheInMemoryCuts) {
  using H = chunked_point_octree<point_octree_attributes(attributes{.colour = true})>;
  const sphere s = built().memory.bounding_sphere(built().memory.root());
  const vec3d centre = built().memory.origin() + s.centre.cast<double>();
  std::vector<camera> cams;
  for (const double az : {0.0, 90.0, 180.0, 270.0})
    cams.push_back(camera::orbit(centre, s.radius, az, 20, 1.5, 1, {128, 128}));
  const auto centres = [](const auto& h, const camera& cam) {
    buffer_sink<H::attrs> sink;
    traverse(h, view(cam, h.origin()), {.tolerance_px = 1}, sink, point_octree_policy{});
    std::vector<vec3f> c;
    for (const auto& sp : sink.splats) c.push_back(sp.centre);
    return c;
  };
  std::vector<std::vector<vec3f>> want;
  for (const camera& cam : cams) want.push_back(centres(built().memory, cam));
  const H h = H::open(built().dir);
  std::atomic<int> differ{0};
  std::vector<std::thread> threads;
  for (std::size_t t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (std::size_t k = 0; k < cams.size(); ++k) {
        const std::size_t v = (k + t) % cams.size();
        if (centres(h, cams[v]) != want[v]) ++differ;
      }
    });
  for (auto& th : threads) th.join();
  EXPECT_EQ(differ.load(), 0);
  EXPECT_GT(h.chunks_loaded(), 0u);
  EXPECT_GT(want[0].size(), 1000u);
}

// More copies of one point than a chunk holds: the split leaves them one node (the mean split
// cannot separate them), which must stay one chunk — the structure passes once marked it for
// splitting again on every pass and never finished. The folder opens and holds every sample.
TEST(ChunkedPointOctreeFiles, CopiesOfOnePointBeyondAChunkStayOneChunk) {
  point_cloud c = make_wavy_surface(4000, 3);
  for (int k = 0; k < 700; ++k) {
    c.positions.push_back(c.positions[2000]);
    c.normals.push_back(c.normals[2000]);
    c.colours.push_back({static_cast<std::uint8_t>(k), 9, 200});
  }
  chunked_point_octree_options o;
  o.chunk_points = 600;
  const std::string dir = temp_dir("copies");
  const chunked_build_report r = build_point_octree_chunked(cloud_point_source(c), dir, o);
  EXPECT_GE(r.largest_chunk, 701u) << "the copies (and the point) are one chunk";
  // (Not compared with the in-memory build: the copies are ties among every neighbour search,
  // which the header's equality excludes.)
  EXPECT_EQ(point_octree_case::hierarchy::open(dir).assemble().samples().size(), c.size());
  fs::remove_all(dir);
}

TEST(ChunkedPointOctreeEstimated, PositionsOnlyWithViewpointEqualsInMemory) {
  // Estimated normals (oriented towards a viewpoint) and ellipses: the halos must give every
  // chunk point the neighbours it has in the whole input.
  const generated_point_source src(40000, 3, /*normals=*/false, /*colours=*/false);
  const point_cloud all = read_all(src);
  chunked_point_octree_options o;
  o.chunk_points = 3000;
  o.builder.viewpoint = vec3d(0.3, 5.0, 0.2);
  const std::string dir = temp_dir("estimated");
  const chunked_build_report r = build_point_octree_chunked(src, dir, o);
  EXPECT_GE(r.chunks, 10u);
  EXPECT_TRUE(r.estimated_normals);
  using H = chunked_point_octree<point_octree_attributes(attributes{})>;
  const auto whole = H::open(dir).assemble();
  const auto memory = build_point_octree(point_set<attributes{}>::from(all), o.builder);
  EXPECT_TRUE(whole == memory);
  fs::remove_all(dir);
}

TEST(ChunkedPointOctreeEstimated, ZeroNormalsAreEstimatedAndCounted) {
  // Every sixth normal zero and one NaN: "no normal", estimated over the chunk and its halo
  // (whose reach then covers the normals' k neighbours too) and oriented by the given normals
  // around each — what build_point_octree does over the whole input: the same tree, every
  // sample's normal within 0.1° of the in-memory build's.
  point_cloud c = make_wavy_surface(20000, 6);
  std::size_t zeroed = 0;
  for (std::size_t i = 0; i < c.size(); i += 6, ++zeroed) c.normals[i].setZero();
  c.normals[1].z() = std::numeric_limits<float>::infinity();
  ++zeroed;
  chunked_point_octree_options o;
  o.chunk_points = 3000;
  const std::string dir = temp_dir("zero_normals");
  const chunked_build_report r = build_point_octree_chunked(cloud_point_source(c), dir, o);
  EXPECT_GE(r.chunks, 5u);
  EXPECT_EQ(r.normals_filled, zeroed);
  EXPECT_FALSE(r.estimated_normals);
  using H = chunked_point_octree<point_octree_attributes(attributes{.colour = true})>;
  const auto whole = H::open(dir).assemble();
  const auto memory =
      build_point_octree(point_set<attributes{.normal = true, .colour = true}>::from(c), o.builder);
  EXPECT_EQ(memory.stats().normals_filled, zeroed);
  ASSERT_EQ(whole.samples().size(), memory.samples().size());
  ASSERT_EQ(whole.nodes().size(), memory.nodes().size());
  std::size_t off = 0;
  for (std::size_t i = 0; i < whole.samples().size(); ++i) {
    ASSERT_EQ(whole.samples().positions[i], memory.samples().positions[i]);
    ASSERT_TRUE(all_finite(whole.samples().normals[i]));
    off += whole.samples().normals[i].dot(memory.samples().normals[i]) <
           std::cos(0.1f * 3.14159265f / 180);
  }
  EXPECT_EQ(off, 0u) << "normals differing from the in-memory estimate";
  fs::remove_all(dir);
}

TEST(ChunkedPointOctreeEstimated, AllZeroNormalsTakeOneOrientationOverTheChunks) {
  // Every normal zero (a 3-D Gaussian Splatting file): estimated chunk after chunk, each chunk
  // oriented by its finished neighbours' estimates in its halo, so the whole closed surface
  // comes out one way (≥ 99 % of the samples agree in sign with the true normals, or ≥ 99 %
  // disagree), on the true normals' lines (|n·n'| ≥ cos 20° for ≥ 99 %).
  const point_cloud truth = make_wavy_surface(20000, 6);
  point_cloud c = truth;
  for (auto& n : c.normals) n.setZero();
  chunked_point_octree_options o;
  o.chunk_points = 2500;
  const std::string dir = temp_dir("all_zero_normals");
  const chunked_build_report r = build_point_octree_chunked(cloud_point_source(c), dir, o);
  EXPECT_GE(r.chunks, 5u);
  EXPECT_EQ(r.normals_filled, c.size());
  EXPECT_TRUE(r.estimated_normals);
  using H = chunked_point_octree<point_octree_attributes(attributes{.colour = true})>;
  const auto whole = H::open(dir).assemble();
  // The samples are in octree order: match them to the input by position (all distinct here).
  std::map<std::array<float, 3>, vec3f> true_normal;
  for (std::size_t i = 0; i < truth.size(); ++i)
    true_normal[{truth.positions[i].x(), truth.positions[i].y(), truth.positions[i].z()}] =
        truth.normals[i];
  ASSERT_EQ(true_normal.size(), truth.size());
  std::size_t same = 0, on_line = 0;
  const auto& s = whole.samples();
  for (std::size_t i = 0; i < s.size(); ++i) {
    const auto it = true_normal.find({s.positions[i].x(), s.positions[i].y(), s.positions[i].z()});
    ASSERT_NE(it, true_normal.end());
    const float d = s.normals[i].dot(it->second);
    same += d > 0;
    on_line += std::abs(d) >= std::cos(20.0f * 3.14159265f / 180);
  }
  const double n = static_cast<double>(s.size());
  std::printf(
      "%zu chunks; %zu of %zu samples agree in sign with the true normals, %zu on their "
      "lines\n",
      r.chunks, same, s.size(), on_line);
  EXPECT_TRUE(same >= 0.99 * n || same <= 0.01 * n) << same << " of " << s.size();
  EXPECT_GE(static_cast<double>(on_line), 0.99 * n);
  fs::remove_all(dir);
}

TEST(ChunkedPointOctreeEstimated, GraphOrientationDiffersOnlyInSign) {
  // Without a viewpoint the signs are propagated over the k-NN graph, which a chunk and its
  // halo see only part of: the normals agree up to sign, the tree's structure exactly.
  const generated_point_source src(30000, 5, false, false);
  chunked_point_octree_options o;
  o.chunk_points = 3000;
  const std::string dir = temp_dir("mst");
  (void)build_point_octree_chunked(src, dir, o);
  using H = chunked_point_octree<point_octree_attributes(attributes{})>;
  const auto whole = H::open(dir).assemble();
  const auto memory = build_point_octree(point_set<attributes{}>::from(read_all(src)), o.builder);
  ASSERT_EQ(whole.samples().size(), memory.samples().size());
  ASSERT_EQ(whole.nodes().size(), memory.nodes().size());
  std::size_t off = 0;
  for (std::size_t i = 0; i < whole.samples().size(); ++i) {
    ASSERT_EQ(whole.samples().positions[i], memory.samples().positions[i]);
    off += std::abs(whole.samples().normals[i].dot(memory.samples().normals[i])) < 0.9999f;
  }
  EXPECT_EQ(off, 0u) << "normals differing by more than their sign";
  fs::remove_all(dir);
}

}  // namespace
}  // namespace pbr_lod
