// pbr_lod — LAZ encoding: a chunk of point formats 0–5 (point-wise, laz_decoder.cpp) or of LAS 1.4
// formats 6–10 (layered, laz_layered.cpp) — the decoders' models run forwards; both reproduce
// LASzip's chunks byte for byte — and a whole LAS file (laz_writer.cpp); the COPC writer
// (copc_writer.cpp) builds on them. Not installed.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace pbr_lod::detail {

/// (laz_layered.cpp) `count` records of LAS 1.4 format 6–10 (extra
/// bytes after the format's fields) compressed into one layered chunk as LASzip writes it — the
/// first record raw, the point count, the layer sizes, the layers. The first step of a LAZ (and
/// COPC) writer; the chunk table is encoded with laz_codec.hpp's integer_codec.
[[nodiscard]] std::vector<unsigned char> encode_layered_chunk(unsigned format,
                                                              std::uint16_t record_length,
                                                              const unsigned char* records,
                                                              std::uint64_t count);

/// (laz_decoder.cpp) `count` records of LAS format 0–5 (extra bytes after the format's fields)
/// compressed into one point-wise chunk as LASzip writes it: the first record raw, then one
/// arithmetic-coded stream of POINT10, GPSTIME11, RGB12, WAVEPACKET13 and BYTE.
[[nodiscard]] std::vector<unsigned char> encode_pointwise_chunk(unsigned format,
                                                                std::uint16_t record_length,
                                                                const unsigned char* records,
                                                                std::uint64_t count);

/// LASzip's VLR (its 54-byte header and payload) for records of point format `format` (0–10)
/// with `extra` extra bytes: compressor 2 (point-wise) for 0–5, 3 (layered) for 6–10, the items
/// encode_pointwise_chunk / encode_layered_chunk write, chunks of `chunk_size` points
/// (0xFFFFFFFF: variable, the chunk table gives each chunk's count).
[[nodiscard]] std::string laszip_vlr(unsigned format, std::size_t extra, std::uint32_t chunk_size);

/// Appends a LAZ chunk table to `out`: version 0, the chunk count, then each chunk's point count
/// (when `counts` is given: variable chunks) and byte count, arithmetic-coded as LASzip codes
/// them (read_laz_layout reads it back).
void append_chunk_table(std::string& out, const std::vector<std::uint64_t>& bytes,
                        const std::vector<std::uint64_t>* counts);

/// The LAS file `las` (its bytes; any point format 0–10, not compressed) as LAZ: its header
/// and VLRs with bit 7 of the format byte set and LASzip's VLR appended (compressor 2, items
/// POINT10 [GPSTIME11] [RGB12] [WAVEPACKET13] [BYTE] for formats 0–5; compressor 3, items
/// POINT14 [RGB14 | RGBNIR14] [WAVEPACKET14] [BYTE14] for 6–10; fixed chunks of `chunk_size`
/// points), the offsets after it moved; the records in chunks, compressed in parallel; the chunk
/// table; then a LAS 1.4 file's EVLRs (bytes after the records of older versions are dropped).
/// `path` names the input in messages. Throws FormatError for a file it cannot encode
/// (parse_las_header's checks, another format, VLRs past the points).
[[nodiscard]] std::string encode_laz_file(const std::string& path, const std::string& las,
                                          std::uint32_t chunk_size = 50000);

}  // namespace pbr_lod::detail
