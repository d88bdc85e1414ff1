// pbr_lod — internals of the LAS and PCD readers shared by read_points (las_reader.cpp,
// pcd_reader.cpp) and the streaming point source (point_source_file.cpp): header parsing and
// the decoding of one point. Not installed.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>

#include "io_internal.hpp"

namespace pbr_lod::detail {

// --- LAS ------------------------------------------------------------------------------------

/// A checked LAS header: where the records are and how to decode one.
struct las_header {
  std::uint32_t data_offset = 0;    ///< byte offset of the first point record
  std::uint16_t record_length = 0;  ///< bytes per record (≥ the format's minimum)
  std::uint16_t rgb_offset = 0;     ///< byte offset of R G B in a record; 0 = the format has none
  std::uint64_t count = 0;          ///< point records
  std::uint16_t header_size = 0;    ///< bytes of the header (the VLRs follow it)
  std::uint32_t vlr_count = 0;      ///< variable length records between header and points
  unsigned format = 0;              ///< point data record format, 0–10
  /// Bit 7 or 6 of the format byte: the records are LAZ (LASzip) chunks, not stored as they are
  /// (laz_decoder.hpp); the size check of the records is then the chunk table's.
  bool compressed = false;
  double scale[3] = {}, offset[3] = {}, bmin[3] = {}, bmax[3] = {};

  /// World position of the record at rec: X·scale + offset in double.
  [[nodiscard]] vec3d position(const unsigned char* rec) const {
    vec3d p;
    for (int a = 0; a < 3; ++a) p[a] = load_le<std::int32_t>(rec + 4 * a) * scale[a] + offset[a];
    return p;
  }
  /// Whether p lies outside the header's bounds by more than one quantum (a stale header).
  [[nodiscard]] bool outside(const vec3d& p) const {
    for (int a = 0; a < 3; ++a)
      if (p[a] < bmin[a] - std::abs(scale[a]) || p[a] > bmax[a] + std::abs(scale[a])) return true;
    return false;
  }
  /// The record's 16-bit R G B (the caller checks rgb_offset != 0).
  [[nodiscard]] std::array<std::uint16_t, 3> rgb16(const unsigned char* rec) const {
    return {load_le<std::uint16_t>(rec + rgb_offset), load_le<std::uint16_t>(rec + rgb_offset + 2),
            load_le<std::uint16_t>(rec + rgb_offset + 4)};
  }
  /// The specification scales RGB to 16 bits, but many writers store 0–255: kept as they are
  /// when no value in the file exceeds 255 (`top`), else every value is shifted right by 8.
  [[nodiscard]] static int colour_shift(std::uint16_t top) { return top > 255 ? 8 : 0; }
  [[nodiscard]] static rgb8 colour(const std::array<std::uint16_t, 3>& c, int shift) {
    return {static_cast<std::uint8_t>(c[0] >> shift), static_cast<std::uint8_t>(c[1] >> shift),
            static_cast<std::uint8_t>(c[2] >> shift)};
  }
};

/// Parses and checks the header of a LAS file of `file_size` bytes whose first
/// min(file_size, 375) bytes are at b; warnings go to `report`. Throws FormatError.
[[nodiscard]] las_header parse_las_header(const std::string& path, const unsigned char* b,
                                          std::uint64_t file_size, read_report& report);
/// The warning for `outside` points beyond the header's bounds (none when 0).
void las_outside_warning(const std::string& path, std::uint64_t outside, read_report& report);

// --- PCD ------------------------------------------------------------------------------------

struct pcd_field {
  std::string name;
  std::size_t size = 4;
  char type = 'F';
  std::uint64_t count = 1;
  std::uint64_t offset = 0;       ///< byte offset inside one point (binary / ascii value index)
  std::uint64_t value_index = 0;  ///< index of the first value in an ASCII row
};

struct pcd_header {
  std::vector<pcd_field> fields;
  std::uint64_t width = 0, height = 0, points = 0;
  std::uint64_t point_size = 0;  ///< bytes per point
  std::uint64_t values_per_point = 0;
  enum class data_kind { ascii, binary, compressed } data = data_kind::ascii;
  std::size_t data_begin = 0;
  std::size_t data_line = 0;
  double viewpoint[7] = {0, 0, 0, 1, 0, 0, 0};
};

/// Parses the header of the PCD whose first bytes are `bytes` (through the DATA line, or the
/// whole file). Throws FormatError.
[[nodiscard]] pcd_header parse_pcd_header(const std::string& path, std::string_view bytes);

/// POINTS × point size, the bytes of the data (FormatError when it overflows).
[[nodiscard]] std::uint64_t pcd_data_bytes(const std::string& path, const pcd_header& h);

/// The fields read_points uses (null when absent).
struct pcd_wanted {
  const pcd_field* xyz[3] = {};
  const pcd_field* normal[3] = {};
  const pcd_field* rgb = nullptr;
};
/// Finds x y z (FormatError without them), normals and colours; warns about VIEWPOINT and an
/// unusable colour field into `report`.
[[nodiscard]] pcd_wanted pcd_fields(const std::string& path, const pcd_header& h,
                                    read_report& report);

/// A point as stored, before finish_mesh's rules.
struct pcd_point {
  vec3d position;
  vec3f normal = vec3f::Zero();
  rgb8 colour{};
};

/// Reads one value of field f from raw little-endian bytes, as double.
[[nodiscard]] double pcd_load_value(const unsigned char* p, const pcd_field& f);
/// 0x00RRGGBB → rgb8.
[[nodiscard]] rgb8 pcd_unpack_rgb(std::uint32_t v);

/// One binary point; addr(f) gives where field f of this point starts.
template <class Addr>
[[nodiscard]] pcd_point pcd_load_point(const pcd_wanted& w, Addr addr) {
  pcd_point q;
  for (int a = 0; a < 3; ++a) q.position[a] = pcd_load_value(addr(*w.xyz[a]), *w.xyz[a]);
  if (w.normal[0])
    for (int a = 0; a < 3; ++a)
      q.normal[a] = static_cast<float>(pcd_load_value(addr(*w.normal[a]), *w.normal[a]));
  if (w.rgb) q.colour = pcd_unpack_rgb(load_le<std::uint32_t>(addr(*w.rgb)));
  return q;
}

/// One ASCII point from its line's values `tok` (point i, on line `line_no`). Throws FormatError.
[[nodiscard]] pcd_point pcd_parse_ascii_point(const std::string& path, const pcd_header& h,
                                              const pcd_wanted& w,
                                              const std::vector<std::string_view>& tok,
                                              std::uint64_t i, std::size_t line_no);
/// The FormatError for an ASCII file whose lines end before point i of n.
[[noreturn]] void pcd_ascii_truncated(const std::string& path, std::uint64_t i, std::uint64_t n);

/// Binary data: throws FormatError when the `available` bytes after the header hold fewer than
/// POINTS whole points, warns about bytes after the last one.
void pcd_check_binary_size(const std::string& path, const pcd_header& h, std::uint64_t available,
                           read_report& report);

}  // namespace pbr_lod::detail
