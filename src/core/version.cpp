#include "pbr_lod/version.hpp"

namespace pbr_lod {
const char* version() {
  return "0.1.0";
}
}  // namespace pbr_lod
