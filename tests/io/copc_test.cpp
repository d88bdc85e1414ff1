// COPC out (include/pbr_lod/io/copc.hpp): the file is read back through the parts of the format
// a COPC reader uses — the header, the info VLR at offset 375, the hierarchy EVLR's entries, the
// LAZ chunk each entry points at — and every point is checked against its input: position within
// half a quantum, colour, normal bit for bit, its level in the user data byte, its voxel holding
// it at COPC level max(0, level − shift). The shift rule, determinism, the spatial reference
// and the hard cases (no points, one point, every point the same, 10^7 from the origin).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <map>
#include <random>
#include <set>

#include "io/io_internal.hpp"
#include "io_test_util.hpp"
#include "laz_test_util.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/copc.hpp"
#include "pbr_lod/io/read.hpp"
#include "support/data.hpp"

namespace {

namespace detail = pbr_lod::detail;
using pbr_lod::copc_options;
using pbr_lod::copc_summary;
using pbr_lod::point_cloud;
using pbr_lod::vec3d;
using pbr_lod::vec3f;
using pbr_lod::write_copc;
using pbr_lod::detail::cat;
using pbr_lod::test::header_of;
using pbr_lod::test::layout_of;
using pbr_lod::test::slurp;

using Copc = pbr_lod::test::scratch_dir;

template <class T>
T at_le(const std::string& b, std::uint64_t at) {
  T v;
  std::memcpy(&v, b.data() + at, sizeof(T));
  return v;
}

struct entry {
  std::int32_t level, x, y, z;
  std::uint64_t offset;
  std::int32_t bytes, count;
};

/// What a COPC reader sees: the info VLR's fields and the root page's entries (one page).
struct copc_file {
  std::string bytes;
  vec3d centre;
  double halfsize = 0, spacing = 0;
  std::vector<entry> entries;
};

copc_file open_copc(const std::string& path) {
  copc_file f;
  f.bytes = slurp(path);
  const std::string& b = f.bytes;
  EXPECT_EQ(b.compare(0, 4, "LASF"), 0);
  EXPECT_EQ(b[24], 1);
  EXPECT_EQ(b[25], 4);
  EXPECT_EQ(b.compare(377, 4, "copc"), 0);  // the checks COPC's reader notes ask for
  EXPECT_EQ(static_cast<unsigned char>(b[393]), 1u);
  EXPECT_EQ(static_cast<unsigned char>(b[394]), 0u);
  EXPECT_EQ(at_le<std::uint16_t>(b, 395), 160u);  // the info VLR's length
  const std::uint64_t info = 375 + 54;
  f.centre = {at_le<double>(b, info), at_le<double>(b, info + 8), at_le<double>(b, info + 16)};
  f.halfsize = at_le<double>(b, info + 24);
  f.spacing = at_le<double>(b, info + 32);
  const auto page_at = at_le<std::uint64_t>(b, info + 40);
  const auto page_size = at_le<std::uint64_t>(b, info + 48);
  for (std::uint64_t k = 0; k < 11; ++k) EXPECT_EQ(at_le<std::uint64_t>(b, info + 72 + 8 * k), 0u);
  // The hierarchy EVLR, found from the header as a LAS 1.4 reader finds it.
  const auto evlr = at_le<std::uint64_t>(b, 235);
  EXPECT_EQ(at_le<std::uint32_t>(b, 243), 1u);
  EXPECT_EQ(b.compare(evlr + 2, 4, "copc"), 0);
  EXPECT_EQ(at_le<std::uint16_t>(b, evlr + 18), 1000u);
  EXPECT_EQ(at_le<std::uint64_t>(b, evlr + 20), page_size);
  EXPECT_EQ(page_at, evlr + 60);
  EXPECT_EQ(page_size % 32, 0u);
  EXPECT_EQ(page_at + page_size, b.size());
  for (std::uint64_t e = page_at; e + 32 <= page_at + page_size; e += 32)
    f.entries.push_back({at_le<std::int32_t>(b, e), at_le<std::int32_t>(b, e + 4),
                         at_le<std::int32_t>(b, e + 8), at_le<std::int32_t>(b, e + 12),
                         at_le<std::uint64_t>(b, e + 16), at_le<std::int32_t>(b, e + 24),
                         at_le<std::int32_t>(b, e + 28)});
  return f;
}

/// A cloud of n points with normals and colours, and a level for each: levels grow with the
/// point index as a hierarchy's do (few coarse, many fine).
std::pair<point_cloud, std::vector<std::uint8_t>> levelled_cloud(std::size_t n, vec3d origin) {
  point_cloud c = pbr_lod::make_wavy_surface(n, 3);
  c.origin = origin;
  std::vector<std::uint8_t> levels(n);
  for (std::size_t i = 0; i < n; ++i)
    levels[i] = static_cast<std::uint8_t>(std::floor(std::log2(double(i + 1)) / 1.5));
  return {c, levels};
}

/// Every check of the file against its input; returns the summary's shift as read back.
void check_copc(const std::string& path, const point_cloud& c,
                const std::vector<std::uint8_t>& levels, const copc_summary& s) {
  const copc_file f = open_copc(path);
  const detail::las_header h = header_of(path, f.bytes);
  ASSERT_EQ(h.count, c.size());
  EXPECT_EQ(h.format, c.colours.empty() ? 6u : 7u);
  const std::size_t at_normal = c.colours.empty() ? 30 : 36;
  EXPECT_EQ(h.record_length, at_normal + (c.normals.empty() ? 0 : 12));
  EXPECT_EQ(f.centre, s.centre);
  EXPECT_EQ(f.halfsize, s.halfsize);

  // Entries: unique keys, every parent listed, the data entries exactly the LAZ chunks in order.
  std::set<std::array<std::int32_t, 4>> keys;
  for (const entry& e : f.entries) EXPECT_TRUE(keys.insert({e.level, e.x, e.y, e.z}).second);
  const detail::laz_layout L = layout_of(path, f.bytes);
  std::size_t chunk = 0, data = 0, empty = 0;
  std::vector<int> seen(c.size(), 0);
  for (const entry& e : f.entries) {
    if (e.level > 0) {
      EXPECT_TRUE(keys.count({e.level - 1, e.x >> 1, e.y >> 1, e.z >> 1}));
    }
    if (e.count == 0) {
      EXPECT_EQ(e.offset, 0u);
      EXPECT_EQ(e.bytes, 0);
      ++empty;
      continue;
    }
    ASSERT_GT(e.count, 0);
    ASSERT_LT(chunk, L.chunks.size());
    const detail::laz_chunk& ch = L.chunks[chunk];
    EXPECT_EQ(e.offset, ch.offset);
    EXPECT_EQ(std::uint64_t(e.bytes), ch.bytes);
    EXPECT_EQ(std::uint64_t(e.count), ch.count);
    // The node's records: in its voxel, at its level, equal to an input point.
    std::vector<unsigned char> rec(static_cast<std::size_t>(ch.count * h.record_length));
    detail::decode_laz_chunks(path, L, chunk, chunk + 1, pbr_lod::test::fetch_from(f.bytes),
                              rec.data(), 1);
    const double cell = 2 * f.halfsize / std::ldexp(1.0, e.level);
    const vec3d lo = f.centre - vec3d::Constant(f.halfsize);
    for (std::uint64_t j = 0; j < ch.count; ++j) {
      const unsigned char* r = rec.data() + j * h.record_length;
      const vec3d p = h.position(r);
      const std::int32_t v[3] = {e.x, e.y, e.z};
      for (int a = 0; a < 3; ++a) {
        EXPECT_GE(p[a], lo[a] + v[a] * cell - 1e-9 * cell) << "entry level " << e.level;
        EXPECT_LE(p[a], lo[a] + (v[a] + 1) * cell + 1e-9 * cell) << "entry level " << e.level;
      }
      const std::uint8_t level = r[17];
      EXPECT_EQ(e.level, std::max(0, int(level) - s.shift));
      EXPECT_EQ(r[14], 0x11);
      // Which input point: the nearest of that level (positions are distinct in these clouds).
      std::size_t best = c.size();
      double best_d = 1e300;
      for (std::size_t i = 0; i < c.size(); ++i)
        if (levels[i] == level && (c.world(i) - p).norm() < best_d) {
          best_d = (c.world(i) - p).norm();
          best = i;
        }
      ASSERT_LT(best, c.size());
      ++seen[best];
      // Half a quantum per axis, and the rounding of X·scale + offset in double.
      EXPECT_LE(best_d, std::sqrt(3.0) * 0.5 * h.scale[0] + 1e-15 * p.norm());
      if (!c.normals.empty()) {  // "no normal" (zero or not finite) is written as zero
        float nx, ny, nz;
        std::memcpy(&nx, r + at_normal, 4);
        std::memcpy(&ny, r + at_normal + 4, 4);
        std::memcpy(&nz, r + at_normal + 8, 4);
        const vec3f n = c.normals[best];
        EXPECT_EQ(vec3f(nx, ny, nz), pbr_lod::all_finite(n) ? n : vec3f::Zero());
      }
      if (!c.colours.empty()) {
        const auto k = h.rgb16(r);
        EXPECT_EQ(k[0], c.colours[best].r * 257);
        EXPECT_EQ(k[1], c.colours[best].g * 257);
        EXPECT_EQ(k[2], c.colours[best].b * 257);
      }
    }
    ++chunk;
    ++data;
  }
  EXPECT_EQ(chunk, L.chunks.size());
  EXPECT_EQ(data, s.nodes);
  EXPECT_EQ(empty, s.empty_nodes);
  for (std::size_t i = 0; i < c.size(); ++i) ASSERT_EQ(seen[i], 1) << "input point " << i;
}

TEST_F(Copc, EveryPointInItsVoxelAndLevelWithItsAttributes) {
  auto [c, levels] = levelled_cloud(3000, vec3d(10, -20, 5));
  const std::string p = path("a.copc.laz");
  const copc_summary s = write_copc(p, c, levels, {.node_points = 64});
  EXPECT_GT(s.nodes, 10u);  // the test must exercise a real octree, not one chunk
  check_copc(p, c, levels, s);
  // Our own reader reads it as the LAZ 1.4 file it is.
  const point_cloud back = pbr_lod::read_points(p);
  ASSERT_EQ(back.size(), c.size());
}

TEST_F(Copc, WithoutColoursOrNormals) {
  auto [c, levels] = levelled_cloud(1000, vec3d::Zero());
  c.normals[5] = vec3f(NAN, 0, 1);  // no normal: written as zero
  c.normals[6] = vec3f::Zero();
  c.colours.clear();
  std::string p = path("plain.copc.laz");
  check_copc(p, c, levels, write_copc(p, c, levels, {.node_points = 32}));
  c.normals.clear();
  p = path("bare.copc.laz");
  check_copc(p, c, levels, write_copc(p, c, levels, {.node_points = 32}));
}

// The shift is the smallest that gives the mean node `node_points` points: checked against a
// brute-force count of the nodes each shift would make.
TEST_F(Copc, ShiftIsTheSmallestThatFillsTheNodes) {
  auto [c, levels] = levelled_cloud(5000, vec3d::Zero());
  for (const std::uint32_t target : {1u, 50u, 200u, 1000u, 100000u}) {
    const copc_summary s = write_copc(path("s.copc.laz"), c, levels, {.node_points = target});
    const auto nodes_at = [&](int shift) {
      std::set<std::array<long, 4>> keys;
      for (std::size_t i = 0; i < c.size(); ++i) {
        const int L = std::max(0, int(levels[i]) - shift);
        const double cells = std::ldexp(1.0, L);
        std::array<long, 4> k{L, 0, 0, 0};
        for (int a = 0; a < 3; ++a) {
          const double t = (c.world(i)[a] - (s.centre[a] - s.halfsize)) / (2 * s.halfsize);
          k[std::size_t(a) + 1] = std::clamp(long(std::floor(t * cells)), 0L, long(cells) - 1);
        }
        keys.insert(k);
      }
      return keys.size();
    };
    EXPECT_EQ(s.nodes, nodes_at(s.shift)) << target;
    if (s.shift > 0) {
      EXPECT_LT(c.size(), std::size_t{target} * nodes_at(s.shift - 1)) << target;
    }
    if (s.shift < *std::max_element(levels.begin(), levels.end())) {
      EXPECT_GE(c.size(), std::size_t{target} * s.nodes) << target;
    }
  }
}

TEST_F(Copc, SameBytesForAnyThreadCount) {
  auto [c, levels] = levelled_cloud(4000, vec3d(1e5, 2e5, 0));
  write_copc(path("one.copc.laz"), c, levels, {.node_points = 50, .threads = 1});
  write_copc(path("two.copc.laz"), c, levels, {.node_points = 50, .threads = 2});
  EXPECT_EQ(slurp(path("one.copc.laz")), slurp(path("two.copc.laz")));
}

TEST_F(Copc, SpatialReferenceRoundTrips) {
  auto [c, levels] = levelled_cloud(200, vec3d::Zero());
  const std::string wkt = "PROJCS[\"NAD83 / UTM zone 10N\",GEOGCS[\"NAD83\"],UNIT[\"metre\",1]]";
  write_copc(path("w.copc.laz"), c, levels, {.wkt = wkt});
  EXPECT_EQ(pbr_lod::las_wkt(path("w.copc.laz")), wkt);
  write_copc(path("n.copc.laz"), c, levels);
  EXPECT_EQ(pbr_lod::las_wkt(path("n.copc.laz")), "");
  // A real COPC file from PDAL's test data, which carries one.
  EXPECT_NE(pbr_lod::las_wkt(pbr_lod::test::repository_file("laz/simple.copc.laz")).find("PROJCS"),
            std::string::npos);
}

TEST_F(Copc, HardCases) {
  // No points: a header, the VLRs, an empty chunk table and an empty page.
  point_cloud none;
  const copc_summary s0 = write_copc(path("0.copc.laz"), none, {});
  EXPECT_EQ(s0.nodes, 0u);
  EXPECT_EQ(pbr_lod::read_points(path("0.copc.laz")).size(), 0u);
  // One point; every point the same; 10^7 from the origin.
  auto [one, l1] = levelled_cloud(1, vec3d(3, 4, 5));
  check_copc(path("1.copc.laz"), one, l1, write_copc(path("1.copc.laz"), one, l1));
  auto [far, lf] = levelled_cloud(800, vec3d(1e7, -1e7, 1e7));
  const copc_summary sf = write_copc(path("far.copc.laz"), far, lf, {.node_points = 16});
  check_copc(path("far.copc.laz"), far, lf, sf);
  point_cloud same = far;
  for (auto& q : same.positions) q = vec3f(1, 2, 3);
  const copc_summary ss = write_copc(path("same.copc.laz"), same, lf, {.node_points = 16});
  EXPECT_TRUE(std::isfinite(ss.scale) && ss.scale > 0);
  const point_cloud back = pbr_lod::read_points(path("same.copc.laz"));
  ASSERT_EQ(back.size(), same.size());
  for (std::size_t i = 0; i < back.size(); ++i)
    ASSERT_LE((back.world(i) - same.world(i)).norm(), ss.scale);
}

TEST_F(Copc, BadArgumentsLeaveTheOldFile) {
  auto [c, levels] = levelled_cloud(100, vec3d::Zero());
  const std::string p = path("keep.copc.laz");
  write_copc(p, c, levels);
  const std::string before = slurp(p);
  levels.pop_back();
  EXPECT_THROW(write_copc(p, c, levels), pbr_lod::InvalidArgument);
  levels.push_back(0);
  EXPECT_THROW(write_copc(p, c, levels, {.node_points = 0}), pbr_lod::InvalidArgument);
  c.positions[3] = vec3f(NAN, 0, 0);
  EXPECT_THROW(write_copc(p, c, levels), pbr_lod::InvalidArgument);
  EXPECT_EQ(slurp(p), before);
}

}  // namespace
