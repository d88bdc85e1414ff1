// The tests every chunked (out-of-core) build passes, whatever the builder: a type-parameterised
// GoogleTest suite over a *case*, which each builder's test file defines and instantiates
// (chunked_point_octree_test.cpp, chunked_pmr_test.cpp, chunked_pca_octree_test.cpp). A sixth
// builder that plugs into the chunked layer writes its case and gets these tests.
//
// A case C gives (see the three for examples):
//   options, hierarchy (its reader, with colours), uncoloured (the reader without), tree (what
//   hierarchy::assemble() returns, the in-memory hierarchy);
//   static const char* name: its temporary folders' prefix;
//   static point_cloud cloud(), static options options_for_many(): the shared build, in many
//   chunks; static chunked_build_report build(const point_source&, const std::string& dir, const
//   options&); static tree in_memory(const point_cloud&, const options&): the in-memory build of
//   the same; static void expect_equal(const tree& assembled, const tree& memory): the builder's
//   own detail; static std::string chunk_file(std::uint32_t), static bool is_chunked(const
//   std::string&), static bool has_colours(const std::string&); static
//   std::vector<std::unique_ptr<point_source>> ranks_sources(), static options ranks_options():
//   builds three ranks share; static point_cloud one_chunk_cloud(): an input that fits one chunk
//   with default options; static int one_chunk_passes: the passes such a build makes (0: not
//   checked); static bool make_bad(options&): sets a builder option the build refuses (false:
//   none); static options damage_options(), damage steps top_cut, top_flip (0: from the file size).
#pragma once

#include <gtest/gtest.h>

#include <barrier>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "chunked_test_util.hpp"
#include "pbr_lod/builders/chunked.hpp"
#include "pbr_lod/core/point_source.hpp"
#include "pbr_lod/core/synthetic.hpp"

namespace pbr_lod::test {

/// A point_source that holds its cloud (cloud_point_source refers to one).
class owned_cloud_source final : public point_source {
 public:
  explicit owned_cloud_source(point_cloud c) : cloud_(std::move(c)), src_(cloud_) {}
  [[nodiscard]] attributes attrs() const override { return src_.attrs(); }
  [[nodiscard]] vec3d origin() const override { return src_.origin(); }
  [[nodiscard]] std::uint64_t size() const override { return src_.size(); }
  void read(std::uint64_t first, std::size_t count, point_block& out) const override {
    src_.read(first, count, out);
  }
  [[nodiscard]] std::optional<vec3d> sensor() const override { return src_.sensor(); }
  [[nodiscard]] std::string name() const override { return src_.name(); }

 private:
  point_cloud cloud_;
  cloud_point_source src_;
};

/// The case's shared build (many chunks) and the in-memory build of the same input, made once per
/// test program and removed at its end; the builder's own tests use them too.
template <class C>
struct chunked_build {
  point_cloud cloud = C::cloud();
  std::string dir = temp_dir(std::string("pbr_lod_") + C::name + "_", "equal");
  typename C::options options = C::options_for_many();
  chunked_build_report report = C::build(cloud_point_source(cloud), dir, options);
  typename C::tree memory = C::in_memory(cloud, options);
  ~chunked_build() { std::filesystem::remove_all(dir); }

  static const chunked_build& get() {
    static const chunked_build b;
    return b;
  }
};

/// A builder's own tests of its case's shared build: TEST_F(ChunkedX, …) with
/// `using ChunkedX = test::chunked_fixture<x_case>;`.
template <class C>
class chunked_fixture : public ::testing::Test {
 protected:
  static const chunked_build<C>& built() { return chunked_build<C>::get(); }
};

}  // namespace pbr_lod::test

namespace pbr_lod {

template <class C>
class ChunkedLayer : public ::testing::Test {
 protected:
  static const test::chunked_build<C>& shared() { return test::chunked_build<C>::get(); }
  static std::string temp(const std::string& what) {
    return test::temp_dir(std::string("pbr_lod_") + C::name + "_", what);
  }
};
TYPED_TEST_SUITE_P(ChunkedLayer);

// Opening reads the top file only; the reader's index (chunks, nodes, files) is the build's.
TYPED_TEST_P(ChunkedLayer, OpensLazilyWithTheBuildsIndex) {
  using C = TypeParam;
  const auto& b = this->shared();
  EXPECT_FALSE(std::filesystem::exists(std::filesystem::path(b.dir) / "tmp-build"))
      << "temporary files left behind";
  EXPECT_TRUE(C::is_chunked(b.dir));
  EXPECT_TRUE(C::has_colours(b.dir));
  EXPECT_FALSE(C::is_chunked(b.dir + "/" + C::chunk_file(0))) << "a chunk file is not a folder";
  const typename C::hierarchy h = C::hierarchy::open(b.dir);
  EXPECT_EQ(h.chunks_loaded(), 0u) << "opening read a chunk";
  EXPECT_EQ(h.chunk_count(), b.report.chunks);
  EXPECT_EQ(h.top_node_count(), b.report.top_nodes);
  EXPECT_EQ(h.node_count(), b.memory.nodes().size());
  std::uint64_t bytes = 0;
  for (const auto& e : std::filesystem::directory_iterator(b.dir)) bytes += e.file_size();
  EXPECT_EQ(h.file_bytes(), bytes);
}

TYPED_TEST_P(ChunkedLayer, AssemblesToTheInMemoryBuildByteForByte) {
  using C = TypeParam;
  const auto& b = this->shared();
  const typename C::hierarchy h = C::hierarchy::open(b.dir);
  const typename C::tree whole = h.assemble();
  EXPECT_EQ(h.chunks_loaded(), h.chunk_count()) << "assemble() reads every chunk";
  ASSERT_EQ(whole.nodes().size(), b.memory.nodes().size());
  C::expect_equal(whole, b.memory);
  const std::string x = this->temp("assembled"), y = this->temp("memory");
  whole.save(x);
  b.memory.save(y);
  EXPECT_EQ(test::bytes_of(x), test::bytes_of(y));
  std::filesystem::remove(x);
  std::filesystem::remove(y);
}

// Three "ranks" as threads with a barrier: the steps are shared round robin, rank 0 writes the
// chunk files and the top — the same bytes as one process. Over an earlier build with more
// chunks, which the ranks' folder replaces whole (a chunk file of the earlier build left behind
// would be one file too many).
TYPED_TEST_P(ChunkedLayer, ThreeRanksWriteTheOneProcessFolder) {
  using C = TypeParam;
  const typename C::options o = C::ranks_options();
  for (const std::unique_ptr<point_source>& src : C::ranks_sources()) {
    SCOPED_TRACE(src->attrs().normal ? "with normals" : "positions only");
    const std::string one = this->temp("dist_one"), many = this->temp("dist_many");
    const chunked_build_report r1 = C::build(*src, one, o);
    ASSERT_GE(r1.chunks, 6u);
    typename C::options finer = o;
    finer.chunk_points = o.chunk_points / 5;
    ASSERT_GT(C::build(*src, many, finer).chunks, r1.chunks);
    std::barrier sync(3);
    std::vector<chunked_build_report> reports(3);
    std::vector<std::thread> ranks;
    for (int rank = 0; rank < 3; ++rank)
      ranks.emplace_back([&, rank] {
        typename C::options mine = o;
        mine.distributed = {rank, 3, [&] { sync.arrive_and_wait(); }};
        reports[static_cast<std::size_t>(rank)] = C::build(*src, many, mine);
      });
    for (auto& t : ranks) t.join();
    EXPECT_EQ(reports[0].chunks, r1.chunks);
    EXPECT_EQ(reports[0].halo_points, r1.halo_points);
    test::expect_same_folders(one, many);
    EXPECT_FALSE(std::filesystem::exists(std::filesystem::path(many) / "tmp-build"));
    EXPECT_FALSE(std::filesystem::exists(many + ".partial")) << "the staging folder was left";
    std::filesystem::remove_all(one);
    std::filesystem::remove_all(many);
  }
}

// An input that fits one chunk with the default options: one chunk, no halo, the in-memory
// build's tree; two ranks write the same folder.
TYPED_TEST_P(ChunkedLayer, OneChunkWhenTheInputFits) {
  using C = TypeParam;
  const point_cloud c = C::one_chunk_cloud();
  const std::string dir = this->temp("one"), ranks_dir = this->temp("one_ranks");
  const chunked_build_report r = C::build(cloud_point_source(c), dir, {});
  EXPECT_EQ(r.chunks, 1u);
  EXPECT_EQ(r.top_nodes, 1u);
  EXPECT_EQ(r.halo_points, 0u);
  if (C::one_chunk_passes) {
    EXPECT_EQ(r.passes, C::one_chunk_passes);
  }
  EXPECT_TRUE(C::hierarchy::open(dir).assemble() == C::in_memory(c, {}));
  std::barrier sync(2);
  std::vector<std::thread> ranks;
  for (int rank = 0; rank < 2; ++rank)
    ranks.emplace_back([&, rank] {
      typename C::options o;
      o.distributed = {rank, 2, [&] { sync.arrive_and_wait(); }};
      (void)C::build(cloud_point_source(c), ranks_dir, o);
    });
  for (auto& t : ranks) t.join();
  test::expect_same_folders(dir, ranks_dir);
  std::filesystem::remove_all(dir);
  std::filesystem::remove_all(ranks_dir);
}

TYPED_TEST_P(ChunkedLayer, BadInputAndDamagedDirectoriesAreErrors) {
  using C = TypeParam;
  using H = typename C::hierarchy;
  const point_cloud empty;
  EXPECT_THROW((void)C::build(cloud_point_source(empty), this->temp("e"), {}), InvalidArgument);
  const point_cloud c = C::damage_cloud();
  if (typename C::options bad; C::make_bad(bad)) {
    EXPECT_THROW((void)C::build(cloud_point_source(c), this->temp("b"), bad), InvalidArgument);
  }
  const std::string dir = this->temp("damage");
  (void)C::build(cloud_point_source(c), dir, C::damage_options());
  EXPECT_THROW((void)C::uncoloured::open(dir), FormatError)
      << "a coloured hierarchy opened as uncoloured";
  // Every truncation and every flipped byte of the top file is an error, never a crash.
  const std::string top = dir + "/" + chunked_top_file;
  const std::size_t flip = C::top_flip ? C::top_flip : std::filesystem::file_size(top) / 300 + 1;
  test::expect_damage_is_error(top, C::top_cut, flip, [&] { (void)H::open(dir); });
  // A chunk's file cut or flipped: an error when it is read.
  const std::string chunk0 = dir + "/" + C::chunk_file(0);
  const std::size_t size0 = std::filesystem::file_size(chunk0);
  test::expect_damage_is_error(chunk0, size0 / 97 + 1, size0 / 97 + 1,
                               [&] { (void)H::open(dir).chunk(0); });
  // Two chunks' files swapped: each valid on its own, but not the one the top names.
  test::expect_swapped_chunks_are_errors(H::open(dir), dir, C::chunk_file);
  std::filesystem::remove_all(dir);
}

REGISTER_TYPED_TEST_SUITE_P(ChunkedLayer, OpensLazilyWithTheBuildsIndex,
                            AssemblesToTheInMemoryBuildByteForByte,
                            ThreeRanksWriteTheOneProcessFolder, OneChunkWhenTheInputFits,
                            BadInputAndDamagedDirectoriesAreErrors);

}  // namespace pbr_lod
