// LAZ files of several chunks made from a real one-chunk file: its chunk repeated under a chunk
// table encoded with the library's own coder (src/io/laz_codec.hpp). For laz_test.cpp and the
// LAZ benchmark; the real twins are small, so each is a single chunk. Needs src/ on the include
// path.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "io/laz_codec.hpp"
#include "io/laz_decoder.hpp"
#include "io_test_util.hpp"

namespace pbr_lod::test {

/// Multiplies the point counts of the LAS header at the start of `las` by `copies` (the legacy
/// count, and for LAS 1.4 the 64-bit one) and drops its EVLRs (LAS 1.4).
inline void las_multiply_count(std::string& las, std::uint32_t copies) {
  std::uint32_t legacy = 0;
  std::memcpy(&legacy, las.data() + 107, 4);
  legacy *= copies;
  std::memcpy(las.data() + 107, &legacy, 4);
  if (las[25] >= 4) {
    std::uint64_t count = 0;
    std::memcpy(&count, las.data() + 247, 8);
    count *= copies;
    std::memcpy(las.data() + 247, &count, 8);
    const std::uint64_t no_evlr[2] = {0, 0};  // start of the first EVLR (235), their count (243)
    std::memcpy(las.data() + 235, no_evlr, 12);
  }
}

/// `laz` (the bytes of a LAZ file whose points are one chunk) with that chunk repeated `copies`
/// times: fixed chunks (the VLR's chunk size becomes the file's point count) or variable ones
/// (chunk size 0xFFFFFFFF; the table then holds each chunk's count). The header's point counts
/// are multiplied; what followed the chunk table (LAS 1.4 EVLRs) is left out.
inline std::string laz_repeat_chunk(const std::string& laz, std::uint32_t copies, bool variable) {
  const auto* b = reinterpret_cast<const unsigned char*>(laz.data());
  pbr_lod::read_report r;
  const detail::las_header h = detail::parse_las_header("laz", b, laz.size(), r);
  const detail::laz_layout L = detail::read_laz_layout(
      "laz", h, laz.size(),
      [&](std::uint64_t at, std::size_t n, unsigned char* out) { std::memcpy(out, b + at, n); });
  const detail::laz_chunk c = L.chunks.at(0);
  const std::string chunk =
      laz.substr(static_cast<std::size_t>(c.offset), static_cast<std::size_t>(c.bytes));
  const auto poke32 = [](std::string& s, std::size_t at, std::uint32_t v) {
    std::memcpy(s.data() + at, &v, 4);
  };

  std::string out = laz.substr(0, h.data_offset);
  las_multiply_count(out, copies);
  // The chunk size field of the LASzip VLR (found as read_laz_layout finds it).
  std::size_t at = h.header_size;
  for (std::uint32_t i = 0; i < h.vlr_count; ++i) {
    std::uint16_t length = 0;
    std::memcpy(&length, out.data() + at + 20, 2);
    if (out.compare(at + 2, 14, "laszip encoded") == 0)
      poke32(out, at + 54 + 12, variable ? 0xFFFFFFFFu : static_cast<std::uint32_t>(h.count));
    at += 54 + length;
  }
  const std::int64_t table_at =
      h.data_offset + 8 + std::int64_t{copies} * std::int64_t(chunk.size());
  out.append(reinterpret_cast<const char*>(&table_at), 8);
  for (std::uint32_t i = 0; i < copies; ++i) out += chunk;
  const std::uint32_t table_head[2] = {0, copies};
  out.append(reinterpret_cast<const char*>(table_head), 8);
  std::vector<unsigned char> coded;
  detail::laz::range_encoder enc(coded);
  detail::laz::integer_codec ic(32, 2);
  std::int32_t prev_count = 0, prev_bytes = 0;
  for (std::uint32_t i = 0; i < copies; ++i) {
    if (variable) {
      ic.encode(enc, prev_count, static_cast<std::int32_t>(c.count), 0);
      prev_count = static_cast<std::int32_t>(c.count);
    }
    ic.encode(enc, prev_bytes, static_cast<std::int32_t>(chunk.size()), 1);
    prev_bytes = static_cast<std::int32_t>(chunk.size());
  }
  enc.done();
  out.append(coded.begin(), coded.end());
  return out;
}

inline detail::las_header header_of(const std::string& path, const std::string& bytes) {
  pbr_lod::read_report r;
  return detail::parse_las_header(path, reinterpret_cast<const unsigned char*>(bytes.data()),
                                  bytes.size(), r);
}

inline detail::laz_fetch fetch_from(const std::string& bytes) {
  return [&bytes](std::uint64_t at, std::size_t n, unsigned char* out) {
    std::memcpy(out, bytes.data() + at, n);
  };
}

/// The layout of a LAZ file held in `bytes`.
inline detail::laz_layout layout_of(const std::string& path, const std::string& bytes) {
  return detail::read_laz_layout(path, header_of(path, bytes), bytes.size(), fetch_from(bytes));
}

/// Every record of the LAZ file at `path`, decoded.
inline std::string laz_records(const std::string& path) {
  const std::string bytes = slurp(path);
  const detail::laz_layout L = layout_of(path, bytes);
  const detail::las_header h = header_of(path, bytes);
  std::string out(static_cast<std::size_t>(h.count * h.record_length), '\0');
  detail::decode_laz_chunks(path, L, 0, L.chunks.size(), fetch_from(bytes),
                            reinterpret_cast<unsigned char*>(out.data()));
  return out;
}

}  // namespace pbr_lod::test
