// pbr_lod — what every chunked (out-of-core) build shares: its report and its top file's name.
// The builds: builders/chunked_point_octree.hpp, chunked_pca_octree.hpp, chunked_pmr.hpp
// (docs/scale.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace pbr_lod {

/// What a chunked build did (the steps are each build's; its header numbers them).
struct chunked_build_report {
  std::uint64_t input_points = 0;
  std::size_t chunks = 0, top_nodes = 0;
  std::uint64_t chunk_points = 0;   ///< the limit used
  std::uint64_t largest_chunk = 0;  ///< samples in the largest chunk
  std::uint64_t halo_points = 0;    ///< summed over the chunks
  int passes = 0;                   ///< full passes over the source
  double seconds = 0;               ///< the whole build
  /// The streaming passes and rank 0's serial steps between the chunk builds (each build's
  /// header says which of its steps count where).
  double pass_seconds = 0;
  double estimation_seconds = 0;   ///< per-chunk normal estimation (point-octree, PMR's parts)
  double chunk_build_seconds = 0;  ///< the chunks' builds
  bool estimated_normals = false;
  /// Input normals that were zero or not finite — "no normal" — and were estimated from the
  /// positions over each chunk and its halo (fill_missing_normals), as the in-memory builds do.
  std::uint64_t normals_filled = 0;
};

/// The top file of a chunked directory (each chunk has a file of its own beside it).
inline constexpr const char* chunked_top_file = "top.pbrlod";

/// Throws FormatError naming `dir` when it is a folder but not a finished chunked build: one an
/// interrupted build left (its staging folder `<output>.partial`, see atomic_directory), a folder
/// without the top file, which a build writes last (say, one left by a build of an older version
/// that wrote in place), or any other folder. Does nothing when `dir` is not a folder or holds
/// the top file: opening it then says what else is wrong. Every chunked open() calls it first.
void check_chunked_folder(const std::string& dir);

/// Throws IoError when `dir` exists and may not be replaced by a chunked build: only an empty
/// folder or a finished chunked build (a folder holding the top file) is replaced — a build
/// never removes a folder of other files because its name was given as the output.
void check_chunked_output(const std::string& dir);

}  // namespace pbr_lod
