#pragma once
namespace pbr_lod {
/// Library version, "major.minor.patch".
const char* version();
}  // namespace pbr_lod
