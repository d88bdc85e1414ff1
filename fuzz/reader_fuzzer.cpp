// Fuzz target for one mesh / point-cloud reader (PLY, OBJ, OFF, PCD or LAS; fuzz/CMakeLists.txt
// picks it with PBR_LOD_FUZZ_EXT). read.hpp promises: any file gives data that passes validate()
// or a pbr_lod::Error — never a crash, a hang, an out-of-bounds read or another exception (a
// std::bad_alloc would mean a count in the file was trusted before it was checked).
#include <cstddef>
#include <cstdint>

#include "fuzz_util.hpp"
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

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string& path = input_path();
  pbr_lod::fuzz::write_bytes(path, data, size);
  try {
#if PBR_LOD_FUZZ_MESH
    const pbr_lod::triangle_mesh m = pbr_lod::read_mesh(path);
    m.validate();  // a reader's result must be valid: indices in range, attribute counts match
#else
    const pbr_lod::point_cloud c = pbr_lod::read_points(path);
    c.validate();
#endif
  } catch (const pbr_lod::FormatError&) {
  } catch (const pbr_lod::IoError&) {
  }
  return 0;
}
