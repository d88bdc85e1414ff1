// Fuzz target for one mesh / point-cloud reader (PLY, OBJ, OFF, PCD or LAS; fuzz/CMakeLists.txt
// picks it with PBR_LOD_FUZZ_EXT), or, with PBR_LOD_FUZZ_GAUSSIANS, one 3-D Gaussian reader
// (3DGS PLY, .splat, .spz: io/gaussians.hpp, whose result must pass gaussian_cloud::validate —
// the bad-value rule lets no NaN through). read.hpp promises: any file gives data that passes
// validate() or a pbr_lod::Error — never a crash, a hang, an out-of-bounds read or another
// exception (a std::bad_alloc would mean a count in the file was trusted before it was checked).
// For PLY, PCD and LAS (PBR_LOD_FUZZ_SOURCE) the block reader of out-of-core builds reads the same
// bytes and must agree with the reader.
#include <cstddef>
#include <cstdint>

#include <algorithm>
#include <optional>

#include "fuzz_util.hpp"
#include "pbr_lod/io/gaussians.hpp"
#include "pbr_lod/io/point_source_file.hpp"
#include "pbr_lod/io/read.hpp"

namespace {
const std::string& input_path() {
  static pbr_lod::fuzz::scratch_files cleanup;
  static const std::string p = [] {
    cleanup.paths.push_back(pbr_lod::fuzz::scratch_path(PBR_LOD_FUZZ_EXT));
    return cleanup.paths.back();
  }();
  return p;
}
}  // namespace

#if PBR_LOD_FUZZ_SOURCE
/// The same file as a point source (io/point_source_file.hpp), read in blocks of 7 points so that
/// reads start inside its index runs: it must give what the reader gave, point for point, or an
/// error where the reader gave one too.
void check_point_source(const std::string& path, const pbr_lod::point_cloud* whole) {
  std::optional<pbr_lod::point_cloud> got;
  try {
    const auto src = pbr_lod::open_point_source(path);
    got = pbr_lod::point_cloud{};
    got->origin = src->origin();
    got->sensor = src->sensor();
    pbr_lod::point_block b;
    for (std::uint64_t first = 0; first < src->size(); first += 7) {
      src->read(first, static_cast<std::size_t>(std::min<std::uint64_t>(7, src->size() - first)),
                b);
      got->positions.insert(got->positions.end(), b.positions.begin(), b.positions.end());
      got->normals.insert(got->normals.end(), b.normals.begin(), b.normals.end());
      got->colours.insert(got->colours.end(), b.colours.begin(), b.colours.end());
    }
  } catch (const pbr_lod::FormatError&) {
    got.reset();
  } catch (const pbr_lod::IoError&) {
    got.reset();
  }
  if (!got || !whole)
    return;  // either may refuse what the other reads (faces, lists: see the header)
  if (got->origin != whole->origin || got->positions != whole->positions ||
      got->normals != whole->normals || got->colours != whole->colours)
    __builtin_trap();  // the block reader and read_points disagree on a file both read
}
#endif

#if PBR_LOD_FUZZ_GAUSSIANS
/// The same file as a gaussian_source (the out-of-core build's input), read in blocks of 7: a
/// file both read must give read_gaussians' Gaussians, each block valid; a file the reader
/// refuses must not open as a source that reads.
void check_gaussian_source(const std::string& path, const pbr_lod::gaussian_cloud* whole) {
  std::optional<pbr_lod::gaussian_cloud> got;
  try {
    const auto src = pbr_lod::open_gaussian_source(path);
    got = pbr_lod::gaussian_cloud{};
    got->origin = src->origin();
    got->sh_degree = src->sh_degree();
    pbr_lod::gaussian_cloud b;
    for (std::uint64_t first = 0; first < src->size(); first += 7) {
      src->read(first, static_cast<std::size_t>(std::min<std::uint64_t>(7, src->size() - first)),
                b);
      b.validate();
      got->positions.insert(got->positions.end(), b.positions.begin(), b.positions.end());
      got->scales.insert(got->scales.end(), b.scales.begin(), b.scales.end());
      got->rotations.insert(got->rotations.end(), b.rotations.begin(), b.rotations.end());
      got->opacities.insert(got->opacities.end(), b.opacities.begin(), b.opacities.end());
      got->sh.insert(got->sh.end(), b.sh.begin(), b.sh.end());
    }
  } catch (const pbr_lod::FormatError&) {
    got.reset();
  } catch (const pbr_lod::IoError&) {
    got.reset();
  }
  if (!got && !whole) return;
  if (!got || !whole || got->origin != whole->origin || got->sh_degree != whole->sh_degree ||
      got->positions != whole->positions || got->scales != whole->scales ||
      got->rotations != whole->rotations || got->opacities != whole->opacities ||
      got->sh != whole->sh)
    __builtin_trap();  // the source and read_gaussians disagree
}
#endif

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string& path = input_path();
  pbr_lod::fuzz::write_bytes(path, data, size);
#if PBR_LOD_FUZZ_GAUSSIANS
  std::optional<pbr_lod::gaussian_cloud> whole;
  try {
    whole = pbr_lod::read_gaussians(path);
    whole->validate();
  } catch (const pbr_lod::FormatError&) {
    whole.reset();
  } catch (const pbr_lod::IoError&) {
    whole.reset();
  }
  check_gaussian_source(path, whole ? &*whole : nullptr);
#else
  std::optional<pbr_lod::point_cloud> whole;
  try {
#if PBR_LOD_FUZZ_MESH
    const pbr_lod::triangle_mesh m = pbr_lod::read_mesh(path);
    m.validate();  // a reader's result must be valid: indices in range, attribute counts match
    whole = m.vertices;
#else
    const pbr_lod::point_cloud c = pbr_lod::read_points(path);
    c.validate();
    whole = c;
#endif
  } catch (const pbr_lod::FormatError&) {
  } catch (const pbr_lod::IoError&) {
  }
#if PBR_LOD_FUZZ_SOURCE
  check_point_source(path, whole ? &*whole : nullptr);
#endif
#endif
  return 0;
}
