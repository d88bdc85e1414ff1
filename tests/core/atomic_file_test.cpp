// Outputs appear whole or not at all (core/atomic_file.hpp): a save that fails under a file-size
// limit, or a process killed mid-write, leaves the previous file byte for byte and nothing
// partial under the target's name. The failing writes run in a forked child, so the limit and
// the signal never touch the test process.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <string>

#include "pbr_lod/builders/point_octree.hpp"
#include "pbr_lod/core/atomic_file.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/write.hpp"
#include "pbr_lod/raster/png.hpp"
#include "support/limited_write.hpp"

namespace pbr_lod {
namespace {

namespace fs = std::filesystem;

std::string slurp(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

/// A fresh folder for one test.
struct scratch {
  fs::path dir;
  explicit scratch(const std::string& name)
      : dir(fs::temp_directory_path() /
            ("pbr_lod_atomic_" + name + "_" + std::to_string(::getpid()))) {
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  ~scratch() { fs::remove_all(dir); }
  /// Names in the folder other than `keep`.
  [[nodiscard]] std::vector<std::string> others(const std::string& keep) const {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(dir))
      if (e.path().filename() != keep) out.push_back(e.path().filename().string());
    return out;
  }
};

using test::run_limited;

point_octree<point_octree_attributes(with_normals_colours)> small_tree(std::size_t n) {
  const point_cloud c = sample_surface(make_demo_scene(8), n, 3);
  return build_point_octree(point_set<with_normals_colours>::from(c));
}

// A hierarchy saved over an older one under a file-size limit smaller than the new file: the
// save throws IoError naming the file, the old file is byte-identical, no temporary is left.
// (With a plain truncating write the old file would be cut to the limit.)
TEST(AtomicOutput, SaveOverFileSizeLimitKeepsTheOldFile) {
  const scratch s("limit");
  const std::string path = (s.dir / "tree.lod").string();
  small_tree(500).save(path);
  const std::string old = slurp(path);
  const auto bigger = small_tree(20000);
  const int status = run_limited(old.size() / 2, true, path, [&] { bigger.save(path); });
  ASSERT_TRUE(WIFEXITED(status)) << "the child was killed: SIGXFSZ not ignored?";
  EXPECT_EQ(WEXITSTATUS(status), 7) << "expected IoError naming " << path;
  EXPECT_EQ(slurp(path), old);
  EXPECT_TRUE(s.others("tree.lod").empty()) << "a temporary file was left";
}

// The same save killed by SIGXFSZ in the middle of its write: the old file is byte-identical;
// what the killed process leaves is a `.partial-` file beside it, never a partial target.
TEST(AtomicOutput, SaveKilledMidWriteKeepsTheOldFile) {
  const scratch s("killed");
  const std::string path = (s.dir / "tree.lod").string();
  small_tree(500).save(path);
  const std::string old = slurp(path);
  const auto bigger = small_tree(20000);
  const int status = run_limited(old.size() / 2, false, path, [&] { bigger.save(path); });
  ASSERT_TRUE(WIFSIGNALED(status));
  EXPECT_EQ(WTERMSIG(status), SIGXFSZ);
  EXPECT_EQ(slurp(path), old);
  for (const auto& name : s.others("tree.lod"))
    EXPECT_NE(name.find("tree.lod.partial-"), std::string::npos) << name;
}

// PNG and PLY writers go through the same path.
TEST(AtomicOutput, PngAndPlyOverFileSizeLimitKeepTheOldFile) {
  const scratch s("png_ply");
  const std::string png = (s.dir / "a.png").string(), ply = (s.dir / "a.ply").string();
  image small(4, 4, {1, 2, 3}), large(512, 512);
  for (std::size_t i = 0; i < large.size(); ++i) {
    large.colour[i] = {static_cast<std::uint8_t>(i * 7), static_cast<std::uint8_t>(i * 13),
                       static_cast<std::uint8_t>(i >> 5)};
    large.depth[i] = 1;
  }
  write_png(png, small);
  const triangle_mesh m = make_demo_scene(6);
  triangle_mesh tiny;
  tiny.vertices.positions = {vec3f(0, 0, 0), vec3f(1, 0, 0), vec3f(0, 1, 0)};
  tiny.faces = {{0, 1, 2}};
  write_ply(ply, tiny);
  const std::string old_png = slurp(png), old_ply = slurp(ply);
  EXPECT_EQ(WEXITSTATUS(run_limited(4096, true, png, [&] { write_png(png, large); })), 7);
  EXPECT_EQ(WEXITSTATUS(run_limited(4096, true, ply, [&] { write_ply(ply, m); })), 7);
  EXPECT_EQ(slurp(png), old_png);
  EXPECT_EQ(slurp(ply), old_ply);
  EXPECT_EQ(s.others("").size(), 2u) << "a temporary file was left";
  // Without a limit both are replaced.
  write_png(png, large);
  write_ply(ply, m);
  EXPECT_NE(slurp(png), old_png);
  EXPECT_NE(slurp(ply), old_ply);
}

// A write into a folder that does not exist fails with the target's name and creates nothing.
TEST(AtomicOutput, MissingFolderIsAnIoError) {
  const std::string path = "/nonexistent-pbr_lod-folder/x.lod";
  const std::string bytes = "abc";
  try {
    write_file_atomically(path, bytes.data(), bytes.size());
    FAIL() << "no error";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace pbr_lod
