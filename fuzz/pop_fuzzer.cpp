// Fuzz target for the POP hierarchy file format: load() of any bytes gives a hierarchy or a
// pbr_lod::Error, and a hierarchy that loads saves and loads again (fuzz_util.hpp). The input's
// checksum is resealed first so that mutations reach the parser (fuzz_util.hpp says why).
#include <cstddef>
#include <cstdint>

#include "fuzz_util.hpp"
#include "pbr_lod/builders/pop.hpp"

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
  pbr_lod::fuzz::load_and_round_trip<pbr_lod::pop_tree<pbr_lod::with_normals>>(in, out);
  pbr_lod::fuzz::load_and_round_trip<pbr_lod::pop_tree<pbr_lod::with_normals_colours>>(in, out);
  return 0;
}
