// Chunked folders appear whole or not at all (core/atomic_file.hpp atomic_directory, used by the
// three chunked builds): a build that fails under a file-size limit, or is killed mid-write,
// leaves the previous folder byte for byte; a folder an unfinished build left is named as such
// when opened. The failing builds run in a forked child, so the limit and the signal never touch
// the test process.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <string>

#include "chunked_test_util.hpp"
#include "pbr_lod/builders/chunked_pca_octree.hpp"
#include "pbr_lod/builders/chunked_pmr.hpp"
#include "pbr_lod/builders/chunked_point_octree.hpp"
#include "pbr_lod/core/atomic_file.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "support/limited_write.hpp"

namespace pbr_lod {
namespace {

namespace fs = std::filesystem;

/// One chunked build: how to build a cloud into a folder (small chunks, one thread) and open it.
struct chunked_kind {
  const char* name;
  std::function<void(const point_cloud&, const std::string&)> build;
  std::function<void(const std::string&)> open;
};

std::vector<chunked_kind> kinds() {
  return {
      {"point_octree",
       [](const point_cloud& c, const std::string& dir) {
         chunked_point_octree_options o;
         o.chunk_points = 2000;
         o.builder.threads = 1;
         (void)build_point_octree_chunked(cloud_point_source(c), dir, o);
       },
       [](const std::string& dir) {
         (void)chunked_point_octree<point_octree_attributes(with_normals_colours)>::open(dir);
       }},
      {"pmr",
       [](const point_cloud& c, const std::string& dir) {
         chunked_pmr_options o;
         o.chunk_points = 2000;
         o.builder.max_leaf_points = 500;
         o.builder.threads = 1;
         (void)build_pmr_chunked(cloud_point_source(c), dir, o);
       },
       [](const std::string& dir) { (void)chunked_pmr<with_normals_colours>::open(dir); }},
      {"pca_octree",
       [](const point_cloud& c, const std::string& dir) {
         chunked_pca_octree_options o;
         o.chunk_points = 2000;
         o.builder.threads = 1;
         o.builder.position_codebook = 64;
         o.builder.normal_codebook = 64;
         (void)build_pca_octree_chunked(cloud_point_source(c), dir, o);
       },
       [](const std::string& dir) { (void)chunked_pca_octree<with_normals_colours>::open(dir); }},
  };
}

/// Every file under `dir` (relative name → bytes).
std::map<std::string, std::vector<char>> snapshot(const fs::path& dir) {
  std::map<std::string, std::vector<char>> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file())
      out[fs::relative(e.path(), dir).string()] = test::bytes_of(e.path().string());
  return out;
}

/// Names in `dir`.
std::vector<std::string> names_in(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) out.push_back(e.path().filename().string());
  std::sort(out.begin(), out.end());
  return out;
}

using test::run_limited;

/// A fresh folder (the output's parent) for one test.
struct scratch {
  fs::path dir;
  explicit scratch(const std::string& name) : dir(test::temp_dir("pbr_lod_cfolder_", name)) {
    fs::create_directories(dir);
  }
  ~scratch() { fs::remove_all(dir); }
};

std::string message_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const FormatError& e) {
    return e.what();
  }
  return "(no FormatError)";
}

// Over an earlier build, a build of a larger cloud under a file-size limit smaller than its
// chunks' files: it throws IoError naming the output, the earlier folder is byte-identical and
// nothing else is left beside it (no staging folder). With a plain in-place build the earlier
// folder would hold the new build's first files and the old top.
TEST(ChunkedFolders, FileSizeLimitKeepsTheEarlierFolder) {
  const point_cloud small = make_wavy_surface(6000, 3), large = make_wavy_surface(16000, 5);
  for (const chunked_kind& k : kinds()) {
    SCOPED_TRACE(k.name);
    const scratch s(std::string("limit_") + k.name);
    const std::string out = (s.dir / "out").string();
    k.build(small, out);
    const auto before = snapshot(out);
    ASSERT_GT(before.size(), 3u) << "several chunks";
    const int status = run_limited(32 * 1024, true, out, [&] { k.build(large, out); });
    ASSERT_TRUE(WIFEXITED(status)) << "the child was killed: SIGXFSZ not ignored?";
    EXPECT_EQ(WEXITSTATUS(status), 7) << "expected IoError naming " << out;
    EXPECT_EQ(snapshot(out), before);
    EXPECT_EQ(names_in(s.dir), std::vector<std::string>{"out"}) << "a staging folder was left";
    EXPECT_NO_THROW(k.open(out));
  }
}

// The same build killed by SIGXFSZ mid-write: the earlier folder is byte-identical; what the
// killed process leaves is its staging folder `out.partial`, which opens as an interrupted build.
// The next build replaces both: its folder equals a build into a fresh folder, byte for byte.
TEST(ChunkedFolders, KilledBuildKeepsTheEarlierFolderAndNamesItsOwn) {
  const point_cloud small = make_wavy_surface(6000, 3), large = make_wavy_surface(16000, 5);
  for (const chunked_kind& k : kinds()) {
    SCOPED_TRACE(k.name);
    const scratch s(std::string("killed_") + k.name);
    const std::string out = (s.dir / "out").string(), partial = out + ".partial";
    k.build(small, out);
    const auto before = snapshot(out);
    const int status = run_limited(32 * 1024, false, out, [&] { k.build(large, out); });
    ASSERT_TRUE(WIFSIGNALED(status));
    EXPECT_EQ(WTERMSIG(status), SIGXFSZ);
    EXPECT_EQ(snapshot(out), before);
    ASSERT_TRUE(fs::is_directory(partial));
    EXPECT_NE(message_of([&] { k.open(partial); }).find("interrupted chunked build"),
              std::string::npos)
        << message_of([&] { k.open(partial); });
    k.build(large, out);
    EXPECT_FALSE(fs::exists(partial));
    const std::string fresh = (s.dir / "fresh").string();
    k.build(large, fresh);
    EXPECT_EQ(snapshot(out), snapshot(fresh));
    EXPECT_NE(snapshot(out), before);
  }
}

// A folder without the top file (a build of an older version that wrote in place and was cut
// short) is named as an incomplete build; an empty or unrelated folder as not a chunked build —
// never "no file extension".
TEST(ChunkedFolders, IncompleteFoldersAreNamed) {
  const point_cloud c = make_wavy_surface(6000, 3);
  for (const chunked_kind& k : kinds()) {
    SCOPED_TRACE(k.name);
    const scratch s(std::string("incomplete_") + k.name);
    const std::string out = (s.dir / "out").string();
    k.build(c, out);
    fs::remove(fs::path(out) / chunked_top_file);
    EXPECT_NE(message_of([&] { k.open(out); }).find("incomplete chunked build"), std::string::npos)
        << message_of([&] { k.open(out); });
    const std::string empty = (s.dir / "empty").string();
    fs::create_directories(empty);
    EXPECT_NE(message_of([&] { k.open(empty); }).find("not a chunked build"), std::string::npos)
        << message_of([&] { k.open(empty); });
  }
}

// A build replaces only an empty folder or an earlier chunked build: given a folder of other
// files, or a file, as its output it stops before writing anything and the folder is untouched.
TEST(ChunkedFolders, OtherFoldersAreNotReplaced) {
  const point_cloud c = make_wavy_surface(3000, 3);
  const scratch s("refuse");
  const std::string notes = (s.dir / "notes").string(), file = (s.dir / "file").string();
  fs::create_directories(notes);
  std::ofstream(notes + "/keep.txt") << "mine";
  std::ofstream(file) << "mine";
  for (const chunked_kind& k : kinds()) {
    SCOPED_TRACE(k.name);
    EXPECT_THROW(k.build(c, notes), IoError);
    EXPECT_THROW(k.build(c, file), IoError);
    EXPECT_EQ(names_in(notes), std::vector<std::string>{"keep.txt"});
    EXPECT_EQ(names_in(s.dir), (std::vector<std::string>{"file", "notes"}));
    EXPECT_THROW(k.build(c, "."), InvalidArgument);
  }
}

// atomic_directory on its own: destroyed without commit() it removes its staging folder; a
// commit swaps an existing folder out whole (no file of the old one stays beside the new ones).
TEST(AtomicDirectory, CommitReplacesWholeAndAbandonRemoves) {
  const scratch s("atomic_dir");
  const std::string target = (s.dir / "d").string();
  fs::create_directories(target);
  std::ofstream(target + "/old.txt") << "old";
  {
    atomic_directory d(target, true);
    d.create();
    EXPECT_TRUE(is_unfinished_directory(d.staging_path()));
    std::ofstream(d.staging_path() + "/new.txt") << "new";
  }
  EXPECT_EQ(names_in(s.dir), std::vector<std::string>{"d"});
  EXPECT_EQ(names_in(target), std::vector<std::string>{"old.txt"});
  atomic_directory d(target + "/", true);  // a trailing '/' names the same folder
  d.create();
  std::ofstream(d.staging_path() + "/new.txt") << "new";
  d.commit();
  EXPECT_EQ(names_in(s.dir), std::vector<std::string>{"d"});
  EXPECT_EQ(names_in(target), std::vector<std::string>{"new.txt"});
  EXPECT_FALSE(is_unfinished_directory(target));
}

}  // namespace
}  // namespace pbr_lod
