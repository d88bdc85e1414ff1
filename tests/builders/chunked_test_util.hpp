// Helpers of the chunked-build tests (chunked_point_octree_test.cpp, chunked_pmr_test.cpp,
// chunked_pca_octree_test.cpp).
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "pbr_lod/core/error.hpp"

namespace pbr_lod::test {

/// A fresh folder name under the temporary directory, unique to this process.
inline std::string temp_dir(const std::string& prefix, const std::string& what) {
  const std::filesystem::path p =
      std::filesystem::temp_directory_path() / (prefix + std::to_string(::getpid()) + "_" + what);
  std::filesystem::remove_all(p);
  return p.string();
}

inline std::vector<char> bytes_of(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

/// Every file of folder a equals b's, and they hold the same file names.
inline void expect_same_folders(const std::string& a, const std::string& b) {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(a))
    names.push_back(e.path().filename().string());
  std::size_t in_b = 0;
  for (const auto& e : std::filesystem::directory_iterator(b)) in_b += e.is_regular_file() ? 1 : 0;
  EXPECT_EQ(names.size(), in_b);
  for (const auto& f : names) EXPECT_EQ(bytes_of(a + "/" + f), bytes_of(b + "/" + f)) << f;
}

inline void write_bytes(const std::string& path, const std::vector<char>& b, std::size_t keep) {
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(b.data(), static_cast<std::streamsize>(keep));
}

/// The file at `path` cut at every cut_step-th byte and flipped at every flip_step-th: `open()`
/// throws an Error each time, never crashes. The file is restored after.
template <class Open>
void expect_damage_is_error(const std::string& path, std::size_t cut_step, std::size_t flip_step,
                            Open open) {
  const std::vector<char> good = bytes_of(path);
  for (std::size_t cut = 0; cut < good.size(); cut += cut_step) {
    write_bytes(path, good, cut);
    EXPECT_THROW(open(), Error) << path << " cut at " << cut;
  }
  for (std::size_t at = 0; at < good.size(); at += flip_step) {
    std::vector<char> b = good;
    b[at] = static_cast<char>(b[at] ^ 0x5a);
    write_bytes(path, b, b.size());
    EXPECT_THROW(open(), Error) << path << " byte " << at << " flipped";
  }
  write_bytes(path, good, good.size());
}

/// Chunks 0 and 1 of `dir` swap their files (each valid on its own, but not the chunk the top
/// names): reading chunk 0, and so assembling, is a FormatError. `chunk(c)` names c's file.
template <class H, class Name>
void expect_swapped_chunks_are_errors(const H& h, const std::string& dir, Name chunk) {
  ASSERT_GE(h.chunk_count(), 2u);
  namespace fs = std::filesystem;
  fs::rename(dir + "/" + chunk(0), dir + "/swap");
  fs::rename(dir + "/" + chunk(1), dir + "/" + chunk(0));
  fs::rename(dir + "/swap", dir + "/" + chunk(1));
  EXPECT_THROW((void)h.chunk(0), FormatError);
  EXPECT_THROW((void)h.assemble(), FormatError);
}

}  // namespace pbr_lod::test
