// Every real file in shared/data loads with the counts PROVENANCE.md states (those were
// computed by parsing every element of the files independently of this code).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <thread>

#include "io_test_util.hpp"
#include "pbr_lod/io/read.hpp"
#include "support/data.hpp"

namespace {

using pbr_lod::read_mesh;
using pbr_lod::read_points;
using pbr_lod::read_report;
using pbr_lod::test::data_file;

/// Vertices referenced by at least one face.
std::size_t referenced(const pbr_lod::triangle_mesh& m) {
  std::vector<char> used(m.num_vertices(), 0);
  for (const auto& f : m.faces)
    for (auto i : f) used[i] = 1;
  return static_cast<std::size_t>(std::count(used.begin(), used.end(), 1));
}

/// Faces that repeat an earlier face's vertex set.
std::size_t duplicate_faces(const pbr_lod::triangle_mesh& m) {
  std::set<std::array<std::uint32_t, 3>> seen;
  std::size_t dup = 0;
  for (auto f : m.faces) {
    std::sort(f.begin(), f.end());
    dup += !seen.insert(f).second;
  }
  return dup;
}

void expect_bounds(const pbr_lod::point_cloud& c, const pbr_lod::vec3d& lo,
                   const pbr_lod::vec3d& hi, double tol) {
  pbr_lod::vec3d mn = pbr_lod::vec3d::Constant(1e300), mx = pbr_lod::vec3d::Constant(-1e300);
  for (std::size_t i = 0; i < c.size(); ++i) {
    mn = mn.cwiseMin(c.world(i));
    mx = mx.cwiseMax(c.world(i));
  }
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(mn[a], lo[a], tol) << "axis " << a;
    EXPECT_NEAR(mx[a], hi[a], tol) << "axis " << a;
  }
}

// The bunny: 35,947 vertices and 69,451 triangles; 1,113 vertices no face uses — a reader that
// compacted or duplicated vertices would change one of these numbers.
TEST(RealData, BunnyFullResolution) {
  read_report r;
  const auto m = read_mesh(data_file("bun_zipper.ply"), &r);
  EXPECT_EQ(m.num_vertices(), 35947u);
  EXPECT_EQ(m.num_faces(), 69451u);
  EXPECT_EQ(referenced(m), 35947u - 1113u);
  EXPECT_EQ(r.points_read, 35947u);
  EXPECT_EQ(r.dropped_non_finite, 0u);
  EXPECT_EQ(r.faces_dropped, 0u);
  EXPECT_TRUE(r.warnings.empty());
  // x y z confidence intensity: no normals, no colours, no texture.
  EXPECT_TRUE(m.vertices.normals.empty());
  EXPECT_TRUE(m.vertices.colours.empty());
  EXPECT_TRUE(m.face_texcoords.empty());
  EXPECT_NO_THROW(m.validate());
  // The origin is the centre of the bounds PROVENANCE lists (6 significant digits there).
  const pbr_lod::vec3d lo(-0.0946899, 0.0329874, -0.0618736), hi(0.0610091, 0.187321, 0.0587997);
  EXPECT_TRUE(m.vertices.origin.isApprox(0.5 * (lo + hi), 1e-6));
  expect_bounds(m.vertices, lo, hi, 1e-7);
}

// The decimated bunnies: counts from PROVENANCE; their duplicate faces are kept (a reader
// returns the file; cleaning is a builder's choice).
TEST(RealData, BunnyDecimatedLevels) {
  struct level {
    const char* file;
    std::size_t v, f, dup;
  };
  for (const level& l :
       {level{"bun_zipper_res2.ply", 8171, 16301, 87}, level{"bun_zipper_res3.ply", 1889, 3851, 83},
        level{"bun_zipper_res4.ply", 453, 948, 40}}) {
    const auto m = read_mesh(data_file(l.file));
    EXPECT_EQ(m.num_vertices(), l.v) << l.file;
    EXPECT_EQ(m.num_faces(), l.f) << l.file;
    EXPECT_EQ(duplicate_faces(m), l.dup) << l.file;
  }
}

// Happy Buddha res3: 32,328 vertices and all 67,240 faces, including its 1,650 duplicate faces
// and 2,816 non-manifold edges. (OpenMesh's TriMesh would report 45,168 vertices here: it splits
// off copies of the vertices of every face it cannot add to a manifold half-edge structure.)
TEST(RealData, HappyBuddhaKeepsNonManifoldFaces) {
  read_report r;
  const auto m = read_mesh(data_file("happy_vrip_res3.ply"), &r);
  EXPECT_EQ(m.num_vertices(), 32328u);
  EXPECT_EQ(m.num_faces(), 67240u);
  EXPECT_EQ(duplicate_faces(m), 1650u);
  EXPECT_EQ(referenced(m), 32328u - 12u);
  EXPECT_EQ(r.faces_dropped, 0u);
  expect_bounds(m.vertices, {-0.0460971, 0.0498485, -0.0473756}, {0.0351966, 0.247673, 0.0339706},
                1e-7);
}

// The cow: 2,930 v / 5,856 triangles, "f v/vt" faces → a texture coordinate per corner, and the
// map_Kd of cow.mtl, which lives next to the OBJ.
TEST(RealData, CowObjWithTexture) {
  read_report r;
  const auto m = read_mesh(data_file("cow.obj"), &r);
  EXPECT_EQ(m.num_vertices(), 2930u);
  EXPECT_EQ(m.num_faces(), 5856u);
  ASSERT_EQ(m.face_texcoords.size(), 5856u);
  // Every corner lies in the range of the file's vt lines (u -0.0522421..0.989055,
  // v 0.111175..1.00065, computed with awk): no uninitialised or misindexed corner.
  for (const auto& t : m.face_texcoords)
    for (const auto& uv : t) {
      EXPECT_GE(uv.x(), -0.0522421f);
      EXPECT_LE(uv.x(), 0.989055f);
      EXPECT_GE(uv.y(), 0.111175f);
      EXPECT_LE(uv.y(), 1.00065f);
    }
  EXPECT_EQ(std::filesystem::path(m.texture_path).filename(), "cow_texture.png");
  EXPECT_TRUE(std::filesystem::exists(m.texture_path)) << m.texture_path;
  ASSERT_NE(m.texture, nullptr);  // loaded with the mesh: 1024 × 1024 RGB (`file` says so)
  EXPECT_EQ(m.texture->width, 1024);
  EXPECT_EQ(m.texture->height, 1024);
  EXPECT_EQ(m.texture->texels.size(), 1024u * 1024u);
  EXPECT_TRUE(m.texture->alpha.empty());
  EXPECT_TRUE(r.warnings.empty()) << r.warnings.front();
  EXPECT_NO_THROW(m.validate());
  expect_bounds(m.vertices, {-0.471552, -0.736784, -0.668909}, {0.471552, 0.953646, 1.049}, 1e-6);
}

// The first face is "f 739/1 735/2 736/3": corner k gets vt k+1 (1-based), vt 1 = line 1 of
// the vt block. Checks that corners are not rotated or taken from the wrong face.
TEST(RealData, CowFirstFaceCorners) {
  const auto m = read_mesh(data_file("cow.obj"));
  std::ifstream in(data_file("cow.obj"));
  std::vector<pbr_lod::vec2f> vt;
  for (std::string line; std::getline(in, line);)
    if (line.rfind("vt ", 0) == 0) {
      float u = 0, v = 0;
      std::sscanf(line.c_str(), "vt %f %f", &u, &v);
      vt.emplace_back(u, v);
    }
  ASSERT_EQ(vt.size(), 3225u);
  EXPECT_EQ(m.faces[0], (std::array<std::uint32_t, 3>{738, 734, 735}));
  for (int k = 0; k < 3; ++k) EXPECT_EQ(m.face_texcoords[0][k], vt[k]) << "corner " << k;
}

// The Kinect scan: 640×480 = 307,200 points, 65,793 of them NaN ("no return"), so 241,407
// finite ones with colours; binary_compressed, so this exercises the LZF path.
TEST(RealData, MilkCartonPcd) {
  read_report r;
  const auto c = read_points(data_file("milk_cartoon_all_small_clorox.pcd"), &r);
  EXPECT_EQ(c.size(), 241407u);
  EXPECT_EQ(c.colours.size(), 241407u);
  EXPECT_TRUE(c.normals.empty());
  EXPECT_EQ(r.points_read, 307200u);
  EXPECT_EQ(r.dropped_non_finite, 65793u);
  ASSERT_FALSE(r.warnings.empty());
  EXPECT_NE(r.warnings.front().find("milk_cartoon_all_small_clorox.pcd: dropped 65793 "
                                    "non-finite points"),
            std::string::npos)
      << r.warnings.front();
  expect_bounds(c, {-1.0608, -0.219669, -2.063}, {1.15249, 0.869233, -0.501}, 1e-5);
  // PROVENANCE counts 90,348 distinct colours among the finite points.
  std::set<std::uint32_t> distinct;
  for (const auto& col : c.colours)
    distinct.insert((std::uint32_t{col.r} << 16) | (std::uint32_t{col.g} << 8) | col.b);
  EXPECT_EQ(distinct.size(), 90348u);
  // The points are in the Kinect's frame: the scanner at the origin, every point in front of it
  // (z < 0, looking down −z), which is what orienting normals towards it relies on.
  ASSERT_TRUE(c.sensor.has_value());
  EXPECT_EQ(*c.sensor, pbr_lod::vec3d::Zero());
  EXPECT_FALSE(read_points(data_file("1.2-with-color.las")).sensor.has_value());
}

// The LiDAR sample: 1,065 points with colours; world coordinates (origin + positions) must
// reach the bounds the LAS header states, to within one quantum (scale 0.01).
TEST(RealData, LasWithColour) {
  const std::string file = data_file("1.2-with-color.las");
  read_report r;
  const auto c = read_points(file, &r);
  EXPECT_EQ(c.size(), 1065u);
  EXPECT_EQ(c.colours.size(), 1065u);
  EXPECT_TRUE(r.warnings.empty());
  const std::string h = pbr_lod::test::slurp(file);
  double hi[3], lo[3];
  for (int a = 0; a < 3; ++a) {
    std::memcpy(&hi[a], h.data() + 179 + 16 * a, 8);
    std::memcpy(&lo[a], h.data() + 187 + 16 * a, 8);
  }
  expect_bounds(c, {lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}, 0.01);
  // Float positions relative to a local origin keep centimetres at 6·10⁵ from the world origin.
  EXPECT_LT(c.positions[0].cwiseAbs().maxCoeff(), 3000.0f);
  // Colours are stored 0..255 in the 16-bit fields: kept as they are, not shifted to zero.
  const auto brightest = std::max_element(c.colours.begin(), c.colours.end(), [](auto a, auto b) {
    return a.r + a.g + a.b < b.r + b.g + b.b;
  });
  EXPECT_GT(brightest->r + brightest->g + brightest->b, 100);
  // Every point's colour against the file's own bytes, parsed here from the header fields
  // (offset to point data at 96, format at 104, record length at 105; RGB at byte 20 of a
  // format 2 record, 28 of a format 3 one), in file order: the reader keeps the order and drops
  // nothing here.
  std::uint32_t data_at = 0;
  std::uint16_t record = 0;
  std::memcpy(&data_at, h.data() + 96, 4);
  std::memcpy(&record, h.data() + 105, 2);
  const int format = static_cast<unsigned char>(h[104]);
  ASSERT_TRUE(format == 2 || format == 3) << format;
  const std::size_t rgb_at = format == 2 ? 20 : 28;
  ASSERT_EQ(h.size(), data_at + std::size_t{1065} * record);
  for (std::size_t i = 0; i < c.size(); ++i) {
    std::uint16_t rgb[3];
    std::memcpy(rgb, h.data() + data_at + i * record + rgb_at, 6);
    ASSERT_LE(std::max({rgb[0], rgb[1], rgb[2]}), 255) << "the sample stores 8-bit values";
    ASSERT_EQ(c.colours[i],
              (pbr_lod::rgb8{static_cast<std::uint8_t>(rgb[0]), static_cast<std::uint8_t>(rgb[1]),
                             static_cast<std::uint8_t>(rgb[2])}))
        << "point " << i;
  }
}

// read_points on a mesh file gives its vertices (unreferenced ones included).
TEST(RealData, PointsFromMeshFile) {
  const auto c = read_points(data_file("bun_zipper.ply"));
  EXPECT_EQ(c.size(), 35947u);
}

// read.hpp promises concurrent reads are safe: OBJ goes through OpenMesh's global reader
// objects (serialised by our mutex), PLY through our own parser. Four threads mixing both must
// all get the exact counts.
TEST(RealData, ConcurrentReads) {
  const std::string obj = data_file("cow.obj"), ply = data_file("bun_zipper_res4.ply");
  std::vector<int> ok(4, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (int k = 0; k < 5; ++k) {
        const auto a = read_mesh(obj);
        const auto b = read_mesh(ply);
        ok[static_cast<std::size_t>(t)] +=
            a.num_faces() == 5856 && a.face_texcoords.size() == 5856 && b.num_faces() == 948;
      }
    });
  for (auto& th : threads) th.join();
  EXPECT_EQ(ok, std::vector<int>(4, 5));
}

}  // namespace
