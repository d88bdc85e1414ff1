// pbr_lod — the out-of-core layer every chunked build shares: its options and memory budget, its
// report, its folder's checks, and the lazy reader of a chunked folder.
//
// A chunked build streams a point_source too large for memory into chunks, builds each chunk in
// memory on its own (from the chunk's points and a halo of its neighbours'), and writes a folder:
// a top file with the nodes above the chunks, and one file per chunk. A builder plugs in by
// supplying its own per-chunk build, the merge of the chunks' roots into the top, and its records
// (docs/adding-a-builder.md, "Out of core"). The builds: builders/chunked_point_octree.hpp,
// chunked_pca_octree.hpp, chunked_pmr.hpp (docs/scale.md).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/point_source.hpp"

namespace pbr_lod {

/// The options of a chunked build of the builder whose in-memory options are `BuilderOptions`:
/// the same four knobs for every builder.
template <class BuilderOptions>
struct chunked_options {
  /// The in-memory builder's options, which every chunk is built with (its progress callback
  /// reports the whole build).
  BuilderOptions builder{};
  /// The memory the whole build may use (one process: each rank of a distributed build is given
  /// the same budget). Unless chunk_points is given, chunks are made small enough that every
  /// chunk the process builds at once fits it together: chunk_points = memory_bytes /
  /// (bytes per point × chunks built at once), see chunk_points_for.
  std::uint64_t memory_bytes = std::uint64_t{4} << 30;
  /// Most samples in one chunk (0: from memory_bytes). At least the builder's leaf size.
  std::uint64_t chunk_points = 0;
  /// Points per block read from the source in the streaming passes.
  std::size_t block_points = std::size_t{1} << 20;
  /// A build shared by `ranks` processes (MPI ranks, say) that see the output on a shared file
  /// system: each calls the build with its rank and a barrier over all of them. Every rank reads
  /// the source in the structure passes; rank 0 writes the chunk and halo files and the top;
  /// chunk c is built by rank c mod ranks. The folder is byte-identical to a one-process build. A
  /// rank that throws leaves the others waiting at the barrier: the caller aborts the job.
  distributed_build distributed{};
};

/// What a builder's chunks cost, for the budget rule.
struct chunk_cost {
  /// Peak bytes of one chunk's build per sample (each builder measures its own).
  std::uint64_t bytes_per_point = 512;
  /// Chunks the builder has in memory at once: 1 when it builds them one after another on all
  /// threads, the thread count when it builds them side by side (one thread each).
  unsigned chunks_at_once = 1;
  /// The fewest samples a chunk may be given (the builder's leaf size).
  std::uint64_t least = 1;
};

/// The budget rule, the one place it is written: `chunk_points` when given, else memory_bytes /
/// (bytes_per_point × chunks_at_once); at least cost.least, at most 2³¹ − 1.
[[nodiscard]] std::uint64_t chunk_points_for(std::uint64_t memory_bytes, std::uint64_t chunk_points,
                                             const chunk_cost& cost);

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

/// The path of `dir`'s top file.
[[nodiscard]] inline std::string chunked_top_path(const std::string& dir) {
  return (std::filesystem::path(dir) / chunked_top_file).string();
}

/// "chunk-NNNNNN.<extension>": the file of chunk c in a chunked directory.
[[nodiscard]] std::string chunk_file(std::uint32_t c, const char* extension);

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

/// Whether `dir` is a folder whose top file starts with `top`'s magic: a chunked build of the
/// builder whose top file has that format.
[[nodiscard]] bool is_chunked_folder(const std::string& dir, const detail::file_format& top);
/// Bit 0 of the flags of `dir`'s top file (after check_chunked_folder): every chunked top file
/// sets it when the hierarchy has colours.
[[nodiscard]] bool chunked_folder_has_colours(const std::string& dir);

/// What every chunked hierarchy shares: the top's index of chunks, and each chunk read from its
/// file the first time it is needed. `Chunk` is what a builder's chunk file loads into. Node ids
/// are (top, i) for node i of the top file and (c, i) for node i of chunk c; a chunk's root is a
/// node of the top file (its record is there), and is named (c, 0).
///
/// Thread safety: const members may be called from several threads (a chunk is loaded once).
template <class Chunk>
class chunked_reader {
 public:
  static constexpr std::uint32_t top = 0xffffffffu;
  struct node_id {
    std::uint32_t chunk = top;
    std::uint32_t index = 0;
    friend bool operator==(const node_id&, const node_id&) = default;
  };

  [[nodiscard]] node_id root() const { return canonical(top, 0); }
  [[nodiscard]] std::size_t top_node_count() const { return frontier_.size(); }
  [[nodiscard]] std::size_t chunk_count() const { return chunk_top_.size(); }
  /// Chunks read so far.
  [[nodiscard]] std::size_t chunks_loaded() const {
    std::size_t k = 0;
    for (const auto& s : slots_) k += s->ready.load(std::memory_order_acquire) != nullptr;
    return k;
  }
  /// Nodes over the whole hierarchy (the top's inner nodes and every chunk's), from the top file.
  [[nodiscard]] std::uint64_t node_count() const {
    std::uint64_t k = 0;
    for (const std::uint32_t f : frontier_) k += f == top ? 1 : 0;
    for (const std::uint64_t c : chunk_nodes_) k += c;
    return k;
  }
  /// Bytes of the directory's files (top file and chunks).
  [[nodiscard]] std::uint64_t file_bytes() const {
    namespace fs = std::filesystem;
    std::uint64_t b = fs::file_size(fs::path(dir_) / chunked_top_file);
    for (std::uint32_t c = 0; c < chunk_top_.size(); ++c) b += fs::file_size(chunk_path(c));
    return b;
  }

 protected:
  explicit chunked_reader(const char* extension = "") : extension_(extension) {}

  /// A top node that is a chunk's root is named by the chunk.
  [[nodiscard]] node_id canonical(std::uint32_t c, std::uint32_t i) const {
    if (c == top && frontier_[i] != top) return {frontier_[i], 0};
    return {c, i};
  }
  /// The top file's index of node n (a chunk's root is there too), or `top` for a node that is
  /// only in its chunk's file.
  [[nodiscard]] std::uint32_t in_top(node_id n) const {
    if (n.chunk == top) return n.index;
    return n.index == 0 ? chunk_top_[n.chunk] : top;
  }
  [[nodiscard]] std::string chunk_path(std::uint32_t c) const {
    return (std::filesystem::path(dir_) / chunk_file(c, extension_)).string();
  }
  /// Chunk c, loaded by load(path) → Chunk on first use (once, whichever thread asks first). A
  /// load that throws (a damaged chunk) leaves the slot empty and the next call tries again. Not
  /// std::call_once: libstdc++'s, on pthread_once, does not reset its flag when the function
  /// throws on every platform (GCC bug 66146; under ThreadSanitizer the next call waited
  /// forever).
  template <class Load>
  const Chunk& load_chunk(std::uint32_t c, Load&& load) const {
    slot& s = *slots_.at(c);
    if (const Chunk* ready = s.ready.load(std::memory_order_acquire)) return *ready;
    const std::lock_guard lock(s.mutex);
    if (!s.loaded) {
      s.loaded = std::make_unique<const Chunk>(load(chunk_path(c)));
      s.ready.store(s.loaded.get(), std::memory_order_release);
    }
    return *s.loaded;
  }
  /// After open() has read the index: one empty slot per chunk.
  void make_slots() {
    slots_.clear();
    for (std::size_t c = 0; c < chunk_top_.size(); ++c) slots_.push_back(std::make_unique<slot>());
  }

  std::string dir_;
  std::vector<std::uint32_t> frontier_;   // per top node: its chunk, or `top`
  std::vector<std::uint32_t> chunk_top_;  // per chunk: its root's top node
  std::vector<std::uint64_t> chunk_samples_, chunk_nodes_;

 private:
  struct slot {
    std::mutex mutex;
    std::unique_ptr<const Chunk> loaded;       // under mutex
    std::atomic<const Chunk*> ready{nullptr};  // loaded.get() once set
  };
  const char* extension_;
  std::vector<std::unique_ptr<slot>> slots_;
};

}  // namespace pbr_lod
