// Helpers of the chunked-build tests (chunked_point_octree_test.cpp, chunked_pmr_test.cpp).
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

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

}  // namespace pbr_lod::test
