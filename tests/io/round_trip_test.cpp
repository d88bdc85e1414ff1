// write_ply then read gives back the same data: bit-identical positions (float, relative to the
// same double origin), normals, colours, faces and texture coordinates, in binary and ASCII.
#include <gtest/gtest.h>

#include <random>

#include "io_test_util.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/io/write.hpp"
#include "support/data.hpp"

namespace {

using pbr_lod::point_cloud;
using pbr_lod::read_mesh;
using pbr_lod::read_points;
using pbr_lod::triangle_mesh;
using pbr_lod::vec3d;
using pbr_lod::vec3f;
using pbr_lod::write_ply;

using RoundTrip = pbr_lod::test::scratch_dir;

void expect_identical(const point_cloud& a, const point_cloud& b) {
  EXPECT_EQ(a.origin, b.origin);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.normals, b.normals);
  EXPECT_EQ(a.colours, b.colours);
}

void expect_identical(const triangle_mesh& a, const triangle_mesh& b) {
  expect_identical(a.vertices, b.vertices);
  EXPECT_EQ(a.faces, b.faces);
  EXPECT_EQ(a.face_texcoords, b.face_texcoords);
}

// Random points with normals and colours. Random data is fine: the claim is exactness for any
// float positions, and a fixed seed keeps failures reproducible.
point_cloud random_cloud(std::size_t n, const vec3d& origin, float extent) {
  std::mt19937 rng(42);
  std::uniform_real_distribution<float> u(-extent, extent);
  std::uniform_int_distribution<int> byte(0, 255);
  point_cloud c;
  c.origin = origin;
  for (std::size_t i = 0; i < n; ++i) {
    c.positions.emplace_back(u(rng), u(rng), u(rng));
    c.normals.push_back(vec3f(u(rng), u(rng), u(rng)).normalized());
    c.colours.push_back({static_cast<std::uint8_t>(byte(rng)), static_cast<std::uint8_t>(byte(rng)),
                         static_cast<std::uint8_t>(byte(rng))});
  }
  return c;
}

// A cloud read from a file (origin = box centre) survives write → read exactly, both encodings.
TEST_F(RoundTrip, PointCloudWithNormalsAndColours) {
  point_cloud c0 = random_cloud(1000, vec3d::Zero(), 1.0f);
  write_ply(path("seed.ply"), c0);
  const point_cloud c1 = read_points(path("seed.ply"));  // origin is now the box centre
  // The first pass against the data written, not only against itself: c1 == c2 below also holds
  // for a writer that drops normals or colours, or a writer and reader that swap two channels
  // alike. Normals and colours exactly; positions as world coordinates (the origin moved, so the
  // relative floats were rounded once: |p| ≤ 2 here, float ulp 2.4e-7).
  ASSERT_EQ(c1.size(), c0.size());
  EXPECT_EQ(c1.normals, c0.normals);
  EXPECT_EQ(c1.colours, c0.colours);
  for (std::size_t i = 0; i < c0.size(); ++i)
    ASSERT_LT((c1.world(i) - c0.world(i)).cwiseAbs().maxCoeff(), 3e-7) << "point " << i;
  for (const bool binary : {true, false}) {
    const std::string p = path(binary ? "b.ply" : "a.ply");
    write_ply(p, c1, binary);
    pbr_lod::read_report r;
    const point_cloud c2 = read_points(p, &r);
    SCOPED_TRACE(binary ? "binary" : "ascii");
    expect_identical(c1, c2);
    EXPECT_TRUE(r.warnings.empty());
  }
}

// The real bunny: read → write → read identical (positions, faces), binary and ASCII.
TEST_F(RoundTrip, BunnyMesh) {
  const triangle_mesh m1 = read_mesh(pbr_lod::test::data_file("bun_zipper.ply"));
  for (const bool binary : {true, false}) {
    const std::string p = path(binary ? "bunny_b.ply" : "bunny_a.ply");
    write_ply(p, m1, binary);
    SCOPED_TRACE(binary ? "binary" : "ascii");
    expect_identical(m1, read_mesh(p));
  }
}

// The textured cow through PLY: MeshLab's per-corner texcoord list and TextureFile comment carry
// the texture; the path is stored relative to the PLY, so it names the same file afterwards.
TEST_F(RoundTrip, TexturedCow) {
  const triangle_mesh m1 = read_mesh(pbr_lod::test::data_file("cow.obj"));
  write_ply(path("cow.ply"), m1);
  const triangle_mesh m2 = read_mesh(path("cow.ply"));
  expect_identical(m1, m2);
  EXPECT_TRUE(std::filesystem::equivalent(m1.texture_path, m2.texture_path))
      << m1.texture_path << " vs " << m2.texture_path;
}

// Georeferenced data: origin 10⁷ units out, points within ±50 of it. Written as doubles, read
// back with the stored origin: the relative float coordinates come back to within float
// precision of the originals (in practice exactly). A float file would be off by up to 0.5.
TEST_F(RoundTrip, FarFromTheOrigin) {
  const vec3d origin(1.0e7, -2.0e7, 3.0e6);
  const point_cloud c0 = random_cloud(2000, origin, 50.0f);
  write_ply(path("geo.ply"), c0);
  const point_cloud c1 = read_points(path("geo.ply"));
  ASSERT_EQ(c1.size(), c0.size());
  for (std::size_t i = 0; i < c0.size(); ++i) {
    const vec3d d = c1.world(i) - c0.world(i);
    // One float ulp at 50 is 3.8e-6.
    EXPECT_LT(d.cwiseAbs().maxCoeff(), 4e-6) << "point " << i;
  }
  EXPECT_EQ(c1.normals, c0.normals);
  EXPECT_EQ(c1.colours, c0.colours);
}

// Without the stored origin (another tool rewrote the header) the reader falls back to the box
// centre; world coordinates still agree to float precision of the relative coordinates.
TEST_F(RoundTrip, FarFromTheOriginWithoutStoredOrigin) {
  const point_cloud c0 = random_cloud(500, vec3d(1.0e7, 1.0e7, 1.0e7), 50.0f);
  write_ply(path("geo.ply"), c0, false);
  std::string text = pbr_lod::test::slurp(path("geo.ply"));
  const auto at = text.find("comment pbr_lod_origin");
  text.erase(at, text.find('\n', at) + 1 - at);
  const point_cloud c1 = read_points(write("stripped.ply", text));
  ASSERT_EQ(c1.size(), c0.size());
  for (std::size_t i = 0; i < c0.size(); ++i)
    EXPECT_LT((c1.world(i) - c0.world(i)).cwiseAbs().maxCoeff(), 8e-6) << "point " << i;
}

// An empty cloud and a single point are valid files too.
TEST_F(RoundTrip, EmptyAndSinglePoint) {
  write_ply(path("empty.ply"), point_cloud{});
  EXPECT_TRUE(read_points(path("empty.ply")).empty());
  point_cloud one;
  one.origin = vec3d(5, 6, 7);
  one.positions = {vec3f::Zero()};
  write_ply(path("one.ply"), one);
  const point_cloud back = read_points(path("one.ply"));
  ASSERT_EQ(back.size(), 1u);
  EXPECT_EQ(back.world(0), vec3d(5, 6, 7));
}

// Writers validate: a NaN position is the caller's bug, reported as InvalidArgument.
TEST_F(RoundTrip, WriterRejectsInvalidInput) {
  point_cloud c;
  c.positions = {vec3f(0, std::numeric_limits<float>::quiet_NaN(), 0)};
  EXPECT_THROW(write_ply(path("nan.ply"), c), pbr_lod::InvalidArgument);
  triangle_mesh m;
  m.vertices.positions = {vec3f::Zero()};
  m.faces = {{0, 0, 1}};
  EXPECT_THROW(write_ply(path("bad.ply"), m), pbr_lod::InvalidArgument);
}

TEST_F(RoundTrip, WriterReportsUnwritablePath) {
  EXPECT_THROW(write_ply(path("no/such/dir/x.ply"), point_cloud{}), pbr_lod::IoError);
}

}  // namespace
