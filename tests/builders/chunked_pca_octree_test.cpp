// The chunked (out-of-core) PCA octree: the chunked layer's suite (chunked_suite.hpp), and what is
// the PCA octree's own: node numbers, the same points drawn, unquantised builds, estimated normals.
#include <gtest/gtest.h>

#include <barrier>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <thread>

#include "chunked_suite.hpp"
#include "pbr_lod/builders/chunked_pca_octree.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/traverse/sink.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod {
namespace {

namespace fs = std::filesystem;

std::string temp_dir(const std::string& what) {
  return test::temp_dir("pbr_lod_cpca_", what);
}
using test::bytes_of;
using test::expect_same_folders;

constexpr attributes NC = with_normals_colours;
using H = chunked_pca_octree<NC>;

/// The wavy surface (normals, colours) with a few exact duplicates, and 700 copies of one point:
/// a cell of one repeated position is never split, so it becomes a chunk above chunk_points.
point_cloud surface_with_duplicates(std::size_t n) {
  point_cloud c = make_wavy_surface(n, 7);
  for (std::size_t i = 0; i < n; i += n / 7) {
    c.positions.push_back(c.positions[i]);
    c.normals.push_back(c.normals[i]);
    c.colours.push_back({1, 2, 3});
  }
  for (int k = 0; k < 700; ++k) {
    c.positions.push_back(c.positions[n / 2]);
    c.normals.push_back(c.normals[(n / 2 + static_cast<std::size_t>(k)) % n]);
    c.colours.push_back({static_cast<std::uint8_t>(k), 9, 200});
  }
  return c;
}

pca_octree_options small_codebooks() {
  pca_octree_options o;
  o.position_codebook = 256;
  o.normal_codebook = 256;
  o.kmeans_sample = 4000;  // fewer than the nodes: the sample is a true subset
  return o;
}

pca_octree<NC> in_memory(const point_cloud& c, const pca_octree_options& o) {
  return build_pca_octree(point_set<NC>::from(c), o);
}

/// The PCA octree's case of the chunked layer's suite (chunked_suite.hpp).
struct pca_case {
  using options = chunked_pca_octree_options;
  using hierarchy = H;
  using uncoloured = chunked_pca_octree<with_normals>;
  using tree = pca_octree<NC>;
  static constexpr const char* name = "cpca";
  static point_cloud cloud() { return surface_with_duplicates(14000); }
  static options options_for_many() {
    options o;
    o.builder = small_codebooks();
    o.chunk_points = 600;
    return o;
  }
  static chunked_build_report build(const point_source& src, const std::string& dir,
                                    const options& o) {
    return build_pca_octree_chunked(src, dir, o);
  }
  static tree in_memory(const point_cloud& c, const options& o) {
    return pbr_lod::in_memory(c, o.builder);
  }
  static void expect_equal(const tree& whole, const tree& memory) {
    EXPECT_EQ(whole.data().codebook_p, memory.data().codebook_p);
    EXPECT_TRUE(whole.data().records == memory.data().records);
    EXPECT_TRUE(whole.nodes() == memory.nodes());
    EXPECT_TRUE(whole == memory);
  }
  static std::string chunk_file(std::uint32_t c) { return pca_chunk_file_name(c); }
  static bool is_chunked(const std::string& dir) { return is_chunked_pca_octree(dir); }
  static bool has_colours(const std::string& dir) { return chunked_folder_has_colours(dir); }
  /// With normals, and without: then the halo cells come from every rank, the estimation from
  /// rank 0, and the chunks are built round robin from the files it rewrote.
  static std::vector<std::unique_ptr<point_source>> ranks_sources() {
    std::vector<std::unique_ptr<point_source>> out;
    point_cloud c = make_wavy_surface(8000, 9);
    out.push_back(std::make_unique<test::owned_cloud_source>(c));
    c.normals.clear();
    out.push_back(std::make_unique<test::owned_cloud_source>(std::move(c)));
    return out;
  }
  static options ranks_options() {
    options o;
    o.builder = small_codebooks();
    o.builder.threads = 1;
    o.chunk_points = 500;
    return o;
  }
  static point_cloud one_chunk_cloud() { return make_wavy_surface(6000, 5); }
  static constexpr int one_chunk_passes = 0;
  static bool make_bad(options& o) {
    o.builder.gamma = 0;
    return true;
  }
  static point_cloud damage_cloud() { return make_wavy_surface(4000, 4); }
  static options damage_options() {
    options o;
    o.builder = small_codebooks();
    o.chunk_points = 600;
    return o;
  }
  static constexpr std::size_t top_cut = 7, top_flip = 0;  // flips: every size / 300-th byte
};
INSTANTIATE_TYPED_TEST_SUITE_P(ChunkedPca, ChunkedLayer, pca_case);

using ChunkedPca = test::chunked_fixture<pca_case>;

TEST_F(ChunkedPca, SplitsIntoChunksAndOpensLazily) {
  EXPECT_GE(built().report.chunks, 20u);
  EXPECT_EQ(built().report.largest_chunk, 701u)
      << "the repeated point (and its 700 copies) is one chunk";
  const H h = H::open(built().dir);
  EXPECT_EQ(h.input_points(), built().cloud.size());
  EXPECT_GT(h.top_node_count(), h.chunk_count());
  // Every node reached through the hierarchy is the in-memory node of its number.
  std::vector<H::node_id> stack{h.root()};
  std::size_t visited = 0;
  while (!stack.empty()) {
    const H::node_id x = stack.back();
    stack.pop_back();
    const std::uint64_t g = h.global_id(x);
    ASSERT_LT(g, built().memory.nodes().size());
    const pca_node& want = built().memory.at(static_cast<std::uint32_t>(g));
    EXPECT_EQ(h.at(x).mean, want.mean) << "node " << g;
    EXPECT_EQ(h.at(x).radius, want.radius) << "node " << g;
    EXPECT_EQ(h.at(x).count, want.count) << "node " << g;
    ++visited;
    for (const H::node_id c : h.children(x)) stack.push_back(c);
  }
  EXPECT_EQ(visited, built().memory.nodes().size());
}

TEST_F(ChunkedPca, DrawsThePointsOfTheInMemoryBuildAndLoadsOnlyWhatItNeeds) {
  const sphere s = built().memory.bounding_sphere(built().memory.root());
  const vec3d centre = built().memory.origin() + s.centre.cast<double>();
  for (const double dist : {3.0, 0.4}) {
    const H h = H::open(built().dir);
    const camera cam = camera::orbit(centre, s.radius, 30, 25, dist, 1, {160, 160});
    buffer_sink<NC> got, want;
    const pca_octree_policy policy;
    const traverse_stats sg = traverse(h, view(cam, h.origin()), {}, got, policy);
    const traverse_stats sw =
        traverse(built().memory, view(cam, built().memory.origin()), {}, want, policy);
    EXPECT_EQ(sg.visited, sw.visited);
    ASSERT_EQ(got.points.size(), want.points.size());
    EXPECT_GT(got.points.size(), 1000u);
    std::size_t differ = 0;
    for (std::size_t i = 0; i < got.points.size(); ++i) {
      const auto &p = got.points[i], &q = want.points[i];
      differ += !(p.position == q.position &&
                  static_cast<const vec3f&>(p.normal) == static_cast<const vec3f&>(q.normal) &&
                  static_cast<const rgb8&>(p.colour) == static_cast<const rgb8&>(q.colour));
    }
    EXPECT_EQ(differ, 0u);
    if (dist < 1) {
      EXPECT_GT(h.chunks_loaded(), 0u);
      EXPECT_LT(h.chunks_loaded(), h.chunk_count()) << "a close view read every chunk";
    }
  }
}

TEST(ChunkedPcaOptions, UnquantisedAndOneChunkEqualTheInMemoryBuild) {
  const point_cloud c = make_wavy_surface(6000, 5);
  pca_octree_options q;
  q.quantise = false;
  for (const std::uint64_t chunk : {std::uint64_t{400}, std::uint64_t{0}}) {
    chunked_pca_octree_options o;
    o.builder = q;
    o.chunk_points = chunk;
    const std::string dir = temp_dir("float" + std::to_string(chunk));
    const auto r = build_pca_octree_chunked(cloud_point_source(c), dir, o);
    EXPECT_EQ(r.chunks > 1, chunk != 0);
    EXPECT_TRUE(H::open(dir).assemble() == in_memory(c, q)) << "chunk points " << chunk;
    fs::remove_all(dir);
  }
}

/// Per node (by whole-tree number) of the chunked build in `dir`: its mean position and mean
/// normal (normal_frame column 2).
std::vector<std::pair<vec3f, vec3f>> node_means(const std::string& dir) {
  const pca_octree<NC> t = H::open(dir).assemble();
  std::vector<std::pair<vec3f, vec3f>> out;
  for (const pca_node& nd : t.nodes()) out.emplace_back(nd.mean, nd.normal_frame.col(2));
  return out;
}

// A zero, non-finite or absent normal is no normal: estimated over each chunk and its halo, chunk
// after chunk, and counted. Some zero (every seventh, one NaN): every node's mean normal within
// 2° of the in-memory build's of the same input (which estimates over the whole input), the
// same positions. All absent: the same positions, mean normals on the same line as the in-memory
// estimate's, and one orientation over the whole surface (≥ 95 % of the nodes agree in sign with
// the true normals, or ≥ 95 % disagree: chunks oriented from their neighbours, not each on its
// own). Both within 20° of the true normals' build for ≥ 90 % of the nodes.
TEST(ChunkedPcaFiles, MissingNormalsAreEstimatedAcrossChunks) {
  const point_cloud c = make_wavy_surface(12000, 4);
  point_cloud some = c, bare = c;
  std::size_t zeroed = 0;
  for (std::size_t i = 0; i < some.size(); i += 7, ++zeroed) some.normals[i].setZero();
  some.normals[3].y() = std::numeric_limits<float>::quiet_NaN();
  ++zeroed;
  bare.normals.clear();
  chunked_pca_octree_options o;
  o.builder.quantise = false;  // compare the statistics, not codebooks trained on them
  // The same tree for every variant, so that nodes compare one to one: the split rule reads the
  // normals (surface_angle), and estimated normals differ from the true ones by a few degrees —
  // across the default 15° they split some leaves the true normals keep.
  o.builder.surface_angle = 60;
  o.chunk_points = 800;
  const std::string truth = temp_dir("mn_truth"), dsome = temp_dir("mn_some"),
                    dbare = temp_dir("mn_bare");
  (void)build_pca_octree_chunked(cloud_point_source(c), truth, o);
  const chunked_build_report rs = build_pca_octree_chunked(cloud_point_source(some), dsome, o);
  const chunked_build_report rb = build_pca_octree_chunked(cloud_point_source(bare), dbare, o);
  ASSERT_GE(rs.chunks, 10u);
  EXPECT_EQ(rs.normals_filled, zeroed);
  EXPECT_FALSE(rs.estimated_normals);
  EXPECT_EQ(rb.normals_filled, c.size());
  EXPECT_TRUE(rb.estimated_normals);
  EXPECT_GT(rb.halo_points, 0u);
  const auto t = node_means(truth), a = node_means(dsome), b = node_means(dbare);
  const auto memory_some = build_pca_octree(point_set<NC>::from(some), o.builder);
  const auto memory_bare =
      build_pca_octree(point_set<attributes{.colour = true}>::from(bare), o.builder);
  const auto& ms = memory_some.nodes();
  const auto& mb = memory_bare.nodes();
  ASSERT_EQ(a.size(), ms.size());
  ASSERT_EQ(b.size(), mb.size());
  ASSERT_EQ(a.size(), t.size());
  const float two = std::cos(2.0f * std::numbers::pi_v<float> / 180),
              twenty = std::cos(20.0f * std::numbers::pi_v<float> / 180);
  std::size_t some_off = 0, bare_off = 0, some_far = 0, bare_far = 0, bare_same_sign = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_TRUE(all_finite(a[i].second) && all_finite(b[i].second)) << "node " << i;
    EXPECT_EQ(a[i].first, ms[i].mean) << "node " << i;
    EXPECT_EQ(b[i].first, mb[i].mean) << "node " << i;
    some_off += a[i].second.dot(ms[i].normal_frame.col(2)) < two;
    bare_off += std::abs(b[i].second.dot(mb[i].normal_frame.col(2))) < two;
    some_far += a[i].second.dot(t[i].second) < twenty;
    bare_far += std::abs(b[i].second.dot(t[i].second)) < twenty;
    bare_same_sign += b[i].second.dot(t[i].second) > 0;
  }
  const double nodes = static_cast<double>(a.size());
  std::printf(
      "%zu nodes; off the in-memory build by > 2 deg: some %zu, bare %zu; > 20 deg from "
      "the true normals: some %zu, bare %zu; bare agreeing in sign: %zu\n",
      a.size(), some_off, bare_off, some_far, bare_far, bare_same_sign);
  EXPECT_EQ(some_off, 0u);
  EXPECT_LE(static_cast<double>(bare_off), 0.01 * nodes);
  EXPECT_LE(static_cast<double>(some_far), 0.1 * nodes);
  EXPECT_LE(static_cast<double>(bare_far), 0.1 * nodes);
  const double same = static_cast<double>(bare_same_sign) / nodes;
  EXPECT_TRUE(same >= 0.95 || same <= 0.05) << same;
  for (const auto& d : {truth, dsome, dbare}) fs::remove_all(d);
}

TEST(ChunkedPcaFiles, ANodeNumberedBeyondTheTreeIsAnError) {
  // A chunk file whose checksum is right but whose level numbers reach past the tree would make
  // assemble() write beyond its nodes: the chunk is refused when read.
  const point_cloud c = make_wavy_surface(4000, 4);
  const std::string dir = temp_dir("numbers");
  chunked_pca_octree_options o;
  o.chunk_points = 600;
  (void)build_pca_octree_chunked(cloud_point_source(c), dir, o);
  const H good = H::open(dir);
  std::uint32_t deep = 0;
  while (deep < good.chunk_count() && good.chunk(deep).level_first.size() < 2) ++deep;
  ASSERT_LT(deep, good.chunk_count());
  // Head: magic 8, version 4, flags, chunk, depth 4 each, points and nodes 8 each, the cell 32,
  // the level count 4: the level numbers start at byte 76.
  const std::string path = dir + "/" + pca_chunk_file_name(deep);
  std::vector<unsigned char> b = detail::load_file_bytes(path);
  const std::uint32_t far = 0xffffff00u;
  std::memcpy(b.data() + 76 + 4, &far, 4);
  const std::uint64_t sum = detail::fnv1a(b.data(), b.size() - 8);
  std::memcpy(b.data() + b.size() - 8, &sum, 8);
  detail::save_file_bytes(path, b);
  EXPECT_THROW((void)H::open(dir).chunk(deep), FormatError);
  EXPECT_THROW((void)H::open(dir).assemble(), FormatError);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace pbr_lod
