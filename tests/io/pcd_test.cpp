// PCD reading: the three encodings, field types and counts, packed colours, NaN points, and
// every header or size that can lie.
#include <gtest/gtest.h>

#include "io_test_util.hpp"
#include "pbr_lod/io/read.hpp"

namespace {

using pbr_lod::FormatError;
using pbr_lod::read_points;
using pbr_lod::read_report;
using pbr_lod::rgb8;
using pbr_lod::vec3d;
using pbr_lod::test::put_le;

using Pcd = pbr_lod::test::scratch_dir;

std::string header(const std::string& fields, const std::string& size, const std::string& type,
                   const std::string& count, int width, int height, int points,
                   const std::string& data) {
  return "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS " + fields + "\nSIZE " +
         size + "\nTYPE " + type + "\nCOUNT " + count + "\nWIDTH " + std::to_string(width) +
         "\nHEIGHT " + std::to_string(height) + "\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " +
         std::to_string(points) + "\nDATA " + data + "\n";
}

// Three points x y z rgb(float, packed), binary, 16 bytes each: the layout PCL writes for
// PointXYZRGB without padding.
std::string xyzrgb_binary_points() {
  std::string s;
  const float xyz[3][3] = {{1, 2, 3}, {4, 5, 6}, {7, 8, 9}};
  const std::uint32_t rgb[3] = {0xFF8040u, 0x102030u, 0x000000u};
  for (int i = 0; i < 3; ++i) {
    for (float v : xyz[i]) put_le(s, v);
    put_le(s, rgb[i]);
  }
  return s;
}

// ASCII with a NaN point ("no return") and packed rgb as an unsigned integer:
// 16744512 = 0xFF8040 → (255, 128, 64).
TEST_F(Pcd, AsciiDropsNaNAndUnpacksRgb) {
  const std::string text = header("x y z rgb", "4 4 4 4", "F F F U", "1 1 1 1", 3, 1, 3, "ascii") +
                           "1 2 3 16744512\nnan nan nan 0\n4 5 6 255\n";
  read_report r;
  const auto c = read_points(write("a.pcd", text), &r);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(r.points_read, 3u);
  EXPECT_EQ(r.dropped_non_finite, 1u);
  EXPECT_EQ(c.world(1), vec3d(4, 5, 6));
  EXPECT_EQ(c.colours[0], (rgb8{255, 128, 64}));
  EXPECT_EQ(c.colours[1], (rgb8{0, 0, 255}));
}

// ASCII rgb of TYPE F: the text is the float whose bits are the packed colour (PCL's PointXYZRGB).
// 0x00FF8040 as a float is 2.34646e-38 (a denormal-free normal float), written with 9 digits.
TEST_F(Pcd, AsciiFloatPackedRgb) {
  const float packed = std::bit_cast<float>(0x00FF8040u);
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", static_cast<double>(packed));
  const std::string text = header("x y z rgb", "4 4 4 4", "F F F F", "1 1 1 1", 1, 1, 1, "ascii") +
                           "0 0 0 " + buf + "\n";
  const auto c = read_points(write("f.pcd", text));
  ASSERT_EQ(c.colours.size(), 1u);
  EXPECT_EQ(c.colours[0], (rgb8{255, 128, 64}));
}

TEST_F(Pcd, BinaryXyzRgb) {
  const auto c = read_points(
      write("b.pcd", header("x y z rgb", "4 4 4 4", "F F F F", "1 1 1 1", 3, 1, 3, "binary") +
                         xyzrgb_binary_points()));
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(c.world(2), vec3d(7, 8, 9));
  EXPECT_EQ(c.colours[1], (rgb8{0x10, 0x20, 0x30}));
}

// Mixed types and a COUNT > 1 field: x F8, y I2, z U1, normal_* F4, a 3-byte padding field
// "_" of U1 × 3, and curvature F4 (ignored). Point size 8+2+1+12+3+4 = 30 bytes.
TEST_F(Pcd, BinaryMixedTypesAndCounts) {
  std::string s = header("x y z normal_x normal_y normal_z _ curvature", "8 2 1 4 4 4 1 4",
                         "F I U F F F U F", "1 1 1 1 1 1 3 1", 2, 1, 2, "binary");
  for (int i = 0; i < 2; ++i) {
    put_le(s, 0.25 + i);                                 // x, double
    put_le(s, static_cast<std::int16_t>(-7 * (i + 1)));  // y
    s.push_back(static_cast<char>(200 + i));             // z, uchar
    for (float n : {0.f, 1.f, 0.f}) put_le(s, n);
    s.append(3, '\x7f');  // padding
    put_le(s, 0.5f);      // curvature
  }
  const auto c = read_points(write("mixed.pcd", s));
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c.world(0), vec3d(0.25, -7, 200));
  EXPECT_EQ(c.world(1), vec3d(1.25, -14, 201));
  ASSERT_EQ(c.normals.size(), 2u);
  EXPECT_EQ(c.normals[1], pbr_lod::vec3f(0, 1, 0));
  EXPECT_TRUE(c.colours.empty());
}

// binary_compressed: the same three points as BinaryXyzRgb, but field-major (all x, all y, all
// z, all rgba) before LZF — reading it as point-major would scramble the coordinates.
TEST_F(Pcd, CompressedIsFieldMajor) {
  std::string soa;
  for (float v : {1.f, 4.f, 7.f}) put_le(soa, v);
  for (float v : {2.f, 5.f, 8.f}) put_le(soa, v);
  for (float v : {3.f, 6.f, 9.f}) put_le(soa, v);
  for (std::uint32_t v : {0xFF8040u, 0x102030u, 0u}) put_le(soa, v);
  const std::string lzf = pbr_lod::test::lzf_literals(soa);
  std::string s =
      header("x y z rgba", "4 4 4 4", "F F F U", "1 1 1 1", 3, 1, 3, "binary_compressed");
  put_le(s, static_cast<std::uint32_t>(lzf.size()));
  put_le(s, static_cast<std::uint32_t>(soa.size()));
  s += lzf;
  const auto c = read_points(write("c.pcd", s));
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(c.world(0), vec3d(1, 2, 3));
  EXPECT_EQ(c.world(2), vec3d(7, 8, 9));
  EXPECT_EQ(c.colours[0], (rgb8{255, 128, 64}));
}

// A sensor pose is not applied (PCL does not either), but the report says it is there.
TEST_F(Pcd, ViewpointIsReportedNotApplied) {
  std::string text = header("x y z", "4 4 4", "F F F", "1 1 1", 1, 1, 1, "ascii") + "1 2 3\n";
  text.replace(text.find("VIEWPOINT 0 0 0"), 15, "VIEWPOINT 5 0 0");
  read_report r;
  const auto c = read_points(write("vp.pcd", text), &r);
  EXPECT_EQ(c.world(0), vec3d(1, 2, 3));
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_NE(r.warnings[0].find("VIEWPOINT"), std::string::npos);
}

// --- malformed

TEST_F(Pcd, PointsNotWidthTimesHeight) {
  PBR_LOD_EXPECT_THROW_MSG(
      read_points(write("wh.pcd", header("x y z", "4 4 4", "F F F", "1 1 1", 2, 2, 3, "ascii") +
                                      "0 0 0\n0 0 0\n0 0 0\n")),
      FormatError, "POINTS is 3 but WIDTH × HEIGHT = 2 × 2 = 4");
}

TEST_F(Pcd, TruncatedBinary) {
  std::string pts = xyzrgb_binary_points();
  pts.resize(pts.size() - 1);
  PBR_LOD_EXPECT_THROW_MSG(
      read_points(write(
          "t.pcd", header("x y z rgb", "4 4 4 4", "F F F F", "1 1 1 1", 3, 1, 3, "binary") + pts)),
      FormatError, "truncated: 3 points of 16 bytes need 48 bytes, the file has 47");
}

TEST_F(Pcd, TruncatedAscii) {
  PBR_LOD_EXPECT_THROW_MSG(
      read_points(write("ta.pcd", header("x y z", "4 4 4", "F F F", "1 1 1", 3, 1, 3, "ascii") +
                                      "0 0 0\n1 1 1\n")),
      FormatError, "point 2: the file ends");
}

TEST_F(Pcd, CompressedSizeBeyondFile) {
  std::string s = header("x y z", "4 4 4", "F F F", "1 1 1", 1, 1, 1, "binary_compressed");
  put_le(s, 1000u);
  put_le(s, 12u);
  s += "abc";
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("cs.pcd", s)), FormatError,
                           "compressed size 1000 runs past the end of the file");
}

TEST_F(Pcd, UncompressedSizeNotPointsTimesSize) {
  std::string s = header("x y z", "4 4 4", "F F F", "1 1 1", 1, 1, 1, "binary_compressed");
  const std::string lzf = pbr_lod::test::lzf_literals(std::string(16, '\0'));
  put_le(s, static_cast<std::uint32_t>(lzf.size()));
  put_le(s, 16u);
  s += lzf;
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("us.pcd", s)), FormatError,
                           "uncompressed size 16 does not match POINTS × point size = 1 × 12 = 12");
}

// The sizes agree with the header, but the LZF stream only holds 8 of the 12 bytes.
TEST_F(Pcd, DecompressedSizeMismatch) {
  std::string s = header("x y z", "4 4 4", "F F F", "1 1 1", 1, 1, 1, "binary_compressed");
  const std::string lzf = pbr_lod::test::lzf_literals(std::string(8, '\0'));
  put_le(s, static_cast<std::uint32_t>(lzf.size()));
  put_le(s, 12u);
  s += lzf;
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("ds.pcd", s)), FormatError,
                           "decompressed to 8 bytes, expected 12");
}

// 3 compressed bytes cannot hold 1.2 MB: refused before allocating.
TEST_F(Pcd, ImpossibleExpansion) {
  std::string s =
      header("x y z", "4 4 4", "F F F", "1 1 1", 100000, 1, 100000, "binary_compressed");
  put_le(s, 3u);
  put_le(s, 1200000u);
  s += "abc";
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("ie.pcd", s)), FormatError, "is impossible for 3");
}

// A control byte that points back before the start of the output: corrupt LZF.
TEST_F(Pcd, CorruptLzf) {
  std::string s = header("x y z", "4 4 4", "F F F", "1 1 1", 1, 1, 1, "binary_compressed");
  const std::string lzf = "\xe0\xff\xff\x00";
  put_le(s, static_cast<std::uint32_t>(lzf.size()));
  put_le(s, 12u);
  s += lzf;
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("cl.pcd", s)), FormatError, "LZF data");
}

TEST_F(Pcd, MissingXyz) {
  PBR_LOD_EXPECT_THROW_MSG(
      read_points(write("m.pcd", header("x y", "4 4", "F F", "1 1", 1, 1, 1, "ascii") + "0 0\n")),
      FormatError, "FIELDS must include x, y and z");
}

TEST_F(Pcd, UnsupportedTypeSize) {
  PBR_LOD_EXPECT_THROW_MSG(
      read_points(write("ts.pcd",
                        header("x y z", "4 4 2", "F F F", "1 1 1", 1, 1, 1, "ascii") + "0 0 0\n")),
      FormatError, "field z: unsupported TYPE F with SIZE 2");
}

TEST_F(Pcd, SizeListLengthMismatch) {
  PBR_LOD_EXPECT_THROW_MSG(
      read_points(
          write("sl.pcd", header("x y z", "4 4", "F F F", "1 1 1", 1, 1, 1, "ascii") + "0 0 0\n")),
      FormatError, "FIELDS names 3 fields but SIZE has 2");
}

TEST_F(Pcd, NoDataLine) {
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("nd.pcd", "VERSION 0.7\nFIELDS x y z\n")), FormatError,
                           "no DATA line");
}

TEST_F(Pcd, NotAPcd) {
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("np.pcd", "\x89PNG\r\n")), FormatError,
                           "not a PCD file");
}

}  // namespace
