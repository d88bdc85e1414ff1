// Fuzz target for the ρ-grid file format, all three layouts (NIS, IS, compressed) and every ρ:
// rho_grid<R>::parse() of any bytes gives a grid or a pbr_lod::Error, and a grid that parses
// serialises in every layout to bytes that parse again. The ρ-grid has an in-memory entry point
// (parse), so no file is written. The checksum is resealed first (fuzz_util.hpp says why).
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "fuzz_util.hpp"
#include "pbr_lod/builders/rho_grid.hpp"

namespace {

template <int Rho>
void parse_and_round_trip(const std::vector<unsigned char>& bytes) {
  using grid = pbr_lod::rho_grid<Rho>;
  std::optional<grid> g;
  try {
    g.emplace(grid::parse(bytes, "fuzz input"));
  } catch (const pbr_lod::FormatError&) {
    return;
  }
  // No catch: a grid that parsed and does not parse again after serialise() is a bug.
  for (const auto layout : {pbr_lod::rho_grid_layout::nis, pbr_lod::rho_grid_layout::is,
                            pbr_lod::rho_grid_layout::compressed})
    (void)grid::parse(g->serialise(layout), "re-serialised fuzz input");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto bytes = pbr_lod::fuzz::resealed(data, size);
  // Each ρ is a type; the file's ρ field picks one, the others reject it in the header.
  parse_and_round_trip<2>(bytes);
  parse_and_round_trip<3>(bytes);
  parse_and_round_trip<4>(bytes);
  parse_and_round_trip<5>(bytes);
  return 0;
}
