// pbr_lod — our LAS reader (ASPRS LAS 1.0–1.4, point data record formats 0–10).
//
// Read: X Y Z (32-bit integers, world = X·scale + offset, in double) and, for formats 2, 3, 5,
// 7, 8 and 10, the 16-bit RGB. The specification says RGB is scaled to 16 bits, but many writers
// store 0–255 in the 16-bit fields (the PDAL sample does): when no value exceeds 255 they are
// kept, otherwise every value is shifted right by 8.
//
// Checked before any point is read: signature "LASF", version 1.0–1.4, header size at least the
// version's minimum (227 / 235 / 375 bytes for 1.0–1.2 / 1.3 / 1.4), format ≤ 10 (bits 7 and 6 of
// the format byte, LAZ compression, masked off), record length ≥ the format's minimum, scale
// factors finite and non-zero, offsets finite, point data offset ≥ header size, and
// offset + count × record length ≤ file size (overflow-checked). Record lengths longer than the
// minimum ("extra bytes") are fine: we step by the declared length.
//
// LAZ (bit 7 or 6 of the format byte set, whatever the extension): the point data is LASzip
// chunks. laz_decoder.hpp checks the LASzip VLR and the chunk table against the file in place of
// the size check above, decodes the chunks (in parallel) to the records they replace, and those
// go through exactly the record parsing below, so a LAZ reads to the point_cloud of its LAS twin.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>

#include "laz_decoder.hpp"
#include "point_formats.hpp"

namespace pbr_lod::detail {
namespace {

// Minimum record length and RGB offset (0 = none) per point data record format.
constexpr std::uint16_t min_record_length[11] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};
constexpr std::uint16_t rgb_offset[11] = {0, 0, 20, 28, 0, 28, 0, 30, 30, 0, 30};

}  // namespace

las_header parse_las_header(const std::string& path, const unsigned char* b,
                            std::uint64_t file_size, read_report& report) {
  const std::string name = std::filesystem::path(path).filename().string();
  if (file_size < 4 || std::memcmp(b, "LASF", 4) != 0)
    format_error(path, "header", "expected the signature 'LASF' (not a LAS file)");
  if (file_size < 227)
    format_error(path, "header", cat("truncated: ", file_size, " bytes, a LAS header needs 227"));

  const unsigned major = b[24], minor = b[25];
  if (major != 1 || minor > 4)
    format_error(path, "header",
                 cat("unsupported LAS version ", major, ".", minor, " (expected 1.0 to 1.4)"));
  const std::uint16_t header_size = load_le<std::uint16_t>(b + 94);
  const std::uint32_t data_offset = load_le<std::uint32_t>(b + 96);
  const std::uint8_t format_byte = b[104];
  const std::uint16_t record_length = load_le<std::uint16_t>(b + 105);
  const std::uint32_t legacy_count = load_le<std::uint32_t>(b + 107);

  const std::uint16_t min_header = minor <= 2 ? 227 : minor == 3 ? 235 : 375;
  if (header_size < min_header)
    format_error(path, "header",
                 cat("header size ", header_size, " is below the ", min_header, " bytes LAS 1.",
                     minor, " requires"));
  if (header_size > file_size)
    format_error(
        path, "header",
        cat("truncated: header size ", header_size, " but the file has ", file_size, " bytes"));
  // Bits 7 and 6 of the format byte mark LAZ (LASzip) compressed points.
  const unsigned format = format_byte & 0x3Fu;
  if (format > 10)
    format_error(path, "header",
                 cat("unknown point data record format ", format, " (expected 0 to 10)"));
  if (record_length < min_record_length[format])
    format_error(path, "header",
                 cat("point record length ", record_length, " is smaller than the ",
                     min_record_length[format], " bytes format ", format, " needs"));

  las_header h;
  h.record_length = record_length;
  h.data_offset = data_offset;
  h.rgb_offset = rgb_offset[format];
  h.count = legacy_count;
  h.header_size = header_size;
  h.vlr_count = load_le<std::uint32_t>(b + 100);
  h.format = format;
  h.compressed = (format_byte & 0xC0) != 0;
  if (minor >= 4) {
    const std::uint64_t count64 = load_le<std::uint64_t>(b + 247);
    if (count64 != 0) {
      if (legacy_count != 0 && legacy_count != count64)
        report.warnings.push_back(cat(name, ": legacy point count ", legacy_count,
                                      " differs from the 64-bit count ", count64,
                                      "; using the latter"));
      h.count = count64;
    }
  }

  for (int a = 0; a < 3; ++a) {
    h.scale[a] = load_le<double>(b + 131 + 8 * a);
    h.offset[a] = load_le<double>(b + 155 + 8 * a);
    h.bmax[a] = load_le<double>(b + 179 + 16 * a);
    h.bmin[a] = load_le<double>(b + 187 + 16 * a);
    if (!std::isfinite(h.scale[a]) || h.scale[a] == 0.0)
      format_error(
          path, "header",
          cat("scale factor ", "xyz"[a], " = ", h.scale[a], " is not a finite non-zero number"));
    if (!std::isfinite(h.offset[a]))
      format_error(path, "header", cat("offset ", "xyz"[a], " is not finite"));
  }

  if (data_offset < header_size)
    format_error(path, "header",
                 cat("offset to point data ", data_offset, " lies inside the ", header_size,
                     "-byte header"));
  if (data_offset > file_size)
    format_error(path, "header",
                 cat("offset to point data ", data_offset, " is beyond the end of the file (",
                     file_size, " bytes)"));
  if (h.compressed) return h;  // read_laz_layout checks the chunks against the file
  const auto point_bytes = mul_checked(h.count, record_length);
  const auto end = point_bytes ? add_checked(data_offset, *point_bytes) : std::nullopt;
  if (!end || *end > file_size)
    format_error(path, "points",
                 cat("truncated: ", h.count, " points of ", record_length, " bytes from offset ",
                     data_offset, " need ", end ? cat(*end) : std::string("more than 2^64"),
                     " bytes, the file has ", file_size));
  return h;
}

void las_outside_warning(const std::string& path, std::uint64_t outside, read_report& report) {
  if (outside > 0)
    report.warnings.push_back(cat(std::filesystem::path(path).filename().string(), ": ", outside,
                                  " points lie outside the bounding box the header states"));
}

namespace {

/// The records of a LAZ file held in memory, decoded chunk by chunk in parallel.
std::unique_ptr<unsigned char[]> decode_laz_file(const std::string& path, const las_header& h,
                                                 const std::string& bytes) {
  const laz_layout L = read_laz_layout(path, h, bytes.size(),
                                       [&](std::uint64_t at, std::size_t n, unsigned char* out) {
                                         std::memcpy(out, bytes.data() + at, n);
                                       });
  // Not zero-filled: the decoders write every byte of every record (or throw).
  auto records = std::make_unique_for_overwrite<unsigned char[]>(
      static_cast<std::size_t>(h.count * h.record_length));
  decode_laz_chunks(
      path, L, 0, L.chunks.size(),
      [&](std::uint64_t at, std::size_t n, unsigned char* out) {
        std::memcpy(out, bytes.data() + at, n);
      },
      records.get());
  return records;
}

}  // namespace

raw_geometry read_las_file(const std::string& path, read_report& report) {
  const std::string bytes = read_file_bytes(path);
  const auto* b = reinterpret_cast<const unsigned char*>(bytes.data());
  const las_header h = parse_las_header(path, b, bytes.size(), report);
  const std::uint64_t count = h.count;
  // LAZ: the chunks decoded to the LAS records they replace, then read as LAS.
  std::unique_ptr<unsigned char[]> decoded;
  if (h.compressed) decoded = decode_laz_file(path, h, bytes);
  const unsigned char* records = h.compressed ? decoded.get() : b + h.data_offset;

  raw_geometry g;
  g.positions.resize(count);
  const unsigned char* rec = records;
  std::uint64_t outside = 0;
  for (std::uint64_t i = 0; i < count; ++i, rec += h.record_length) {
    g.positions[i] = h.position(rec);
    if (h.outside(g.positions[i])) ++outside;
  }

  if (h.rgb_offset != 0) {
    std::vector<std::array<std::uint16_t, 3>> rgb(count);
    std::uint16_t top = 0;
    rec = records;
    for (std::uint64_t i = 0; i < count; ++i, rec += h.record_length) {
      rgb[i] = h.rgb16(rec);
      top = std::max({top, rgb[i][0], rgb[i][1], rgb[i][2]});
    }
    const int shift = las_header::colour_shift(top);
    g.colours.resize(count);
    for (std::uint64_t i = 0; i < count; ++i) g.colours[i] = las_header::colour(rgb[i], shift);
  }
  las_outside_warning(path, outside, report);
  return g;
}

}  // namespace pbr_lod::detail
