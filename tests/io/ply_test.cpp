// PLY reading: what is accepted (encodings, types, polygons, extra elements) and every way a
// file can lie, each of which must end in a pbr_lod::Error — not a crash, a hang or garbage.
#include <gtest/gtest.h>

#include <chrono>

#include "io_test_util.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/io/write.hpp"

namespace {

using pbr_lod::FormatError;
using pbr_lod::IoError;
using pbr_lod::read_mesh;
using pbr_lod::read_points;
using pbr_lod::read_report;
using pbr_lod::vec3d;
using pbr_lod::vec3f;

using Ply = pbr_lod::test::scratch_dir;

const char* const tri_header =
    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
    "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";

// One triangle: the smallest mesh; checks the origin rule on it (box centre (0.5, 0.5, 0)).
TEST_F(Ply, AsciiTriangle) {
  const auto m =
      read_mesh(write("t.ply", std::string(tri_header) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"));
  ASSERT_EQ(m.num_vertices(), 3u);
  ASSERT_EQ(m.num_faces(), 1u);
  EXPECT_EQ(m.faces[0], (std::array<std::uint32_t, 3>{0, 1, 2}));
  EXPECT_EQ(m.vertices.origin, vec3d(0.5, 0.5, 0));
  EXPECT_EQ(m.vertices.world(1), vec3d(1, 0, 0));
}

// Windows line endings and blank lines between rows are tolerated.
TEST_F(Ply, CrLfAndBlankLines) {
  const std::string text =
      "ply\r\nformat ascii 1.0\r\nelement vertex 3\r\nproperty float x\r\nproperty float y\r\n"
      "property float z\r\nelement face 1\r\nproperty list uchar int vertex_indices\r\n"
      "end_header\r\n0 0 0\r\n\r\n1 0 0\r\n0 1 0\r\n3 0 1 2\r\n";
  const auto m = read_mesh(write("crlf.ply", text));
  ASSERT_EQ(m.num_vertices(), 3u);
  ASSERT_EQ(m.num_faces(), 1u);
  // The values too, not only the counts: a '\r' read as part of the last number, or a blank
  // line read as a vertex of zeros, would move a vertex.
  EXPECT_EQ(m.vertices.world(0), vec3d(0, 0, 0));
  EXPECT_EQ(m.vertices.world(1), vec3d(1, 0, 0));
  EXPECT_EQ(m.vertices.world(2), vec3d(0, 1, 0));
  EXPECT_EQ(m.faces[0], (std::array<std::uint32_t, 3>{0, 1, 2}));
}

// A quad and a pentagon become 2 + 3 triangles, fanned from the first corner as OpenMesh does.
TEST_F(Ply, PolygonsAreFanTriangulated) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
      "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0.5 2 0\n4 0 1 2 3\n5 0 1 2 4 3\n";
  const auto m = read_mesh(write("poly.ply", text));
  ASSERT_EQ(m.num_faces(), 5u);
  EXPECT_EQ(m.faces[0], (std::array<std::uint32_t, 3>{0, 1, 2}));
  EXPECT_EQ(m.faces[1], (std::array<std::uint32_t, 3>{0, 2, 3}));
  EXPECT_EQ(m.faces[4], (std::array<std::uint32_t, 3>{0, 4, 3}));
}

// Faces repeating a vertex or with < 3 corners are dropped and counted, not returned as
// zero-area triangles: (0,0,1) and the 2-gon go, the good triangle stays.
TEST_F(Ply, DegenerateFacesDroppedAndCounted) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 3\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n3 0 0 1\n2 0 1\n3 0 1 2\n";
  read_report r;
  const auto m = read_mesh(write("degenerate.ply", text), &r);
  EXPECT_EQ(m.num_faces(), 1u);
  EXPECT_EQ(r.faces_dropped, 2u);
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_NE(r.warnings[0].find("2 degenerate faces"), std::string::npos) << r.warnings[0];
}

// "element face 0" and no face element at all both mean: a point cloud.
TEST_F(Ply, VertexOnlyFilesHaveNoFaces) {
  const std::string a =
      "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
      "property double z\nend_header\n1 2 3\n4 5 6\n";
  const std::string b =
      "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
      "property double z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n"
      "1 2 3\n4 5 6\n";
  for (const auto& text : {a, b}) {
    const auto m = read_mesh(write("points.ply", text));
    EXPECT_EQ(m.num_vertices(), 2u);
    EXPECT_TRUE(m.faces.empty());
  }
}

// double x y z keep all 17 digits — OpenMesh's reader rounds them to float, which is why we
// parse PLY ourselves. 10000000.123456789 would come back as 10000000 from a float.
TEST_F(Ply, DoubleCoordinatesKeepTheirPrecision) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
      "property double z\nend_header\n10000000.123456789 0 0\n10000001.123456789 0 0\n";
  const auto c = read_points(write("geo.ply", text));
  EXPECT_NEAR(c.world(0).x(), 10000000.123456789, 1e-8);
  EXPECT_NEAR(c.world(1).x(), 10000001.123456789, 1e-8);
}

// Normals, uchar colours, float colours and unknown properties/elements are handled: unknown
// ones (confidence, the "edge" element with its own list) are read past, not misread.
TEST_F(Ply, AttributesAndUnknownElements) {
  const std::string text =
      "ply\nformat ascii 1.0\ncomment made by hand\nobj_info nothing\n"
      "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "property float confidence\nproperty float nx\nproperty float ny\nproperty float nz\n"
      "property uchar red\nproperty uchar green\nproperty uchar blue\n"
      "element edge 1\nproperty list uchar int vertices\nproperty uchar flag\n"
      "element face 1\nproperty list uchar uint vertex_indices\nend_header\n"
      "0 0 0 0.5 0 0 1 255 0 0\n1 0 0 0.5 0 0 1 0 255 0\n0 1 0 0.5 0 0 1 0 0 255\n"
      "2 0 1 7\n3 0 1 2\n";
  const auto m = read_mesh(write("attrs.ply", text));
  ASSERT_EQ(m.vertices.normals.size(), 3u);
  ASSERT_EQ(m.vertices.colours.size(), 3u);
  EXPECT_EQ(m.vertices.normals[2], vec3f(0, 0, 1));
  EXPECT_EQ(m.vertices.colours[1], (pbr_lod::rgb8{0, 255, 0}));
  EXPECT_EQ(m.num_faces(), 1u);
}

// Big-endian binary: bytes reversed per value. Vertex (1, 2, 3) as big-endian floats, one
// triangle with big-endian int indices.
TEST_F(Ply, BinaryBigEndian) {
  std::string s =
      "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  for (float v : {1.f, 2.f, 3.f, 4.f, 5.f, 6.f, 7.f, 8.f, 10.f}) pbr_lod::test::put_be(s, v);
  s.push_back(3);
  for (std::int32_t i : {2, 1, 0}) pbr_lod::test::put_be(s, i);
  const auto m = read_mesh(write("be.ply", s));
  ASSERT_EQ(m.num_vertices(), 3u);
  EXPECT_EQ(m.vertices.world(0), vec3d(1, 2, 3));
  EXPECT_EQ(m.vertices.world(2), vec3d(7, 8, 10));
  EXPECT_EQ(m.faces[0], (std::array<std::uint32_t, 3>{2, 1, 0}));
}

// NaN and Inf coordinates are dropped and counted; the face using the NaN vertex goes too, and
// the remaining face is re-indexed (vertex 3 becomes 2).
TEST_F(Ply, NonFiniteCoordinatesAreDroppedWithACount) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
      "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\nnan 0 0\n1 0 0\n0 1 0\n0 0 inf\n3 0 1 2\n3 0 2 3\n";
  read_report r;
  const auto m = read_mesh(write("nan.ply", text), &r);
  EXPECT_EQ(m.num_vertices(), 3u);
  EXPECT_EQ(r.points_read, 5u);
  EXPECT_EQ(r.dropped_non_finite, 2u);
  EXPECT_EQ(r.faces_dropped, 1u);
  ASSERT_EQ(m.num_faces(), 1u);
  EXPECT_EQ(m.faces[0], (std::array<std::uint32_t, 3>{0, 1, 2}));
  ASSERT_FALSE(r.warnings.empty());
  EXPECT_NE(r.warnings[0].find("nan.ply: dropped 2 non-finite points"), std::string::npos);
}

// --- malformed files: each throws a pbr_lod::Error naming the problem ---------------------------

TEST_F(Ply, MissingFile) {
  PBR_LOD_EXPECT_THROW_MSG(read_mesh(path("nope.ply")), IoError, "no such file");
}

TEST_F(Ply, Directory) {
  std::filesystem::create_directories(path("dir.ply"));
  PBR_LOD_EXPECT_THROW_MSG(read_mesh(path("dir.ply")), IoError, "directory");
}

TEST_F(Ply, EmptyFile) {
  PBR_LOD_EXPECT_THROW_MSG(read_mesh(write("empty.ply", "")), FormatError, "empty");
}

TEST_F(Ply, WrongMagic) {
  PBR_LOD_EXPECT_THROW_MSG(read_mesh(write("magic.ply", "plx\nformat ascii 1.0\nend_header\n")),
                           FormatError, "header line 1: expected the magic 'ply'");
}

TEST_F(Ply, NoEndHeader) {
  PBR_LOD_EXPECT_THROW_MSG(
      read_mesh(write("noend.ply", "ply\nformat ascii 1.0\nelement vertex 1\n")), FormatError,
      "before 'end_header'");
}

TEST_F(Ply, UnknownPropertyType) {
  PBR_LOD_EXPECT_THROW_MSG(read_mesh(write("type.ply",
                                           "ply\nformat ascii 1.0\nelement vertex 1\n"
                                           "property float128 x\nend_header\n1\n")),
                           FormatError, "header line 4: unknown type 'float128'");
}

TEST_F(Ply, MissingCoordinates) {
  PBR_LOD_EXPECT_THROW_MSG(read_mesh(write("xy.ply",
                                           "ply\nformat ascii 1.0\nelement vertex 1\n"
                                           "property float x\nproperty float y\n"
                                           "end_header\n1 2\n")),
                           FormatError, "needs properties x, y and z");
}

// The header promises 3 vertices and 1 face = 4 lines; the file has 3.
TEST_F(Ply, AsciiFewerLinesThanPromised) {
  PBR_LOD_EXPECT_THROW_MSG(
      read_mesh(write("short.ply", std::string(tri_header) + "0 0 0\n1 0 0\n0 1 0\n")), FormatError,
      "promises 4 data lines (3 vertex, 1 face) but the file has only 3");
}

TEST_F(Ply, AsciiTooFewValuesOnALine) {
  PBR_LOD_EXPECT_THROW_MSG(
      read_mesh(write("few.ply", std::string(tri_header) + "0 0 0\n1 0\n0 1 0\n3 0 1 2\n")),
      FormatError, "vertex 1 (line 11)");
}

TEST_F(Ply, AsciiTooManyValuesOnALine) {
  PBR_LOD_EXPECT_THROW_MSG(
      read_mesh(write("many.ply", std::string(tri_header) + "0 0 0 7\n1 0 0\n0 1 0\n3 0 1 2\n")),
      FormatError, "more values on the line than the header declares");
}

TEST_F(Ply, AsciiGarbageValue) {
  PBR_LOD_EXPECT_THROW_MSG(read_mesh(write("garbage.ply", std::string(tri_header) +
                                                              "0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n")),
                           FormatError, "'zero' is not a number");
}

TEST_F(Ply, FaceIndexOutOfRange) {
  PBR_LOD_EXPECT_THROW_MSG(
      read_mesh(write("range.ply", std::string(tri_header) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n")),
      FormatError, "face 0 (line 13): vertex index 3 is out of range: the file has 3 vertices");
}

TEST_F(Ply, NegativeFaceIndex) {
  PBR_LOD_EXPECT_THROW_MSG(
      read_mesh(write("neg.ply", std::string(tri_header) + "0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n")),
      FormatError, "vertex index -1 is out of range");
}

// A list longer than the values on its line: the count is checked before anything is read.
TEST_F(Ply, AsciiListLongerThanLine) {
  PBR_LOD_EXPECT_THROW_MSG(
      read_mesh(write("list.ply", std::string(tri_header) + "0 0 0\n1 0 0\n0 1 0\n200 0 1 2\n")),
      FormatError, "runs past the end of the line");
}

// A binary file cut short: write a real one, drop its last 5 bytes.
TEST_F(Ply, TruncatedBinary) {
  pbr_lod::triangle_mesh m;
  m.vertices.positions = {vec3f(0, 0, 0), vec3f(1, 0, 0), vec3f(0, 1, 0)};
  m.faces = {{0, 1, 2}};
  const std::string p = path("full.ply");
  pbr_lod::write_ply(p, m, true);
  std::string bytes = pbr_lod::test::slurp(p);
  bytes.resize(bytes.size() - 5);
  PBR_LOD_EXPECT_THROW_MSG(read_mesh(write("cut.ply", bytes)), FormatError, "truncated");
}

// A binary header promising 4·10⁹ vertices over a few bytes must fail at once — not allocate
// 96 GB and not loop.
TEST_F(Ply, BinaryHugeCountFailsFast) {
  const auto t0 = std::chrono::steady_clock::now();
  PBR_LOD_EXPECT_THROW_MSG(
      read_mesh(write("huge.ply",
                      "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\n"
                      "property float x\nproperty float y\nproperty float z\nend_header\n"
                      "0123456789ab")),
      FormatError, "truncated: the header needs at least 48000000000 bytes");
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(1));
}

// A binary face whose uchar count says 255 corners at the very end of the file.
TEST_F(Ply, BinaryListPastTheEnd) {
  std::string s =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
      "property float y\nproperty float z\nelement face 1\n"
      "property list uchar int vertex_indices\nend_header\n";
  for (int i = 0; i < 9; ++i) pbr_lod::test::put_le(s, 0.5f * static_cast<float>(i));
  s.push_back(static_cast<char>(255));
  for (std::int32_t i : {0, 1, 2}) pbr_lod::test::put_le(s, i);
  PBR_LOD_EXPECT_THROW_MSG(read_mesh(write("list.ply", s)), FormatError,
                           "face 0: list vertex_indices of length 255 runs past the end");
}

// Elements without properties take no bytes: a huge count of them must not loop for nothing.
TEST_F(Ply, ElementWithoutProperties) {
  PBR_LOD_EXPECT_THROW_MSG(read_mesh(write("empty_el.ply",
                                           "ply\nformat binary_little_endian 1.0\n"
                                           "element nothing 18446744073709551615\nend_header\n")),
                           FormatError, "has rows but no properties");
}

TEST_F(Ply, UnsupportedExtension) {
  PBR_LOD_EXPECT_THROW_MSG(read_mesh(write("a.stl", "solid")), FormatError,
                           "unsupported extension '.stl'");
}

}  // namespace
