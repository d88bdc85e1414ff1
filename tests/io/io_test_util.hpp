// Test helpers for tests/io: a scratch folder per test, writing small hand-made files, and
// byte-level builders for the binary formats (so malformed variants are one edit away).
#pragma once

#include <gtest/gtest.h>

#include <unistd.h>
#include <array>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "pbr_lod/core/error.hpp"

namespace pbr_lod::test {

/// A fresh folder under the system temp dir, removed when the test ends.
class scratch_dir : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ =
        std::filesystem::temp_directory_path() / ("pbr_lod_io_" + std::to_string(::getpid()) + "_" +
                                                  info->test_suite_name() + "_" + info->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

 public:
  /// Full path of `name` inside the scratch folder.
  [[nodiscard]] std::string path(const std::string& name) const { return (dir_ / name).string(); }

  /// Writes `bytes` verbatim to `name` and returns its path.
  std::string write(const std::string& name, const std::string& bytes) const {
    const std::string p = path(name);
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    return p;
  }

 protected:
  std::filesystem::path dir_;
};

/// Reads a whole file (to corrupt it in tests).
inline std::string slurp(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// Appends the little-endian bytes of v.
template <class T>
void put_le(std::string& s, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  s.append(b, sizeof(T));
}
template <class T>
void poke_le(std::string& s, std::size_t at, T v) {
  std::memcpy(s.data() + at, &v, sizeof(T));
}
template <class T>
void put_be(std::string& s, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  for (std::size_t i = sizeof(T); i-- > 0;) s.push_back(b[i]);
}

/// A LAS file: header of the version's minimum size, no VLRs, points right after the header.
/// Records are zero-filled beyond X Y Z (and RGB where the format has it).
struct las_spec {
  int minor = 2;
  std::uint8_t format = 3;
  std::uint16_t record_length = 34;
  double scale[3] = {0.01, 0.01, 0.01};
  double offset[3] = {0, 0, 0};
  std::vector<std::array<std::int32_t, 3>> xyz;
  std::vector<std::array<std::uint16_t, 3>> rgb;  ///< empty or one per point
  std::uint16_t rgb_offset = 28;                  ///< byte offset of RGB in the record
};

inline std::string make_las(const las_spec& s) {
  const std::uint16_t header_size = s.minor <= 2 ? 227 : s.minor == 3 ? 235 : 375;
  std::string b(header_size, '\0');
  std::memcpy(b.data(), "LASF", 4);
  b[24] = 1;
  b[25] = static_cast<char>(s.minor);
  poke_le<std::uint16_t>(b, 94, header_size);
  poke_le<std::uint32_t>(b, 96, header_size);  // offset to point data: no VLRs
  b[104] = static_cast<char>(s.format);
  poke_le<std::uint16_t>(b, 105, s.record_length);
  const auto n = static_cast<std::uint32_t>(s.xyz.size());
  poke_le<std::uint32_t>(b, 107, s.minor >= 4 && s.format >= 6 ? 0u : n);
  if (s.minor >= 4) poke_le<std::uint64_t>(b, 247, n);
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (const auto& p : s.xyz)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], p[a] * s.scale[a] + s.offset[a]);
      hi[a] = std::max(hi[a], p[a] * s.scale[a] + s.offset[a]);
    }
  for (int a = 0; a < 3; ++a) {
    poke_le<double>(b, 131 + 8 * a, s.scale[a]);
    poke_le<double>(b, 155 + 8 * a, s.offset[a]);
    poke_le<double>(b, 179 + 16 * a, n ? hi[a] : 0.0);
    poke_le<double>(b, 187 + 16 * a, n ? lo[a] : 0.0);
  }
  for (std::size_t i = 0; i < s.xyz.size(); ++i) {
    std::string rec(s.record_length, '\0');
    for (int a = 0; a < 3; ++a)
      poke_le<std::int32_t>(rec, 4 * static_cast<std::size_t>(a), s.xyz[i][a]);
    if (!s.rgb.empty())
      for (int c = 0; c < 3; ++c)
        poke_le<std::uint16_t>(rec, s.rgb_offset + 2 * static_cast<std::size_t>(c), s.rgb[i][c]);
    b += rec;
  }
  return b;
}

/// LZF "compression" using literal runs only (control byte L-1 then L ≤ 32 bytes): valid input
/// for lzf_decompress, so tests can build binary_compressed PCD files without linking liblzf.
inline std::string lzf_literals(const std::string& raw) {
  std::string out;
  for (std::size_t i = 0; i < raw.size(); i += 32) {
    const std::size_t len = std::min<std::size_t>(32, raw.size() - i);
    out.push_back(static_cast<char>(len - 1));
    out.append(raw, i, len);
  }
  return out;
}

}  // namespace pbr_lod::test

/// Expects `stmt` to throw exactly `Type` (derived from pbr_lod::Error) with `fragment` in its
/// message, so a test documents what the user is told.
#define PBR_LOD_EXPECT_THROW_MSG(stmt, Type, fragment)                            \
  do {                                                                            \
    try {                                                                         \
      (void)(stmt);                                                               \
      ADD_FAILURE() << "expected " #Type " from: " #stmt;                         \
    } catch (const Type& e) {                                                     \
      static_assert(std::is_base_of_v<pbr_lod::Error, Type>);                     \
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos)          \
          << "message was: " << e.what();                                         \
    } catch (const std::exception& e) {                                           \
      ADD_FAILURE() << "expected " #Type ", got another exception: " << e.what(); \
    }                                                                             \
  } while (0)
