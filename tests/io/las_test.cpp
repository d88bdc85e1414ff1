// LAS reading: versions, point formats, scale/offset in double, colour depth, and the header
// fields that can lie.
#include <gtest/gtest.h>

#include "io_test_util.hpp"
#include "pbr_lod/io/read.hpp"

namespace {

using pbr_lod::FormatError;
using pbr_lod::read_points;
using pbr_lod::read_report;
using pbr_lod::rgb8;
using pbr_lod::vec3d;
using pbr_lod::test::las_spec;
using pbr_lod::test::make_las;

using Las = pbr_lod::test::scratch_dir;

las_spec two_points() {
  las_spec s;  // LAS 1.2, format 3 (GPS time + RGB), 34-byte records like the PDAL sample
  s.offset[0] = 600000.0;
  s.scale[0] = 0.001;
  s.xyz = {{12345, 100, 7}, {-5, 200, 9}};
  s.rgb = {{10, 20, 30}, {255, 0, 128}};
  return s;
}

// World = X·scale + offset, computed in double: 12345·0.001 + 600000 = 600012.345. What is
// stored is a float relative to the box centre (600006.17): ±6.175 carries a float ulp of
// 4.8e-7, so world coordinates come back within 2.4e-7 — at 6·10⁵ a float alone would be off
// by up to 0.03. Colours ≤ 255 are kept as they are.
TEST_F(Las, ScaleOffsetAndEightBitColours) {
  const auto c = read_points(write("a.las", make_las(two_points())));
  ASSERT_EQ(c.size(), 2u);
  EXPECT_NEAR(c.world(0).x(), 600012.345, 2.5e-7);
  EXPECT_NEAR(c.world(1).x(), 599999.995, 2.5e-7);
  EXPECT_NEAR(c.world(1).y(), 2.0, 1e-12);
  EXPECT_EQ(c.colours[0], (rgb8{10, 20, 30}));
  EXPECT_EQ(c.colours[1], (rgb8{255, 0, 128}));
}

// Colours using the 16-bit range (as the specification asks) are scaled down by >> 8.
TEST_F(Las, SixteenBitColoursAreScaled) {
  las_spec s = two_points();
  s.rgb = {{65535, 256, 0}, {32768, 511, 255}};
  const auto c = read_points(write("c16.las", make_las(s)));
  EXPECT_EQ(c.colours[0], (rgb8{255, 1, 0}));
  EXPECT_EQ(c.colours[1], (rgb8{128, 1, 0}));
}

// LAS 1.4, format 7: RGB at byte 30, legacy count 0 and the 64-bit count at 247.
TEST_F(Las, Version14Format7) {
  las_spec s = two_points();
  s.minor = 4;
  s.format = 7;
  s.record_length = 36;
  s.rgb_offset = 30;
  const auto c = read_points(write("14.las", make_las(s)));
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c.colours[1], (rgb8{255, 0, 128}));
}

// Format 0 has no colour; a record longer than the minimum (extra bytes) is stepped over.
TEST_F(Las, Format0WithExtraBytes) {
  las_spec s = two_points();
  s.format = 0;
  s.record_length = 27;  // 20 + 7 extra bytes
  s.rgb.clear();
  const auto c = read_points(write("f0.las", make_las(s)));
  ASSERT_EQ(c.size(), 2u);
  EXPECT_TRUE(c.colours.empty());
  EXPECT_NEAR(c.world(1).z(), 0.09, 1e-9);  // float ulp at the relative 0.01 is 9.3e-10
}

// --- malformed

TEST_F(Las, WrongSignature) {
  std::string b = make_las(two_points());
  b[0] = 'X';
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("sig.las", b)), FormatError, "signature 'LASF'");
}

TEST_F(Las, TruncatedPoints) {
  std::string b = make_las(two_points());
  b.resize(b.size() - 10);
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("t.las", b)), FormatError,
                           "truncated: 2 points of 34 bytes from offset 227 need 295 bytes");
}

TEST_F(Las, TruncatedHeader) {
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("th.las", make_las(two_points()).substr(0, 100))),
                           FormatError, "a LAS header needs 227");
}

TEST_F(Las, PointOffsetBeyondFile) {
  std::string b = make_las(two_points());
  pbr_lod::test::poke_le<std::uint32_t>(b, 96, 100000);
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("o.las", b)), FormatError,
                           "offset to point data 100000 is beyond the end of the file");
}

TEST_F(Las, PointOffsetInsideHeader) {
  std::string b = make_las(two_points());
  pbr_lod::test::poke_le<std::uint32_t>(b, 96, 100);
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("oi.las", b)), FormatError, "lies inside the");
}

TEST_F(Las, RecordLengthTooSmall) {
  las_spec s = two_points();
  s.record_length = 26;  // format 3 needs 34
  s.rgb.clear();
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("rl.las", make_las(s))), FormatError,
                           "record length 26 is smaller than the 34 bytes format 3 needs");
}

TEST_F(Las, HeaderSizeTooSmall) {
  std::string b = make_las(two_points());
  pbr_lod::test::poke_le<std::uint16_t>(b, 94, 200);
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("hs.las", b)), FormatError,
                           "header size 200 is below the 227 bytes");
}

// LASzip sets bit 7 of the point format byte; the decoder then needs LASzip's VLR
// (tests/io/laz_test.cpp reads real LAZ files).
TEST_F(Las, CompressedBitNeedsTheLaszipVlr) {
  std::string b = make_las(two_points());
  b[104] = static_cast<char>(0x80 | 3);
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("z.las", b)), FormatError,
                           "none of the 0 VLRs is LASzip's");
}

// The format byte decides, not the extension: uncompressed points named .laz read as LAS.
TEST_F(Las, LazExtensionWithUncompressedPoints) {
  const auto c = read_points(write("z.laz", make_las(two_points())));
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c.colours[1], (rgb8{255, 0, 128}));
}

TEST_F(Las, UnknownVersion) {
  std::string b = make_las(two_points());
  b[24] = 2;
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("v.las", b)), FormatError,
                           "unsupported LAS version 2.2");
}

TEST_F(Las, ZeroScale) {
  las_spec s = two_points();
  s.scale[1] = 0.0;
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("zs.las", make_las(s))), FormatError,
                           "scale factor y = 0 is not a finite non-zero number");
}

TEST_F(Las, UnknownPointFormat) {
  std::string b = make_las(two_points());
  b[104] = 11;
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("pf.las", b)), FormatError,
                           "unknown point data record format 11");
}

// A count whose byte size overflows 64 bits must be caught, not wrapped into a small number.
TEST_F(Las, CountOverflow) {
  las_spec s = two_points();
  s.minor = 4;
  s.format = 7;
  s.record_length = 36;
  s.rgb_offset = 30;
  std::string b = make_las(s);
  pbr_lod::test::poke_le<std::uint64_t>(b, 247, ~std::uint64_t{0} / 8);
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("ov.las", b)), FormatError, "truncated");
}

// A LAS file is not a mesh.
TEST_F(Las, NotAMesh) {
  PBR_LOD_EXPECT_THROW_MSG((void)pbr_lod::read_mesh(write("m.las", make_las(two_points()))),
                           FormatError, "use read_points");
}

}  // namespace
