// Fuzz target for the point-octree hierarchy file format: load() of any bytes gives a hierarchy or
// a pbr_lod::Error, and a hierarchy that loads saves and loads again (fuzz_util.hpp). The input's
// checksum is resealed first so that mutations reach the parser (fuzz_util.hpp says why).
#include <cstddef>
#include <cstdint>

#include "fuzz_util.hpp"
#include "pbr_lod/builders/point_octree.hpp"

namespace {
const pbr_lod::fuzz::scratch_files& scratch() {
  static const pbr_lod::fuzz::scratch_files s{
      {pbr_lod::fuzz::scratch_path(".lod", "in"), pbr_lod::fuzz::scratch_path(".lod", "out")}};
  return s;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto& in = scratch().paths[0];
  const auto& out = scratch().paths[1];
  const auto bytes = pbr_lod::fuzz::resealed(data, size);
  pbr_lod::fuzz::write_bytes(in, bytes.data(), bytes.size());
  pbr_lod::fuzz::load_and_round_trip<
      pbr_lod::point_octree<pbr_lod::point_octree_attributes(pbr_lod::positions_only)>>(in, out);
  pbr_lod::fuzz::load_and_round_trip<
      pbr_lod::point_octree<pbr_lod::point_octree_attributes(pbr_lod::attributes{.colour = true})>>(
      in, out);
  return 0;
}
