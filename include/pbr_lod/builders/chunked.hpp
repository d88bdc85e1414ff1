// pbr_lod — what every chunked (out-of-core) build shares: its report and its top file's name.
// The builds: builders/chunked_point_octree.hpp, chunked_pca_octree.hpp, chunked_pmr.hpp
// (docs/scale.md).
#pragma once

#include <cstddef>
#include <cstdint>

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
};

/// The top file of a chunked directory (each chunk has a file of its own beside it).
inline constexpr const char* chunked_top_file = "top.pbrlod";

}  // namespace pbr_lod
