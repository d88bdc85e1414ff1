// Damaged files: every reader, given a valid file cut at many lengths or with random bytes
// changed, either reads something valid or throws a pbr_lod::Error — never crashes, hangs,
// throws anything else (std::bad_alloc would mean a lying count made us allocate) or returns a
// mesh whose indices are out of range. Run under ASan/UBSan in CI, this is the memory-safety net
// for all the hand-written parsing.
//
// Random mutations are fine here because the property must hold for every input; the fixed seed
// makes a failure reproducible.
#include <gtest/gtest.h>

#include <random>

#include "io_test_util.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/io/write.hpp"
#include "support/data.hpp"

namespace {

using Mutation = pbr_lod::test::scratch_dir;

/// Reads `bytes` saved as `name`; fails the test on anything but success or a pbr_lod::Error.
void read_or_error(const Mutation& t, const std::string& name, const std::string& bytes, bool mesh,
                   const std::string& label) {
  const std::string p = t.write(name, bytes);
  try {
    if (mesh) {
      const auto m = pbr_lod::read_mesh(p);
      m.validate();
    } else {
      const auto c = pbr_lod::read_points(p);
      c.validate();
    }
  } catch (const pbr_lod::FormatError&) {
  } catch (const pbr_lod::IoError&) {
  } catch (const std::exception& e) {
    ADD_FAILURE() << label << ": " << typeid(e).name() << ": " << e.what();
  }
}

/// The intact file first: it must read, with `points` points (a mesh's vertices) — else a reader
/// that refuses everything would pass every mutation below. Then the cuts and random changes.
void mutate_all(const Mutation& t, const std::string& name, const std::string& good, bool mesh,
                int flips, std::size_t points) {
  const std::string intact = t.write(name, good);
  const std::size_t read =
      mesh ? pbr_lod::read_mesh(intact).num_vertices() : pbr_lod::read_points(intact).size();
  ASSERT_EQ(read, points) << name << ": the intact file";
  // Cuts: every length for small files, else ~400 spread over the file plus the first 300.
  const std::size_t n = good.size();
  const std::size_t step = std::max<std::size_t>(1, n / 400);
  for (std::size_t len = 0; len < n; len += (len < 300 ? 1 : step))
    read_or_error(t, name, good.substr(0, len), mesh, "cut at " + std::to_string(len));
  std::mt19937 rng(42);
  std::uniform_int_distribution<std::size_t> where(0, n - 1);
  std::uniform_int_distribution<int> byte(0, 255);
  for (int k = 0; k < flips; ++k) {
    std::string bad = good;
    const int changes = 1 + k % 4;
    for (int c = 0; c < changes; ++c) bad[where(rng)] = static_cast<char>(byte(rng));
    read_or_error(t, name, bad, mesh, "mutation " + std::to_string(k));
  }
}

TEST_F(Mutation, BinaryPly) {
  pbr_lod::write_ply(path("src.ply"),
                     pbr_lod::read_mesh(pbr_lod::test::data_file("bun_zipper_res4.ply")));
  mutate_all(*this, "m.ply", pbr_lod::test::slurp(path("src.ply")), true, 400, 453);
}

TEST_F(Mutation, AsciiPly) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
      "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
      "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0 1 2 3\n1 0 0 4 5 6\n1 1 0 7 8 9\n0 1 0 10 11 12\n3 0 1 2\n3 0 2 3\n";
  mutate_all(*this, "m.ply", text, true, 400, 4);
}

TEST_F(Mutation, Obj) {
  const std::string text =
      "mtllib none.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n"
      "f 1/1/1 2/2/1 3/3/1\nf 1/1 3/3 4/2\nf -4 -2 -1\n";
  mutate_all(*this, "m.obj", text, true, 300, 4);
}

TEST_F(Mutation, Off) {
  const std::string text = "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n4 0 1 2 3\n";
  mutate_all(*this, "m.off", text, true, 300, 4);
}

TEST_F(Mutation, CompressedPcd) {
  // The first 8 KB of the real scan's compressed stream would not decompress on its own, so
  // build a small valid binary_compressed file: 64 points, x y z rgba.
  std::string soa;
  for (int f = 0; f < 4; ++f)
    for (int i = 0; i < 64; ++i) pbr_lod::test::put_le(soa, static_cast<float>(i * (f + 1)));
  const std::string lzf = pbr_lod::test::lzf_literals(soa);
  std::string s =
      "VERSION 0.7\nFIELDS x y z rgba\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 8\n"
      "HEIGHT 8\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 64\nDATA binary_compressed\n";
  pbr_lod::test::put_le(s, static_cast<std::uint32_t>(lzf.size()));
  pbr_lod::test::put_le(s, static_cast<std::uint32_t>(soa.size()));
  s += lzf;
  mutate_all(*this, "m.pcd", s, false, 400, 64);
}

TEST_F(Mutation, AsciiPcd) {
  const std::string s =
      "VERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 3\n"
      "HEIGHT 1\nPOINTS 3\nDATA ascii\n1 2 3 255\nnan nan nan 0\n4 5 6 65280\n";
  mutate_all(*this, "m.pcd", s, false, 300, 2);  // the NaN point dropped
}

TEST_F(Mutation, Las) {
  mutate_all(*this, "m.las", pbr_lod::test::slurp(pbr_lod::test::data_file("1.2-with-color.las")),
             false, 400, 1065);
}

}  // namespace
