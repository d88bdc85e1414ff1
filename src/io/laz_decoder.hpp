// pbr_lod — our LAZ (LASzip-compressed LAS) decoder: the LASzip VLR, the chunk table, the
// point-wise chunked compressor of point data record formats 0–5 (items POINT10, GPSTIME11,
// RGB12 and BYTE version 2, WAVEPACKET13 version 1) and the layered chunked compressor of LAS 1.4
// formats 6–10 (POINT14, RGB14, RGBNIR14, WAVEPACKET14 and BYTE14, version 3). Not installed; see
// laz_decoder.cpp for the format and docs/io.md.
//
// A LAZ file is a LAS file whose point records are replaced by chunks of compressed records.
// Chunks are independent (every chunk restarts the models and stores its first record raw), so
// they decode in any order and in parallel, and a decoded chunk is exactly the LAS records it
// replaced: the LAS record parsing (point_formats.hpp) reads them unchanged.
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "point_formats.hpp"

namespace pbr_lod::detail {

/// One item of a LASzip point record: what it is (LASzip's item type), its bytes and the
/// version of its compressor.
struct laz_item {
  std::uint16_t type = 0, size = 0, version = 0;
};

/// A chunk of compressed records: records [first, first + count) of the file, compressed in
/// `bytes` bytes at file offset `offset`.
struct laz_chunk {
  std::uint64_t first = 0, count = 0;
  std::uint64_t offset = 0, bytes = 0;
};

/// What the LASzip VLR and the chunk table say, checked against the LAS header and the file.
struct laz_layout {
  std::uint16_t compressor = 0;  ///< 2: point-wise chunked (formats 0–5); 3: layered (6–10)
  std::uint32_t chunk_size = 0;  ///< points per chunk; 0xFFFFFFFF: variable (the table says)
  unsigned format = 0;           ///< point data record format (the format byte without bits 7, 6)
  std::uint16_t record_length = 0;
  std::vector<laz_item> items;
  std::vector<laz_chunk> chunks;
  /// Largest chunk in records (the scratch a chunk decode needs).
  [[nodiscard]] std::uint64_t max_chunk_count() const;
  /// The chunk holding record r (r < total records).
  [[nodiscard]] std::size_t chunk_of(std::uint64_t r) const;
};

/// Reads `n` bytes of the file at `offset` into out. The caller (read_laz_layout, the chunk
/// decoders) has checked that the range lies inside the file.
using laz_fetch = std::function<void(std::uint64_t offset, std::size_t n, unsigned char* out)>;

/// Finds and checks the LASzip VLR (user id "laszip encoded", record id 22204) among the VLRs
/// after the header, and reads and checks the chunk table. `h` is the file's parsed header
/// (h.compressed set), `file_size` its size. Throws FormatError naming the file and the element.
[[nodiscard]] laz_layout read_laz_layout(const std::string& path, const las_header& h,
                                         std::uint64_t file_size, const laz_fetch& fetch);

/// Decodes chunk k, whose compressed bytes are at `bytes` (L.chunks[k].bytes of them), into
/// L.chunks[k].count records of L.record_length bytes at `records`. Throws FormatError when
/// the chunk is damaged in a way that shows (its stream runs past its end).
void decode_laz_chunk(const std::string& path, const laz_layout& L, std::size_t k,
                      const unsigned char* bytes, unsigned char* records);

/// Decodes chunk k of a layered (LAS 1.4, formats 6–10) file from its `n_bytes` bytes into its
/// `count` records; returns how many bytes its layers' decoders read past their ends (0 for an
/// intact chunk). Throws FormatError for a chunk whose header does not fit. (laz_layered.cpp;
/// called by decode_laz_chunk.)
[[nodiscard]] std::uint64_t decode_layered_chunk(const std::string& path, const laz_layout& L,
                                                 std::size_t k, const unsigned char* bytes,
                                                 std::size_t n_bytes, std::uint64_t count,
                                                 unsigned char* records);

/// Decodes chunks [c0, c1) into consecutive records at `records` (the first record of chunk c0
/// first), reading their bytes with `fetch`, on up to `threads` threads (0: every core).
void decode_laz_chunks(const std::string& path, const laz_layout& L, std::size_t c0, std::size_t c1,
                       const laz_fetch& fetch, unsigned char* records, unsigned threads = 0);

/// Records of a LAZ file read by range from an open file, for the streaming point source: the
/// chunks wholly inside a large range decode straight into it (in parallel); the chunks a large
/// range only touches, and every chunk of a small one, are decoded once into a cache of recent
/// chunks, so that reads of a few points at a time do not decode a chunk per read. Memory: a few
/// chunks, or 2^16 records of small ones. read() is safe to call from several threads at once.
class laz_record_reader {
 public:
  laz_record_reader(const posix_file& file, laz_layout layout)
      : file_(file), layout_(std::move(layout)) {}
  [[nodiscard]] const laz_layout& layout() const { return layout_; }
  /// Records [first, first + n) into out (n · record_length bytes).
  void read(std::uint64_t first, std::uint64_t n, unsigned char* out) const;

 private:
  using chunk_records = std::shared_ptr<const std::vector<unsigned char>>;
  [[nodiscard]] chunk_records cached(std::size_t k) const;
  [[nodiscard]] laz_fetch fetch() const;

  /// The cache keeps at least cache_min_chunks chunks, more while they hold no more than
  /// cache_records records; reads of fewer records than that go through it.
  static constexpr std::size_t cache_min_chunks = 4;
  static constexpr std::uint64_t cache_records = std::uint64_t{1} << 16;

  const posix_file& file_;
  laz_layout layout_;
  mutable std::mutex mutex_;
  mutable std::unordered_map<std::size_t, chunk_records> cache_;
  mutable std::deque<std::size_t> order_;  ///< the cached chunks, oldest first
  mutable std::uint64_t cached_records_ = 0;
};

}  // namespace pbr_lod::detail
