// open_point_source: a file read in blocks must give exactly what read_points gives for it —
// origin, bit-identical positions, normals, colours, sensor, report — whatever the block sizes
// and offsets, from several threads at once, and fail as read_points fails on broken files.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <filesystem>
#include <limits>
#include <random>
#include <thread>

#include "io/io_internal.hpp"
#include "io_test_util.hpp"
#include "pbr_lod/core/point_source.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/point_source_file.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/io/write.hpp"
#include "support/data.hpp"

namespace {

using pbr_lod::FormatError;
using pbr_lod::InvalidArgument;
using pbr_lod::IoError;
using pbr_lod::open_point_source;
using pbr_lod::point_block;
using pbr_lod::point_cloud;
using pbr_lod::point_source;
using pbr_lod::read_points;
using pbr_lod::read_report;
using pbr_lod::vec3d;
using pbr_lod::vec3f;
using pbr_lod::detail::cat;
using pbr_lod::test::put_be;
using pbr_lod::test::put_le;

using Source = pbr_lod::test::scratch_dir;

bool same_bits(const vec3f& a, const vec3f& b) {
  return std::bit_cast<std::uint32_t>(a.x()) == std::bit_cast<std::uint32_t>(b.x()) &&
         std::bit_cast<std::uint32_t>(a.y()) == std::bit_cast<std::uint32_t>(b.y()) &&
         std::bit_cast<std::uint32_t>(a.z()) == std::bit_cast<std::uint32_t>(b.z());
}

// Points [first, first + n) of `got` equal points [at, at + n) of `want`, bit for bit.
void expect_points(const point_block& got, const point_cloud& want, std::size_t at,
                   const std::string& what) {
  ASSERT_EQ(got.normals.size(), want.normals.empty() ? 0 : got.size()) << what;
  ASSERT_EQ(got.colours.size(), want.colours.empty() ? 0 : got.size()) << what;
  std::size_t bad = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    bool ok = same_bits(got.positions[i], want.positions[at + i]);
    if (!want.normals.empty()) ok = ok && same_bits(got.normals[i], want.normals[at + i]);
    if (!want.colours.empty()) ok = ok && got.colours[i] == want.colours[at + i];
    if (!ok && bad++ == 0) ADD_FAILURE() << what << ": first difference at point " << at + i;
  }
  EXPECT_EQ(bad, 0u) << what;
}

// The whole source equals the cloud read_points gave.
void expect_same_cloud(const point_cloud& got, const point_cloud& want) {
  EXPECT_EQ(got.origin, want.origin);
  EXPECT_EQ(got.sensor, want.sensor);
  ASSERT_EQ(got.size(), want.size());
  point_block b;
  b.positions = got.positions;
  b.normals = got.normals;
  b.colours = got.colours;
  ASSERT_EQ(got.normals.size(), want.normals.size());
  ASSERT_EQ(got.colours.size(), want.colours.size());
  expect_points(b, want, 0, "read_all");
}

// The report at open is read_points' report without what concerns faces (the source reads none).
void expect_same_report(const read_report& got, const read_report& want) {
  EXPECT_EQ(got.points_read, want.points_read);
  EXPECT_EQ(got.dropped_non_finite, want.dropped_non_finite);
  EXPECT_EQ(got.faces_dropped, 0u);
  std::vector<std::string> w;
  for (const std::string& s : want.warnings)
    if (s.find("faces") == std::string::npos) w.push_back(s);
  EXPECT_EQ(got.warnings, w);
}

// Reads of odd sizes at random offsets give the same points as the whole. Sizes 1 and 7 are
// smaller than anything, 65535 / 65537 straddle the index's runs of 2^16 points.
void expect_blocks(const point_source& src, const point_cloud& want, std::uint64_t seed = 7) {
  std::mt19937_64 rng(seed);  // random offsets: any of them must work, so any sample is a test
  point_block b;
  const std::uint64_t n = src.size();
  for (const std::size_t size : {1, 7, 65535, 65537}) {
    for (int k = 0; k < 4; ++k) {
      const std::size_t count = static_cast<std::size_t>(std::min<std::uint64_t>(size, n));
      const std::uint64_t first = n == count ? 0 : rng() % (n - count + 1);
      src.read(first, count, b);
      ASSERT_EQ(b.size(), count);
      expect_points(b, want, static_cast<std::size_t>(first),
                    "block [" + std::to_string(first) + ", +" + std::to_string(count) + ")");
    }
  }
  // The last point alone, and an empty read at the end.
  if (n > 0) {
    src.read(n - 1, 1, b);
    expect_points(b, want, static_cast<std::size_t>(n - 1), "last point");
  }
  src.read(n, 0, b);
  EXPECT_EQ(b.size(), 0u);
}

// The whole contract for one file; returns the cloud for further checks.
point_cloud check_file(const std::string& path) {
  read_report want_report, got_report;
  const point_cloud want = read_points(path, &want_report);
  const auto src = open_point_source(path, &got_report);
  EXPECT_EQ(src->size(), want.size());
  EXPECT_EQ(src->attrs().normal, !want.normals.empty());
  EXPECT_EQ(src->attrs().colour, !want.colours.empty());
  expect_same_report(got_report, want_report);
  expect_same_cloud(read_all(*src), want);
  expect_blocks(*src, want);
  return want;
}

// --- real data --------------------------------------------------------------------------------

class RealFile : public ::testing::TestWithParam<const char*> {};

TEST_P(RealFile, SameAsReadPoints) {
  check_file(pbr_lod::test::data_file(GetParam()));
}

INSTANTIATE_TEST_SUITE_P(SharedData, RealFile,
                         ::testing::Values("bun_zipper.ply", "bun_zipper_res2.ply",
                                           "bun_zipper_res3.ply", "bun_zipper_res4.ply",
                                           "happy_vrip_res3.ply",
                                           "milk_cartoon_all_small_clorox.pcd",
                                           "1.2-with-color.las"),
                         [](const auto& p) {
                           std::string s = p.param;
                           for (char& c : s)
                             if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                           return s;
                         });

// --- hand-made files --------------------------------------------------------------------------

// Big-endian doubles, non-unit normals (renormalised by the shared rule) and colours: every
// byte of a record must be swapped and placed right.
TEST_F(Source, BinaryBigEndianPly) {
  std::string s =
      "ply\nformat binary_big_endian 1.0\nelement vertex 4\nproperty double x\n"
      "property double y\nproperty double z\nproperty float nx\nproperty float ny\n"
      "property float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
      "end_header\n";
  const double xyz[4][3] = {{1e6, 2, 3}, {1e6 + 0.25, -2, 3.5}, {1e6 - 1, 0, 0}, {1e6, 1, 1}};
  const float nrm[4][3] = {{0, 0, 1}, {0, 2, 0}, {3, 4, 0}, {0, 0, 0}};
  for (int i = 0; i < 4; ++i) {
    for (double v : xyz[i]) put_be(s, v);
    for (float v : nrm[i]) put_be(s, v);
    for (int c = 0; c < 3; ++c) s.push_back(static_cast<char>(40 * i + c));
  }
  const point_cloud c = check_file(write("be.ply", s));
  ASSERT_EQ(c.size(), 4u);
  EXPECT_EQ(c.world(1), vec3d(1e6 + 0.25, -2, 3.5));
  EXPECT_EQ(c.normals[2], vec3f(0.6f, 0.8f, 0));  // (3, 4, 0) normalised
}

// Comments, properties we do not use (a scalar and a list), blank lines, CRLF and a face
// element: only the vertices are points, with the right values.
TEST_F(Source, AsciiPlyWithCommentsAndExtraProperties) {
  const std::string s =
      "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\nobj_info anything\r\n"
      "element vertex 3\r\nproperty float x\r\nproperty float confidence\r\nproperty float y\r\n"
      "property list uchar int extra\r\nproperty float z\r\nproperty uchar red\r\n"
      "property uchar green\r\nproperty uchar blue\r\ncomment between\r\nelement face 1\r\n"
      "property list uchar int vertex_indices\r\nend_header\r\n"
      "0 0.5 0 2 7 8 0 10 20 30\r\n\r\n  \r\n1 0.5 0 0 0 40 50 60\r\n0 0.5 1 1 9 0 70 80 90\r\n"
      "3 0 1 2\r\n";
  const point_cloud c = check_file(write("a.ply", s));
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(c.world(1), vec3d(1, 0, 0));  // x, confidence, y, an empty list, z
  EXPECT_EQ(c.world(2), vec3d(0, 1, 0));  // the list [9] is read past
  EXPECT_EQ(c.colours[2], (pbr_lod::rgb8{70, 80, 90}));
}

// NaN and Inf points are dropped and the later ones move up: source index 1 is file vertex 2.
// A NaN normal on a kept point becomes zero. 70000 vertices with a NaN every 1000 put dropped
// points inside and across the index's runs of 2^16.
TEST_F(Source, PlyWithNonFinitePoints) {
  std::string s =
      "ply\nformat ascii 1.0\nelement vertex 70005\nproperty float x\n"
      "property float y\nproperty float z\nproperty float nx\nproperty float ny\n"
      "property float nz\nend_header\n";
  s += "0 0 0 0 0 1\nnan 1 1 0 0 1\n2 2 2 nan 0 1\n3 inf 3 0 0 1\n4 4 4 0 1 0\n";
  for (int i = 0; i < 70000; ++i)
    s += (i % 1000 == 999 ? std::string("nan") : std::to_string(i)) + " 1 2 0 0 1\n";
  read_report r;
  const point_cloud c = check_file(write("nan.ply", s));
  (void)read_points(path("nan.ply"), &r);
  EXPECT_EQ(r.dropped_non_finite, 2u + 70u);
  ASSERT_EQ(c.size(), 70005u - 72u);
  EXPECT_EQ(c.world(1), vec3d(2, 2, 2));
  EXPECT_EQ(c.normals[1], vec3f::Zero());
  EXPECT_EQ(c.world(2), vec3d(4, 4, 4));
  const auto src = open_point_source(path("nan.ply"));
  point_block b;
  src->read(2, 2, b);
  EXPECT_EQ(b.positions[0], (vec3d(4, 4, 4) - c.origin).cast<float>());
  EXPECT_EQ(b.positions[1], (vec3d(0, 1, 2) - c.origin).cast<float>());
}

// Points dropped in the second of three index runs only (binary and ASCII): reads of 7 in order
// (each starts where the last ended), backwards, across the runs' ends, and from two threads at
// once (each may start where the other's last read ended) give read_points' points.
TEST_F(Source, ReadsInOrderAndBackAcrossDroppedPoints) {
  const int n = 140000;
  const auto dropped = [](int i) { return i >= 70000 && i < 100000 && i % 997 == 3; };
  for (const bool binary : {true, false}) {
    std::string s =
        cat("ply\nformat ", binary ? "binary_little_endian" : "ascii", " 1.0\nelement vertex ", n,
            "\nproperty float x\nproperty float y\nproperty float z\nend_header\n");
    for (int i = 0; i < n; ++i) {
      const float x = dropped(i) ? std::numeric_limits<float>::quiet_NaN() : float(i % 1000);
      const float y = float(i / 1000), z = float(i % 7);
      if (binary) {
        for (const float v : {x, y, z}) put_le(s, v);
      } else {
        s += cat(dropped(i) ? std::string("nan") : std::to_string(i % 1000), " ", i / 1000, " ",
                 i % 7, "\n");
      }
    }
    const std::string p = write(binary ? "drops.ply" : "drops_ascii.ply", s);
    const point_cloud want = read_points(p);
    ASSERT_EQ(want.size(), std::size_t(n - 30));  // 30 values ≡ 3 (mod 997) in [70000, 100000)
    const auto src = open_point_source(p);
    point_block b;
    for (std::uint64_t first = 0; first < src->size(); first += 7) {
      const auto count = static_cast<std::size_t>(std::min<std::uint64_t>(7, src->size() - first));
      src->read(first, count, b);
      expect_points(b, want, static_cast<std::size_t>(first), cat(p, " in order at ", first));
    }
    for (std::uint64_t first = src->size(); first >= 1000; first -= 1000) {
      src->read(first - 1000, 1000, b);
      expect_points(b, want, static_cast<std::size_t>(first - 1000), cat(p, " backwards"));
    }
    for (const std::uint64_t first : {65530ull, 65536ull, 131060ull, 131066ull, 65530ull}) {
      src->read(first, 12, b);
      expect_points(b, want, static_cast<std::size_t>(first), cat(p, " across runs ", first));
    }
    std::vector<std::string> failures(2);
    const auto work = [&](int t) {
      point_block tb;
      for (std::uint64_t first = std::uint64_t(t) * 3; first + 5 < src->size(); first += 5)
        if (src->read(first, 5, tb); !(same_bits(tb.positions[4], want.positions[first + 4]))) {
          failures[std::size_t(t)] = cat("thread ", t, " at ", first);
          return;
        }
    };
    std::thread t0(work, 0), t1(work, 1);
    t0.join();
    t1.join();
    EXPECT_EQ(failures[0], "") << p;
    EXPECT_EQ(failures[1], "") << p;
  }
}

// A cloud far from the world origin, written with its origin in a comment: the source honours
// it as read_points does, so positions come back as the floats that were written.
TEST_F(Source, PlyOriginComment) {
  point_cloud w = pbr_lod::make_wavy_surface(2000, 3);
  w.origin = vec3d(5e5, 4e6, 100);
  for (const bool binary : {true, false}) {
    const std::string p = path(binary ? "o.ply" : "o_ascii.ply");
    pbr_lod::write_ply(p, w, binary);
    const point_cloud c = check_file(p);
    EXPECT_EQ(open_point_source(p)->origin(), w.origin);
    EXPECT_EQ(c.origin, w.origin);
  }
}

// A fixed-size element before the vertices is skipped by arithmetic.
TEST_F(Source, BinaryPlyElementBeforeVertices) {
  std::string s =
      "ply\nformat binary_little_endian 1.0\nelement camera 2\nproperty float a\n"
      "property uchar b\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nend_header\n";
  for (int i = 0; i < 2; ++i) {
    put_le(s, 9.5f);
    s.push_back('\1');
  }
  for (int i = 0; i < 9; ++i) put_le(s, static_cast<float>(i));
  s += "xyz";  // trailing bytes: the same warning as read_points
  const point_cloud c = check_file(write("cam.ply", s));
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(c.world(2), vec3d(6, 7, 8));
}

// ASCII: the rows of an element before the vertices (one line each) are skipped, and the
// lines after the faces draw read_points' warning.
TEST_F(Source, AsciiPlyElementBeforeVertices) {
  const std::string s =
      "ply\nformat ascii 1.0\nelement camera 2\nproperty list uchar float k\n"
      "element vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "2 1 2\n\n0\n5 6 7\n8 9 10\n3 0 1 1\nextra\n";
  const point_cloud c = check_file(write("cam_ascii.ply", s));
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c.world(0), vec3d(5, 6, 7));
}

std::string pcd_header(const std::string& fields, const std::string& size, const std::string& type,
                       int points, const std::string& data,
                       const std::string& viewpoint = "0 0 0 1 0 0 0") {
  std::string count;
  for (std::size_t i = 0, n = std::count(fields.begin(), fields.end(), ' ') + 1; i < n; ++i)
    count += i ? " 1" : "1";
  return "# .PCD v0.7\nVERSION 0.7\nFIELDS " + fields + "\nSIZE " + size + "\nTYPE " + type +
         "\nCOUNT " + count + "\nWIDTH " + std::to_string(points) + "\nHEIGHT 1\nVIEWPOINT " +
         viewpoint + "\nPOINTS " + std::to_string(points) + "\nDATA " + data + "\n";
}

// ASCII PCD with a NaN ("no return") point, packed colours and normals, and a VIEWPOINT that
// read_points warns about; the sensor is the frame's origin in both.
TEST_F(Source, PcdAscii) {
  const std::string s =
      pcd_header("x y z normal_x normal_y normal_z rgb", "4 4 4 4 4 4 4", "F F F F F F U", 4,
                 "ascii", "1 2 3 1 0 0 0") +
      "1 2 3 0 0 1 16744512\nnan nan nan 0 0 1 0\n\n4 5 6 0 2 0 1056816\n7 8 9 0 0 1 0\n";
  const point_cloud c = check_file(write("a.pcd", s));
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(c.sensor, vec3d::Zero());
  EXPECT_EQ(c.colours[0], (pbr_lod::rgb8{255, 128, 64}));
}

TEST_F(Source, PcdBinary) {
  std::string s = pcd_header("x y z _ rgb", "4 4 4 2 4", "F F F U F", 3, "binary");
  for (int i = 0; i < 3; ++i) {
    for (int a = 0; a < 3; ++a) put_le(s, static_cast<float>(10 * i + a));
    put_le<std::uint16_t>(s, 0);
    put_le(s, std::bit_cast<float>(0x00102030u + static_cast<std::uint32_t>(i)));
  }
  const point_cloud c = check_file(write("b.pcd", s));
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(c.world(2), vec3d(20, 21, 22));
}

// binary_compressed is read whole, but through the same interface and with the same result.
TEST_F(Source, PcdBinaryCompressed) {
  std::string soa;
  for (int a = 0; a < 3; ++a)
    for (int i = 0; i < 5; ++i) put_le(soa, static_cast<float>(i * (a + 1)));
  const std::string lzf = pbr_lod::test::lzf_literals(soa);
  std::string s = pcd_header("x y z", "4 4 4", "F F F", 5, "binary_compressed");
  put_le(s, static_cast<std::uint32_t>(lzf.size()));
  put_le(s, static_cast<std::uint32_t>(soa.size()));
  s += lzf;
  const point_cloud c = check_file(write("c.pcd", s));
  ASSERT_EQ(c.size(), 5u);
  EXPECT_EQ(c.world(4), vec3d(4, 8, 12));
}

// LAS 1.2 format 2 with 16-bit colours (all shifted by 8 because one exceeds 255, which the
// source only knows after its pass over the file).
TEST_F(Source, Las12Format2) {
  pbr_lod::test::las_spec spec;
  spec.minor = 2;
  spec.format = 2;
  spec.record_length = 26;
  spec.rgb_offset = 20;
  spec.offset[0] = 500000;
  spec.offset[1] = 4100000;
  for (int i = 0; i < 1000; ++i) {
    spec.xyz.push_back({i * 7, i * 3, -i});
    spec.rgb.push_back({static_cast<std::uint16_t>(i), 200, static_cast<std::uint16_t>(999 - i)});
  }
  const point_cloud c = check_file(write("f2.las", pbr_lod::test::make_las(spec)));
  ASSERT_EQ(c.size(), 1000u);
  EXPECT_EQ(c.colours[999], (pbr_lod::rgb8{3, 0, 0}));
}

// LAS 1.4 format 6: 64-bit count, no colours, a stale header box (the same warning).
TEST_F(Source, Las14Format6) {
  pbr_lod::test::las_spec spec;
  spec.minor = 4;
  spec.format = 6;
  spec.record_length = 30;
  for (int i = 0; i < 300; ++i) spec.xyz.push_back({i, 2 * i, 3 * i});
  std::string bytes = pbr_lod::test::make_las(spec);
  pbr_lod::test::poke_le<double>(bytes, 179, 1.0);  // max x: most points lie outside
  read_report r;
  const auto src = open_point_source(write("f6.las", bytes), &r);
  EXPECT_FALSE(src->attrs().colour);
  ASSERT_FALSE(r.warnings.empty());
  EXPECT_NE(r.warnings[0].find("outside the bounding box"), std::string::npos);
  const point_cloud c = check_file(path("f6.las"));
  EXPECT_EQ(c.size(), 300u);
}

// --- broken files -----------------------------------------------------------------------------

TEST_F(Source, MalformedFilesThrowAtOpen) {
  const std::string ply_head =
      "ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n"
      "property float y\nproperty float z\nend_header\n";
  PBR_LOD_EXPECT_THROW_MSG(open_point_source(write("t.ply", ply_head + std::string(100, '\0'))),
                           FormatError, "truncated");
  PBR_LOD_EXPECT_THROW_MSG(open_point_source(write("h.ply", "ply\nformat ascii 1.0\nelement")),
                           FormatError, "end_header");
  PBR_LOD_EXPECT_THROW_MSG(
      open_point_source(write("a.ply",
                              "ply\nformat ascii 1.0\nelement vertex 3\nproperty float "
                              "x\nproperty float y\nproperty float z\nend_header\n"
                              "0 0 0\n1 1 1\n")),
      FormatError, "only 2");
  PBR_LOD_EXPECT_THROW_MSG(
      open_point_source(write("v.ply",
                              "ply\nformat ascii 1.0\nelement vertex 2\nproperty float "
                              "x\nproperty float y\nproperty float z\nend_header\n"
                              "0 0 0\n1 x 1\n")),
      FormatError, "vertex 1 (line 9)");
  pbr_lod::test::las_spec spec;
  spec.xyz = {{1, 2, 3}, {4, 5, 6}};
  spec.rgb = {{1, 2, 3}, {4, 5, 6}};
  std::string las = pbr_lod::test::make_las(spec);
  las.resize(las.size() - 1);
  PBR_LOD_EXPECT_THROW_MSG(open_point_source(write("t.las", las)), FormatError, "truncated");
  PBR_LOD_EXPECT_THROW_MSG(open_point_source(write("s.las", las.substr(0, 100))), FormatError,
                           "227");
  PBR_LOD_EXPECT_THROW_MSG(
      open_point_source(write(
          "t.pcd", pcd_header("x y z", "4 4 4", "F F F", 3, "binary") + std::string(30, '\0'))),
      FormatError, "truncated");
  PBR_LOD_EXPECT_THROW_MSG(
      open_point_source(
          write("ta.pcd", pcd_header("x y z", "4 4 4", "F F F", 3, "ascii") + "1 2 3\n4 5 6\n")),
      FormatError, "point 2");
  PBR_LOD_EXPECT_THROW_MSG(open_point_source(path("missing.ply")), IoError, "no such file");
  PBR_LOD_EXPECT_THROW_MSG(open_point_source(write("m.obj", "v 0 0 0\n")), FormatError, ".pcd");
  // .laz is LAS whose format byte says compressed: checked as LAS.
  PBR_LOD_EXPECT_THROW_MSG(open_point_source(write("m.laz", "LASF")), FormatError,
                           "a LAS header needs 227");
}

// Each malformed file fails the same way read_points fails on it.
TEST_F(Source, SameErrorsAsReadPoints) {
  const std::vector<std::pair<std::string, std::string>> files = {
      {"x.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n"},
      {"y.ply",
       "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
       "property float y\nproperty float z\nproperty list uchar int l\nend_header\n"},
      {"z.pcd", pcd_header("x y z", "4 4 4", "F F F", 1, "ascii") + "1 2\n"},
      {"w.pcd", "VERSION 0.7\nFIELDS x y z\nDATA ascii\n"},
  };
  for (const auto& [name, bytes] : files) {
    const std::string p = write(name, bytes);
    std::string want;
    try {
      (void)read_points(p);
    } catch (const FormatError& e) {
      want = e.what();
    }
    ASSERT_FALSE(want.empty()) << name;
    PBR_LOD_EXPECT_THROW_MSG(open_point_source(p), FormatError, want);
  }
}

TEST_F(Source, ReadBeyondSizeThrows) {
  const auto src = open_point_source(
      write("r.pcd", pcd_header("x y z", "4 4 4", "F F F", 2, "ascii") + "1 2 3\n4 5 6\n"));
  point_block b;
  ASSERT_EQ(src->size(), 2u);
  EXPECT_THROW(src->read(1, 2, b), InvalidArgument);
  EXPECT_THROW(src->read(3, 0, b), InvalidArgument);
  EXPECT_THROW(src->read(std::numeric_limits<std::uint64_t>::max(), 1, b), InvalidArgument);
  EXPECT_NO_THROW(src->read(2, 0, b));
}

// A file cut short after it was opened: the read fails, it does not return garbage.
TEST_F(Source, FileCutShortAfterOpen) {
  const point_cloud w = pbr_lod::make_wavy_surface(5000, 2);
  for (const bool binary : {true, false}) {
    const std::string p = path(binary ? "cut.ply" : "cut_ascii.ply");
    pbr_lod::write_ply(p, w, binary);
    const auto src = open_point_source(p);
    std::filesystem::resize_file(p, std::filesystem::file_size(p) / 2);
    point_block b;
    if (binary) {
      EXPECT_THROW(src->read(4000, 1000, b), IoError) << p;
    } else {  // ASCII: the cut may fall inside a line, which then has too few values
      EXPECT_THROW(src->read(4000, 1000, b), pbr_lod::Error) << p;
    }
  }
}

// --- concurrency and size -----------------------------------------------------------------------

// Two threads reading interleaved random ranges get what one thread reading them in turn gets.
TEST_F(Source, ConcurrentReads) {
  const point_cloud w = pbr_lod::make_wavy_surface(200000, 4);
  for (const bool binary : {true, false}) {
    const std::string p = path(binary ? "mt.ply" : "mt_ascii.ply");
    pbr_lod::write_ply(p, w, binary);
    const point_cloud want = read_points(p);
    const auto src = open_point_source(p);
    std::vector<std::string> failures(2);
    const auto work = [&](int t) {
      std::mt19937_64 rng(100 + t);  // any ranges will do: each must come back right
      point_block b;
      for (int k = 0; k < 40; ++k) {
        const std::size_t count = 1 + rng() % 70000;
        const std::uint64_t first = rng() % (src->size() - count + 1);
        src->read(first, count, b);
        for (std::size_t i = 0; i < count; ++i)
          if (!same_bits(b.positions[i], want.positions[first + i]) ||
              b.colours[i] != want.colours[first + i]) {
            failures[static_cast<std::size_t>(t)] =
                "thread " + std::to_string(t) + " point " + std::to_string(first + i);
            return;
          }
      }
    };
    std::thread a(work, 0), b(work, 1);
    a.join();
    b.join();
    EXPECT_EQ(failures[0], "") << p;
    EXPECT_EQ(failures[1], "") << p;
  }
}

// A file many blocks long (3 M points, ~117 MB): the count, and sample ranges across it,
// including the last ones, equal read_points.
TEST_F(Source, FileLargerThanTheBlockSize) {
  pbr_lod::generated_point_source gen(3'000'000, 5, true, true);
  point_cloud w = read_all(gen);
  w.origin = vec3d(1000, -2000, 30);
  const std::string p = path("big.ply");
  pbr_lod::write_ply(p, w, true);
  w = point_cloud{};
  const point_cloud want = read_points(p);
  const auto src = open_point_source(p);
  ASSERT_EQ(src->size(), 3'000'000u);
  EXPECT_EQ(src->origin(), want.origin);
  point_block b;
  for (const std::uint64_t first : {0ull, 65535ull, 1'000'003ull, 2'999'000ull}) {
    src->read(first, 1000, b);
    expect_points(b, want, static_cast<std::size_t>(first), "big " + std::to_string(first));
  }
  src->read(1'500'000, 1'500'000, b);  // more than one 4 MiB block in one read
  expect_points(b, want, 1'500'000, "big second half");
  expect_blocks(*src, want, 11);
}

}  // namespace
