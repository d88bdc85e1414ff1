// pbr_lod fuzz targets — what they share: a scratch file per process (the readers and loaders
// take a path), and resealing a hierarchy file's checksum.
//
// Why reseal: every hierarchy file ends with the FNV-1a checksum of the rest, which load() checks
// before anything else. A mutated input would almost never match it, so without resealing the
// fuzzer would only ever test the checksum comparison. The targets overwrite the last 8 bytes
// with the checksum of the others, so mutations reach the parsers' validation. (The checksum
// itself is tested in the unit tests.)
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "pbr_lod/core/binary.hpp"

namespace pbr_lod::fuzz {

/// A scratch path for this process ending in `ext`: in /dev/shm when it exists (a write and a
/// read of a RAM file cost microseconds), else in the system temp folder. Per process, so
/// parallel fuzzing jobs (-jobs=N) do not share it.
inline std::string scratch_path(const std::string& ext, const char* tag = "in") {
  const std::filesystem::path dir = std::filesystem::is_directory("/dev/shm")
                                        ? std::filesystem::path("/dev/shm")
                                        : std::filesystem::temp_directory_path();
  return (dir / ("pbr_lod_fuzz_" + std::to_string(::getpid()) + "_" + tag + ext)).string();
}

/// Writes the bytes to `path` (replacing it); aborts on failure, which is the harness's fault.
inline void write_bytes(const std::string& path, const std::uint8_t* data, std::size_t size) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f || (size && std::fwrite(data, 1, size, f) != size) || std::fclose(f) != 0) {
    std::perror(path.c_str());
    std::abort();
  }
}

/// The input with its last 8 bytes replaced by the FNV-1a checksum of the rest (see above).
inline std::vector<unsigned char> resealed(const std::uint8_t* data, std::size_t size) {
  std::vector<unsigned char> b(data, data + size);
  if (b.size() >= 8) {
    const std::uint64_t sum = detail::fnv1a(b.data(), b.size() - 8);
    std::memcpy(b.data() + b.size() - 8, &sum, 8);
  }
  return b;
}

/// Removes the scratch files at exit (libFuzzer exits through exit() after -max_total_time).
struct scratch_files {
  std::vector<std::string> paths;
  ~scratch_files() {
    for (const auto& p : paths) std::remove(p.c_str());
  }
};

}  // namespace pbr_lod::fuzz

namespace pbr_lod::fuzz {

/// Loads the file at `in` as hierarchy type H (H::load(path), H::save(path)). A pbr_lod::Error
/// is the expected answer to most inputs. A file that loads must save and load again: the loader
/// accepted it, so everything in it is within what the format promises. Anything else (another
/// exception, a sanitizer report) is a finding.
template <class H>
void load_and_round_trip(const std::string& in, const std::string& out) {
  try {
    const H h = H::load(in);
    h.save(out);
  } catch (const Error&) {
    return;
  }
  (void)H::load(out);  // no catch: a saved hierarchy that does not load again is a bug
}

/// The whole of a hierarchy file target: the input resealed, written to this process's scratch
/// file, and loaded (and round-tripped) as each of the hierarchy types a file of that format may
/// hold.
template <class... Hierarchies>
int hierarchy_target(const std::uint8_t* data, std::size_t size) {
  static const scratch_files scratch{{scratch_path(".lod", "in"), scratch_path(".lod", "out")}};
  const auto bytes = resealed(data, size);
  write_bytes(scratch.paths[0], bytes.data(), bytes.size());
  (load_and_round_trip<Hierarchies>(scratch.paths[0], scratch.paths[1]), ...);
  return 0;
}

}  // namespace pbr_lod::fuzz
