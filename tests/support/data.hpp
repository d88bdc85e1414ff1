// Test support: the real scans in ../shared/data. A test that needs one fails loudly — never
// skips — when the folder is missing, so CI cannot pass without exercising real data.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace pbr_lod::test {

inline std::filesystem::path data_dir() {
  if (const char* env = std::getenv("PBR_LOD_DATA")) return env;
  return PBR_LOD_DATA_DIR;
}

/// Full path of a file in the shared data folder; throws (failing the test) when it is missing.
inline std::string data_file(const std::string& name) {
  const auto p = data_dir() / name;
  if (!std::filesystem::exists(p))
    throw std::runtime_error("shared test data missing: " + p.string() +
                             " (set PBR_LOD_DATA or -DPBR_LOD_DATA_DIR to the shared/data folder)");
  return p.string();
}

}  // namespace pbr_lod::test
