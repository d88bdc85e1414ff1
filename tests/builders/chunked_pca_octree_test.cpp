// The chunked (out-of-core) PCA octree: equal to the in-memory build node for node and bit for
// bit, the same points drawn, lazy opening, ranks, damaged directories.
#include <gtest/gtest.h>

#include <barrier>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <thread>

#include "chunked_test_util.hpp"
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

class ChunkedPca : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    cloud_ = new point_cloud(surface_with_duplicates(14000));
    dir_ = new std::string(temp_dir("equal"));
    chunked_pca_octree_options o;
    o.builder = small_codebooks();
    o.chunk_points = 600;
    report_ =
        new chunked_build_report(build_pca_octree_chunked(cloud_point_source(*cloud_), *dir_, o));
    memory_ = new pca_octree<NC>(in_memory(*cloud_, o.builder));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete cloud_;
    delete dir_;
    delete report_;
    delete memory_;
  }
  static point_cloud* cloud_;
  static std::string* dir_;
  static chunked_build_report* report_;
  static pca_octree<NC>* memory_;
};
point_cloud* ChunkedPca::cloud_ = nullptr;
std::string* ChunkedPca::dir_ = nullptr;
chunked_build_report* ChunkedPca::report_ = nullptr;
pca_octree<NC>* ChunkedPca::memory_ = nullptr;

TEST_F(ChunkedPca, SplitsIntoChunksAndOpensLazily) {
  EXPECT_GE(report_->chunks, 20u);
  EXPECT_EQ(report_->largest_chunk, 701u) << "the repeated point (and its 700 copies) is one chunk";
  EXPECT_FALSE(fs::exists(fs::path(*dir_) / "tmp-build")) << "temporary files left behind";
  const H h = H::open(*dir_);
  EXPECT_EQ(h.chunk_count(), report_->chunks);
  EXPECT_EQ(h.node_count(), memory_->nodes().size());
  EXPECT_EQ(h.input_points(), cloud_->size());
  EXPECT_EQ(h.chunks_loaded(), 0u) << "opening read a chunk";
  EXPECT_GT(h.top_node_count(), h.chunk_count());
  // Every node reached through the hierarchy is the in-memory node of its number.
  std::vector<H::node_id> stack{h.root()};
  std::size_t visited = 0;
  while (!stack.empty()) {
    const H::node_id x = stack.back();
    stack.pop_back();
    const std::uint64_t g = h.global_id(x);
    ASSERT_LT(g, memory_->nodes().size());
    const pca_node& want = memory_->at(static_cast<std::uint32_t>(g));
    EXPECT_EQ(h.at(x).mean, want.mean) << "node " << g;
    EXPECT_EQ(h.at(x).radius, want.radius) << "node " << g;
    EXPECT_EQ(h.at(x).count, want.count) << "node " << g;
    ++visited;
    for (const H::node_id c : h.children(x)) stack.push_back(c);
  }
  EXPECT_EQ(visited, memory_->nodes().size());
}

TEST_F(ChunkedPca, AssemblesToTheInMemoryBuildByteForByte) {
  const pca_octree<NC> whole = H::open(*dir_).assemble();
  ASSERT_EQ(whole.nodes().size(), memory_->nodes().size());
  EXPECT_EQ(whole.data().codebook_p, memory_->data().codebook_p);
  EXPECT_TRUE(whole.data().records == memory_->data().records);
  EXPECT_TRUE(whole.nodes() == memory_->nodes());
  EXPECT_TRUE(whole == *memory_);
  const std::string a = *dir_ + "/assembled.pca", b = *dir_ + "/memory.pca";
  whole.save(a);
  memory_->save(b);
  EXPECT_EQ(bytes_of(a), bytes_of(b));
  fs::remove(a);
  fs::remove(b);
}

TEST_F(ChunkedPca, DrawsThePointsOfTheInMemoryBuildAndLoadsOnlyWhatItNeeds) {
  const sphere s = memory_->bounding_sphere(memory_->root());
  const vec3d centre = memory_->origin() + s.centre.cast<double>();
  for (const double dist : {3.0, 0.4}) {
    const H h = H::open(*dir_);
    const camera cam = camera::orbit(centre, s.radius, 30, 25, dist, 1, {160, 160});
    buffer_sink<NC> got, want;
    const pca_octree_policy policy;
    const traverse_stats sg = traverse(h, view(cam, h.origin()), {}, got, policy);
    const traverse_stats sw = traverse(*memory_, view(cam, memory_->origin()), {}, want, policy);
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

/// Three "ranks" as threads with a barrier write the one-process folder of `c`.
void expect_three_ranks_write_the_one_process_folder(const point_cloud& c,
                                                     const std::string& name) {
  const cloud_point_source src(c);
  chunked_pca_octree_options o;
  o.builder = small_codebooks();
  o.builder.threads = 1;
  o.chunk_points = 500;
  const std::string one = temp_dir(name + "_one"), many = temp_dir(name + "_many");
  const chunked_build_report r1 = build_pca_octree_chunked(src, one, o);
  ASSERT_GE(r1.chunks, 6u);
  std::barrier sync(3);
  std::vector<std::thread> ranks;
  for (int rank = 0; rank < 3; ++rank)
    ranks.emplace_back([&, rank] {
      chunked_pca_octree_options mine = o;
      mine.distributed = {rank, 3, [&] { sync.arrive_and_wait(); }};
      (void)build_pca_octree_chunked(src, many, mine);
    });
  for (auto& t : ranks) t.join();
  expect_same_folders(one, many);
  fs::remove_all(one);
  fs::remove_all(many);
}

TEST(ChunkedPcaDistributed, ThreeRanksWriteTheOneProcessFolder) {
  expect_three_ranks_write_the_one_process_folder(make_wavy_surface(8000, 9), "dist");
}

// Without normals: the halo cells come from every rank, the estimation from rank 0, and the
// chunks are built round robin from the files it rewrote.
TEST(ChunkedPcaDistributed, ThreeRanksEstimateMissingNormalsAsOneProcess) {
  point_cloud c = make_wavy_surface(8000, 9);
  c.normals.clear();
  expect_three_ranks_write_the_one_process_folder(c, "dist_bare");
}

TEST(ChunkedPcaFiles, BadInputAndDamagedDirectoriesAreErrors) {
  point_cloud empty;
  EXPECT_THROW((void)build_pca_octree_chunked(cloud_point_source(empty), temp_dir("e"), {}),
               InvalidArgument);
  point_cloud c = make_wavy_surface(4000, 4);
  chunked_pca_octree_options bad;
  bad.builder.gamma = 0;
  EXPECT_THROW((void)build_pca_octree_chunked(cloud_point_source(c), temp_dir("b"), bad),
               InvalidArgument);
  const std::string dir = temp_dir("damage");
  chunked_pca_octree_options o;
  o.builder = small_codebooks();
  o.chunk_points = 600;
  (void)build_pca_octree_chunked(cloud_point_source(c), dir, o);
  EXPECT_TRUE(is_chunked_pca_octree(dir));
  EXPECT_TRUE(chunked_pca_octree_has_colours(dir));
  EXPECT_THROW((void)chunked_pca_octree<with_normals>::open(dir), FormatError)
      << "a coloured hierarchy opened as uncoloured";
  const std::string top = dir + "/" + chunked_top_file;
  test::expect_damage_is_error(top, 7, fs::file_size(top) / 300 + 1, [&] { (void)H::open(dir); });
  // A chunk's file cut or flipped: an error when it is read.
  const std::string chunk0 = dir + "/" + pca_chunk_file_name(0);
  const std::size_t size0 = fs::file_size(chunk0);
  test::expect_damage_is_error(chunk0, size0 / 97 + 1, size0 / 97 + 1,
                               [&] { (void)H::open(dir).chunk(0); });
  test::expect_swapped_chunks_are_errors(H::open(dir), dir, pca_chunk_file_name);
  fs::remove_all(dir);
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
