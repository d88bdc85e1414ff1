// The Gaussian hierarchy out of core (builders/chunked_gaussian_hierarchy.hpp): the folder's
// hierarchy is build_gaussian_hierarchy's, byte for byte, whatever the chunk size, leaf size,
// SH degree, block size, thread count and number of ranks; it draws and cuts as the in-memory
// one, reading only the chunks a view needs; the sources it reads give read_gaussians' Gaussians.
#include <gtest/gtest.h>

#include <barrier>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <thread>

#include <unistd.h>

#include "chunked_test_util.hpp"
#include "pbr_lod/builders/chunked_gaussian_hierarchy.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/gaussian_source.hpp"
#include "pbr_lod/io/gaussians.hpp"
#include "pbr_lod/raster/gaussians.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "support/data.hpp"

namespace pbr_lod {
namespace {

namespace fs = std::filesystem;

std::string temp(const std::string& name) {
  return (fs::temp_directory_path() /
          ("pbr_lod_chunked_gaussian_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

/// n random Gaussians of SH degree `degree`; every 7th shares the previous one's mean (ties in
/// the splits, which the index breaks) and every 11th is a copy of an earlier one.
gaussian_cloud random_cloud(std::size_t n, int degree, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1, 1), s(0.002f, 0.03f), op(0.2f, 1);
  gaussian_cloud g;
  g.sh_degree = degree;
  g.origin = vec3d(1e6, -2e5, 30);
  for (std::size_t i = 0; i < n; ++i) {
    g.positions.emplace_back(u(rng), 0.5f * u(rng), 0.3f * u(rng));
    if (i % 7 == 6) g.positions.back() = g.positions[i - 1];
    g.scales.emplace_back(s(rng), s(rng), 0.1f * s(rng));
    g.rotations.push_back(vec4f(u(rng), u(rng), u(rng), u(rng)).normalized());
    g.opacities.push_back(op(rng));
    for (std::size_t k = 0; k < g.sh_stride(); ++k) g.sh.push_back(u(rng));
    if (i % 11 == 10) {
      const std::size_t j = i / 2;
      g.positions.back() = g.positions[j];
      g.scales.back() = g.scales[j];
      g.rotations.back() = g.rotations[j];
      g.opacities.back() = g.opacities[j];
      for (std::size_t k = 0; k < g.sh_stride(); ++k)
        g.sh[i * g.sh_stride() + k] = g.sh[j * g.sh_stride() + k];
    }
  }
  return g;
}

chunked_gaussian_hierarchy_options options(std::uint64_t chunk_points,
                                           int leaf_size = gaussian_hierarchy_options{}.leaf_size,
                                           unsigned threads = 0) {
  chunked_gaussian_hierarchy_options o;
  o.chunk_points = chunk_points;
  o.block_points = 257;  // blocks that straddle the chunks
  o.builder.leaf_size = leaf_size;
  o.builder.threads = threads;
  return o;
}

TEST(ChunkedGaussianHierarchy, AssemblesToTheInMemoryBuildByteForByte) {
  for (const int degree : {0, 3})
    for (const int leaf : {1, 3})
      for (const std::uint64_t chunk : {std::uint64_t{7}, std::uint64_t{333}, std::uint64_t{5000}})
        for (const merged_opacity rule : {merged_opacity::grow, merged_opacity::conserve}) {
          SCOPED_TRACE(testing::Message()
                       << "degree " << degree << ", leaf " << leaf << ", chunk " << chunk
                       << ", conserve " << (rule == merged_opacity::conserve));
          const gaussian_cloud g = random_cloud(2000, degree, 7 + degree + leaf);
          chunked_gaussian_hierarchy_options o = options(chunk, leaf);
          o.builder.opacity = rule;
          const std::string dir = temp("assemble");
          const chunked_build_report r =
              build_gaussian_hierarchy_chunked(cloud_gaussian_source(g), dir, o);
          const std::uint64_t limit = std::max<std::uint64_t>(chunk, 2 * leaf + 1);
          EXPECT_EQ(r.chunk_points, limit);
          EXPECT_LE(r.largest_chunk, limit);
          EXPECT_GE(r.chunks, 2000 / limit);
          EXPECT_EQ(r.passes, 2);
          const auto h = chunked_gaussian_hierarchy::open(dir);
          EXPECT_EQ(h.chunk_count(), r.chunks);
          const gaussian_hierarchy memory = build_gaussian_hierarchy(g, o.builder);
          EXPECT_EQ(h.stored_gaussians(), memory.store().size());
          EXPECT_EQ(h.node_count(), memory.nodes().size());
          EXPECT_EQ(h.depth(), memory.depth());
          EXPECT_TRUE(h.assemble().serialize() == memory.serialize());
          fs::remove_all(dir);
        }
}

TEST(ChunkedGaussianHierarchy, SameFolderForAnyThreadCountAndBlockSize) {
  const gaussian_cloud g = random_cloud(3000, 1, 3);
  const std::string a = temp("threads1"), b = temp("threads2");
  chunked_gaussian_hierarchy_options o1 = options(400, 1, 1), o2 = options(400, 1, 2);
  o2.block_points = 1 << 20;
  (void)build_gaussian_hierarchy_chunked(cloud_gaussian_source(g), a, o1);
  (void)build_gaussian_hierarchy_chunked(cloud_gaussian_source(g), b, o2);
  test::expect_same_folders(a, b);
  fs::remove_all(a);
  fs::remove_all(b);
}

// Three "ranks" as threads with a barrier: chunks built round robin, rank 0 writes the top — the
// one-process folder, over an earlier build with more chunks (replaced whole).
TEST(ChunkedGaussianHierarchy, ThreeRanksWriteTheOneProcessFolder) {
  const gaussian_cloud g = random_cloud(3000, 2, 5);
  const cloud_gaussian_source src(g);
  const std::string one = temp("ranks_one"), many = temp("ranks_many");
  const chunked_build_report r1 = build_gaussian_hierarchy_chunked(src, one, options(300, 1, 1));
  ASSERT_GE(r1.chunks, 8u);
  ASSERT_GT(build_gaussian_hierarchy_chunked(src, many, options(60, 1, 1)).chunks, r1.chunks);
  std::barrier sync(3);
  std::vector<std::thread> ranks;
  for (int rank = 0; rank < 3; ++rank)
    ranks.emplace_back([&, rank] {
      chunked_gaussian_hierarchy_options mine = options(300, 1, 1);
      mine.distributed = {rank, 3, [&] { sync.arrive_and_wait(); }};
      (void)build_gaussian_hierarchy_chunked(src, many, mine);
    });
  for (auto& t : ranks) t.join();
  test::expect_same_folders(one, many);
  EXPECT_FALSE(fs::exists(fs::path(many) / "tmp-build"));
  fs::remove_all(one);
  fs::remove_all(many);
}

// A traversal draws the in-memory build's image and cuts its Gaussians, reading only the chunks
// the view refines into; a coarse view reads none.
TEST(ChunkedGaussianHierarchy, DrawsAndCutsAsTheInMemoryBuildReadingChunksLazily) {
  const gaussian_cloud g = make_gaussian_scene(20000, 1, 4);
  const std::string dir = temp("draw");
  (void)build_gaussian_hierarchy_chunked(cloud_gaussian_source(g), dir, options(1500));
  const gaussian_hierarchy memory = build_gaussian_hierarchy(g, {});
  const auto far = chunked_gaussian_hierarchy::open(dir);
  camera cam;
  cam.eye = vec3d(0.3, 0.4, 1).normalized() * 6;
  cam.vp = {96, 96};
  cam.z_far = 20;
  const view v(cam, g.origin);
  const traverse_options coarse{.tolerance_px = 40};
  EXPECT_EQ(far.cut(v, coarse).positions, memory.cut(v, coarse).positions);
  EXPECT_EQ(far.chunks_loaded(), 0u) << "a coarse cut stays in the top file";
  ASSERT_GE(far.chunk_count(), 13u);
  for (const float tol : {4.0f, 1.0f, 0.25f}) {
    const auto h = chunked_gaussian_hierarchy::open(dir);
    const traverse_options t{.tolerance_px = tol};
    const gaussian_cloud a = h.cut(v, t), b = memory.cut(v, t);
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.scales, b.scales);
    EXPECT_EQ(a.opacities, b.opacities);
    EXPECT_EQ(a.sh, b.sh);
    gaussian_rasterizer ra(v), rb(v);
    const traverse_stats sa = traverse(h, v, t, ra, gaussian_policy{});
    const traverse_stats sb = traverse(memory, v, t, rb, gaussian_policy{});
    EXPECT_EQ(sa.gaussians, sb.gaussians);
    EXPECT_TRUE(ra.finish().colour == rb.finish().colour) << "tolerance " << tol;
  }
  for (const std::size_t level : {0u, 3u, 9u, 40u}) {
    EXPECT_EQ(far.level(level).positions, memory.level(level).positions) << "level " << level;
  }
  fs::remove_all(dir);
}

TEST(ChunkedGaussianHierarchy, AnInputThatFitsIsOneChunk) {
  for (const std::size_t n : {1u, 2u, 3u, 50u}) {
    const gaussian_cloud g = random_cloud(n, 0, 9);
    const std::string dir = temp("one");
    const chunked_build_report r =
        build_gaussian_hierarchy_chunked(cloud_gaussian_source(g), dir, options(0, 3));
    EXPECT_EQ(r.chunks, 1u);
    EXPECT_EQ(r.top_nodes, 1u);
    const auto h = chunked_gaussian_hierarchy::open(dir);
    EXPECT_TRUE(h.assemble().serialize() ==
                build_gaussian_hierarchy(g, {.leaf_size = 3}).serialize())
        << n << " Gaussians";
    fs::remove_all(dir);
  }
}

TEST(ChunkedGaussianHierarchy, RefusesBadInputAndOptions) {
  const gaussian_cloud empty;
  const std::string dir = temp("bad");
  EXPECT_THROW((void)build_gaussian_hierarchy_chunked(cloud_gaussian_source(empty), dir),
               InvalidArgument);
  const gaussian_cloud g = random_cloud(100, 0, 1);
  EXPECT_THROW(
      (void)build_gaussian_hierarchy_chunked(cloud_gaussian_source(g), dir, options(10, 0)),
      InvalidArgument);
  gaussian_cloud nan = g;
  nan.positions[42].x() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW((void)build_gaussian_hierarchy_chunked(cloud_gaussian_source(nan), dir, options(10)),
               InvalidArgument);
  EXPECT_FALSE(fs::exists(dir)) << "a failed build leaves nothing";
  std::ofstream(dir) << "not a folder";
  EXPECT_THROW((void)build_gaussian_hierarchy_chunked(cloud_gaussian_source(g), dir, options(10)),
               IoError);
  EXPECT_FALSE(is_chunked_gaussian_hierarchy(dir));
  fs::remove(dir);
}

// A chunk file swapped for another chunk's, a damaged top file: FormatErrors naming the file.
TEST(ChunkedGaussianHierarchy, DamagedFoldersAreFormatErrors) {
  const gaussian_cloud g = random_cloud(1500, 0, 2);
  const std::string dir = temp("damage");
  (void)build_gaussian_hierarchy_chunked(cloud_gaussian_source(g), dir, options(200));
  const auto intact = chunked_gaussian_hierarchy::open(dir);
  ASSERT_NO_THROW((void)intact.assemble());
  const fs::path c0 = fs::path(dir) / "chunk-000000.gh", c1 = fs::path(dir) / "chunk-000001.gh";
  fs::copy_file(c1, c0, fs::copy_options::overwrite_existing);
  const auto swapped = chunked_gaussian_hierarchy::open(dir);
  try {
    (void)swapped.chunk(0);
    FAIL() << "a swapped chunk loaded";
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("does not match the top file"), std::string::npos)
        << e.what();
  }
  fs::remove_all(dir);
}

/// Replaces a file's bytes in place (no atomic rename, no fsync: a test's thousand damaged copies).
void overwrite(const std::string& path, const std::vector<unsigned char>& bytes) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

// The top file cut at every length and with every byte flipped: a FormatError. With the checksum
// resealed after the flip, the parser's own checks: a FormatError, or a folder that opens and
// whose every chunk still reads or is refused with a FormatError — never a crash.
TEST(ChunkedGaussianHierarchy, EveryDamagedTopFileIsAFormatError) {
  const gaussian_cloud g = random_cloud(60, 0, 4);
  const std::string dir = temp("damage_top");
  ASSERT_GE(build_gaussian_hierarchy_chunked(cloud_gaussian_source(g), dir, options(20)).chunks,
            3u);
  const std::string top = chunked_top_path(dir);
  const std::vector<unsigned char> bytes = detail::load_file_bytes(top);
  ASSERT_NO_THROW((void)chunked_gaussian_hierarchy::open(dir).assemble());
  std::size_t opened = 0;
  for (std::size_t at = 0; at < bytes.size(); ++at) {
    std::vector<unsigned char> bad(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(at));
    overwrite(top, bad);
    EXPECT_THROW((void)chunked_gaussian_hierarchy::open(dir), FormatError) << "cut at " << at;
    bad = bytes;
    bad[at] ^= 0x20;
    overwrite(top, bad);
    EXPECT_THROW((void)chunked_gaussian_hierarchy::open(dir), FormatError) << "flip at " << at;
    if (at + 8 >= bytes.size()) continue;
    const std::uint64_t sum = detail::fnv1a(bad.data(), bad.size() - 8);
    std::memcpy(bad.data() + bad.size() - 8, &sum, 8);
    overwrite(top, bad);
    try {
      const auto h = chunked_gaussian_hierarchy::open(dir);
      ++opened;
      for (std::uint32_t c = 0; c < h.chunk_count(); ++c) {
        try {
          (void)h.chunk(c);
        } catch (const FormatError&) {
        }
      }
    } catch (const FormatError&) {
    }
  }
  std::printf("%zu of %zu resealed flips opened (values the format cannot check)\n", opened,
              bytes.size() - 8);
  fs::remove_all(dir);
}

// save() writes its file in pieces of about 1 MiB, hashing as it goes: the bytes serialize() gives.
TEST(GaussianHierarchyFile, SaveWritesTheSerializedBytesInPieces) {
  const gaussian_hierarchy h = build_gaussian_hierarchy(make_gaussian_scene(16000, 3, 2));
  ASSERT_GT(h.file_bytes(), std::size_t{5} << 20);
  const std::string path = temp("pieces.lod");
  h.save(path);
  const std::vector<unsigned char> bytes = detail::load_file_bytes(path);
  EXPECT_EQ(bytes.size(), h.file_bytes());
  EXPECT_TRUE(bytes == h.serialize());
  EXPECT_TRUE(gaussian_hierarchy::load(path) == h);
  fs::remove(path);
}

// --- a trained scene -----------------------------------------------------------------------------

// A real trained scene (Mip-Splatting's "donut", 45,624 Gaussians, tests/data/gaussians/
// PROVENANCE.md), unseen while the builder was written: cuts against the scene's own full render,
// the chunked build of its file equal to the in-memory one. Floors a little under the values
// measured (GCC 12 Release, 256²), printed by the test.
TEST(TrainedScene, DonutCutsAgainstItsFullRender) {
  const std::string path = test::repository_file("gaussians/donut_mip_splatting.ply");
  read_report report;
  const gaussian_cloud g = read_gaussians(path, &report);
  ASSERT_EQ(g.size(), 45624u);
  EXPECT_EQ(g.sh_degree, 0);
  EXPECT_EQ(report.dropped_non_finite + report.dropped_bad_gaussians, 0u);
  const gaussian_hierarchy h = build_gaussian_hierarchy(g);
  const sphere s = bounding_sphere_about_box_centre(g.positions);
  struct row {
    double distance;
    float tolerance;
    double max_fraction, min_psnr;
  };
  // Measured: 3 radii, tolerance 0.5: all drawn, 91.7 dB; 2: 95.7 %, 40.5 dB; 8: 65.7 %, 25.7 dB;
  // 16: 37.5 %, 20.9 dB; 10 radii, tolerance 3: 50.5 %, 21.0 dB; 12: 7.1 %, 12.8 dB.
  for (const row& r : std::vector<row>{{3, 0.5f, 1.0, 80},
                                       {3, 2, 1.0, 38},
                                       {3, 8, 0.7, 24},
                                       {3, 16, 0.42, 19.5},
                                       {10, 3, 0.55, 19.5},
                                       {10, 12, 0.09, 11.5}}) {
    const camera cam =
        camera::orbit(s.centre.cast<double>(), s.radius, 30, 20, r.distance, 1, viewport{256, 256});
    const view v(cam, g.origin);
    const image full = render_gaussians(g, cam);
    gaussian_rasterizer raster(v);
    const traverse_stats st =
        traverse(h, v, {.tolerance_px = r.tolerance}, raster, gaussian_policy{});
    const double fraction = double(st.gaussians) / double(g.size());
    const double psnr = compare_images(full, raster.finish()).psnr;
    std::printf("donut, %.0f radii, tolerance %.1f: %.3f of the Gaussians, %.1f dB\n", r.distance,
                r.tolerance, fraction, psnr);
    EXPECT_LE(fraction, r.max_fraction);
    EXPECT_GE(psnr, r.min_psnr);
  }
  const std::string dir = temp("donut");
  (void)build_gaussian_hierarchy_chunked(*open_gaussian_source(path), dir, options(4000));
  EXPECT_TRUE(chunked_gaussian_hierarchy::open(dir).assemble().serialize() == h.serialize());
  fs::remove_all(dir);
}

// --- the sources ---------------------------------------------------------------------------------

TEST(GaussianSource, GeneratedBlocksAreTheWholeScene) {
  for (const int degree : {0, 3}) {
    const gaussian_cloud whole = make_gaussian_scene(1001, degree, 5);
    const generated_gaussian_source src(1001, degree, 5);
    gaussian_cloud block;
    for (std::size_t first = 0; first < 1001; first += 97) {
      const std::size_t n = std::min<std::size_t>(97, 1001 - first);
      src.read(first, n, block);
      ASSERT_EQ(block.size(), n);
      for (std::size_t k = 0; k < n; ++k) {
        ASSERT_EQ(block.positions[k], whole.positions[first + k]);
        ASSERT_EQ(block.rotations[k], whole.rotations[first + k]);
        ASSERT_EQ(block.scales[k], whole.scales[first + k]);
        ASSERT_EQ(block.opacities[k], whole.opacities[first + k]);
        for (std::size_t j = 0; j < whole.sh_stride(); ++j)
          ASSERT_EQ(block.sh[k * whole.sh_stride() + j],
                    whole.sh[(first + k) * whole.sh_stride() + j]);
      }
    }
  }
  EXPECT_THROW(generated_gaussian_source(10).read(5, 6, *std::make_unique<gaussian_cloud>()),
               InvalidArgument);
}

/// A 3DGS PLY of the 14 required floats per row, written by hand so that it may hold what
/// write_gaussians_ply refuses (NaN positions, infinite opacities, zero quaternions).
void write_raw_ply(const std::string& path, const std::vector<std::array<float, 14>>& rows) {
  std::ofstream f(path, std::ios::binary);
  f << "ply\nformat binary_little_endian 1.0\nelement vertex " << rows.size() << "\n";
  for (const char* p : {"x", "y", "z", "nx", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0",
                        "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
    if (std::string(p) != "nx") f << "property float " << p << "\n";
  f << "end_header\n";
  for (const auto& r : rows) f.write(reinterpret_cast<const char*>(r.data()), sizeof(r));
}

void expect_same_gaussians(const gaussian_cloud& a, const gaussian_cloud& b) {
  EXPECT_EQ(a.origin, b.origin);
  EXPECT_EQ(a.sh_degree, b.sh_degree);
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.scales, b.scales);
  EXPECT_EQ(a.rotations, b.rotations);
  EXPECT_EQ(a.opacities, b.opacities);
  EXPECT_EQ(a.sh, b.sh);
}

TEST(GaussianSource, FileBlocksAreReadGaussiansWithTheBadValueRule) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-2, 2);
  std::vector<std::array<float, 14>> rows(3000);
  for (auto& r : rows)
    for (float& v : r) v = u(rng);
  const float nan = std::numeric_limits<float>::quiet_NaN(),
              inf = std::numeric_limits<float>::infinity();
  for (const std::size_t i : {0u, 1u, 700u, 701u, 1024u, 2999u}) rows[i][1] = nan;  // dropped
  rows[5][6] = inf;                                           // opacity 1, clamped
  rows[6][8] = nan;                                           // a NaN scale: dropped
  rows[9][10] = rows[9][11] = rows[9][12] = rows[9][13] = 0;  // identity rotation
  rows[12][4] = nan;                                          // SH → 0
  const std::string path = temp("rows.ply");
  write_raw_ply(path, rows);
  read_report whole_report, source_report;
  const gaussian_cloud whole = read_gaussians(path, &whole_report);
  const auto src = open_gaussian_source(path, &source_report);
  ASSERT_EQ(whole.size(), 3000u - 7u);
  EXPECT_EQ(whole_report.dropped_non_finite, 6u);
  EXPECT_EQ(whole_report.rotations_reset, 1u);
  EXPECT_EQ(whole_report.values_clamped, 2u);  // the opacity and the SH coefficient
  ASSERT_EQ(src->size(), whole.size());
  EXPECT_EQ(src->origin(), whole.origin);
  EXPECT_EQ(source_report.points_read, whole_report.points_read);
  EXPECT_EQ(source_report.dropped_non_finite, whole_report.dropped_non_finite);
  EXPECT_EQ(source_report.dropped_bad_gaussians, whole_report.dropped_bad_gaussians);
  EXPECT_EQ(source_report.values_clamped, whole_report.values_clamped);
  EXPECT_EQ(source_report.rotations_reset, whole_report.rotations_reset);
  EXPECT_EQ(source_report.warnings, whole_report.warnings);
  for (const std::size_t block : {1u, 3u, 700u, 5000u}) {
    gaussian_cloud all, b;
    all.origin = whole.origin;
    for (std::uint64_t first = 0; first < src->size(); first += block) {
      const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(block, src->size() - first));
      src->read(first, n, b);
      ASSERT_EQ(b.size(), n);
      all.sh_degree = b.sh_degree;
      all.positions.insert(all.positions.end(), b.positions.begin(), b.positions.end());
      all.scales.insert(all.scales.end(), b.scales.begin(), b.scales.end());
      all.rotations.insert(all.rotations.end(), b.rotations.begin(), b.rotations.end());
      all.opacities.insert(all.opacities.end(), b.opacities.begin(), b.opacities.end());
      all.sh.insert(all.sh.end(), b.sh.begin(), b.sh.end());
    }
    SCOPED_TRACE(block);
    expect_same_gaussians(all, whole);
  }
  EXPECT_THROW(src->read(10, src->size(), *std::make_unique<gaussian_cloud>()), InvalidArgument);
  fs::remove(path);
}

// A written 3DGS PLY and a .splat, built out of core from the file: the in-memory build of
// read_gaussians' cloud.
TEST(GaussianSource, ChunkedBuildFromAFileIsTheInMemoryBuild) {
  const gaussian_cloud g = random_cloud(2500, 3, 11);
  const std::string ply = temp("scene.ply"), dir = temp("from_file");
  write_gaussians_ply(g, ply);
  const gaussian_cloud read = read_gaussians(ply);
  (void)build_gaussian_hierarchy_chunked(*open_gaussian_source(ply), dir, options(300));
  EXPECT_TRUE(chunked_gaussian_hierarchy::open(dir).assemble().serialize() ==
              build_gaussian_hierarchy(read, {}).serialize());
  fs::remove_all(dir);
  fs::remove(ply);
}

}  // namespace
}  // namespace pbr_lod
