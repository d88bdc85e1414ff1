// pbr_lod — a LAS file (formats 0–10) written as LAZ: the file layout around the layered
// chunks of laz_layered.cpp (see laz_decoder.cpp for the layout this writes and the decoder
// reads: the LASzip VLR, the chunk table offset before the chunks, the chunk table after them).
#include <algorithm>

#include "laz_codec.hpp"
#include "laz_decoder.hpp"
#include "laz_encoder.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod::detail {
namespace {

using laz::append_le;
template <class T>
void poke(std::string& s, std::size_t at, T v) {
  laz::store_le(reinterpret_cast<unsigned char*>(s.data() + at), v);
}

}  // namespace

std::string laszip_vlr(unsigned format, std::size_t extra, std::uint32_t chunk_size) {
  const bool layered = format >= 6;
  std::string payload;
  append_le<std::uint16_t>(payload, layered ? 3 : 2);  // compressor: layered / point-wise chunked
  append_le<std::uint16_t>(payload, 0);                // coder: arithmetic
  // The LASzip revision whose output encode_layered_chunk reproduces.
  payload += '\x03';
  payload += '\x04';
  append_le<std::uint16_t>(payload, 3);
  append_le<std::uint32_t>(payload, 0);  // options
  append_le<std::uint32_t>(payload, chunk_size);
  append_le<std::int64_t>(payload, -1);  // special EVLRs: none (as LASzip writes it)
  append_le<std::int64_t>(payload, -1);
  struct item {
    std::uint16_t type, size, version;
  };
  std::vector<item> items;
  if (layered) {
    items.push_back({10, 30, 3});                                  // POINT14
    if (format == 7) items.push_back({11, 6, 3});                  // RGB14
    if (format == 8 || format == 10) items.push_back({12, 8, 3});  // RGBNIR14
    if (format >= 9) items.push_back({13, 29, 3});                 // WAVEPACKET14
  } else {
    items.push_back({6, 20, 2});                                                // POINT10
    if (format != 0 && format != 2) items.push_back({7, 8, 2});                 // GPSTIME11
    if (format == 2 || format == 3 || format == 5) items.push_back({8, 6, 2});  // RGB12
    if (format == 4 || format == 5) items.push_back({9, 29, 1});                // WAVEPACKET13
  }
  if (extra)  // BYTE14 / BYTE
    items.push_back({static_cast<std::uint16_t>(layered ? 14 : 0),
                     static_cast<std::uint16_t>(extra),
                     static_cast<std::uint16_t>(layered ? 3 : 2)});
  append_le<std::uint16_t>(payload, static_cast<std::uint16_t>(items.size()));
  for (const item& it : items) {
    append_le<std::uint16_t>(payload, it.type);
    append_le<std::uint16_t>(payload, it.size);
    append_le<std::uint16_t>(payload, it.version);
  }
  std::string v;
  append_le<std::uint16_t>(v, 0);  // reserved
  std::string id(16, '\0'), description(32, '\0');
  std::copy_n("laszip encoded", 14, id.begin());
  std::copy_n("pbr_lod LAZ writer", 18, description.begin());
  v += id;
  append_le<std::uint16_t>(v, 22204);
  append_le<std::uint16_t>(v, static_cast<std::uint16_t>(payload.size()));
  v += description;
  return v + payload;
}

void append_chunk_table(std::string& out, const std::vector<std::uint64_t>& bytes,
                        const std::vector<std::uint64_t>* counts) {
  append_le<std::uint32_t>(out, 0);  // version
  append_le<std::uint32_t>(out, static_cast<std::uint32_t>(bytes.size()));
  if (bytes.empty()) return;
  // Each chunk's point count (variable chunks only, context 0) and byte count (context 1),
  // coded against the previous chunk's.
  std::vector<unsigned char> coded;
  laz::range_encoder enc(coded);
  laz::integer_codec ic(32, 2);
  std::int32_t prev_count = 0, prev_bytes = 0;
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    if (counts) {
      ic.encode(enc, prev_count, static_cast<std::int32_t>((*counts)[i]), 0);
      prev_count = static_cast<std::int32_t>((*counts)[i]);
    }
    ic.encode(enc, prev_bytes, static_cast<std::int32_t>(bytes[i]), 1);
    prev_bytes = static_cast<std::int32_t>(bytes[i]);
  }
  enc.done();
  out.append(coded.begin(), coded.end());
}

std::string encode_laz_file(const std::string& path, const std::string& las,
                            std::uint32_t chunk_size) {
  const auto* b = reinterpret_cast<const unsigned char*>(las.data());
  read_report report;
  const las_header h = parse_las_header(path, b, las.size(), report);
  if (h.compressed) format_error(path, "header", "already LAZ (bit 7 of the format byte set)");
  if (h.format > 10)
    format_error(path, "header", cat("point format ", h.format, " (expected 0 to 10)"));
  if (chunk_size == 0) throw InvalidArgument("encode_laz_file: chunk size 0");
  constexpr std::size_t min_length_of[11] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};
  const std::size_t min_length = min_length_of[h.format];
  // The VLRs must end before the points (the LASzip VLR goes after them).
  std::uint64_t vlr_end = h.header_size;
  for (std::uint32_t i = 0; i < h.vlr_count; ++i) {
    if (vlr_end + 54 > h.data_offset)
      format_error(path, cat("VLR ", i), "runs past the point data");
    vlr_end += 54 + load_le<std::uint16_t>(b + vlr_end + 20);
    if (vlr_end > h.data_offset) format_error(path, cat("VLR ", i), "runs past the point data");
  }
  const std::string vlr = laszip_vlr(h.format, h.record_length - min_length, chunk_size);
  const std::uint64_t records_end = h.data_offset + h.count * h.record_length;

  // Header, VLRs, LASzip's VLR, whatever lay between the VLRs and the points.
  std::string out = las.substr(0, static_cast<std::size_t>(vlr_end)) + vlr +
                    las.substr(static_cast<std::size_t>(vlr_end),
                               static_cast<std::size_t>(h.data_offset - vlr_end));
  out[104] = static_cast<char>(b[104] | 0x80);
  poke<std::uint32_t>(out, 100, h.vlr_count + 1);
  const std::uint64_t data_offset = h.data_offset + vlr.size();
  if (data_offset > 0xFFFFFFFFu) format_error(path, "header", "the VLRs exceed 4 GiB");
  poke<std::uint32_t>(out, 96, static_cast<std::uint32_t>(data_offset));

  // The chunks, compressed in parallel.
  const std::uint64_t n_chunks = h.count / chunk_size + (h.count % chunk_size ? 1 : 0);
  std::vector<std::vector<unsigned char>> chunks(static_cast<std::size_t>(n_chunks));
  parallel_tasks(chunks.size(), resolve_threads(0), [&](std::size_t k, unsigned) {
    const std::uint64_t first = k * std::uint64_t{chunk_size};
    const std::uint64_t count = std::min<std::uint64_t>(chunk_size, h.count - first);
    const unsigned char* records = b + h.data_offset + first * h.record_length;
    chunks[k] = h.format >= 6 ? encode_layered_chunk(h.format, h.record_length, records, count)
                              : encode_pointwise_chunk(h.format, h.record_length, records, count);
  });
  std::uint64_t table_at = data_offset + 8;
  for (const auto& c : chunks) table_at += c.size();
  append_le<std::int64_t>(out, static_cast<std::int64_t>(table_at));
  for (const auto& c : chunks) out.append(c.begin(), c.end());

  std::vector<std::uint64_t> sizes;
  for (const auto& c : chunks) sizes.push_back(c.size());
  append_chunk_table(out, sizes, nullptr);

  // The EVLRs after the records (LAS 1.4) move with them.
  if (records_end < las.size() && las[25] >= 4) {
    const std::uint64_t evlr_start = load_le<std::uint64_t>(b + 235);
    if (evlr_start >= records_end && evlr_start <= las.size())
      poke<std::uint64_t>(out, 235, evlr_start - records_end + out.size());
    out += las.substr(static_cast<std::size_t>(records_end));
  }
  return out;
}

}  // namespace pbr_lod::detail
