// Fuzz target for the Gaussian hierarchy file format: load() of any bytes gives a hierarchy or a
// pbr_lod::Error, and a hierarchy that loads saves and loads again (fuzz_util.hpp). The input's
// checksum is resealed first so that mutations reach the parser (fuzz_util.hpp says why).
#include <cstddef>
#include <cstdint>

#include "fuzz_util.hpp"
#include "pbr_lod/builders/gaussian_hierarchy.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return pbr_lod::fuzz::hierarchy_target<pbr_lod::gaussian_hierarchy>(data, size);
}
