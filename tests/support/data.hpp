// Test support: the real scans in ../shared/data. On a fresh clone without that folder a test
// that needs one stops with a message tagged PBR_LOD_DATA_SKIP, which ctest reports as skipped
// (SKIP_REGULAR_EXPRESSION, tests/CMakeLists.txt), so everything that runs on generated data
// still runs. With CI=true a missing file fails the test: CI cannot pass without the real data.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace pbr_lod::test {

/// PBR_LOD_DATA_DIR as configured (cmake/test_data.cmake; in a library of its own, so that no
/// test object depends on where the checkout is).
const char* configured_data_dir();

/// The checkout's tests/data folder (files committed with the project, with their PROVENANCE.md).
const char* repository_test_data_dir();

/// Full path of a file committed under tests/data (always present: no skipping).
inline std::string repository_file(const std::string& relative) {
  return (std::filesystem::path(repository_test_data_dir()) / relative).string();
}

inline std::filesystem::path data_dir() {
  if (const char* env = std::getenv("PBR_LOD_DATA")) return env;
  return configured_data_dir();
}

/// Whether this run must have the data (CI=true): then a missing file fails, never skips.
inline bool data_required() {
  const char* ci = std::getenv("CI");
  return ci && std::string(ci) == "true";
}

/// Full path of a file in the shared data folder; throws when it is missing, which fails the test
/// under CI=true and otherwise marks it skipped.
inline std::string data_file(const std::string& name) {
  const auto p = data_dir() / name;
  if (!std::filesystem::exists(p))
    throw std::runtime_error(
        std::string(data_required()
                        ? "shared test data missing (CI=true requires it): "
                        : "PBR_LOD_DATA_SKIP: shared test data missing, test skipped: ") +
        p.string() + " (set PBR_LOD_DATA or -DPBR_LOD_DATA_DIR to the shared/data folder)");
  return p.string();
}

}  // namespace pbr_lod::test
